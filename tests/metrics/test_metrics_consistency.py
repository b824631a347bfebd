"""NEES and the Monte-Carlo χ² band, against hand-computed values and a seeded synthetic estimator."""

import numpy as np
import pytest

from slamcli.metrics import consistency as cs


def test_nees_known_values():
    assert cs.nees([1.0, 2.0, 0.5], np.diag([1.0, 4.0, 0.25])) == pytest.approx(3.0, abs=1e-12)
    # P⁻¹ = (1/3)[[2, −1], [−1, 2]] → eᵀP⁻¹e = 2/3 for e = (1, 1)
    assert cs.nees([1.0, 1.0], [[2.0, 1.0], [1.0, 2.0]]) == pytest.approx(2.0 / 3.0, abs=1e-12)


def test_nees_singular_covariance_is_nan_not_zero():
    e = np.array([[0.0, 0.0, 0.0], [0.1, 0.0, 0.0]])
    P = np.stack([np.zeros((3, 3)), np.eye(3) * 0.01])
    out = cs.nees(e, P)
    assert np.isnan(out[0])
    assert out[1] == pytest.approx(1.0, abs=1e-12)


def test_pose_nees_wraps_heading():
    true = np.array([[0.0, 0.0, np.pi - 0.05]])
    est = np.array([[0.0, 0.0, -np.pi + 0.05]])
    P = np.diag([1.0, 1.0, 0.01])[None]
    # e_θ = wrap(2π − 0.1) = −0.1 → NEES = 0.01 / 0.01 = 1 (without wrapping it would be ≈ 3850)
    assert cs.pose_nees(est, true, P)[0] == pytest.approx(1.0, abs=1e-9)


def test_landmark_nees_uses_assignment():
    true = np.array([[0.0, 0.0], [10.0, 0.0]])
    est = np.array([[10.2, 0.0], [0.0, 0.1], [50.0, 50.0]])
    cov = np.stack([np.eye(2) * 0.04, np.eye(2) * 0.01, np.eye(2)])
    out = cs.landmark_nees(est, true, cov, [1, 0, -1])
    np.testing.assert_allclose(out[:2], [1.0, 1.0], atol=1e-12)
    assert np.isnan(out[2])


def test_chi2_band_reference_values():
    lo, hi = cs.chi2_band(50, 3)
    assert (round(lo, 2), round(hi, 2)) == (2.36, 3.72)
    lo, hi = cs.chi2_band(50, 6)
    assert (round(lo, 2), round(hi, 2)) == (5.08, 7.00)
    lo, hi = cs.chi2_band(1, 3)
    assert (round(lo, 2), round(hi, 2)) == (0.22, 9.35)


def _synthetic_runs(n_runs=50, n_steps=200, overconfidence=1.0, seed=7):
    """Errors drawn from N(0, P_k) with a time-varying true covariance; the estimator reports P_k/factor."""
    rng = np.random.default_rng(seed)
    A = rng.normal(size=(n_steps, 3, 3)) * 0.1
    P = A @ np.swapaxes(A, 1, 2) + np.diag([0.01, 0.01, 0.001])
    L = np.linalg.cholesky(P)
    e = np.einsum("kij,nkj->nki", L, rng.normal(size=(n_runs, n_steps, 3)))
    true = np.zeros((n_runs, n_steps, 3))
    est = true - e  # e = true − est
    reported = np.broadcast_to(P / overconfidence, (n_runs, n_steps, 3, 3))
    return np.stack([cs.pose_nees(est[i], true[i], reported[i]) for i in range(n_runs)])


def test_consistent_estimator_inside_band_overconfident_far_above():
    good = cs.average_nees(_synthetic_runs(overconfidence=1.0), dof=3)
    bad = cs.average_nees(_synthetic_runs(overconfidence=4.0), dof=3)
    assert (good.lower, good.upper) == pytest.approx((2.36, 3.72), abs=0.01)
    assert good.fraction_inside >= 0.85
    assert good.mean == pytest.approx(3.0, abs=0.15)
    assert bad.fraction_inside <= 0.05
    assert bad.mean == pytest.approx(12.0, rel=0.05)
    assert np.nanmin(bad.anees) > bad.upper


def test_average_nees_skips_steps_missing_in_any_run():
    E = np.array([[np.nan, 3.0, 3.0], [np.nan, 3.0, 100.0]])
    a = cs.average_nees(E, dof=3)
    assert np.isnan(a.anees[0])
    np.testing.assert_allclose(a.anees[1:], [3.0, 51.5])
    assert a.fraction_inside == 0.5  # of the two finite steps, one inside


def test_unavailable_reason():
    assert cs.covariance_unavailable_reason(None, "pose", "icm") == "not available: solver 'icm' stores no pose covariances"
    assert cs.covariance_unavailable_reason(np.full((3, 3, 3), np.nan), "pose") is not None
    assert cs.covariance_unavailable_reason(np.eye(3)[None], "pose") is None
