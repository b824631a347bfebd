"""Issue 25 item 5, ICM row: the on-line initialisation at 1k / 10k / 100k poses (goal: ≤ 10 s at 100k) and the
CPU of one sequential ICM sweep per pose, before and after.

* ``before`` — the init as it was: every sighting compared with every running mean (a scan of all L labels,
  O(sightings × L), n^1.5 on a drive that keeps meeting new landmarks), Python pose kernels.
* ``after, python`` — the nearest mean through the grid hash
  (:class:`slamcli.solvers.icm.common.MeanGrid`), Python pose kernels (``SLAMCLI_NO_JIT=1``).
* ``after, numba`` — the same with the compiled pose kernels (optional extra ``fast``). Loading them (numba's
  import and on-disk cache) is a separate row, ``numba load``, paid once per process.

``same_as_before`` compares labels and poses with the ``before`` run of the same size (bit for bit). The sweep
rows time :func:`slamcli.solvers.icm.energy.sweep_poses_sequential` (Algorithm 2's visit order) from the init's
poses, Python and compiled kernels alternating, 3 of each (the median CPU), and the odd/even coding-scheme sweep
for reference; ``ratio`` = Python / this row.

World: a random walk on a 5 m street grid, landmarks near the grid nodes, a point sensor of 8 m range, unknown
association, R = Q = I, S = 0, ϑ = 1 m (paper §5). Times are CPU seconds (``time.process_time``) on a shared
machine; run single-threaded (``OMP_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1``).
``python -m benchmarks icm_init_speed [--quick]`` (quick: 1k and 10k poses, no gated init).
"""

from __future__ import annotations

import os
import time
from contextlib import contextmanager, nullcontext
from unittest import mock

import numpy as np
from scipy.spatial import cKDTree

from slamcli.models import motion, observation
from slamcli.solvers.icm import common
from slamcli.solvers.icm import energy as en
from slamcli.solvers.icm.init_gated import gated_init
from slamcli.types import NoiseSpec, Observations, SlamInputs

#: sensor range, m, and noise of the world
RANGE_M = 8.0
NOISE = NoiseSpec(np.array([0.05, 0.02]), np.array([0.01, 0.01, 0.005]), 0.05, 0.01)
#: the goal of issue 25 for the init at 100k poses, s
GOAL_100K_S = 10.0


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


class _FullScan(common.MeanGrid):
    """The init's map before the grid: every label is a candidate of every sighting (the original scan)."""

    def __init__(self, n_max: int, radius: float):
        super().__init__(n_max, radius)
        self.inv_h = None  # no cells to keep: candidates() below is the whole map

    def candidates(self, pts):
        return np.arange(self.L)


@contextmanager
def _python_kernels():
    old = os.environ.get(en.NO_JIT_ENV)
    os.environ[en.NO_JIT_ENV] = "1"
    try:
        yield
    finally:
        if old is None:
            os.environ.pop(en.NO_JIT_ENV)
        else:
            os.environ[en.NO_JIT_ENV] = old


def _cpu(fn, *args, **kw):
    t0 = time.process_time()
    out = fn(*args, **kw)
    return time.process_time() - t0, out


def _init_rows(T: int, prob, W, numba_ok: bool, run_before: bool) -> tuple[list[dict], tuple]:
    rows, ref = [], None
    base = {"part": "init", "poses": T + 1, "sightings": prob.n_obs}
    variants = [("before", True)] if run_before else []
    variants += [("after, python", False)] + ([("after, numba", False)] if numba_ok else [])
    for name, scan in variants:
        with mock.patch.object(common, "MeanGrid", _FullScan) if scan else nullcontext():
            if name != "after, numba":
                with _python_kernels():
                    cpu, out = _cpu(common.online_init, prob, W, radius=1.0)
            else:
                cpu, out = _cpu(common.online_init, prob, W, radius=1.0)
        if ref is None and scan:
            ref = out
        same = None if scan or ref is None else bool(np.array_equal(out[0], ref[0]) and np.array_equal(out[1], ref[1]))
        goal = GOAL_100K_S if T + 1 >= 100_000 and not scan else None
        rows.append({**base, "variant": name, "labels": int(out[2].shape[0]), "cpu_s": cpu,
                     "us_per_pose": 1e6 * cpu / (T + 1), "same_as_before": same, "goal_s": goal,
                     "met": None if goal is None else cpu <= goal})
    return rows, out


def _sweep_rows(T: int, prob, W, init, numba_ok: bool) -> list[dict]:
    poses0, labels, landmarks, _ = init
    stats = en.step_stats(prob, labels, landmarks, W)
    cpu: dict[str, list[float]] = {"sequential, python": [], "sequential, numba": [], "parallel (odd/even)": []}
    outs = {}
    for _ in range(3):  # alternating, so the machine's load falls on both alike
        for name in cpu:
            if name == "sequential, numba" and not numba_ok:
                continue
            p = poses0.copy()
            if name == "sequential, python":
                with _python_kernels():
                    c, outs[name] = _cpu(en.sweep_poses_sequential, prob, W, p, stats)
            elif name == "sequential, numba":
                c, outs[name] = _cpu(en.sweep_poses_sequential, prob, W, p, stats)
            else:
                c, outs[name] = _cpu(en.sweep_poses_parallel, prob, W, p, stats)
            cpu[name].append(c)
    py = float(np.median(cpu["sequential, python"]))
    rows = []
    for name, cs in cpu.items():
        if not cs:
            continue
        med = float(np.median(cs))
        same = bool(np.array_equal(outs[name], outs["sequential, python"])) if name.startswith("seq") else None
        rows.append({"part": "sweep", "poses": T + 1, "sightings": prob.n_obs, "variant": name, "cpu_s": med,
                     "us_per_pose": 1e6 * med / T, "ratio": py / med, "same_as_before": same})
    return rows


def run(quick: bool = False) -> list[dict]:
    t0 = time.process_time()
    numba_ok = en.compiled_kernels() is not None
    rows = [{"part": "numba load", "cpu_s": time.process_time() - t0 if numba_ok else None,
             "variant": "import + on-disk cache" if numba_ok else "numba not installed"}]
    W = en.Weights.from_params(1.0, 0.0, 1.0)
    for T in [1_000, 10_000] if quick else [1_000, 10_000, 100_000]:
        inputs = street_world(T)
        prob = en.Problem.from_inputs(inputs)
        init_rows, init = _init_rows(T, prob, W, numba_ok, run_before=True)
        rows += init_rows
        if T == 10_000:
            rows += _sweep_rows(T, prob, W, init, numba_ok)
        if T == 100_000 and not quick:
            cpu, out = _cpu(gated_init, prob, inputs, gate_prob=0.99, birth_prob=0.9999)
            rows.append({"part": "init", "poses": T + 1, "sightings": prob.n_obs, "variant": "gated (cKDTree)",
                         "labels": int(out[2].shape[0]), "cpu_s": cpu, "us_per_pose": 1e6 * cpu / (T + 1)})
    return rows
