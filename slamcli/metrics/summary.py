"""Everything ``slamcli evaluate`` reports, computed from one ``SolverResult`` and its ``GroundTruth``.

Pure: typed containers in, a dict of scalars and three tidy DataFrames out (one row per iteration, per
pose, per estimated landmark). Files are written by :mod:`slamcli.api.evaluate`.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pandas as pd

from slamcli.metrics import consistency, landmarks, trajectory
from slamcli.types import GroundTruth, SolverResult


@dataclass(frozen=True)
class EvaluationParams:
    """Options of an evaluation (all echoed into ``metrics.json``).

    Attributes
    ----------
    cutoff_m : float = 1.0          cut-off c of the landmark assignment, OSPA and GOSPA, m.
    ospa_order : float = 2.0        order p of OSPA / GOSPA.
    near_path_m : float | None = None  paper's near-path landmark error: only landmarks whose nearest true
                                    landmark is within this distance of the true path; None = not computed.
    rpe_delta : float = 1.0         RPE pair separation ...
    rpe_unit : str = "steps"        ... in ``"steps"`` or ``"m"`` travelled.
    """

    cutoff_m: float = 1.0
    ospa_order: float = 2.0
    near_path_m: float | None = None
    rpe_delta: float = 1.0
    rpe_unit: str = "steps"


@dataclass(frozen=True)
class Evaluation:
    """Scalars (JSON-friendly: str/int/float/None) and the three tidy tables."""

    scalars: dict
    per_iteration: pd.DataFrame
    per_step: pd.DataFrame
    per_landmark: pd.DataFrame


PER_ITERATION_COLUMNS = ["iteration", "n_landmarks", "err_min_m", "err_mean_m", "err_max_m", "map_change_m",
                         "objective", "time_s"]


def evaluate_result(result: SolverResult, truth: GroundTruth, odometry_xyt=None,
                    params: EvaluationParams = EvaluationParams()) -> Evaluation:
    """Evaluate one solver result against the ground truth.

    Parameters
    ----------
    result : SolverResult
    truth : GroundTruth
    odometry_xyt : ndarray (T+1, 3) | None   dead-reckoning path, reported as a reference ATE.
    params : EvaluationParams

    Raises
    ------
    ValueError  when the result and the truth do not describe the same run (pose count).
    """
    p = params
    est_xyt = np.asarray(result.poses_xyt, float)
    true_xyt = np.asarray(truth.poses_xyt, float)
    if est_xyt.shape != true_xyt.shape:
        raise ValueError(f"result has {len(est_xyt)} poses but the dataset has {len(true_xyt)}")
    est_lm = np.asarray(result.landmarks_xy, float).reshape(-1, 2)
    true_lm = np.asarray(truth.landmarks_xy, float).reshape(-1, 2)
    true_path = true_xyt[:, :2]

    s: dict = {
        "solver": result.solver,
        "status": getattr(result.status, "value", str(result.status)),
        "n_poses": len(est_xyt),
        "n_landmarks_true": len(true_lm),
        "n_landmarks_est": len(est_lm),
        "cutoff_m": float(p.cutoff_m),
        "ospa_order": float(p.ospa_order),
        "rpe_delta": float(p.rpe_delta),
        "rpe_unit": p.rpe_unit,
        "near_path_m": p.near_path_m,
        "nees_convention": "un-normalised, E[NEES] = d (pose d=3, landmark d=2); world-frame [x, y, theta]",
    }
    per_step = _trajectory_metrics(s, est_xyt, true_xyt, odometry_xyt, p)
    per_landmark, t_of_e = _landmark_metrics(s, est_lm, true_lm, true_path, p)
    _consistency_metrics(s, result, est_xyt, true_xyt, est_lm, true_lm, t_of_e, per_step, per_landmark, p)
    per_it = _iteration_metrics(s, result, truth, true_lm, true_path, p)
    return Evaluation(s, per_it, per_step, per_landmark)


def _trajectory_metrics(s: dict, est_xyt, true_xyt, odometry_xyt, p: EvaluationParams) -> pd.DataFrame:
    """Add the ATE (raw and aligned), RPE and odometry ATE to ``s``; return the per-step table."""
    # --- trajectory ------------------------------------------------------------------------------------
    s.update(trajectory.ate(est_xyt, true_xyt, align=False))
    s.update({f"aligned_{k}": v for k, v in trajectory.ate(est_xyt, true_xyt, align=True).items()})
    s.update(trajectory.rpe(est_xyt, true_xyt, p.rpe_delta, p.rpe_unit))
    if odometry_xyt is not None:
        s["odometry_ate_rmse_m"] = trajectory.ate(odometry_xyt, true_xyt)["ate_rmse_m"]
    e_un, h_un = trajectory.ate_errors(est_xyt, true_xyt, align=False)
    e_al, h_al = trajectory.ate_errors(est_xyt, true_xyt, align=True)
    per_step = pd.DataFrame({
        "step": np.arange(len(est_xyt)),
        "est_x": est_xyt[:, 0], "est_y": est_xyt[:, 1], "est_theta": est_xyt[:, 2],
        "true_x": true_xyt[:, 0], "true_y": true_xyt[:, 1], "true_theta": true_xyt[:, 2],
        "trans_err_m": e_un, "heading_err_rad": h_un,
        "aligned_trans_err_m": e_al, "aligned_heading_err_rad": h_al,
    })
    if odometry_xyt is not None:
        e_od, _ = trajectory.ate_errors(odometry_xyt, true_xyt)
        per_step["odometry_trans_err_m"] = e_od
    return per_step


def _landmark_metrics(s: dict, est_lm, true_lm, true_path, p: EvaluationParams):
    """Add the paper-convention and honest (assignment, OSPA/GOSPA) map errors to ``s``.

    Returns the per-landmark table and ``t_of_e (L',)``, the true landmark assigned to each estimate.
    """
    # --- landmarks: paper convention ---------------------------------------------------------------------
    if len(est_lm) and len(true_lm):
        nn_err, nn_idx = landmarks.nearest_true_errors(est_lm, true_lm)
    else:
        nn_err, nn_idx = np.zeros(0), np.zeros(0, np.int64)
    st = landmarks.ErrorStats(0, np.nan, np.nan, np.nan) if nn_err.size == 0 else landmarks.paper_landmark_error(
        est_lm, true_lm)
    s.update({"paper_err_min_m": st.min, "paper_err_mean_m": st.mean, "paper_err_max_m": st.max})
    near = None
    if p.near_path_m is not None and nn_err.size:
        near = landmarks.near_path_mask(est_lm, true_lm, true_path, p.near_path_m)
        s["paper_err_mean_near_path_m"] = float(nn_err[near].mean()) if near.any() else float("nan")
        s["paper_n_near_path"] = int(near.sum())

    # --- landmarks: honest ---------------------------------------------------------------------------------
    s.update({f"lm_{k}": v for k, v in
              landmarks.honest_landmark_error(est_lm, true_lm, p.cutoff_m, p.ospa_order).items()})
    s.update({f"lm_aligned_{k}": v for k, v in
              landmarks.honest_landmark_error(est_lm, true_lm, p.cutoff_m, p.ospa_order, align=True).items()
              if k not in ("n_true", "n_est")})
    a = landmarks.assign_landmarks(est_lm, true_lm, p.cutoff_m, p.ospa_order)
    t_of_e = a.true_of_est()
    matched_d = np.full(len(est_lm), np.nan)
    matched_d[a.est_idx] = a.dist_m
    per_landmark = pd.DataFrame({
        "est_index": np.arange(len(est_lm)),
        "est_x": est_lm[:, 0], "est_y": est_lm[:, 1],
        "nearest_true": nn_idx, "nearest_err_m": nn_err,
        "assigned_true": t_of_e, "assigned_err_m": matched_d,
    })
    if near is not None:
        per_landmark["near_path"] = near
    return per_landmark, t_of_e


def _consistency_metrics(s: dict, result: SolverResult, est_xyt, true_xyt, est_lm, true_lm, t_of_e,
                         per_step: pd.DataFrame, per_landmark: pd.DataFrame, p: EvaluationParams) -> None:
    """Add the pose and landmark NEES (or why not available) to ``s`` and their columns to the tables."""
    # --- consistency ---------------------------------------------------------------------------------------
    why = consistency.covariance_unavailable_reason(result.pose_cov, "pose", result.solver)
    if why is None:
        pn = consistency.pose_nees(est_xyt, true_xyt, result.pose_cov)
        per_step["pose_nees"] = pn
        f = np.isfinite(pn)
        lo, hi = consistency.chi2_band(1, 3)
        s["pose_nees_mean"] = float(pn[f].mean()) if f.any() else None
        s["pose_nees_frac_in_band_n1"] = float(np.mean((pn[f] >= lo) & (pn[f] <= hi))) if f.any() else None
        s["pose_nees_note"] = (f"{int(f.sum())} of {len(pn)} steps with a positive-definite covariance; "
                               f"single-run band [{lo:.2f}, {hi:.2f}]; use Monte-Carlo runs for a real test")
    else:
        s["pose_nees_mean"] = None
        s["pose_nees_frac_in_band_n1"] = None
        s["pose_nees_note"] = why
    why = consistency.covariance_unavailable_reason(result.landmark_cov, "landmark", result.solver)
    if why is None and len(est_lm):
        ln = consistency.landmark_nees(est_lm, true_lm, result.landmark_cov, t_of_e)
        per_landmark["landmark_nees"] = ln
        f = np.isfinite(ln)
        s["landmark_nees_mean"] = float(ln[f].mean()) if f.any() else None
        s["landmark_nees_note"] = (f"mean over {int(f.sum())} assigned landmarks (cut-off {p.cutoff_m} m); "
                                   "not a chi2 statistic (landmark errors are correlated)")
    else:
        s["landmark_nees_mean"] = None
        s["landmark_nees_note"] = why or "not available: the result has no landmarks"


def _iteration_metrics(s: dict, result: SolverResult, truth: GroundTruth, true_lm, true_path,
                       p: EvaluationParams) -> pd.DataFrame:
    """Add the iteration count and set-membership metrics (cuik) to ``s``; return the per-iteration table."""
    # --- per iteration ---------------------------------------------------------------------------------------
    if result.trace is not None and len(result.trace) and len(true_lm):
        per_it = landmarks.paper_error_per_iteration(result.trace, true_lm, true_path, p.near_path_m)
        s["n_iterations"] = len(per_it)
        s["per_iteration_note"] = "ok"
    else:
        per_it = pd.DataFrame({c: [] for c in PER_ITERATION_COLUMNS})
        s["n_iterations"] = 0
        s["per_iteration_note"] = "not available: the result has no iteration trace"
    if result.hypotheses is not None and len(result.hypotheses):  # set-membership results (cuik)
        from slamcli.metrics.sets import set_metrics

        s.update({f"set_{k}": v for k, v in set_metrics(result.hypotheses, truth.poses_xyt, truth.landmarks_xy,
                                                         truth.obs_landmark).items()})
    return per_it


def monte_carlo_pose_nees(pairs, confidence: float = 0.95):
    """Average pose NEES over N runs ``[(SolverResult, GroundTruth), ...]`` of equal length.

    Returns
    -------
    (AverageNees, None) or (None, reason)  — reason when a run has no pose covariances or lengths differ.
    """
    pairs = list(pairs)
    if not pairs:
        return None, "not available: no runs given"
    rows = []
    for k, (res, truth) in enumerate(pairs):
        why = consistency.covariance_unavailable_reason(res.pose_cov, "pose", res.solver)
        if why is not None:
            return None, f"run {k}: {why}"
        if len(res.poses_xyt) != len(pairs[0][0].poses_xyt):
            return None, (f"not available: run {k} has {len(res.poses_xyt)} poses, run 0 has "
                          f"{len(pairs[0][0].poses_xyt)}; Monte-Carlo runs must have equal length")
        rows.append(consistency.pose_nees(res.poses_xyt, truth.poses_xyt, res.pose_cov))
    return consistency.average_nees(np.vstack(rows), 3, confidence), None
