"""ATE / RPE / SE(2) alignment against hand-computed values."""

import numpy as np
import pytest

from slamcli.metrics import trajectory as tr
from slamcli.models import se2


def _path(n=60, seed=0):
    rng = np.random.default_rng(seed)
    inc = np.column_stack([rng.uniform(0.2, 0.6, n), rng.normal(0, 0.05, n), rng.normal(0, 0.1, n)])
    poses = [np.zeros(3)]
    for d in inc:
        poses.append(se2.compose(poses[-1], d))
    return np.array(poses)


def test_umeyama_recovers_known_rotation_and_translation():
    rng = np.random.default_rng(1)
    src = rng.normal(size=(30, 2)) * 10
    phi, t = 0.7, np.array([3.0, -2.0])
    R = np.array([[np.cos(phi), -np.sin(phi)], [np.sin(phi), np.cos(phi)]])
    dst = src @ R.T + t
    R_hat, t_hat = tr.umeyama_se2(src, dst)
    np.testing.assert_allclose(R_hat, R, atol=1e-12)
    np.testing.assert_allclose(t_hat, t, atol=1e-12)


def test_umeyama_returns_proper_rotation_for_reflected_points():
    # Mirrored points: the best *rotation* must still have det +1.
    src = np.array([[1.0, 0.0], [0.0, 2.0], [-1.0, 0.5], [0.3, -1.0]])
    dst = src * np.array([1.0, -1.0])
    R, _ = tr.umeyama_se2(src, dst)
    assert np.linalg.det(R) == pytest.approx(1.0, abs=1e-12)


def test_ate_of_shifted_trajectory():
    true = _path()
    est = true.copy()
    est[:, :2] += [0.3, 0.4]  # every position 0.5 m off
    m = tr.ate(est, true)
    assert m["ate_rmse_m"] == pytest.approx(0.5, abs=1e-12)
    assert m["ate_max_m"] == pytest.approx(0.5, abs=1e-12)
    assert m["heading_rmse_rad"] == 0.0
    # alignment removes a pure shift
    assert tr.ate(est, true, align=True)["ate_rmse_m"] < 1e-12


def test_aligned_ate_removes_rigid_motion_and_heading_offset():
    true = _path()
    S = np.array([1.0, -2.0, 2.5])  # large rotation → heading offset wraps across ±π
    est = se2.compose(S, true)
    assert tr.ate(est, true)["ate_rmse_m"] > 1.0
    m = tr.ate(est, true, align=True)
    assert m["ate_rmse_m"] < 1e-10
    assert m["heading_rmse_rad"] < 1e-10


def test_heading_error_is_wrapped():
    true = np.zeros((3, 3))
    est = np.zeros((3, 3))
    true[:, 2] = np.pi - 0.01
    est[:, 2] = -np.pi + 0.01
    _, h = tr.ate_errors(est, true)
    np.testing.assert_allclose(h, 0.02, atol=1e-12)


def test_rpe_of_known_drift_per_step():
    # P_{i+1} = P_i ⊕ (Δ_i ⊕ d): then E_i,i+1 = Δ_i⁻¹ Δ_i d = d exactly.
    true = _path(80)
    d = np.array([0.1, 0.0, 0.01])
    inc = se2.between(true[:-1], true[1:])
    est = [true[0]]
    for k in range(len(inc)):
        est.append(se2.compose(est[-1], se2.compose(inc[k], d)))
    est = np.array(est)
    i, j, et, er = tr.rpe_errors(est, true, 1, "steps")
    assert len(i) == len(true) - 1 and np.all(j == i + 1)
    np.testing.assert_allclose(et, 0.1, atol=1e-12)
    np.testing.assert_allclose(er, 0.01, atol=1e-12)
    m = tr.rpe(est, true, 1)
    assert m["rpe_trans_rmse_m"] == pytest.approx(0.1, abs=1e-12)
    assert m["rpe_rot_mean_rad"] == pytest.approx(0.01, abs=1e-12)


def test_rpe_over_distance_on_straight_line_with_scale_drift():
    # Truth: 1 m per step along x; estimate: 1.1 m per step. Over 5 m travelled: j = i + 5, error 0.5 m.
    n = 21
    true = np.column_stack([np.arange(n, dtype=float), np.zeros(n), np.zeros(n)])
    est = true.copy()
    est[:, 0] *= 1.1
    i, j, et, er = tr.rpe_errors(est, true, 5.0, "m")
    np.testing.assert_array_equal(j - i, 5)
    assert len(i) == n - 5
    np.testing.assert_allclose(et, 0.5, atol=1e-12)
    np.testing.assert_allclose(er, 0.0, atol=1e-15)


def test_rpe_bad_arguments():
    true = _path(5)
    with pytest.raises(ValueError, match="unit"):
        tr.rpe(true, true, 1, "furlongs")
    with pytest.raises(ValueError, match="integer"):
        tr.rpe(true, true, 1.5, "steps")
    with pytest.raises(ValueError, match="differ"):
        tr.ate(true, true[:-1])
    assert tr.rpe(true, true, 100)["rpe_pairs"] == 0
