"""EKF-SLAM throughput: steps/s with known and maximum-likelihood association.

Worlds (``slamcli.sim``, seed 0, ``sensor.report_ids=true`` so ``known`` can run):

* ``paper-sim1`` — the paper-000 Simulation-1 world with its 181-beam laser (several returns per post,
  ≈ 40 observations per step, 63 landmarks). Full mode runs the whole 3250-step run, quick mode 300 steps.
* ``paper-sim1/point`` — the same world and path with a point sensor (one return per visible landmark,
  ``sensor.kind=point``, σ_b = 0.01 rad), the setting EKF-SLAM is designed for.

Association variants: ``known`` (reported ids), ``ml+provisional`` and plain ``ml`` on the same world with
``clutter.rate=0``. The scenario has 0.2 clutter returns per scan; plain ML turns each one that gates nowhere
into a landmark (≈650 over the full run), so its state — and its O(n²) update — grows with the clutter and
the run measures the clutter, not the filter; the provisional list drops those candidates. On the laser
world the ML variants use ``group_returns`` (one measurement per post and step) with
``range_offset = π/4 · landmark_radius`` (returns come from the post's surface, not its centre); ``known``
is run both raw (every return fused as an independent centre measurement) and grouped.
Each row: steps/s and updates/s of the whole ``solve`` (best of ``repeats``), number of landmarks, mean
position error against the truth (a sanity column, not a target). A last row compares one Joseph-form update
of :func:`slamcli.solvers.ekf.update` (sparse H: O(n²)) with the textbook dense form
``P = (I−KH)P(I−KH)ᵀ + KRKᵀ`` with a full ``(2, n)`` H (O(n³)) at the final state size of the laser run,
measured in the same process: ``ratio = dense / ours``.

Scale rows (``ekf n=…``, issues 17 and 25): the filter against :func:`blas_reference_ekf` — an EKF-SLAM
written from the textbook with plain numpy and ``scipy.linalg.blas`` (known association, ``P`` preallocated
at its final size, one in-place ``dgemm`` rank-2 update ``P −= K Uᵀ`` per observation) — on
:func:`ekf_scale_world` worlds whose ``L = (n − 3)/2`` landmarks (50, 500, 2000) are all seen at step 0, so
that every later update runs at state size ``n``. Both run the same data alternately in one child process
with every BLAS pool at one thread; CPU time (``time.process_time``). ``ratio_ours_over_reference`` is over
the steps after step 0 (goal ≤ 1.2, issue 25 item 5), ``ratio_whole_run`` includes step 0, where our state
grows landmark by landmark and the reference's is preallocated; ``max_pose_diff``: they compute the same
filter, so their poses agree to round-off. ``python -m benchmarks scale`` runs the same measurement in
subprocesses with peak RSS.
"""

from __future__ import annotations

import time

import numpy as np

from slamcli.models.angles import wrap_angle_fast
from slamcli.sim import resolve_scenario, simulate_scenario
from slamcli.solvers.ekf import EkfParams, EkfSlam, update
from slamcli.types import NoiseSpec, Observations, SlamInputs

SCALE_N = (103, 1003, 4003)  # L = 50, 500, 2000 landmarks


def ekf_scale_world(n: int, n_steps: int, obs_per_step: int = 10, seed: int = 0) -> SlamInputs:
    """Known-id inputs with state size ``n = 3 + 2L``: all ``L`` landmarks observed at step 0, then
    ``obs_per_step`` random landmarks per step (no range limit), robot on a slow circle in a 100 m square."""
    rng = np.random.default_rng(seed)
    L = (n - 3) // 2
    dt, v, w = 0.1, 1.0, 0.05
    lm = rng.uniform(-50, 50, size=(L, 2))
    u = np.tile([v, w], (n_steps, 1))
    u_true = u + rng.normal(0, [0.05, 0.01], size=u.shape)
    poses = np.zeros((n_steps + 1, 3))
    for t in range(n_steps):
        x, y, th = poses[t]
        poses[t + 1] = [x + dt * u_true[t, 0] * np.cos(th), y + dt * u_true[t, 0] * np.sin(th),
                        wrap_angle_fast(th + dt * u_true[t, 1])]
    steps, ids = [np.zeros(L, np.int64)], [np.arange(L)]
    for t in range(1, n_steps + 1):
        steps.append(np.full(obs_per_step, t))
        ids.append(rng.choice(L, size=obs_per_step, replace=False))
    step, rid = np.concatenate(steps), np.concatenate(ids)
    d = lm[rid] - poses[step, :2]
    z = np.stack([np.hypot(d[:, 0], d[:, 1]), np.arctan2(d[:, 1], d[:, 0]) - poses[step, 2]], -1)
    z += rng.normal(0, [0.1, 0.01], size=z.shape)
    return SlamInputs(
        dt=dt, timestamps=dt * np.arange(n_steps + 1), x0=np.zeros(3), controls=u, odometry_xyt=poses.copy(),
        observations=Observations.from_rows(step, z, n_steps + 1, reported_id=rid),
        noise=NoiseSpec(motion_std=np.array([0.05, 0.01]), odometry_std=np.array([0.01, 0.01, 0.005]),
                        range_std=0.1, bearing_std=0.01),
    )


def blas_reference_ekf(inputs: SlamInputs, on_step0=None) -> tuple[np.ndarray, int]:
    """In-place BLAS EKF-SLAM (Thrun et al. ch. 10), known association, DDMR prediction from the controls —
    the yardstick of issue 25 item 5.

    ``P (n, n)`` is allocated once at its final size (one slot per reported id); every observation is one
    in-place rank-2 update ``P −= K Uᵀ`` with ``U = P Hᵀ`` over the 5 nonzero columns of ``H`` and
    ``K = U S⁻¹``, written by ``scipy.linalg.blas.dgemm`` (``beta = 1``, ``overwrite_c``) into ``P``'s
    Fortran-order transpose (``K Uᵀ`` is symmetric): one pass over ``P``, no (n, n) temporary, no per-update
    allocation of ``P``'s size. Written independently of :mod:`slamcli.solvers.ekf`. ``on_step0()`` is called
    once step 0 (every landmark's initialisation in :func:`ekf_scale_world`) is done. Returns the filtered
    poses ``(T+1, 3)`` and the number of updates.
    """
    from scipy.linalg.blas import dgemm

    obs = inputs.observations
    rid = np.asarray(obs.reported_id)
    slot = {int(k): i for i, k in enumerate(np.unique(rid[rid >= 0]))}
    n = 3 + 2 * len(slot)
    x = np.zeros(n)
    x[:3] = inputs.x0
    P = np.zeros((n, n))
    PT = P.T  # Fortran-order view: what dgemm updates in place
    seen = np.zeros(len(slot), bool)
    R = np.diag([inputs.noise.range_std**2, inputs.noise.bearing_std**2])
    M = np.diag(np.square(inputs.noise.motion_std))
    dt, T = inputs.dt, inputs.n_poses - 1
    poses = np.empty((T + 1, 3))
    n_upd = 0
    for t in range(T + 1):
        if t > 0:
            v, w = inputs.controls[t - 1]
            c, s = np.cos(x[2]), np.sin(x[2])
            F = np.array([[1, 0, -dt * v * s], [0, 1, dt * v * c], [0, 0, 1.0]])
            G = np.array([[dt * c, 0], [dt * s, 0], [0, dt]])
            x[:3] += [dt * v * c, dt * v * s, dt * w]
            x[2] = wrap_angle_fast(x[2])
            P[:3, :] = F @ P[:3, :]
            P[:, :3] = P[:, :3] @ F.T
            P[:3, :3] += G @ M @ G.T
        for i in range(int(obs.offsets[t]), int(obs.offsets[t + 1])):
            if rid[i] < 0:
                continue
            j = slot[int(rid[i])]
            k = 3 + 2 * j
            r, b = float(obs.range_m[i]), float(obs.bearing_rad[i])
            if not seen[j]:  # m = p + r [cos(θ+b), sin(θ+b)], linearised covariance
                seen[j] = True
                c, s = np.cos(x[2] + b), np.sin(x[2] + b)
                x[k : k + 2] = x[:2] + r * np.array([c, s])
                Mx = np.array([[1, 0, -r * s], [0, 1, r * c]])
                Mz = np.array([[c, -r * s], [s, r * c]])
                P[k : k + 2, :] = Mx @ P[:3, :]
                P[:, k : k + 2] = P[k : k + 2, :].T
                P[k : k + 2, k : k + 2] = Mx @ P[:3, :3] @ Mx.T + Mz @ R @ Mz.T
                continue
            dx, dy = x[k] - x[0], x[k + 1] - x[1]
            q = dx * dx + dy * dy
            sq = np.sqrt(q)
            H = np.array([[-dx / sq, -dy / sq, 0, dx / sq, dy / sq], [dy / q, -dx / q, -1, -dy / q, dx / q]])
            U = P[:, :3] @ H[:, :3].T + P[:, k : k + 2] @ H[:, 3:].T  # P Hᵀ (n, 2)
            S = H[:, :3] @ U[:3] + H[:, 3:] @ U[k : k + 2] + R
            K = np.asfortranarray(np.linalg.solve(S, U.T).T)
            y = np.array([r - sq, wrap_angle_fast(b - np.arctan2(dy, dx) + x[2])])
            x += K @ y
            x[2] = wrap_angle_fast(x[2])
            dgemm(-1.0, K, np.asfortranarray(U), 1.0, PT, trans_b=1, overwrite_c=1)  # P −= K Uᵀ in place
            n_upd += 1
        poses[t] = x[:3]
        if t == 0 and on_step0 is not None:
            on_step0()
    return poses, n_upd


def scale_row(n: int, n_steps: int, which: str) -> dict:
    """Time one filter (``which`` = "slamcli" | "reference") on :func:`ekf_scale_world` of size ``n``.

    CPU time (``time.process_time``) of the whole run and of the steps after step 0 (``steady``: every
    update at state size ``n``; step 0 initialises all landmarks, where our state grows and the reference's
    is preallocated at its final size).
    """
    inputs = ekf_scale_world(n, n_steps)
    marks: list[float] = []
    c0 = time.process_time()
    if which == "slamcli":
        res = EkfSlam(EkfParams(association="known")).solve(
            inputs, rng=np.random.default_rng(0),
            progress=lambda done, total: marks.append(time.process_time()) if not marks else None)
        poses, n_upd = res.poses_xyt, res.extra["n_updates"]
    else:
        poses, n_upd = blas_reference_ekf(inputs, on_step0=lambda: marks.append(time.process_time()))
    c2 = time.process_time()
    steady_upd = n_steps * 10  # ekf_scale_world: 10 observations per step after step 0
    return {"cpu_s": c2 - c0, "steady_cpu_s": c2 - marks[0], "updates": n_upd,
            "us_per_update": (c2 - marks[0]) / steady_upd * 1e6, "poses": poses}


def scale_pair(n: int, n_steps: int, repeats: int = 2) -> dict:
    """Ours and the BLAS reference alternately in this process (best of ``repeats`` each)."""
    import scipy.linalg.blas  # noqa: F401 — imported before any timing: both sides measure arithmetic only

    best: dict[str, dict] = {}
    for _ in range(repeats):
        for which in ("slamcli", "reference"):
            r = scale_row(n, n_steps, which)
            if which not in best or r["steady_cpu_s"] < best[which]["steady_cpu_s"]:
                best[which] = r
    ours, ref = best["slamcli"], best["reference"]
    return {
        "updates": ours["updates"],
        "ours_us_per_update": ours["us_per_update"],
        "reference_us_per_update": ref["us_per_update"],
        "ratio_ours_over_reference": ours["steady_cpu_s"] / ref["steady_cpu_s"],
        "ratio_whole_run": ours["cpu_s"] / ref["cpu_s"],
        "max_pose_diff": float(np.abs(ours["poses"] - ref["poses"]).max()),
    }


def scale_pair_single_threaded(n: int, n_steps: int) -> dict:
    """:func:`scale_pair` in a child process with every BLAS/OpenMP pool at one thread (the variables must be
    set before numpy loads its BLAS, hence the child)."""
    import json
    import os
    import subprocess
    import sys
    from pathlib import Path

    env = {**os.environ, "OMP_NUM_THREADS": "1", "OPENBLAS_NUM_THREADS": "1", "MKL_NUM_THREADS": "1"}
    code = f"import json; from benchmarks.bench_ekf import scale_pair; print(json.dumps(scale_pair({n}, {n_steps})))"
    out = subprocess.run([sys.executable, "-c", code], env=env, check=True, capture_output=True, text=True,
                         cwd=Path(__file__).resolve().parent.parent)
    return json.loads(out.stdout.strip().splitlines()[-1])


def _dense_joseph_update(x, P, z, j, R):
    """Reference: textbook dense EKF update with a full H (2, n), O(n³)."""
    from slamcli.models import observation

    n = x.shape[0]
    k = 3 + 2 * j
    H_r, H_m = observation.range_bearing_jacobians(x[:3], x[k : k + 2])
    H = np.zeros((2, n))
    H[:, :3] = H_r
    H[:, k : k + 2] = H_m
    y = observation.measurement_residual(z, observation.range_bearing(x[:3], x[k : k + 2]))
    S = H @ P @ H.T + R
    K = P @ H.T @ np.linalg.inv(S)
    I_KH = np.eye(n) - K @ H
    return x + K @ y, I_KH @ P @ I_KH.T + K @ R @ K.T


def _time_solve(ds, params, repeats):
    best, res = np.inf, None
    for _ in range(repeats):
        t0 = time.perf_counter()
        res = EkfSlam(params).solve(ds.inputs, rng=np.random.default_rng(0))
        best = min(best, time.perf_counter() - t0)
    return best, res


def run(quick: bool = False) -> list[dict]:
    n_steps = 300 if quick else None
    repeats = 1
    worlds = {
        "paper-sim1": {"sensor.report_ids": True},
        "paper-sim1/point": {"sensor.report_ids": True, "sensor.kind": "point", "sensor.bearing_std": 0.01},
    }
    rows: list[dict] = []
    final_state = None
    for name, ov in worlds.items():
        ov = dict(ov)
        if n_steps:
            ov["n_steps"] = n_steps
        ds = simulate_scenario("paper-sim1", seed=0, overrides=ov)
        ds_clean = simulate_scenario("paper-sim1", seed=0, overrides={**ov, "clutter.rate": 0.0})
        if name == "paper-sim1":
            # laser: one measurement per post and step, re-centred by π/4 · radius (see module docstring)
            g = {"group_returns": True, "range_offset": np.pi / 4 * resolve_scenario("paper-sim1").world.landmark_radius}
            variants = {
                "known": (EkfParams(association="known"), ds),
                "known+grouped": (EkfParams(association="known", **g), ds),
                "ml+provisional+grouped": (EkfParams(association="ml", provisional=True, **g), ds),
                "ml+grouped (no clutter)": (EkfParams(association="ml", **g), ds_clean),
            }
        else:
            variants = {
                "known": (EkfParams(association="known"), ds),
                "ml+provisional": (EkfParams(association="ml", provisional=True), ds),
                "ml (no clutter)": (EkfParams(association="ml"), ds_clean),
            }
        for assoc, (params, data) in variants.items():
            T1 = data.inputs.n_poses
            wall, res = _time_solve(data, params, repeats)
            err = np.linalg.norm(res.poses_xyt[:, :2] - data.truth.poses_xyt[:, :2], axis=1)
            rows.append(
                {
                    "world": name,
                    "association": assoc,
                    "steps": T1,
                    "observations": len(data.inputs.observations),
                    "landmarks_true": int(data.truth.landmarks_xy.shape[0]),
                    "landmarks_est": int(res.landmarks_xy.shape[0]),
                    "wall_s": wall,
                    "steps_per_s": T1 / wall,
                    "updates_per_s": res.extra["n_updates"] / wall,
                    "mean_pos_err_m": float(err.mean()),
                    "status": res.status.value,
                }
            )
            if name == "paper-sim1" and assoc == "known":
                final_state = res

    # sparse vs dense update at the final state size of the laser run (same process, same inputs)
    L = final_state.landmarks_xy.shape[0]
    n = 3 + 2 * L
    rng = np.random.default_rng(1)
    x = np.r_[final_state.poses_xyt[-1], final_state.landmarks_xy.ravel()]
    A = rng.normal(size=(n, n))
    P = A @ A.T / n * 1e-2 + 1e-3 * np.eye(n)
    R = np.diag([0.25**2, 0.017**2])
    z = np.array([5.0, 0.2])
    reps = 50 if quick else 200

    def bench(fn):
        best = np.inf
        for _ in range(3):
            t0 = time.perf_counter()
            for i in range(reps):
                fn(x, P, z, i % L, R)
            best = min(best, (time.perf_counter() - t0) / reps)
        return best

    t_ours = bench(update)
    t_dense = bench(_dense_joseph_update)
    xo, Po = update(x, P, z, 0, R)[:2]
    xd, Pd = _dense_joseph_update(x, P, z, 0, R)
    rows.append(
        {
            "world": f"update n={n}",
            "association": "-",
            "ours_us": t_ours * 1e6,
            "dense_us": t_dense * 1e6,
            "ratio_dense_over_ours": t_dense / t_ours,
            "max_abs_diff_P": float(np.abs(Po - Pd).max()),
            "max_abs_diff_x": float(np.abs(xo - xd).max()),
        }
    )
    # scale rows: our filter vs the in-place BLAS reference at L = 50 / 500 / 2000 landmarks (same data,
    # same child process, single-threaded; CPU time of the steps after step 0)
    for n in SCALE_N:
        n_steps = (20 if quick else 100) if n < 2000 else (4 if quick else 30)
        rows.append({"world": f"ekf n={n}", "association": "known", "landmarks": (n - 3) // 2, "steps": n_steps + 1,
                     **scale_pair_single_threaded(n, n_steps)})
    return rows
