"""Landmark-map errors: paper nearest-neighbour convention vs assignment / OSPA / GOSPA, hand-computed."""

import numpy as np
import pytest

from slamcli.metrics import landmarks as lm
from slamcli.types import IterationTrace


def test_collapsed_map_nn_error_hides_what_ospa_and_gospa_flag():
    # Two estimates collapsed onto true landmark 0; true landmark 1 (5 m away) never mapped.
    true = np.array([[0.0, 0.0], [5.0, 0.0]])
    est = np.array([[0.1, 0.0], [0.0, 0.05]])
    err, idx = lm.nearest_true_errors(est, true)
    np.testing.assert_allclose(err, [0.1, 0.05], atol=1e-15)
    np.testing.assert_array_equal(idx, [0, 0])
    s = lm.paper_landmark_error(est, true)
    assert (s.min, s.mean, s.max) == pytest.approx((0.05, 0.075, 0.1), abs=1e-15)

    h = lm.honest_landmark_error(est, true, cutoff_m=1.0, p=2)
    assert (h["n_matched"], h["n_missed"], h["n_spurious"]) == (1, 1, 1)
    assert h["rmse_matched_m"] == pytest.approx(0.05, abs=1e-15)
    # OSPA: sqrt((0.05² + 1²·(2−1)) / 2); GOSPA: sqrt(0.05² + ½·1 + ½·1)
    assert h["ospa_m"] == pytest.approx(np.sqrt((0.0025 + 1.0) / 2), abs=1e-12)
    assert h["ospa_m"] == pytest.approx(0.70799, abs=1e-5)
    assert h["gospa_m"] == pytest.approx(np.sqrt(1.0025), abs=1e-12)
    assert h["gospa_missed"] == 0.5 and h["gospa_false"] == 0.5
    assert h["gospa_localisation"] == pytest.approx(0.0025, abs=1e-15)


def test_assignment_is_optimal_not_greedy():
    true = np.array([[0.0, 0.0], [1.0, 0.0]])
    est = np.array([[0.9, 0.0], [1.8, 0.0]])
    # greedy NN would pair est0↔true1 (0.1) and est1↔true0 (1.8): Σd² = 3.25; optimal Σd² = 0.81 + 0.64.
    a = lm.assign_landmarks(est, true, cutoff_m=2.0)
    np.testing.assert_array_equal(a.true_of_est(), [0, 1])
    h = lm.honest_landmark_error(est, true, cutoff_m=2.0)
    assert h["rmse_matched_m"] == pytest.approx(np.sqrt(0.725), abs=1e-12)
    assert h["ospa_m"] == pytest.approx(np.sqrt(0.725), abs=1e-12)


def test_ospa_gospa_unequal_cardinality_order_one():
    est = np.array([[0.0, 0.0]])
    true = np.array([[0.0, 0.3], [10.0, 10.0], [20.0, 20.0]])
    h = lm.honest_landmark_error(est, true, cutoff_m=2.0, p=1)
    # OSPA: (1/3)(0.3 + 2·2) ; GOSPA: 0.3 + (2/2)·2 missed
    assert h["ospa_m"] == pytest.approx(4.3 / 3, abs=1e-12)
    assert h["gospa_m"] == pytest.approx(2.3, abs=1e-12)
    assert (h["n_missed"], h["n_spurious"]) == (2, 0)


def test_ospa_gospa_empty_sets():
    true = np.array([[0.0, 0.0], [1.0, 1.0], [2.0, 0.0]])
    h = lm.honest_landmark_error(np.zeros((0, 2)), true, cutoff_m=1.0, p=2)
    assert h["ospa_m"] == 1.0
    assert h["gospa_m"] == pytest.approx(np.sqrt(1.5), abs=1e-12)
    assert np.isnan(h["rmse_matched_m"])
    h0 = lm.honest_landmark_error(np.zeros((0, 2)), np.zeros((0, 2)), cutoff_m=1.0)
    assert h0["ospa_m"] == 0.0 and h0["gospa_m"] == 0.0


def test_pair_at_cutoff_is_not_matched():
    h = lm.honest_landmark_error(np.array([[1.5, 0.0]]), np.array([[0.0, 0.0]]), cutoff_m=1.0)
    assert (h["n_matched"], h["n_missed"], h["n_spurious"]) == (0, 1, 1)
    assert h["ospa_m"] == 1.0


def test_aligned_landmark_error_removes_rigid_motion():
    true = np.array([[0.0, 0.0], [10.0, 0.0], [10.0, 8.0], [0.0, 8.0], [5.0, 4.0]])
    phi = 0.02
    R = np.array([[np.cos(phi), -np.sin(phi)], [np.sin(phi), np.cos(phi)]])
    est = np.vstack([true @ R.T + [0.2, -0.1], [[30.0, 30.0]]])  # plus one spurious landmark
    un = lm.honest_landmark_error(est, true, cutoff_m=1.0)
    al = lm.honest_landmark_error(est, true, cutoff_m=1.0, align=True)
    assert un["n_matched"] == 5 and un["rmse_matched_m"] > 0.1
    assert al["n_matched"] == 5 and al["n_spurious"] == 1
    assert al["rmse_matched_m"] < 1e-10


def _trace(true, offsets, n_iter=4):
    maps = [true + offsets / (k + 1) for k in range(n_iter)]
    return IterationTrace.from_lists(np.arange(n_iter, 0, -1.0), np.zeros(n_iter), np.ones(n_iter), maps)


def test_paper_error_curve_on_synthetic_trace():
    true = np.array([[0.0, 1.0], [5.0, 1.0], [10.0, 8.0]])
    offsets = np.array([[0.4, 0.0], [0.0, -0.2], [0.36, 0.48]])  # norms 0.4, 0.2, 0.6
    norms = np.array([0.4, 0.2, 0.6])
    path = np.column_stack([np.linspace(0, 10, 50), np.zeros(50)])
    df = lm.paper_error_per_iteration(_trace(true, offsets), true, path, near_path_m=2.0)
    assert list(df["iteration"]) == [0, 1, 2, 3]
    for k in range(4):
        row = df.iloc[k]
        assert row["err_min_m"] == pytest.approx(0.2 / (k + 1), abs=1e-12)
        assert row["err_mean_m"] == pytest.approx(norms.mean() / (k + 1), abs=1e-12)
        assert row["err_max_m"] == pytest.approx(0.6 / (k + 1), abs=1e-12)
        # only the two landmarks at y = 1 are within 2 m of the path
        assert row["err_mean_near_path_m"] == pytest.approx(0.3 / (k + 1), abs=1e-12)
        expected_change = 0.0 if k == 0 else norms.mean() * (1 / k - 1 / (k + 1))
        assert row["map_change_m"] == pytest.approx(expected_change, abs=1e-12)


def test_map_change_undefined_when_map_size_changes():
    assert np.isnan(lm.map_change(np.zeros((2, 2)), np.zeros((3, 2))))
    assert lm.map_change([[0.0, 0.0], [1.0, 1.0]], [[3.0, 4.0], [1.0, 1.0]]) == pytest.approx(2.5)
