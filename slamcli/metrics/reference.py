"""Metrics for real recordings without full ground truth.

* :func:`ate_vs_position_reference` — ATE against a time-stamped position-only reference (GPS): the estimate
  (dense) is interpolated linearly at each reference time inside its span, ``e_i = p̂(t_i) − g_i``,
  ``ATE = sqrt(mean_i ‖e_i‖²)``, reported unaligned and after the least-squares SE(2) alignment onto the
  reference (2-D Kabsch/Umeyama without scale; a real run's start heading in the GPS frame is unknown). The
  caller passes the positions of the body point the reference refers to (``GroundTruth.ref_offset_xy``).
  Glitch fixes are left out (count and times reported; the ATE over every fix is kept as ``gps_ate_*_raw_*``).
* :func:`glitches` — an interior fix is a glitch when it is farther from *both* neighbours than a body at
  ``max_speed_mps`` could get in the time between them plus ``glitch_tol_m``, while those neighbours agree
  with each other under the same bound::

      ‖g_i − g_{i±1}‖ > v_max·|t_i − t_{i±1}| + tol  (both),   ‖g_{i+1} − g_{i−1}‖ ≤ v_max·(t_{i+1} − t_{i−1}) + tol

  It uses the reference only, never the estimate; end fixes and runs of bad fixes are not gated (what it
  rejects on the recordings: benchmarks/results/design_notes.md).
* :func:`gaps` — the intervals without reference fixes longer than ``gap_s`` (stated with every ATE).
* :func:`trajectory_against` — ATE and landmark distances of one result against another (``evaluate
  --against``): same pose count; landmarks matched by optimal assignment with a cut-off.
* :func:`nis_summary` — average normalised innovation squared with its two-sided χ² band.
"""

from __future__ import annotations

import numpy as np

from slamcli.metrics.consistency import chi2_ppf
from slamcli.metrics.landmarks import assign_landmarks
from slamcli.metrics.trajectory import umeyama_se2


def gaps(ref_time_s, t_from: float, t_to: float, gap_s: float) -> list[tuple[float, float]]:
    """Intervals ``(start, end)`` within ``[t_from, t_to]`` longer than ``gap_s`` with no reference fix."""
    t = np.clip(np.concatenate([[t_from], np.asarray(ref_time_s, float), [t_to]]), t_from, t_to)
    d = np.diff(t)
    return [(float(t[i]), float(t[i + 1])) for i in np.flatnonzero(d > gap_s)]


#: defaults of the glitch gate (see the module docstring): the fastest the body is taken to move, m/s, and the
#: position tolerance for receiver noise, m
GLITCH_MAX_SPEED_MPS = 20.0
GLITCH_TOL_M = 5.0


def glitches(ref_time_s, ref_xy, max_speed_mps: float = GLITCH_MAX_SPEED_MPS,
             tol_m: float = GLITCH_TOL_M) -> np.ndarray:
    """Mask ``(G,)`` of the reference fixes that are glitches (module docstring); uses the reference only."""
    t = np.asarray(ref_time_s, float)
    g = np.asarray(ref_xy, float).reshape(-1, 2)
    if not (max_speed_mps > 0 and tol_m >= 0):
        raise ValueError("the glitch gate needs max_speed_mps > 0 and tol_m ≥ 0")
    out = np.zeros(t.size, bool)
    if t.size < 3:
        return out
    far = np.linalg.norm(np.diff(g, axis=0), axis=1) > max_speed_mps * np.diff(t) + tol_m
    agree = np.linalg.norm(g[2:] - g[:-2], axis=1) <= max_speed_mps * (t[2:] - t[:-2]) + tol_m
    out[1:-1] = far[:-1] & far[1:] & agree
    return out


def _aligned_errors(est: np.ndarray, g: np.ndarray):
    """``(unaligned errors, aligned errors, (R, t))`` of matched positions ``est``, ``g`` (m ≥ 2 rows)."""
    R, t = umeyama_se2(est, g)
    return np.linalg.norm(est - g, axis=1), np.linalg.norm(est @ R.T + t - g, axis=1), (R, t)


def _rms(e: np.ndarray) -> float:
    return float(np.sqrt(np.mean(e**2))) if e.size else float("nan")


def ate_vs_position_reference(timestamps, poses_xyt, ref_time_s, ref_xy, *, gap_s: float = 1.0,
                              max_speed_mps: float = GLITCH_MAX_SPEED_MPS, glitch_tol_m: float = GLITCH_TOL_M) -> dict:
    """ATE of ``poses_xyt (T+1, 3)`` at ``timestamps (T+1,)`` against a reference ``ref_xy (G, 2)`` at
    ``ref_time_s (G,)``, without the reference's glitches (:func:`glitches` with ``max_speed_mps``,
    ``glitch_tol_m``).

    Returns
    -------
    dict with ``gps_ate_rmse_m`` (unaligned), ``gps_ate_aligned_rmse_m``, ``gps_ate_aligned_max_m`` (the fixes
    that passed the glitch gate), ``gps_ate_raw_rmse_m``, ``gps_ate_aligned_raw_rmse_m`` (every fix, glitches
    included, aligned on its own), ``gps_n_rejected`` and ``gps_rejected_time_s`` (glitches inside the run),
    ``gps_glitch_max_speed_mps``, ``gps_glitch_tol_m``, ``gps_n_matched`` (fixes used), ``gps_n_outside``,
    ``gps_gap_count``, ``gps_gap_total_s``, ``gps_longest_gap_s`` (gaps between the fixes used),
    ``gps_gap_threshold_s``, ``gps_errors_aligned_m`` (per fix used) and ``gps_matched_time_s``, and
    ``gps_alignment`` ``(R, t)`` (or None).
    """
    ts = np.asarray(timestamps, float)
    p = np.asarray(poses_xyt, float)
    rt = np.asarray(ref_time_s, float)
    rxy = np.asarray(ref_xy, float).reshape(-1, 2)
    inside = (rt >= ts[0]) & (rt <= ts[-1])
    bad = glitches(rt, rxy, max_speed_mps, glitch_tol_m)
    use = inside & ~bad
    est_all = np.column_stack([np.interp(rt[inside], ts, p[:, 0]), np.interp(rt[inside], ts, p[:, 1])])
    used = use[inside]
    t_m, g, est = rt[use], rxy[use], est_all[used]
    gl = gaps(t_m, float(ts[0]), float(ts[-1]), gap_s)
    out = {
        "gps_n_matched": int(use.sum()),
        "gps_n_outside": int((~inside).sum()),
        "gps_n_rejected": int((inside & bad).sum()),
        "gps_rejected_time_s": rt[inside & bad].tolist(),
        "gps_glitch_max_speed_mps": float(max_speed_mps),
        "gps_glitch_tol_m": float(glitch_tol_m),
        "gps_gap_count": len(gl),
        "gps_gap_total_s": float(sum(b - a for a, b in gl)),
        "gps_longest_gap_s": float(max((b - a for a, b in gl), default=0.0)),
        "gps_gap_threshold_s": float(gap_s),
    }
    nan = float("nan")
    if len(t_m) < 2:
        out.update(gps_ate_rmse_m=nan, gps_ate_aligned_rmse_m=nan, gps_ate_aligned_max_m=nan,
                   gps_ate_raw_rmse_m=nan, gps_ate_aligned_raw_rmse_m=nan, gps_errors_aligned_m=np.zeros(0),
                   gps_matched_time_s=t_m, gps_alignment=None)
        return out
    e, ea, align = _aligned_errors(est, g)
    e_raw, ea_raw, _ = _aligned_errors(est_all, rxy[inside]) if out["gps_n_rejected"] else (e, ea, align)
    out.update(gps_ate_rmse_m=_rms(e), gps_ate_aligned_rmse_m=_rms(ea), gps_ate_aligned_max_m=float(ea.max()),
               gps_ate_raw_rmse_m=_rms(e_raw), gps_ate_aligned_raw_rmse_m=_rms(ea_raw), gps_errors_aligned_m=ea,
               gps_matched_time_s=t_m, gps_alignment=align)
    return out


def _matched_rmse(est_xy: np.ndarray, ref_xy: np.ndarray, cutoff_m: float) -> tuple[int, float]:
    """Pairs matched by the metrics' optimal assignment with a cut-off
    (:func:`slamcli.metrics.landmarks.assign_landmarks`) and their RMSE (NaN when none)."""
    a = assign_landmarks(est_xy, ref_xy, cutoff_m)
    rmse = float(np.sqrt(np.mean(a.dist_m**2))) if a.n_matched else float("nan")
    return a.n_matched, rmse


def landmarks_vs_surveyed(est_xy, surveyed_xy, R, t, *, cutoff_m: float = 2.0) -> dict:
    """Estimated landmarks mapped into the reference frame by the trajectory alignment ``(R, t)`` (from
    :func:`ate_vs_position_reference`), then matched to surveyed landmarks by optimal assignment with a cut-off:
    ``survey_lm_matched``, ``survey_lm_rmse_m`` (matched pairs), ``survey_lm_missed``, ``survey_lm_spurious``."""
    est = np.asarray(est_xy, float).reshape(-1, 2) @ np.asarray(R).T + np.asarray(t)
    sv = np.asarray(surveyed_xy, float).reshape(-1, 2)
    n, rmse = _matched_rmse(est, sv, cutoff_m)
    return {"survey_lm_matched": n, "survey_lm_rmse_m": rmse, "survey_lm_missed": int(len(sv) - n),
            "survey_lm_spurious": int(len(est) - n), "survey_lm_cutoff_m": float(cutoff_m)}


def trajectory_against(poses_a, poses_b, landmarks_a, landmarks_b, *, cutoff_m: float = 2.0) -> dict:
    """Result A against result B (B as the reference): pose-position RMSE unaligned and SE(2)-aligned, mean
    heading difference, and landmark distances after optimal assignment with a cut-off.

    Returns
    -------
    dict: ``against_ate_rmse_m``, ``against_ate_aligned_rmse_m``, ``against_heading_rmse_rad``,
    ``against_lm_matched``, ``against_lm_rmse_m`` (matched pairs within ``cutoff_m``), ``against_lm_only_a``,
    ``against_lm_only_b``, ``against_lm_cutoff_m``.
    """
    from slamcli.models.angles import angle_diff

    pa, pb = np.asarray(poses_a, float), np.asarray(poses_b, float)
    if pa.shape != pb.shape:
        raise ValueError(f"the two results have {pa.shape[0]} and {pb.shape[0]} poses; compare results of one dataset")
    e, ea, _ = _aligned_errors(pa[:, :2], pb[:, :2])
    dth = np.asarray(angle_diff(pa[:, 2], pb[:, 2]), float)
    la = np.asarray(landmarks_a, float).reshape(-1, 2)
    lb = np.asarray(landmarks_b, float).reshape(-1, 2)
    n_match, lm_rmse = _matched_rmse(la, lb, cutoff_m)
    return {
        "against_ate_rmse_m": _rms(e),
        "against_ate_aligned_rmse_m": _rms(ea),
        "against_heading_rmse_rad": _rms(dth),
        "against_lm_matched": n_match,
        "against_lm_rmse_m": lm_rmse,
        "against_lm_only_a": int(len(la) - n_match),
        "against_lm_only_b": int(len(lb) - n_match),
        "against_lm_cutoff_m": float(cutoff_m),
    }


def nis_summary(nis: np.ndarray, dof: np.ndarray | int, confidence: float = 0.95) -> dict:
    """Mean NIS over ``N`` innovations and the two-sided band of the mean, ``chi2.ppf([α/2, 1−α/2], Σd)/N``
    (the sum of N independent χ²_d is χ²_{Σd}); also the fraction of single innovations inside their own
    per-innovation band ``chi2.ppf([α/2, 1−α/2], d)``."""
    nis = np.asarray(nis, float)
    dof = np.broadcast_to(np.asarray(dof, float), nis.shape)
    N = nis.size
    if N == 0:
        return {"nis_n": 0, "nis_mean": float("nan"), "nis_band_lo": float("nan"), "nis_band_hi": float("nan"),
                "nis_frac_inside": float("nan")}
    a = 1.0 - confidence
    lo, hi = chi2_ppf(np.array([a / 2, 1 - a / 2]), dof.sum()) / N
    lo1, hi1 = chi2_ppf(a / 2, dof), chi2_ppf(1 - a / 2, dof)
    return {"nis_n": int(N), "nis_mean": float(nis.mean()), "nis_mean_dof": float(dof.mean()),
            "nis_band_lo": float(lo), "nis_band_hi": float(hi),
            "nis_frac_inside": float(np.mean((nis >= lo1) & (nis <= hi1)))}


def mean_nis_band(mean_nis: float, n: int, dof: int = 2, confidence: float = 0.95) -> dict:
    """Two-sided band of the mean NIS of ``n`` innovations of dimension ``dof`` under consistency:
    ``chi2.ppf([α/2, 1−α/2], n·dof)/n`` (treats the innovations as independent)."""
    if not n or mean_nis is None or not np.isfinite(mean_nis):
        return {"nis_mean": float("nan"), "nis_n": int(n or 0), "nis_band_lo": float("nan"),
                "nis_band_hi": float("nan"), "nis_inside_band": None}
    a = 1.0 - confidence
    lo, hi = chi2_ppf(np.array([a / 2, 1 - a / 2]), n * dof) / n
    return {"nis_mean": float(mean_nis), "nis_n": int(n), "nis_band_lo": float(lo), "nis_band_hi": float(hi),
            "nis_inside_band": bool(lo <= mean_nis <= hi)}


#: metrics that need true poses / true landmarks / the true association (reported as not available)
TRUTH_ONLY_METRICS = ("ate_rmse_m (true poses)", "rpe (true poses)", "heading error (true headings)",
                      "landmark errors / OSPA / GOSPA (true landmarks)", "pose and landmark NEES (true poses)",
                      "association accuracy (true association)")


def own_model_metrics(result) -> dict:
    """Metrics a result carries about its own model, needing no truth: final cost/energy (iterative solvers'
    last trace objective or ``extra["final_cost"]``), mean NIS with its χ² band (filters that record
    ``mean_nis`` and their update count), map size and associated rows."""
    out: dict = {"n_landmarks_est": int(np.asarray(result.landmarks_xy).reshape(-1, 2).shape[0]),
                 "n_obs_associated": int(np.sum(np.asarray(result.assoc) >= 0)),
                 "n_obs": int(np.asarray(result.assoc).shape[0])}
    extra = result.extra or {}
    cost = extra.get("final_cost")
    if cost is None and result.trace is not None and len(result.trace):
        cost = float(result.trace.objective[-1])
    out["final_cost"] = float(cost) if cost is not None else float("nan")
    out["final_cost_note"] = ("the solver's own objective at its estimate (graph: ½Σ‖e‖²_Σ; icm: its energy)"
                              if cost is not None else "not available: the solver records no objective")
    n_upd = extra.get("n_updates", extra.get("particle_landmark_updates"))
    if extra.get("mean_nis") is not None and n_upd:
        out.update(mean_nis_band(float(extra["mean_nis"]), int(n_upd)))
        out["nis_note"] = "mean NIS of all updates (χ²(2) each) and the 95 % band of the mean"
    else:
        out["nis_note"] = "not available: the solver records no innovations"
    return out
