"""The in-place EKF kernels against the textbook dense Joseph-form algebra, and the growing state buffers."""

from __future__ import annotations

import numpy as np
import pytest

from slamcli.models import observation
from slamcli.models.angles import wrap_angle
from slamcli.solvers.ekf import _GrowingState, update_inplace, update_position_inplace


def random_problem(seed: int, L: int):
    """A random state of ``L`` landmarks around the robot and a random SPD covariance ``P (n, n)``."""
    rng = np.random.default_rng(seed)
    n = 3 + 2 * L
    x = np.r_[rng.uniform(-1, 1, 2), rng.uniform(-np.pi, np.pi), rng.uniform(-8, 8, 2 * L)]
    A = rng.normal(size=(n, n))
    P = 1e-2 * (A @ A.T / n) + 1e-3 * np.eye(n)
    R = np.diag([rng.uniform(0.05, 0.3) ** 2, rng.uniform(0.005, 0.05) ** 2])
    return rng, x, P, R


def textbook_joseph(x, P, z, j, R):
    """Dense textbook EKF update with the full ``H (2, n)``: ``P = (I−KH)P(I−KH)ᵀ + KRKᵀ``, O(n³)."""
    n = x.shape[0]
    k = 3 + 2 * j
    H_r, H_m = observation.range_bearing_jacobians(x[:3], x[k : k + 2])
    H = np.zeros((2, n))
    H[:, :3], H[:, k : k + 2] = H_r, H_m
    y = observation.measurement_residual(z, observation.range_bearing(x[:3], x[k : k + 2]))
    S = H @ P @ H.T + R
    K = P @ H.T @ np.linalg.inv(S)
    I_KH = np.eye(n) - K @ H
    x_new = x + K @ y
    x_new[2] = wrap_angle(x_new[2])
    return x_new, I_KH @ P @ I_KH.T + K @ R @ K.T, y, S


@pytest.mark.parametrize("seed,L", [(0, 1), (1, 7), (2, 50)])
def test_update_inplace_equals_textbook_joseph_form(seed, L):
    rng, x, P, R = random_problem(seed, L)
    for _ in range(5):  # a few consecutive updates of random landmarks with noisy measurements
        j = int(rng.integers(L))
        k = 3 + 2 * j
        z = observation.range_bearing(x[:3], x[k : k + 2]) + rng.normal(0, np.sqrt(np.diag(R)))
        x_ref, P_ref, y_ref, S_ref = textbook_joseph(x, P, z, j, R)
        P_id = id(P)
        y, S = update_inplace(x, P, z, j, R)
        assert id(P) == P_id
        np.testing.assert_allclose(y, y_ref, rtol=0, atol=1e-12)
        np.testing.assert_allclose(S, S_ref, rtol=1e-12, atol=0)
        np.testing.assert_allclose(x, x_ref, rtol=0, atol=1e-10)
        np.testing.assert_allclose(P, P_ref, rtol=0, atol=1e-10 * np.abs(P_ref).max())
        np.testing.assert_allclose(P, P.T, rtol=0, atol=1e-15 * np.abs(P).max())  # symmetric to round-off
        assert np.linalg.eigvalsh(P).min() > 0


def test_update_position_inplace_equals_textbook_joseph_form():
    rng, x, P, R = random_problem(3, 20)
    n = x.shape[0]
    z = x[:2] + rng.normal(0, 0.5, 2)
    H = np.zeros((2, n))
    H[:, :2] = np.eye(2)
    S = H @ P @ H.T + R
    K = P @ H.T @ np.linalg.inv(S)
    I_KH = np.eye(n) - K @ H
    x_ref, P_ref = x + K @ (z - x[:2]), I_KH @ P @ I_KH.T + K @ R @ K.T
    update_position_inplace(x, P, z, R)
    np.testing.assert_allclose(x, x_ref, rtol=0, atol=1e-10)
    np.testing.assert_allclose(P, P_ref, rtol=0, atol=1e-10 * np.abs(P_ref).max())
    np.testing.assert_allclose(P, P.T, rtol=0, atol=1e-15 * np.abs(P).max())


def test_growing_state_relayout_keeps_every_entry():
    """Landmarks go into the zero padding of the contiguous buffers; a full padding is re-laid out."""
    rng = np.random.default_rng(5)
    P0 = np.diag([1.0, 2.0, 3.0])
    st = _GrowingState(np.array([0.1, 0.2, 0.3]), P0, cap_landmarks=2)
    x_ref, P_ref = st.x.copy(), P0.copy()
    for _ in range(9):  # crosses two re-layouts (room for 2 → 6 → 10 landmarks)
        n = st.n
        m, P_mx, P_mm = rng.normal(size=2), rng.normal(size=(2, n)), rng.normal(size=(2, 2))
        j = st.append_landmark(m, P_mx, P_mm)
        assert j == (n - 3) // 2
        x_ref = np.r_[x_ref, m]
        P_ref = np.block([[P_ref, P_mx.T], [P_mx, P_mm]])
        np.testing.assert_array_equal(st.x, x_ref)
        np.testing.assert_array_equal(st.P, P_ref)
        assert st.Pa.flags.c_contiguous and np.shares_memory(st.P, st.Pa) and np.shares_memory(st.x, st.xa)
        n2 = st.n
        assert not st.xa[n2:].any() and not st.Pa[n2:].any() and not st.Pa[:, n2:].any()
    assert st.xa.shape[0] > 3 + 2 * 6  # re-laid out at least twice
