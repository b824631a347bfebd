"""Occupancy-map metrics (paper 001 Figs. 3-9): map error vs laps, per-cell error, classification accuracy,
pose error with the filter's 3σ bounds and pose NEES.

The estimated grid is compared with the true grid cell by cell: every true cell centre is looked up in the
estimated grid (so the two grids may differ in extent; with the same resolution and lattice — the default —
the lookup is one-to-one). Only cells the estimator *observed* (update count > 0 in the final map) count:

    total map error  E = Σ_{i observed} |P_i − P*_i|          (paper Figs. (e): "total error in the map")
    per-cell error   e = E / n_observed
    accuracy         fraction of observed cells with (P_i > 0.5) = P*_i  (P_i = 0.5 counts as wrong)
"""

from __future__ import annotations

import numpy as np
import pandas as pd

from slamcli.metrics.consistency import pose_nees
from slamcli.types import OccupancyGrid


def lookup(grid: OccupancyGrid, xy: np.ndarray, values: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Values of ``grid`` (its ``prob`` or the given ``(H, W)`` array) at points ``xy (N, 2)``.

    Returns
    -------
    vals : ndarray (N,)  (NaN outside the grid);  inside : ndarray (N,) bool
    """
    arr = grid.prob if values is None else values
    H, W = arr.shape[-2:]
    c = np.floor((xy[:, 0] - grid.origin_xy[0]) / grid.resolution).astype(np.int64)
    r = np.floor((xy[:, 1] - grid.origin_xy[1]) / grid.resolution).astype(np.int64)
    inside = (c >= 0) & (c < W) & (r >= 0) & (r < H)
    vals = np.full(len(xy), np.nan)
    vals[inside] = arr[r[inside], c[inside]]
    return vals, inside


def _truth_points(truth: OccupancyGrid) -> tuple[np.ndarray, np.ndarray]:
    H, W = truth.shape
    xs = truth.origin_xy[0] + (np.arange(W) + 0.5) * truth.resolution
    ys = truth.origin_xy[1] + (np.arange(H) + 0.5) * truth.resolution
    gx, gy = np.meshgrid(xs, ys)
    return np.stack([gx.ravel(), gy.ravel()], -1), np.asarray(truth.prob, float).ravel()


def observed_mask(est: OccupancyGrid, truth: OccupancyGrid) -> np.ndarray:
    """Which true cells the estimator observed ``(H*·W*,)`` (needs ``est.observed``)."""
    pts, _ = _truth_points(truth)
    if est.observed is None:
        raise ValueError("the estimated grid has no 'observed' counts")
    cnt, inside = lookup(est, pts, est.observed)
    return inside & (np.nan_to_num(cnt) > 0)


def map_errors(prob_at_truth: np.ndarray, p_true: np.ndarray, mask: np.ndarray) -> dict:
    """``{total_abs_error, mean_abs_error, accuracy, n_observed}`` over ``mask`` (formulas: module docstring)."""
    n = int(mask.sum())
    if n == 0:
        return {"total_abs_error": float("nan"), "mean_abs_error": float("nan"), "accuracy": float("nan"),
                "n_observed": 0}
    e = np.abs(prob_at_truth[mask] - p_true[mask])
    cls = prob_at_truth[mask] > 0.5
    return {"total_abs_error": float(e.sum()), "mean_abs_error": float(e.mean()),
            "accuracy": float(np.mean(cls == (p_true[mask] > 0.5))), "n_observed": n}


def grid_errors(est: OccupancyGrid, truth: OccupancyGrid, mask: np.ndarray | None = None) -> dict:
    """Errors of the final map ``est.prob`` against ``truth`` on the observed cells (or ``mask``)."""
    pts, p_true = _truth_points(truth)
    m = observed_mask(est, truth) if mask is None else mask
    vals, _ = lookup(est, pts)
    return map_errors(vals, p_true, m)


def laps_at_steps(steps: np.ndarray, lap_end_step: np.ndarray | None) -> np.ndarray:
    """Lap number (float) at each step, piecewise linear between lap ends (lap k ends at ``lap_end_step[k-1]``);
    NaN without lap ends."""
    steps = np.asarray(steps, float)
    if lap_end_step is None or len(lap_end_step) == 0:
        return np.full(steps.shape, np.nan)
    xp = np.concatenate([[0.0], np.asarray(lap_end_step, float)])
    fp = np.arange(len(xp), dtype=float)
    per_lap = xp[-1] / (len(xp) - 1)
    out = np.interp(steps, xp, fp)
    beyond = steps > xp[-1]
    out[beyond] = fp[-1] + (steps[beyond] - xp[-1]) / per_lap
    return out


def snapshot_errors(est: OccupancyGrid, truth: OccupancyGrid, lap_end_step: np.ndarray | None = None,
                    mask: np.ndarray | None = None) -> pd.DataFrame:
    """Map error of every snapshot on the cells observed by the end of the run (paper Figs. (e)).

    Columns: ``step, lap, total_abs_error, mean_abs_error, accuracy, n_observed``.
    """
    if est.snapshots is None:
        return pd.DataFrame(columns=["step", "lap", "total_abs_error", "mean_abs_error", "accuracy", "n_observed"])
    pts, p_true = _truth_points(truth)
    m = observed_mask(est, truth) if mask is None else mask
    rows = []
    for k, step in enumerate(est.snapshot_step):
        vals, _ = lookup(est, pts, est.snapshots[k])
        rows.append({"step": int(step), **map_errors(vals, p_true, m)})
    df = pd.DataFrame(rows)
    df.insert(1, "lap", laps_at_steps(df["step"].to_numpy(), lap_end_step))
    return df


def error_at_lap_ends(df: pd.DataFrame, lap_end_step: np.ndarray, column: str = "total_abs_error") -> np.ndarray:
    """``column`` at the snapshot nearest to each lap end ``(K,)`` (NaN when there are no snapshots)."""
    if df.empty or lap_end_step is None:
        return np.full(0 if lap_end_step is None else len(lap_end_step), np.nan)
    s = df["step"].to_numpy()
    idx = [int(np.argmin(np.abs(s - e))) for e in lap_end_step]
    return df[column].to_numpy()[idx]


def pose_errors_3sigma(est_xyt: np.ndarray, true_xyt: np.ndarray, pose_cov: np.ndarray) -> pd.DataFrame:
    """Pose error per step in x, y, θ (wrapped) with the filter's 3σ bounds and the pose NEES (Figs. (f)-(h)).

    Columns: ``step, err_x, err_y, err_theta, bound3_x, bound3_y, bound3_theta, nees``.
    """
    from slamcli.models.angles import angle_diff

    e = np.asarray(est_xyt, float) - np.asarray(true_xyt, float)
    e[:, 2] = angle_diff(np.asarray(est_xyt)[:, 2], np.asarray(true_xyt)[:, 2])
    sd = np.sqrt(np.maximum(np.einsum("tii->ti", np.asarray(pose_cov, float)), 0.0))
    return pd.DataFrame({
        "step": np.arange(len(e)), "err_x": e[:, 0], "err_y": e[:, 1], "err_theta": e[:, 2],
        "bound3_x": 3 * sd[:, 0], "bound3_y": 3 * sd[:, 1], "bound3_theta": 3 * sd[:, 2],
        "nees": pose_nees(est_xyt, true_xyt, pose_cov),
    })


def common_mask(grids: dict[str, OccupancyGrid], truth: OccupancyGrid) -> np.ndarray:
    """True cells observed by *every* grid (so that the maps are compared on the same cells) ``(H*·W*,)``."""
    mask = None
    for g in grids.values():
        m = observed_mask(g, truth) if g.observed is not None else np.ones(truth.prob.size, bool)
        mask = m if mask is None else mask & m
    return mask


def occupancy_scalars(grids: dict[str, OccupancyGrid], truth: OccupancyGrid, lap_end_step=None) -> dict:
    """Flat scalars for ``metrics.json``: per grid name the final errors on the cells observed by every grid
    (:func:`common_mask`, so the numbers compare) and the total error at each lap end."""
    if not grids:
        return {}
    mask = common_mask(grids, truth)
    out: dict = {}
    for name, g in grids.items():
        for k, v in grid_errors(g, truth, mask).items():
            out[f"grid_{name}_{k}"] = v
        if g.snapshots is not None and lap_end_step is not None and len(lap_end_step):
            df = snapshot_errors(g, truth, lap_end_step, mask)
            for i, v in enumerate(error_at_lap_ends(df, lap_end_step)):
                out[f"grid_{name}_total_abs_error_lap{i + 1}"] = float(v)
    return out
