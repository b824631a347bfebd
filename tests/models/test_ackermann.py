"""Ackermann car model and the sensor mounting offset: Jacobians vs central finite differences, the rear-axle
special case vs the DDMR model, and the laser offset (one landmark seen from two poses maps to one point)."""

from __future__ import annotations

import numpy as np
import pytest

from slamcli.models import observation as obs
from slamcli.models.ackermann import (
    VICTORIA_PARK,
    VICTORIA_PARK_LASER_XY,
    AckermannParams,
    ackermann_jacobians,
    ackermann_step,
    centre_twist,
    integrate_ackermann,
)
from slamcli.models.angles import wrap_angle
from slamcli.models.motion import ddmr_step

VP_LASER = AckermannParams(wheelbase_m=2.83, encoder_offset_m=0.76, ref_x_m=3.78, ref_y_m=0.50)


def _num_jac(f, x0, eps=1e-6):
    x0 = np.asarray(x0, float)
    f0 = np.asarray(f(x0))
    J = np.zeros(f0.shape + x0.shape)
    for i in range(x0.size):
        d = np.zeros_like(x0)
        d[i] = eps
        diff = np.asarray(f(x0 + d)) - np.asarray(f(x0 - d))
        if f0.shape and f0.shape[-1] >= 2 and diff.shape[-1] == 3:
            diff[..., 2] = wrap_angle(diff[..., 2])
        J[..., i] = diff / (2 * eps)
    return J


@pytest.mark.parametrize("params", [VICTORIA_PARK, VP_LASER])
@pytest.mark.parametrize("x,u", [([1.0, -2.0, 0.7], [3.2, 0.25]), ([0.0, 0.0, -2.9], [5.0, -0.45]),
                                 ([-4.0, 3.0, 3.1], [0.4, 0.0])])
def test_ackermann_jacobians_match_finite_differences(params, x, u):
    dt = 0.025
    G_x, G_u = ackermann_jacobians(np.array(x), np.array(u), dt, params)
    Nx = _num_jac(lambda xx: ackermann_step(xx, u, dt, params), x)
    Nu = _num_jac(lambda uu: ackermann_step(x, uu, dt, params), u)
    np.testing.assert_allclose(G_x, Nx, atol=1e-8)
    np.testing.assert_allclose(G_u, Nu, atol=1e-8)


def test_ackermann_centre_speed_hand_values():
    # v_c = v_e / (1 - tan(α) H / L), ω = v_c tan(α) / L, by hand for v_e = 2, α = 0.2
    v_c, w = centre_twist([2.0, 0.2], VICTORIA_PARK)
    t = np.tan(0.2)
    assert v_c == pytest.approx(2.0 / (1 - t * 0.76 / 2.83), rel=1e-14)
    assert w == pytest.approx(v_c * t / 2.83, rel=1e-14)
    # straight ahead: encoder speed is the centre speed, no rotation
    v_c0, w0 = centre_twist([3.0, 0.0], VICTORIA_PARK)
    assert (v_c0, w0) == (3.0, 0.0)


def test_rear_axle_point_is_ddmr_with_centre_twist():
    rng = np.random.default_rng(3)
    x = rng.normal(size=(20, 3))
    u = np.column_stack([rng.uniform(0, 6, 20), rng.uniform(-0.5, 0.5, 20)])
    v_c, w = centre_twist(u, VICTORIA_PARK)
    np.testing.assert_allclose(ackermann_step(x, u, 0.025, VICTORIA_PARK),
                               ddmr_step(x, np.column_stack([v_c, w]), 0.025), atol=1e-14)


def test_laser_point_motion_is_rigid_with_the_rear_axle():
    """Integrating the laser point (a, b) with small steps stays the rigid image of the integrated rear axle
    (the Euler error shrinks with dt)."""
    rng = np.random.default_rng(0)
    controls = np.column_stack([rng.uniform(2, 5, 400), 0.3 * np.sin(np.linspace(0, 6, 400))])
    x0 = np.array([1.0, 2.0, 0.3])
    errs = []
    for sub in (1, 10):
        dt = 0.025 / sub
        c = np.repeat(controls, sub, axis=0)
        body = integrate_ackermann(x0, c, dt, VICTORIA_PARK)
        laser = integrate_ackermann(obs.sensor_pose(x0, VICTORIA_PARK_LASER_XY), c, dt, VP_LASER)
        errs.append(np.abs(obs.sensor_pose(body, VICTORIA_PARK_LASER_XY)[:, :2] - laser[:, :2]).max())
    assert errs[1] < 0.2 * errs[0]
    assert errs[1] < 5e-3


def test_integrate_matches_repeated_steps():
    controls = np.array([[3.0, 0.1], [3.5, -0.2], [0.0, 0.4], [2.0, 0.5]])
    x = np.array([0.5, -1.0, 3.0])
    poses = integrate_ackermann(x, controls, 0.025, VP_LASER)
    for t, u in enumerate(controls):
        x = ackermann_step(x, u, 0.025, VP_LASER)
        np.testing.assert_allclose(poses[t + 1], x, atol=1e-12)


def test_params_reject_bad_geometry():
    with pytest.raises(ValueError, match="wheelbase_m"):
        AckermannParams(wheelbase_m=0.0)


@pytest.mark.parametrize("x,m", [([1.0, 2.0, 0.4], [12.0, 9.0]), ([-3.0, 0.5, -2.8], [-20.0, -4.0])])
def test_offset_observation_jacobians(x, m):
    off = VICTORIA_PARK_LASER_XY
    H_x, H_m = obs.range_bearing_offset_jacobians(np.array(x), np.array(m), off)
    np.testing.assert_allclose(H_x, _num_jac(lambda xx: obs.range_bearing_offset(xx, m, off), x), atol=1e-7)
    np.testing.assert_allclose(H_m, _num_jac(lambda mm: obs.range_bearing_offset(x, mm, off), m), atol=1e-7)
    z = obs.range_bearing_offset(x, m, off)
    M_x, M_z = obs.inverse_range_bearing_offset_jacobians(np.array(x), z, off)
    np.testing.assert_allclose(M_x, _num_jac(lambda xx: obs.inverse_range_bearing_offset(xx, z, off), x),
                               atol=1e-7)
    np.testing.assert_allclose(M_z, _num_jac(lambda zz: obs.inverse_range_bearing_offset(x, zz, off), z),
                               atol=1e-7)


def test_landmark_seen_from_two_poses_maps_to_one_point():
    off = VICTORIA_PARK_LASER_XY
    m = np.array([15.0, 7.0])
    poses = np.array([[0.0, 0.0, 0.2], [6.0, -3.0, 1.4]])
    z = obs.range_bearing_offset(poses, m, off)
    back = obs.inverse_range_bearing_offset(poses, z, off)
    np.testing.assert_allclose(back, [m, m], atol=1e-12)
    # the two measurements differ from the offset-free ones, and ignoring the offset maps to two points
    # that are (a, b) rotated apart from the truth: the offset is not negligible
    wrong = obs.inverse_range_bearing(poses, z)
    assert np.linalg.norm(wrong[0] - wrong[1]) > 1.0
    assert np.linalg.norm(wrong[0] - m) == pytest.approx(np.hypot(*off), rel=1e-12)
    # hand check: the laser of pose 0 sits at R(0.2)(3.78, 0.5)
    c, s = np.cos(0.2), np.sin(0.2)
    np.testing.assert_allclose(obs.sensor_pose(poses[0], off), [3.78 * c - 0.5 * s, 3.78 * s + 0.5 * c, 0.2])
    np.testing.assert_allclose(obs.body_pose_from_sensor(obs.sensor_pose(poses, off), off), poses, atol=1e-12)
