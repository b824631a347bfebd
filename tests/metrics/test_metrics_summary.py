"""evaluate_result: the tables and scalars of one result, incl. 'not available' when there is no covariance."""

import numpy as np
import pytest

from slamcli.metrics.summary import EvaluationParams, evaluate_result, monte_carlo_pose_nees
from slamcli.types import GroundTruth, IterationTrace, SolverResult, Status


def _truth():
    n = 11
    poses = np.column_stack([np.arange(n, dtype=float), np.zeros(n), np.zeros(n)])
    lms = np.array([[0.0, 2.0], [5.0, 2.0], [10.0, 20.0]])
    return GroundTruth(poses, lms, np.zeros(0, np.int64))


def _result(truth, pose_cov=None, landmark_cov=None, trace=None):
    est = truth.poses_xyt.copy()
    est[:, 1] += 0.3
    lm = np.array([[0.1, 2.0], [0.0, 2.05], [30.0, 30.0]])  # two on landmark 0, one spurious
    return SolverResult("toy", "0", {}, Status.COMPLETED, "", est, lm, np.zeros(0, np.int64),
                        pose_cov=pose_cov, landmark_cov=landmark_cov, trace=trace)


def test_evaluate_without_covariances_reports_not_available():
    truth = _truth()
    ev = evaluate_result(_result(truth), truth, params=EvaluationParams(cutoff_m=1.0, near_path_m=3.0))
    s = ev.scalars
    assert s["ate_rmse_m"] == pytest.approx(0.3, abs=1e-12)
    assert s["aligned_ate_rmse_m"] < 1e-12
    assert s["rpe_trans_rmse_m"] == pytest.approx(0.0, abs=1e-12)
    assert s["pose_nees_mean"] is None and s["pose_nees_note"].startswith("not available")
    assert s["landmark_nees_mean"] is None and "not available" in s["landmark_nees_note"]
    assert (s["lm_n_matched"], s["lm_n_missed"], s["lm_n_spurious"]) == (1, 2, 2)
    assert s["paper_err_min_m"] == pytest.approx(0.05, abs=1e-12)
    assert s["paper_n_near_path"] == 2  # the spurious one's nearest true landmark (10, 20) is far from the path
    assert s["paper_err_mean_near_path_m"] == pytest.approx(0.075, abs=1e-12)
    assert s["per_iteration_note"].startswith("not available") and len(ev.per_iteration) == 0
    assert "pose_nees" not in ev.per_step and len(ev.per_step) == 11
    assert list(ev.per_landmark["assigned_true"]) == [-1, 0, -1]


def test_evaluate_with_covariances_and_trace():
    truth = _truth()
    pc = np.broadcast_to(np.diag([0.09, 0.09, 0.01]), (11, 3, 3)).copy()
    pc[0] = 0.0  # known start: NEES undefined there
    lc = np.broadcast_to(np.eye(2) * 0.0025, (3, 2, 2))
    tr = IterationTrace.from_lists([2.0, 1.0], [0.0, 0.0], [0.1, 0.1],
                                   [truth.landmarks_xy + 0.5, truth.landmarks_xy + [0.3, 0.4]])
    ev = evaluate_result(_result(truth, pc, lc, tr), truth)
    s = ev.scalars
    # pose error 0.3 m in y with σ_y = 0.3 → NEES 1 at steps 1..10
    assert s["pose_nees_mean"] == pytest.approx(1.0, abs=1e-12)
    assert np.isnan(ev.per_step["pose_nees"][0])
    # matched landmark (0, 2.05) vs (0, 2): 0.05² / 0.0025 = 1
    assert s["landmark_nees_mean"] == pytest.approx(1.0, abs=1e-12)
    assert list(ev.per_iteration["err_mean_m"]) == pytest.approx([np.sqrt(0.5), 0.5])
    assert ev.per_iteration["map_change_m"][1] == pytest.approx(np.hypot(0.2, 0.1))


def test_length_mismatch_is_an_error():
    truth = _truth()
    r = _result(truth)
    short = GroundTruth(truth.poses_xyt[:-1], truth.landmarks_xy, truth.obs_landmark)
    with pytest.raises(ValueError, match="poses"):
        evaluate_result(r, short)


def test_monte_carlo_nees_not_available_without_covariances():
    truth = _truth()
    a, why = monte_carlo_pose_nees([(_result(truth), truth)])
    assert a is None and "no pose covariances" in why
    pc = np.broadcast_to(np.diag([0.09, 0.09, 0.01]), (11, 3, 3))
    a, why = monte_carlo_pose_nees([(_result(truth, pc), truth)] * 4)
    assert why is None and a.n_runs == 4
    np.testing.assert_allclose(a.anees, 1.0, atol=1e-12)
