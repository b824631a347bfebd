"""Paper 001's claims measured beyond the map figures: consistency over seeds, stored complexity
results, and the mapping with given poses that explains the noisy-sensor plateau.

* :func:`nees_monte_carlo` — the Bayesian part (the EKF on the features) over N seeds; per step the average
  NEES over the seeds (ANEES, d = 3) against the two-sided χ²(3N)/N band (Bailey et al. 2006, paper 001's
  ref. [20]). The scan does not enter the EKF, so the runs simulate 2 beams instead of the full scan: the
  feature rows — and so the EKF's output — are the same (the scan draws come after the feature draws).
* :func:`read_complexity` — the per-step mapping CPU time vs map cells that ``python -m benchmarks hybrid``
  stores in ``benchmarks/results/hybrid.csv`` (the section does not time anything itself).
* :func:`map_with_given_poses` — E2 from a single pose per step (the true pose, or the EKF mean), snapshots
  at the lap ends: how much of the map error is the sensor's and how much the belief's.
"""

from __future__ import annotations

import csv
import math
from pathlib import Path

import numpy as np

from slamcli.metrics.consistency import chi2_band

#: a two-sided 95 % band of the mean NEES over N independent seeds (χ²(3N)/N quantiles, d = 3)
NEES_BAND_PROB = 0.95
#: seeds a configuration needs before its NEES is judged against the band
NEES_MIN_SEEDS = 20
#: a configuration is calibrated when at least this fraction of its steps has the ANEES inside the band ...
NEES_INSIDE_MIN = 0.9
#: ... and optimistic (inconsistent) when more than this fraction lies above it
NEES_ABOVE_MAX = 0.05
#: the stored benchmark table (relative to the repository root)
COMPLEXITY_CSV = Path("benchmarks") / "results" / "hybrid.csv"


def nees_summary(nees: np.ndarray, label: str = "") -> dict:
    """Per-step ANEES of ``nees (N seeds, T steps)`` (NaN steps, e.g. the known start, left out) against
    :func:`slamcli.metrics.consistency.chi2_band` (3 dof, :data:`NEES_BAND_PROB`):
    ``{label, n_seeds, anees_mean, inside, above, below, lo, hi}`` (fractions of steps)."""
    nees = np.atleast_2d(np.asarray(nees, float))
    cols = np.all(np.isfinite(nees), axis=0)
    anees = nees[:, cols].mean(axis=0)
    n = nees.shape[0]
    lo, hi = chi2_band(n, 3, NEES_BAND_PROB)
    return {"label": label, "n_seeds": n, "anees_mean": float(anees.mean()) if anees.size else math.nan,
            "inside": float(np.mean((anees >= lo) & (anees <= hi))) if anees.size else math.nan,
            "above": float(np.mean(anees > hi)) if anees.size else math.nan,
            "below": float(np.mean(anees < lo)) if anees.size else math.nan, "lo": lo, "hi": hi}


def nees_class(s: dict) -> str:
    """``"not judged"`` (fewer than :data:`NEES_MIN_SEEDS` seeds), ``"optimistic"``, ``"calibrated"`` or
    ``"conservative"`` from a :func:`nees_summary`."""
    if s["n_seeds"] < NEES_MIN_SEEDS:
        return "not judged"
    if s["above"] > NEES_ABOVE_MAX:
        return "optimistic"
    return "calibrated" if s["inside"] >= NEES_INSIDE_MIN else "conservative"


def nees_monte_carlo(scenario: str, seeds, overrides: dict | None = None, params: dict | None = None) -> np.ndarray:
    """Pose NEES ``(N, T_min + 1)`` of the hybrid solver's Bayesian part over ``seeds`` (each run cut to the
    shortest: runs that end at a lap end differ in length by a few steps)."""
    from slamcli.metrics.consistency import pose_nees
    from slamcli.sim.simulate import simulate_scenario
    from slamcli.solvers.hybrid import HybridParams, HybridSlam

    solver = HybridSlam(HybridParams(**(params or {})))
    rows = []
    for seed in seeds:
        ds = simulate_scenario(scenario, int(seed), {**(overrides or {}), "sensor.n_beams": 2})
        res = solver.bayesian_part(ds.inputs, np.random.default_rng([1, int(seed)]))
        rows.append(pose_nees(res.poses_xyt, ds.truth.poses_xyt, res.pose_cov))
    n = min(len(r) for r in rows)
    return np.stack([r[:n] for r in rows])


def read_complexity(path: Path) -> list[dict] | None:
    """Rows of the stored benchmark table with ``grid_cells`` and ``cpu_ms_per_map_step`` (None: no file)."""
    if not Path(path).is_file():
        return None
    out = []
    with open(path, newline="") as fh:
        for r in csv.DictReader(fh):
            try:
                cells, ms = float(r.get("grid_cells") or "nan"), float(r.get("cpu_ms_per_map_step") or "nan")
            except ValueError:
                continue
            if math.isfinite(cells) and math.isfinite(ms) and cells > 0 and ms > 0:
                out.append({"world": r.get("world", ""), "grid_cells": cells, "cpu_ms_per_map_step": ms})
    return out


def loglog_slope(cells, seconds) -> float:
    """Least-squares slope of log(time) against log(cells)."""
    return float(np.polyfit(np.log(np.asarray(cells, float)), np.log(np.asarray(seconds, float)), 1)[0])


def map_with_given_poses(ds, poses_xyt: np.ndarray, params: dict | None = None):
    """E2 from one pose per step (``poses_xyt (T+1, 3)``, covariance ≈ 0: a single sample at that pose) over
    the dataset's scans, snapshots at the lap ends. Returns ``(grid, mapper output)``; the grid is an
    :class:`~slamcli.types.OccupancyGrid` with the lap-end snapshots."""
    from slamcli.solvers.hybrid import HybridParams
    from slamcli.solvers.hybrid.solver import grid_for_trajectory, map_scans, scan_geometry, scan_table
    from slamcli.types import OccupancyGrid

    p = HybridParams(**{**(params or {}), "samples": "random", "n_samples": 1, "baseline": False})
    inputs = ds.inputs
    alphas, ranges = scan_table(inputs, p.scan_sensor)
    geo = scan_geometry(inputs, alphas)
    mu = np.asarray(poses_xyt, float)
    spec = grid_for_trajectory(mu, inputs.max_range + p.grid_margin, p.resolution, p.grid_offset)
    cov = np.broadcast_to(1e-14 * np.eye(3), (len(mu), 3, 3))
    laps = np.asarray(ds.truth.lap_end_step if ds.truth is not None else [], np.int64)
    snap_at = laps if len(laps) else np.array([len(mu) - 1])
    mp = map_scans(mu, cov, ranges, geo, spec, p, np.random.default_rng(0), snap_at=snap_at)
    grid = OccupancyGrid(np.asarray(spec.origin_xy, float), spec.resolution,
                         mp.P.reshape(spec.shape).astype(np.float32), mp.count.reshape(spec.shape),
                         mp.snap_steps, np.stack(mp.snaps))
    return grid, mp


def gamma_at_laps(clock: np.ndarray, n_laps: int, a: float, alpha: float) -> list[float]:
    """γ = a·n^(−α) at the end of each lap for the median updated cell, its clock n taken to grow evenly over
    the laps (the route repeats every lap): ``n_k = (k / n_laps) · median(final clock of updated cells)``."""
    c = np.asarray(clock, float)
    c = c[c > 0]
    if not len(c) or n_laps < 1:
        return []
    med = float(np.median(c))
    return [a * max(k / n_laps * med, 1.0) ** (-alpha) for k in range(1, n_laps + 1)]


__all__ = ["COMPLEXITY_CSV", "NEES_BAND_PROB", "NEES_MIN_SEEDS", "gamma_at_laps", "loglog_slope",
           "map_with_given_poses", "nees_class", "nees_monte_carlo", "nees_summary", "read_complexity"]
