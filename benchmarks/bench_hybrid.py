"""Hybrid SLAM (paper 001): steps/s and peak memory on Map 1 and Map 4, and the O(M) claim.

Per world (laser, seed 0, full run length, the solver's full grid): the EKF part runs over all steps first,
then the mapper; the progress callback timestamps every mapping step and stops the solve after
``n_map_steps`` of them, so both worlds are timed over the same number of mapping steps with their real
grids (Map 1: ~1.3·10⁵ cells, Map 4: ~10⁶). Columns: ms per mapping step (E2 + log-odds baseline, steps
``n_warm…n_map_steps``), EKF ms per step, grid cells, peak traced memory of a short traced solve
(tracemalloc, grid and ray arrays; tracing slows numpy, so it is a separate run) and the memory the
snapshots add at the end (computed: 2 grids × n_snapshots × cells × 4 B). On the Map 4 row
``ratio_ms_per_map_step_to_map1`` compares the per-step mapping time in the same process (target ≤ 1.5:
the cost per step grows with the cells a scan crosses, not with the map). Full mode adds the whole Map 4
run with the laser, 2 laps (the paper's run) and checks the 15-min target.
"""

from __future__ import annotations

import time
import tracemalloc

import numpy as np

from slamcli.sim.simulate import simulate_scenario
from slamcli.solvers.hybrid import HybridParams, HybridSlam


class _Stop(Exception):
    pass


def _timed(inputs, params: HybridParams, n_map_steps: int, traced: bool = False) -> dict:
    n = inputs.n_poses
    stamps: dict[int, float] = {}

    def progress(done: int, total: int) -> None:
        stamps[done] = time.perf_counter()
        if done >= n + n_map_steps:
            raise _Stop

    if traced:
        tracemalloc.start()
    t0 = time.perf_counter()
    try:
        HybridSlam(params).solve(inputs, rng=np.random.default_rng(0), progress=progress)
    except _Stop:
        pass
    peak = tracemalloc.get_traced_memory()[1] if traced else 0
    if traced:
        tracemalloc.stop()
    keys = sorted(k for k in stamps if k > n)
    ekf_s = min(stamps[k] for k in keys) - t0 if keys else float("nan")
    return {"stamps": stamps, "keys": keys, "ekf_s": ekf_s, "peak_mb": peak / 1e6}


def _row(world: str, ds, params: HybridParams, n_map_steps: int, n_warm: int) -> dict:
    from slamcli.solvers.hybrid.solver import grid_for_trajectory

    r = _timed(ds.inputs, params, n_map_steps)
    st, keys = r["stamps"], r["keys"]
    k0 = next(k for k in keys if k >= ds.inputs.n_poses + n_warm)
    k1 = keys[-1]
    ms = 1000 * (st[k1] - st[k0]) / (k1 - k0)
    mem = _timed(ds.inputs, params, 30, traced=True)["peak_mb"]
    spec = grid_for_trajectory(ds.truth.poses_xyt, ds.inputs.max_range + params.grid_margin, params.resolution,
                               params.grid_offset)  # ≈ the solver's grid (it uses the EKF trajectory)
    return {"world": world, "steps": ds.inputs.n_poses - 1, "ms_per_map_step": ms, "map_steps_per_s": 1000 / ms,
            "ekf_ms_per_step": 1000 * r["ekf_s"] / ds.inputs.n_poses, "grid_cells": spec.n_cells,
            "peak_mem_mb_traced": mem, "snapshot_mb": 2 * params.n_snapshots * spec.n_cells * 4 / 1e6}


def run(quick: bool = False) -> list[dict]:
    n_map, n_warm = (300, 20) if quick else (900, 50)  # the solver reports progress every T/200 steps
    params = HybridParams()
    ds1 = simulate_scenario("hybrid-map1", 0)
    r1 = _row("hybrid-map1 (laser)", ds1, params, n_map, n_warm)
    ds4 = simulate_scenario("hybrid-map4", 0, {"walls.laps": 2})
    r4 = _row("hybrid-map4 (laser, 2 laps)", ds4, HybridParams(n_snapshots=8), n_map, n_warm)
    ratio = r4["ms_per_map_step"] / r1["ms_per_map_step"]
    r4.update({"ratio_ms_per_map_step_to_map1": ratio, "flat_within_1_5x": bool(ratio <= 1.5)})
    rows = [r1, r4]
    if not quick:
        t0 = time.perf_counter()
        res = HybridSlam(HybridParams(n_snapshots=8)).solve(ds4.inputs, rng=np.random.default_rng(0))
        sec = time.perf_counter() - t0
        rows.append({"world": "hybrid-map4 (laser, 2 laps), whole run", "steps": ds4.inputs.n_poses - 1,
                     "seconds": sec, "steps_per_s": ds4.inputs.n_poses / sec, "grid_cells": res.extra["grid_cells"],
                     "target_s": 900.0, "within_target": bool(sec < 900.0)})
    return rows
