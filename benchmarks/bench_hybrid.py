"""Hybrid SLAM (paper 001): steps/s and peak memory on Map 1 and Map 4, and the O(M) claim.

Per world (laser, seed 0): simulate, then time ``HybridSlam.solve`` on the first ``n_steps`` steps (the
paper's per-step cost: EKF on the features + E2 on the cells the scan crosses). Columns: steps/s, ms/step of
the whole solve, grid cells, cells updated per step, peak traced memory of the solve (tracemalloc), and — on
the Map 4 row — ``ratio_ms_per_step_to_map1``: the per-step time relative to Map 1 *in the same process*
(target ≤ 1.5: the cost per step must not grow with the map, only with the cells a scan crosses; Map 4's grid
has ~20× the cells of Map 1's). The last row runs the whole Map 4 with the laser for 2 laps (the paper's
run, ≈ 12 800 steps) unless ``--quick`` and checks the 15-min target (``within_target``).

Both worlds use the same solver parameters; the EKF part grows with the number of features (16 on Map 1,
~170 on Map 4: O(n²) per update), which is part of the measured time.
"""

from __future__ import annotations

import dataclasses
import time
import tracemalloc

import numpy as np

from slamcli.sim.simulate import simulate_scenario
from slamcli.solvers.hybrid import HybridParams, HybridSlam
from slamcli.types import Observations


def _truncate(inputs, n_steps: int):
    T = min(n_steps, inputs.n_poses - 1)
    o = inputs.observations
    m = o.step <= T
    obs = Observations.from_rows(o.step[m], o.z[m], T + 1, reported_id=o.reported_id[m], sensor=o.sensor[m])
    return dataclasses.replace(inputs, timestamps=inputs.timestamps[: T + 1], controls=inputs.controls[:T],
                               odometry_xyt=inputs.odometry_xyt[: T + 1], observations=obs)


def _measure(inputs, params: HybridParams) -> dict:
    tracemalloc.start()
    t0 = time.perf_counter()
    res = HybridSlam(params).solve(inputs, rng=np.random.default_rng(0))
    dt = time.perf_counter() - t0
    _, peak = tracemalloc.get_traced_memory()
    tracemalloc.stop()
    n = inputs.n_poses
    return {"steps": n, "seconds": dt, "steps_per_s": n / dt, "ms_per_step": 1000 * dt / n,
            "grid_cells": res.extra["grid_cells"], "cells_updated_per_step": res.extra["cells_updated_per_step"],
            "n_features": len(res.landmarks_xy), "peak_mem_mb": peak / 1e6}


def run(quick: bool = False) -> list[dict]:
    n_steps = 150 if quick else 600
    params = HybridParams(n_snapshots=2)
    rows = []
    ds1 = simulate_scenario("hybrid-map1", 0)
    r1 = _measure(_truncate(ds1.inputs, n_steps), params)
    rows.append({"world": "hybrid-map1 (laser)", **r1})
    ds4 = simulate_scenario("hybrid-map4", 0, {"walls.laps": 2})
    # the same number of steps from the start of Map 4 (the robot is in a corridor of the city blocks)
    r4 = _measure(_truncate(ds4.inputs, n_steps), params)
    ratio = r4["ms_per_step"] / r1["ms_per_step"]
    rows.append({"world": "hybrid-map4 (laser)", **r4, "ratio_ms_per_step_to_map1": ratio,
                 "flat_within_1_5x": bool(ratio <= 1.5)})
    if not quick:
        full = _measure(ds4.inputs, HybridParams(n_snapshots=8))
        rows.append({"world": "hybrid-map4 (laser), 2 laps, whole run", **full,
                     "target_s": 900.0, "within_target": bool(full["seconds"] < 900.0)})
    return rows
