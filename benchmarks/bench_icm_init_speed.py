"""Issue 25 item 5, ICM row: the on-line initialisation at 10k and 100k poses (goal: ≤ 10 s at 100k).

The paper's init (:func:`slamcli.solvers.icm.common.online_init`) compares every sighting with every map point
(O(L) per sighting: 49 of 70 s at 100k poses in the issue's profile). The gated init
(:mod:`slamcli.solvers.icm.init_gated`) searches the map through a KD-tree (``scipy.spatial.cKDTree``) and
carries a pose covariance. World: a random walk on a 5 m street grid, landmarks near the grid nodes, a point
sensor of 8 m range, unknown association. Times are CPU seconds (``time.process_time``) of the init alone,
single-threaded (set ``OMP_NUM_THREADS=1``), on a shared machine; the paper init runs at the smaller size only
(its cost at 100k is the issue's measurement). ``python -m benchmarks icm_init_speed [--quick]`` (quick: 10k).
"""

from __future__ import annotations

import time

import numpy as np
from scipy.spatial import cKDTree

from slamcli.models import motion, observation
from slamcli.solvers.icm import energy as en
from slamcli.solvers.icm.common import online_init
from slamcli.solvers.icm.init_gated import gated_init
from slamcli.types import NoiseSpec, Observations, SlamInputs

#: sensor range, m, and noise of the world
RANGE_M = 8.0
NOISE = NoiseSpec(np.array([0.05, 0.02]), np.array([0.01, 0.01, 0.005]), 0.05, 0.01)


def street_world(T: int, seed: int = 0) -> SlamInputs:
    """A ``T``-step drive with landmarks on a jittered 5 m grid, sightings within :data:`RANGE_M`, no ids."""
    rng = np.random.default_rng(seed)
    dt = 0.5
    u = np.column_stack([np.full(T, 1.0), rng.normal(0.0, 0.15, T)])
    x0 = np.zeros(3)
    truth = motion.integrate(x0, u, dt)
    lo, hi = truth[:, :2].min(0) - RANGE_M, truth[:, :2].max(0) + RANGE_M
    gx, gy = np.meshgrid(np.arange(lo[0], hi[0], 5.0), np.arange(lo[1], hi[1], 5.0))
    lm = np.column_stack([gx.ravel(), gy.ravel()]) + rng.normal(0, 0.5, (gx.size, 2))
    near = cKDTree(lm).query_ball_point(truth[:, :2], r=RANGE_M)
    steps = np.repeat(np.arange(T + 1), [len(n) for n in near])
    ids = np.concatenate([np.asarray(n, int) for n in near])
    z = observation.range_bearing(truth[steps], lm[ids]) + rng.normal(0, [NOISE.range_std, NOISE.bearing_std],
                                                                       (len(ids), 2))
    obs = Observations.from_rows(steps, z, T + 1)
    u_meas = u + rng.normal(0, NOISE.motion_std, u.shape)
    return SlamInputs(dt=dt, timestamps=dt * np.arange(T + 1), x0=x0, controls=u_meas,
                      odometry_xyt=motion.integrate(x0, u_meas, dt), observations=obs, noise=NOISE)


def _time(fn, *args, **kw) -> tuple[float, object]:
    t0 = time.process_time()
    out = fn(*args, **kw)
    return time.process_time() - t0, out


def run(quick: bool = False) -> list[dict]:
    rows = []
    for T in [10_000] if quick else [10_000, 100_000]:
        inputs = street_world(T)
        prob = en.Problem.from_inputs(inputs)
        cpu, out = _time(gated_init, prob, inputs, gate_prob=0.99, birth_prob=0.9999)
        rows.append({"init": "gated", "poses": T, "sightings": prob.n_obs, "labels": int(out[2].shape[0]),
                     "cpu_s": cpu, "goal_s": 10.0 if T == 100_000 else None,
                     "met": (cpu <= 10.0) if T == 100_000 else None})
        if T == 10_000:
            W = en.Weights.from_params(1.0, 0.0, 1.0)
            cpu_p, out_p = _time(online_init, prob, W, radius=1.0)
            rows.append({"init": "online (paper)", "poses": T, "sightings": prob.n_obs,
                         "labels": int(out_p[2].shape[0]), "cpu_s": cpu_p, "goal_s": None, "met": None})
    return rows
