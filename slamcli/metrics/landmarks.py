"""Landmark-map error metrics: the ICM-SLAM paper's nearest-neighbour convention and an honest
assignment-based alternative (matched RMSE, missed/spurious counts, OSPA, GOSPA).

All functions are pure: numpy arrays in, numbers / small dataclasses / DataFrames out.

Paper convention (paper 000, §5, Figs 5e/f, 6c/d, 7c/d): the error of an estimated landmark is the distance
to its *nearest* true landmark, ``e_i = min_j ‖m̂_i − m_j‖``; min / mean / max over the estimated landmarks
are reported per ICM iteration. The authors note that this under-estimates errors when an estimate lands on
another landmark's true position; it also ignores unmapped true landmarks. We reproduce it for
comparability and report the assignment metrics next to it (EVALUATION-METHOD.md §A3).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pandas as pd
from scipy.optimize import linear_sum_assignment
from scipy.spatial import cKDTree

from slamcli.metrics.trajectory import umeyama_se2
from slamcli.types import IterationTrace


def _as_xy(a, name: str) -> np.ndarray:
    a = np.asarray(a, dtype=float)
    if a.size == 0:
        return np.zeros((0, 2))
    if a.ndim != 2 or a.shape[1] != 2:
        raise ValueError(f"{name} must have shape (n, 2), got {a.shape}")
    return a


# ---------------------------------------------------------------------------------------------------------
# Paper convention: nearest true landmark
# ---------------------------------------------------------------------------------------------------------


def nearest_true_errors(est_xy, true_xy):
    """Distance of every estimated landmark to its nearest true landmark (paper 000 §5).

    Parameters
    ----------
    est_xy : ndarray (L', 2)   estimated landmarks, m.
    true_xy : ndarray (L, 2)   true landmarks, m (L ≥ 1 when L' ≥ 1).

    Returns
    -------
    err_m : ndarray (L',)      ``min_j ‖m̂_i − m_j‖``.
    nearest : ndarray (L',) int  index j of the nearest true landmark.
    """
    est_xy = _as_xy(est_xy, "est_xy")
    true_xy = _as_xy(true_xy, "true_xy")
    if len(est_xy) == 0:
        return np.zeros(0), np.zeros(0, dtype=np.int64)
    if len(true_xy) == 0:
        raise ValueError("nearest-neighbour error needs at least one true landmark")
    dist, idx = cKDTree(true_xy).query(est_xy, k=1)
    return np.asarray(dist, float), np.asarray(idx, np.int64)


@dataclass(frozen=True)
class ErrorStats:
    """min / mean / max of the paper's nearest-neighbour landmark error, m (NaN when no landmark)."""

    n: int
    min: float
    mean: float
    max: float


def _stats(err) -> ErrorStats:
    err = np.asarray(err, float)
    if err.size == 0:
        return ErrorStats(0, float("nan"), float("nan"), float("nan"))
    return ErrorStats(int(err.size), float(err.min()), float(err.mean()), float(err.max()))


def paper_landmark_error(est_xy, true_xy) -> ErrorStats:
    """min / mean / max nearest-true-landmark error of a map (paper 000 §5)."""
    return _stats(nearest_true_errors(est_xy, true_xy)[0])


def near_path_mask(est_xy, true_xy, path_xy, max_dist_m: float) -> np.ndarray:
    """Which estimated landmarks count for the paper's "near the path" variant.

    An estimated landmark counts when its nearest true landmark lies within ``max_dist_m`` of the true
    trajectory (distance to the nearest true pose position).

    Returns
    -------
    mask : ndarray (L',) bool
    """
    est_xy = _as_xy(est_xy, "est_xy")
    if len(est_xy) == 0:
        return np.zeros(0, bool)
    _, nearest = nearest_true_errors(est_xy, true_xy)
    path_xy = _as_xy(path_xy, "path_xy")
    d_path, _ = cKDTree(path_xy).query(_as_xy(true_xy, "true_xy")[nearest], k=1)
    return np.asarray(d_path) <= max_dist_m


def paper_landmark_error_near_path(est_xy, true_xy, path_xy, max_dist_m: float) -> ErrorStats:
    """Paper error restricted to estimated landmarks whose nearest true landmark is within ``max_dist_m``
    of the true path (paper 000 §5 reports the mean over landmarks close to the trajectory)."""
    err, _ = nearest_true_errors(est_xy, true_xy)
    return _stats(err[near_path_mask(est_xy, true_xy, path_xy, max_dist_m)])


def map_change(prev_xy, curr_xy) -> float:
    """Mean displacement ``(1/L) Σ_i ‖m_i^(k) − m_i^(k−1)‖`` between two iterations (paper 000 Fig. 9d).

    Landmarks are matched by row; when the two maps have different sizes the change is undefined (NaN).
    """
    prev_xy = _as_xy(prev_xy, "prev_xy")
    curr_xy = _as_xy(curr_xy, "curr_xy")
    if len(prev_xy) != len(curr_xy) or len(curr_xy) == 0:
        return float("nan")
    return float(np.mean(np.linalg.norm(curr_xy - prev_xy, axis=1)))


def paper_error_per_iteration(trace: IterationTrace, true_xy, path_xy=None, near_path_m=None) -> pd.DataFrame:
    """The paper's error curves (Figs 5e/f) and map change (Fig 9d) for every iteration of a trace.

    Returns
    -------
    DataFrame, one row per iteration ``k`` (0 = initialisation) with columns
    ``iteration, n_landmarks, err_min_m, err_mean_m, err_max_m, map_change_m, objective, time_s``
    and, when ``path_xy`` and ``near_path_m`` are given, ``err_mean_near_path_m``.
    ``map_change_m`` is recomputed from the landmark estimates (0 for k = 0, NaN if the map size changed).
    """
    rows = []
    prev = None
    for k in range(len(trace)):
        lm = trace.landmarks_at(k)
        s = paper_landmark_error(lm, true_xy)
        row = {
            "iteration": k,
            "n_landmarks": s.n,
            "err_min_m": s.min,
            "err_mean_m": s.mean,
            "err_max_m": s.max,
            "map_change_m": 0.0 if prev is None else map_change(prev, lm),
            "objective": float(trace.objective[k]),
            "time_s": float(trace.time_s[k]),
        }
        if path_xy is not None and near_path_m is not None:
            row["err_mean_near_path_m"] = paper_landmark_error_near_path(lm, true_xy, path_xy, near_path_m).mean
        rows.append(row)
        prev = lm
    return pd.DataFrame(rows)


# ---------------------------------------------------------------------------------------------------------
# Honest: optimal assignment with cut-off, OSPA, GOSPA
# ---------------------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class Assignment:
    """Optimal one-to-one matching of estimated to true landmarks with cut-off ``c``.

    ``est_idx[k] ↔ true_idx[k]`` are the matched pairs (distance ``dist_m[k] < c``).
    """

    est_idx: np.ndarray
    true_idx: np.ndarray
    dist_m: np.ndarray
    n_est: int
    n_true: int
    cutoff_m: float

    @property
    def n_matched(self) -> int:
        return int(self.est_idx.size)

    @property
    def n_missed(self) -> int:
        """True landmarks with no estimate within the cut-off."""
        return self.n_true - self.n_matched

    @property
    def n_spurious(self) -> int:
        """Estimated landmarks with no true landmark within the cut-off."""
        return self.n_est - self.n_matched

    def true_of_est(self) -> np.ndarray:
        """``(L',) int``: matched true landmark of each estimate, −1 when unmatched."""
        out = np.full(self.n_est, -1, np.int64)
        out[self.est_idx] = self.true_idx
        return out


def assign_landmarks(est_xy, true_xy, cutoff_m: float, p: float = 2.0) -> Assignment:
    """Hungarian assignment on the clipped cost ``min(‖m̂_i − m_j‖, c)^p``; pairs at ≥ c are dropped.

    The clipped cost makes this the optimal assignment of both OSPA (order p, cut-off c) and GOSPA (α = 2),
    since leaving a pair unassigned costs ``c^p/2 + c^p/2 = c^p`` in GOSPA.
    """
    if not cutoff_m > 0:
        raise ValueError(f"cut-off must be > 0, got {cutoff_m}")
    est_xy = _as_xy(est_xy, "est_xy")
    true_xy = _as_xy(true_xy, "true_xy")
    empty = np.zeros(0, np.int64)
    if len(est_xy) == 0 or len(true_xy) == 0:
        return Assignment(empty, empty, np.zeros(0), len(est_xy), len(true_xy), float(cutoff_m))
    d = np.linalg.norm(est_xy[:, None, :] - true_xy[None, :, :], axis=-1)
    rows, cols = linear_sum_assignment(np.minimum(d, cutoff_m) ** p)
    keep = d[rows, cols] < cutoff_m
    rows, cols = rows[keep], cols[keep]
    return Assignment(rows.astype(np.int64), cols.astype(np.int64), d[rows, cols], len(est_xy), len(true_xy),
                      float(cutoff_m))


def ospa_from_assignment(a: Assignment, p: float = 2.0) -> float:
    """OSPA (Schuhmacher, Vo & Vo 2008) of order ``p`` with cut-off ``c``.

    ``d = ( (1/n) [ Σ_matched min(d, c)^p + c^p (n − m_matched) ] )^{1/p}``, n = max(|X|, |Y|);
    unmatched items of the smaller set are paired at cost c^p, which is what ``n − m_matched`` counts.
    0 when both sets are empty; c when exactly one is.
    """
    c = a.cutoff_m
    n = max(a.n_est, a.n_true)
    if n == 0:
        return 0.0
    total = float(np.sum(a.dist_m**p)) + c**p * (n - a.n_matched)
    return float((total / n) ** (1.0 / p))


@dataclass(frozen=True)
class Gospa:
    """GOSPA (α = 2, Rahmathullah et al. 2017) and its decomposition (all in m^p before the root)."""

    distance: float
    localisation: float
    missed: float
    false: float


def gospa_from_assignment(a: Assignment, p: float = 2.0) -> Gospa:
    """``d = ( Σ_matched ‖x_i − y_j‖^p + (c^p/2)(#missed + #false) )^{1/p}`` (α = 2)."""
    half = a.cutoff_m**p / 2.0
    loc = float(np.sum(a.dist_m**p))
    missed = half * a.n_missed
    false = half * a.n_spurious
    return Gospa(float((loc + missed + false) ** (1.0 / p)), loc, missed, false)


def honest_landmark_error(est_xy, true_xy, cutoff_m: float = 1.0, p: float = 2.0, align: bool = False) -> dict:
    """Assignment-based map error (EVALUATION-METHOD.md §A3).

    Parameters
    ----------
    est_xy : ndarray (L', 2), true_xy : ndarray (L, 2)
    cutoff_m : float       cut-off c, m: a pair counts as matched only if closer than c.
    p : float              OSPA/GOSPA order.
    align : bool           first fit an SE(2) transform (no scale) on the unaligned matched pairs, apply it
                           to the estimates and re-assign. Needs ≥ 2 matched pairs, else the values are NaN.

    Returns
    -------
    dict with ``n_true, n_est, n_matched, n_missed, n_spurious, rmse_matched_m, ospa_m, gospa_m,
    gospa_localisation, gospa_missed, gospa_false`` (the three GOSPA terms in m^p).
    """
    est_xy = _as_xy(est_xy, "est_xy")
    true_xy = _as_xy(true_xy, "true_xy")
    a = assign_landmarks(est_xy, true_xy, cutoff_m, p)
    if align:
        if a.n_matched < 2:
            keys = ("n_true", "n_est", "n_matched", "n_missed", "n_spurious", "rmse_matched_m", "ospa_m",
                    "gospa_m", "gospa_localisation", "gospa_missed", "gospa_false")
            return {k: float("nan") for k in keys}
        R, t = umeyama_se2(est_xy[a.est_idx], true_xy[a.true_idx])
        est_xy = est_xy @ R.T + t
        a = assign_landmarks(est_xy, true_xy, cutoff_m, p)
    g = gospa_from_assignment(a, p)
    rmse = float(np.sqrt(np.mean(a.dist_m**2))) if a.n_matched else float("nan")
    return {
        "n_true": a.n_true,
        "n_est": a.n_est,
        "n_matched": a.n_matched,
        "n_missed": a.n_missed,
        "n_spurious": a.n_spurious,
        "rmse_matched_m": rmse,
        "ospa_m": ospa_from_assignment(a, p),
        "gospa_m": g.distance,
        "gospa_localisation": g.localisation,
        "gospa_missed": g.missed,
        "gospa_false": g.false,
    }
