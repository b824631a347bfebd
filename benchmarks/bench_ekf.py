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
"""

from __future__ import annotations

import time

import numpy as np

from slamcli.sim import resolve_scenario, simulate_scenario
from slamcli.solvers.ekf import EkfParams, EkfSlam, update


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
    return rows
