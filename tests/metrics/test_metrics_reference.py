"""Metrics without ground truth (issue 14): ATE against a position-only reference by time with gaps, one result
against another, the mean-NIS χ² band, and the own-model metrics — all against hand-computed values."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.stats import chi2

from slamcli.metrics.reference import (
    ate_vs_position_reference,
    gaps,
    glitches,
    mean_nis_band,
    own_model_metrics,
    trajectory_against,
)
from slamcli.metrics.trajectory import umeyama_se2
from slamcli.types import SolverResult, Status


def _line(n=101):
    t = np.linspace(0.0, 10.0, n)
    return t, np.column_stack([t, 0.5 * t, np.zeros(n)])


def test_gps_ate_hand_values_and_alignment():
    t, poses = _line()
    # GPS every 0.5 s in a frame rotated by 30° and shifted: the aligned ATE removes the frame exactly
    rt = np.arange(0.25, 10.0, 0.5)
    p = np.column_stack([rt, 0.5 * rt])
    c, s = np.cos(np.pi / 6), np.sin(np.pi / 6)
    R = np.array([[c, -s], [s, c]])
    ref = p @ R.T + [5.0, -2.0]
    m = ate_vs_position_reference(t, poses, rt, ref)
    assert m["gps_n_matched"] == len(rt) and m["gps_ate_aligned_rmse_m"] == pytest.approx(0.0, abs=1e-9)
    assert m["gps_ate_rmse_m"] == pytest.approx(np.sqrt(np.mean(np.sum((p - ref) ** 2, 1))), rel=1e-12)
    # a known non-rigid error: every other fix 1 m off along the normal of the line
    n = np.array([-0.5, 1.0]) / np.hypot(0.5, 1.0)
    ref2 = p + np.outer((np.arange(len(rt)) % 2) * 2 - 1, n) * 1.0
    m2 = ate_vs_position_reference(t, poses, rt, ref2)
    assert m2["gps_ate_rmse_m"] == pytest.approx(1.0, rel=1e-12)
    assert m2["gps_ate_aligned_rmse_m"] <= 1.0 + 1e-12


def test_gps_fixes_outside_the_run_and_gaps_are_stated():
    t, poses = _line()
    rt = np.array([-1.0, 0.5, 1.0, 4.0, 4.5, 9.5, 12.0])
    m = ate_vs_position_reference(t, poses, rt, np.column_stack([rt, 0.5 * rt]), gap_s=1.0)
    assert m["gps_n_matched"] == 5 and m["gps_n_outside"] == 2
    # gaps > 1 s inside [0, 10]: 1.0→4.0 (3 s) and 4.5→9.5 (5 s)
    assert gaps(rt, 0.0, 10.0, 1.0) == [(1.0, 4.0), (4.5, 9.5)]
    assert m["gps_gap_count"] == 2 and m["gps_gap_total_s"] == pytest.approx(8.0)
    assert m["gps_longest_gap_s"] == pytest.approx(5.0) and m["gps_ate_rmse_m"] == pytest.approx(0.0, abs=1e-12)


def test_align_se2_recovers_a_rotation():
    rng = np.random.default_rng(1)
    a = rng.normal(size=(30, 2))
    th = 1.1
    R = np.array([[np.cos(th), -np.sin(th)], [np.sin(th), np.cos(th)]])
    Rh, th_ = umeyama_se2(a, a @ R.T + [3.0, 4.0])
    np.testing.assert_allclose(Rh, R, atol=1e-12)
    np.testing.assert_allclose(th_, [3.0, 4.0], atol=1e-12)


def test_result_against_result():
    _, poses = _line(11)
    lm = np.array([[0.0, 0.0], [5.0, 5.0], [10.0, 0.0]])
    m = trajectory_against(poses, poses, lm, lm)
    assert m["against_ate_rmse_m"] == 0.0 and m["against_lm_matched"] == 3 and m["against_lm_rmse_m"] == 0.0
    shifted = poses + [0.3, 0.4, 0.0]
    lm_b = np.vstack([lm[:2] + [0.0, 0.5], [[50.0, 50.0]]])  # two near (0.5 m), one far
    m = trajectory_against(shifted, poses, lm, lm_b, cutoff_m=2.0)
    assert m["against_ate_rmse_m"] == pytest.approx(0.5) and m["against_ate_aligned_rmse_m"] == pytest.approx(0, abs=1e-9)
    assert m["against_lm_matched"] == 2 and m["against_lm_rmse_m"] == pytest.approx(0.5)
    assert m["against_lm_only_a"] == 1 and m["against_lm_only_b"] == 1
    with pytest.raises(ValueError, match="poses"):
        trajectory_against(poses[:5], poses, lm, lm)


def test_mean_nis_band_and_own_model_metrics():
    b = mean_nis_band(2.1, 500)
    assert b["nis_band_lo"] == pytest.approx(chi2.ppf(0.025, 1000) / 500)
    assert b["nis_band_hi"] == pytest.approx(chi2.ppf(0.975, 1000) / 500)
    assert b["nis_inside_band"] is True and mean_nis_band(3.0, 500)["nis_inside_band"] is False
    res = SolverResult(solver="ekf", solver_version="0", params={}, status=Status.COMPLETED, message="",
                       poses_xyt=np.zeros((3, 3)), landmarks_xy=np.zeros((4, 2)), assoc=np.array([0, 1, -1, 3, 3]),
                       extra={"mean_nis": 2.1, "n_updates": 500})
    m = own_model_metrics(res)
    assert m["n_landmarks_est"] == 4 and m["n_obs_associated"] == 4 and m["nis_mean"] == 2.1
    assert m["final_cost_note"].startswith("not available") and np.isnan(m["final_cost"])
    res2 = SolverResult(solver="graph", solver_version="0", params={}, status=Status.CONVERGED, message="",
                        poses_xyt=np.zeros((3, 3)), landmarks_xy=np.zeros((0, 2)), assoc=np.zeros(0, np.int64),
                        extra={"final_cost": 12.5})
    m2 = own_model_metrics(res2)
    assert m2["final_cost"] == 12.5 and m2["nis_note"].startswith("not available")


def _balanced_track(speed, n=40, dt=0.2, a=1.0):
    """A straight run at ``speed`` m/s (estimate) and GPS fixes every ``dt`` s displaced ±a m along the normal
    in the pattern + − − + (repeated): Σ sᵢ = Σ sᵢ τᵢ = 0, so the least-squares SE(2) alignment is the identity
    and the aligned ATE is exactly ``a`` (closed form)."""
    u = np.array([0.6, 0.8])
    nrm = np.array([-0.8, 0.6])
    t = np.linspace(0.0, n * dt, 4 * n + 1)
    poses = np.column_stack([speed * t[:, None] * u, np.zeros(t.size)])
    rt = dt * np.arange(n)
    s = np.tile([1.0, -1.0, -1.0, 1.0], n // 4)
    ref = speed * rt[:, None] * u + a * s[:, None] * nrm
    return t, poses, rt, ref, u, nrm


def test_gps_glitch_gate_rejects_a_planted_glitch_and_keeps_the_closed_form_ate():
    t, poses, rt, ref, u, nrm = _balanced_track(speed=8.0)
    m0 = ate_vs_position_reference(t, poses, rt, ref)
    assert m0["gps_n_rejected"] == 0 and m0["gps_ate_aligned_rmse_m"] == pytest.approx(1.0, rel=1e-12)
    # plant a glitch between fixes 20 and 21: 140 m off the line at its own time
    tg, D = 0.5 * (rt[20] + rt[21]), 140.0
    rt2 = np.insert(rt, 21, tg)
    ref2 = np.insert(ref, 21, 8.0 * tg * u + D * nrm, axis=0)
    m = ate_vs_position_reference(t, poses, rt2, ref2)
    assert m["gps_n_rejected"] == 1 and m["gps_rejected_time_s"] == [pytest.approx(tg)]
    assert m["gps_n_matched"] == len(rt)
    assert m["gps_ate_aligned_rmse_m"] == pytest.approx(1.0, rel=1e-12)
    assert m["gps_ate_rmse_m"] == pytest.approx(1.0, rel=1e-12)
    # nothing hidden: the ungated ATE over every fix (unaligned: closed form with the glitch's error D)
    n = len(rt)
    assert m["gps_ate_raw_rmse_m"] == pytest.approx(np.sqrt((n * 1.0 + D**2) / (n + 1)), rel=1e-12)
    assert 1.0 < m["gps_ate_aligned_raw_rmse_m"] <= m["gps_ate_raw_rmse_m"]
    assert m["gps_glitch_max_speed_mps"] == 20.0 and m["gps_glitch_tol_m"] == 5.0


def test_gps_glitch_gate_keeps_fixes_at_a_legitimate_high_speed():
    # 60 m/s, three times the gate's speed: every fix is far from its neighbours, but they agree → none gated
    t, poses, rt, ref, _, _ = _balanced_track(speed=60.0)
    m = ate_vs_position_reference(t, poses, rt, ref)
    assert m["gps_n_rejected"] == 0 and m["gps_n_matched"] == len(rt)
    assert m["gps_ate_aligned_rmse_m"] == pytest.approx(1.0, rel=1e-12)
    assert m["gps_ate_aligned_raw_rmse_m"] == m["gps_ate_aligned_rmse_m"]


def test_gps_glitch_gate_threshold_by_hand():
    # fixes 1 s apart on the x axis; the middle one jumps 30 m sideways (bound 20·1 + 5 = 25 m)
    t = np.array([0.0, 1.0, 2.0])
    xy = np.array([[0.0, 0.0], [1.0, 30.0], [2.0, 0.0]])
    assert glitches(t, xy).tolist() == [False, True, False]
    assert glitches(t, xy, max_speed_mps=26.0).tolist() == [False, False, False]  # 26 + 5 > √(1 + 900)
    assert glitches(t, xy, tol_m=11.0).tolist() == [False, False, False]
    # the neighbours disagree (the last one jumped too): not an isolated glitch, not gated
    assert not glitches(t, [[0.0, 0.0], [1.0, 30.0], [2.0, 60.0]]).any()
    # end fixes are never gated
    assert not glitches(t[:2], xy[:2]).any()
    with pytest.raises(ValueError, match="max_speed_mps"):
        glitches(t, xy, max_speed_mps=0.0)
