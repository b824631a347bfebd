"""Issue 17, ICM row: the ``accelerate="joint"`` Gauss-Newton step at 10k / 50k / 100k poses.

The joint step used to solve the normal equations by a Schur complement on the map with a dense
``H_pp⁻¹ H_pm`` block of 3T × 2L doubles (9.2 GB at 100k poses and ~5k landmarks: a MemoryError, caught
silently). It now factorises the sparse normal matrix with a fill-reducing ordering
(:func:`slamcli.solvers.icm.energy.solve_normal_sparse`). Goal: 100k poses in < 4 GB.

World (built directly, city-like, the shape that broke the dense block): a random walk on a 5 m street grid
with landmarks on the grid, a point sensor of 8 m range seeing ≈ 10 landmarks per pose, known ids. Each size
runs in a fresh subprocess; ``peak_rss_mb`` is that process's ``ru_maxrss`` (world construction included),
``dense_block_gb`` the size of the 3T × 2L block the old step needed. ``python -m benchmarks icm_joint_scale
[--quick]`` (quick: 10k poses only).
"""

from __future__ import annotations

import json
import subprocess
import sys

CHILD = r'''
import json, resource, sys, time
import numpy as np
from scipy.spatial import cKDTree
from slamcli.models import motion, observation
from slamcli.solvers.icm import energy as en
from slamcli.solvers.icm.solver import reported_labels
from slamcli.types import NoiseSpec, Observations, SlamInputs

T = int(sys.argv[1]); rng = np.random.default_rng(0); dt = 0.5
u = np.column_stack([np.full(T, 1.0), rng.normal(0.0, 0.15, T)])
x0 = np.zeros(3); truth = motion.integrate(x0, u, dt)
lo, hi = truth[:, :2].min(0) - 8, truth[:, :2].max(0) + 8
gx, gy = np.meshgrid(np.arange(lo[0], hi[0], 5.0), np.arange(lo[1], hi[1], 5.0))
lm = np.column_stack([gx.ravel(), gy.ravel()]) + rng.normal(0, 0.5, (gx.size, 2))
tree = cKDTree(lm)
near = tree.query_ball_point(truth[:, :2], r=8.0)
steps = np.repeat(np.arange(T + 1), [len(n) for n in near]); ids = np.concatenate([np.asarray(n, int) for n in near])
z = observation.range_bearing(truth[steps], lm[ids]) + rng.normal(0, [0.05, 0.01], (len(ids), 2))
seen = np.unique(ids); remap = -np.ones(len(lm), int); remap[seen] = np.arange(len(seen))
obs = Observations.from_rows(steps, z, T + 1, reported_id=remap[ids])
inputs = SlamInputs(dt=dt, timestamps=dt * np.arange(T + 1), x0=x0, controls=u,
                    odometry_xyt=motion.integrate(x0, u + rng.normal(0, [0.02, 0.01], u.shape), dt),
                    observations=obs, noise=NoiseSpec(np.array([0.05, 0.02]), np.array([0.01, 0.01, 0.005]), 0.05, 0.01))
prob = en.Problem.from_inputs(inputs); W = en.Weights.from_params(1.0, 1.0, 1.0)
labels = reported_labels(obs.reported_id); L = int(labels.max()) + 1
poses = motion.integrate(x0, u, dt); lm0 = np.zeros((L, 2))
pts = prob.landmark_points(poses)
lm0 = np.stack([np.bincount(labels, pts[:, k], L) for k in (0, 1)], -1) / np.bincount(labels, minlength=L)[:, None]
E0 = en.energy(prob, W, poses, lm0, labels)
t0 = time.perf_counter()
p1, m1, E1, ok, err = en.joint_gn_step(prob, W, poses, lm0, labels)
dt_s = time.perf_counter() - t0
print(json.dumps({"poses": T, "landmarks": L, "observations": int(len(ids)), "step_s": dt_s, "accepted": bool(ok),
                  "error": err, "energy_ratio": E1 / E0,
                  "peak_rss_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024,
                  "dense_block_gb": 3 * T * 2 * L * 8 / 1e9}))
'''


def run(quick: bool = False) -> list[dict]:
    rows = []
    for T in ([10_000] if quick else [10_000, 50_000, 100_000]):
        out = subprocess.run([sys.executable, "-c", CHILD, str(T)], capture_output=True, text=True, check=False)
        if out.returncode != 0:
            rows.append({"poses": T, "error": (out.stderr.strip().splitlines() or ["failed"])[-1]})
            continue
        row = json.loads(out.stdout.strip().splitlines()[-1])
        row["under_4gb"] = row["peak_rss_mb"] < 4096
        rows.append(row)
    return rows
