"""Hybrid SLAM (paper 001): CPU time per mapping step against the number of map cells — the O(M) claim.

Per world (laser, seed 0): the first ``n_steps`` steps of the route (``walls.laps = 0``), the EKF part
(``HybridSlam.bayesian_part``) once, then the mapper (``map_scans``: E2 + the log-odds baseline) over those
steps on the grid the whole run would map: the walls' bounding box ± (max range + margin) (the solver sizes
its grid from the EKF trajectory, which runs along the corridors inside the walls). Worlds: Maps 1-4 (Map 4
only for these few steps — its whole 2-lap run is the ``paper001-map4`` reproduce section) and Map 1 on grids
padded by 200 m and 500 m (the same scans, only the map size changes).

Timing: CPU time of this process (``time.process_time``, single-threaded BLAS), the worlds alternated over
``rounds`` rounds and the least time per world kept (the machine may be shared). Columns: ``grid_cells``,
``cpu_ms_per_map_step``, ``ratio_to_map1`` (same steps on the larger grid / Map 1), ``ekf_cpu_ms_per_step``,
``mean_samples_kept``. The reproduce section ``paper001`` reads this table (``benchmarks/results/hybrid.csv``)
and fits the log-log slope of CPU per step against grid cells (linear in M ⇔ slope ≤ 1.2; a per-step cost that
does not grow with M gives ≈ 0).
"""

from __future__ import annotations

import os
import time

import numpy as np

from slamcli.sim.simulate import simulate_scenario
from slamcli.solvers.hybrid import HybridParams, HybridSlam
from slamcli.solvers.hybrid.solver import grid_for_trajectory, map_scans, scan_geometry, scan_table

#: (label, scenario, extra grid padding m)
WORLDS = (("Map 1", "hybrid-map1", 0.0), ("Map 2", "hybrid-map2", 0.0), ("Map 3", "hybrid-map3", 0.0),
          ("Map 4", "hybrid-map4", 0.0), ("Map 1, grid padded by 200 m", "hybrid-map1", 200.0),
          ("Map 1, grid padded by 500 m", "hybrid-map1", 500.0))


def _prepare(scenario: str, pad: float, n_steps: int, params: HybridParams) -> dict:
    ds = simulate_scenario(scenario, 0, {"walls.laps": 0, "n_steps": n_steps})
    inputs = ds.inputs
    c0 = time.process_time()
    ekf = HybridSlam(params).bayesian_part(inputs, np.random.default_rng(0))
    ekf_cpu = time.process_time() - c0
    alphas, ranges = scan_table(inputs, params.scan_sensor)
    w = np.asarray(ds.truth.walls_xyxy, float)
    corners = np.column_stack([np.r_[w[:, 0], w[:, 2]], np.r_[w[:, 1], w[:, 3]]])  # the world's extent
    spec = grid_for_trajectory(corners, inputs.max_range + params.grid_margin + pad, params.resolution,
                               params.grid_offset)
    return {"mu": ekf.poses_xyt, "cov": ekf.pose_cov, "ranges": ranges, "geo": scan_geometry(inputs, alphas),
            "spec": spec, "ekf_ms": 1000 * ekf_cpu / inputs.n_poses}


def run(quick: bool = False) -> list[dict]:
    os.environ.setdefault("OMP_NUM_THREADS", "1")
    os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
    n_steps, rounds = (120, 1) if quick else (400, 2)
    params = HybridParams(n_snapshots=1)
    prep = {lab: _prepare(scen, pad, n_steps, params) for lab, scen, pad in WORLDS}
    best = {lab: np.inf for lab in prep}
    kept = {}
    for _ in range(rounds):
        for lab, d in prep.items():  # alternated: a load change hits every world alike
            c0 = time.process_time()
            mp = map_scans(d["mu"], d["cov"], d["ranges"], d["geo"], d["spec"], params, np.random.default_rng(0))
            best[lab] = min(best[lab], 1000 * (time.process_time() - c0) / len(d["mu"]))
            kept[lab] = mp.samples_kept / len(d["mu"])
    ref = best[WORLDS[0][0]]
    return [{"world": lab, "steps_timed": len(prep[lab]["mu"]), "rounds": rounds,
             "grid_cells": prep[lab]["spec"].n_cells, "cpu_ms_per_map_step": best[lab],
             "ratio_to_map1": best[lab] / ref, "ekf_cpu_ms_per_step": prep[lab]["ekf_ms"],
             "mean_samples_kept": kept[lab]} for lab, _s, _p in WORLDS]
