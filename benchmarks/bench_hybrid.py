"""Hybrid SLAM (paper 001): steps/s and peak memory on Map 1 and Map 4, and the O(M) claim.

Per world (laser, seed 0, the full run length, the solver's own grid): the EKF part (``HybridSlam.
bayesian_part``) runs over all steps once and is timed; then the mapper (``map_scans``: E2 + the log-odds
baseline) runs over the first ``n_map_steps`` steps of the same beliefs and scans, timed in CPU time of this
process (``time.process_time``; the machine may be shared, so wall time is reported beside it). Columns: CPU
and wall ms per mapping step, EKF CPU ms per step, grid cells, peak traced memory of a short traced mapping
run (tracemalloc: grid and ray arrays) and the memory the snapshots add at the end (computed: 2 grids ×
n_snapshots × cells × 4 B). The Map 4 row compares the per-step mapping CPU time with Map 1's
(``ratio_cpu_ms_per_map_step_to_map1``, target ≤ 1.5: the cost per step follows the cells a scan crosses, not
the map size) and extrapolates the whole 2-lap run: EKF CPU + steps × mapping CPU per step (target 900 s).
Full mode also times the whole Map 4 run, 2 laps (the paper's run), in CPU and wall time.
"""

from __future__ import annotations

import time
import tracemalloc

import numpy as np

from slamcli.sim.simulate import simulate_scenario
from slamcli.solvers.hybrid import HybridParams, HybridSlam
from slamcli.solvers.hybrid.solver import grid_for_trajectory, map_scans, scan_geometry, scan_table


def _row(world: str, ds, params: HybridParams, n_map_steps: int) -> dict:
    inputs = ds.inputs
    c0, w0 = time.process_time(), time.perf_counter()
    ekf = HybridSlam(params).bayesian_part(inputs, np.random.default_rng(0))
    ekf_cpu, ekf_wall = time.process_time() - c0, time.perf_counter() - w0
    mu, cov = ekf.poses_xyt, ekf.pose_cov
    alphas, ranges = scan_table(inputs, params.scan_sensor)
    geo = scan_geometry(inputs, alphas)
    spec = grid_for_trajectory(mu, inputs.max_range + params.grid_margin, params.resolution, params.grid_offset)
    n = min(n_map_steps, inputs.n_poses)
    c0, w0 = time.process_time(), time.perf_counter()
    mp = map_scans(mu[:n], cov[:n], ranges[:n], geo, spec, params, np.random.default_rng(0))
    map_cpu, map_wall = time.process_time() - c0, time.perf_counter() - w0
    tracemalloc.start()
    map_scans(mu[:30], cov[:30], ranges[:30], geo, spec, params, np.random.default_rng(0))
    peak = tracemalloc.get_traced_memory()[1]
    tracemalloc.stop()
    steps = inputs.n_poses - 1
    cpu_ms = 1000 * map_cpu / n
    return {"world": world, "steps": steps, "map_steps_timed": n, "cpu_ms_per_map_step": cpu_ms,
            "wall_ms_per_map_step": 1000 * map_wall / n, "map_steps_per_cpu_s": 1000 / cpu_ms,
            "ekf_cpu_ms_per_step": 1000 * ekf_cpu / inputs.n_poses, "ekf_wall_s": ekf_wall,
            "mean_samples_kept": mp.samples_kept / n, "grid_cells": spec.n_cells, "peak_mem_mb_traced": peak / 1e6,
            "snapshot_mb": 2 * params.n_snapshots * spec.n_cells * 4 / 1e6,
            "extrapolated_cpu_s": ekf_cpu + cpu_ms * inputs.n_poses / 1000}


def run(quick: bool = False) -> list[dict]:
    n_map = 300 if quick else 900
    ds1 = simulate_scenario("hybrid-map1", 0)
    r1 = _row("hybrid-map1 (laser, 3 laps)", ds1, HybridParams(), n_map)
    ds4 = simulate_scenario("hybrid-map4", 0, {"walls.laps": 2})
    r4 = _row("hybrid-map4 (laser, 2 laps)", ds4, HybridParams(n_snapshots=8), n_map)
    ratio = r4["cpu_ms_per_map_step"] / r1["cpu_ms_per_map_step"]
    r4.update({"ratio_cpu_ms_per_map_step_to_map1": ratio, "flat_within_1_5x": bool(ratio <= 1.5),
               "target_s": 900.0, "extrapolated_within_target": bool(r4["extrapolated_cpu_s"] < 900.0)})
    rows = [r1, r4]
    if not quick:
        c0, w0 = time.process_time(), time.perf_counter()
        res = HybridSlam(HybridParams(n_snapshots=8)).solve(ds4.inputs, rng=np.random.default_rng(0))
        cpu, sec = time.process_time() - c0, time.perf_counter() - w0
        rows.append({"world": "hybrid-map4 (laser, 2 laps), whole run", "steps": ds4.inputs.n_poses - 1,
                     "cpu_s": cpu, "seconds": sec, "steps_per_cpu_s": ds4.inputs.n_poses / cpu,
                     "grid_cells": res.extra["grid_cells"], "target_s": 900.0, "within_target": bool(cpu < 900.0)})
    return rows
