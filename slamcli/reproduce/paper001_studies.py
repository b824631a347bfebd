"""Paper 001's claims measured beyond the map figures: consistency over seeds, stored complexity results, and
the step size of the maps from given poses that explain the noisy-sensor plateau.

* :func:`nees_summary` — per step the average NEES over N seeds (ANEES, d = 3) of the Bayesian part (the EKF on
  the features) against the two-sided χ²(3N)/N band (Bailey et al. 2006, paper 001's ref. [20]). The scan does
  not enter the EKF, so the Monte-Carlo runs simulate 2 beams (the experiments ``paper001-nees-map*``).
* :func:`read_complexity` — the per-step mapping CPU time vs map cells that ``python -m benchmarks hybrid``
  stores in ``benchmarks/results/hybrid.csv`` (the section does not time anything itself).
* :func:`gamma_at_laps` / :func:`gamma_from_median` — γ = a·n^(−α) of the median updated cell at the lap ends.
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


def gamma_at_laps(clock: np.ndarray, n_laps: int, a: float, alpha: float) -> list[float]:
    """:func:`gamma_from_median` of the per-cell clock ``clock`` (cells never updated, n = 0, left out)."""
    c = np.asarray(clock, float)
    c = c[c > 0]
    return gamma_from_median(float(np.median(c)) if len(c) else None, n_laps, a, alpha)


def gamma_from_median(median_clock: float | None, n_laps: int, a: float, alpha: float) -> list[float]:
    """γ = a·n^(−α) at the end of each lap for the median updated cell, its clock n taken to grow evenly over
    the laps (the route repeats every lap): ``n_k = (k / n_laps) · median_clock`` (the median of the final
    clocks of the updated cells; None: no cell updated → ``[]``)."""
    if median_clock is None or not math.isfinite(median_clock) or n_laps < 1:
        return []
    return [a * max(k / n_laps * median_clock, 1.0) ** (-alpha) for k in range(1, n_laps + 1)]


__all__ = ["COMPLEXITY_CSV", "NEES_BAND_PROB", "NEES_MIN_SEEDS", "gamma_at_laps", "gamma_from_median",
           "loglog_slope", "nees_class", "nees_summary", "read_complexity"]
