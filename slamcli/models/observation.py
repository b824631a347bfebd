"""Range-bearing observation model, its inverse, and their Jacobians.

Forward model (measurement space)::

    h(x, m) = [ ‖m − p‖,  wrap(atan2(m_y − y, m_x − x) − θ) ]

Inverse model (landmark space; paper 000 writes it as h(x_t, z_{t,i}) and builds its observation
potentials on it)::

    m = h⁻¹(x, z) = p + r · [cos(θ + b), sin(θ + b)]

Paper 000 measures the bearing from the robot's right side (0 = right, π = left), i.e. ``b_paper = b + π/2``;
slamcli stores the conventional bearing ``b`` (0 = straight ahead) everywhere.
"""

from __future__ import annotations

import numpy as np

from slamcli.models.angles import wrap_angle


def range_bearing(x, m):
    """Predicted measurement ``z = [range, bearing] (..., 2)`` of landmark(s) ``m (..., 2)`` from pose(s)
    ``x (..., 3)``."""
    x = np.asarray(x, float)
    m = np.asarray(m, float)
    dx = m[..., 0] - x[..., 0]
    dy = m[..., 1] - x[..., 1]
    return np.stack([np.hypot(dx, dy), wrap_angle(np.arctan2(dy, dx) - x[..., 2])], -1)


def range_bearing_jacobians(x, m):
    """Jacobians of :func:`range_bearing`.

    Returns
    -------
    H_x : ndarray (..., 2, 3)   ∂h/∂x
    H_m : ndarray (..., 2, 2)   ∂h/∂m  (note H_m = −H_x[..., :2])
    """
    x = np.asarray(x, float)
    m = np.asarray(m, float)
    dx = m[..., 0] - x[..., 0]
    dy = m[..., 1] - x[..., 1]
    q = dx * dx + dy * dy
    r = np.sqrt(q)
    lead = np.broadcast_shapes(x.shape[:-1], m.shape[:-1])
    H_m = np.empty(lead + (2, 2))
    H_m[..., 0, 0] = dx / r
    H_m[..., 0, 1] = dy / r
    H_m[..., 1, 0] = -dy / q
    H_m[..., 1, 1] = dx / q
    H_x = np.zeros(lead + (2, 3))
    H_x[..., :, :2] = -H_m
    H_x[..., 1, 2] = -1.0
    return H_x, H_m


def inverse_range_bearing(x, z):
    """Landmark position ``(..., 2)`` that pose(s) ``x (..., 3)`` would see at measurement(s) ``z (..., 2)``."""
    x = np.asarray(x, float)
    z = np.asarray(z, float)
    a = x[..., 2] + z[..., 1]
    return np.stack([x[..., 0] + z[..., 0] * np.cos(a), x[..., 1] + z[..., 0] * np.sin(a)], -1)


def inverse_range_bearing_jacobians(x, z):
    """Jacobians of :func:`inverse_range_bearing`.

    Returns
    -------
    M_x : ndarray (..., 2, 3)   ∂m/∂x
    M_z : ndarray (..., 2, 2)   ∂m/∂z
    """
    x = np.asarray(x, float)
    z = np.asarray(z, float)
    a = x[..., 2] + z[..., 1]
    c, s = np.cos(a), np.sin(a)
    r = z[..., 0]
    lead = np.broadcast_shapes(x.shape[:-1], z.shape[:-1])
    M_x = np.zeros(lead + (2, 3))
    M_x[..., 0, 0] = 1.0
    M_x[..., 1, 1] = 1.0
    M_x[..., 0, 2] = -r * s
    M_x[..., 1, 2] = r * c
    M_z = np.empty(lead + (2, 2))
    M_z[..., 0, 0] = c
    M_z[..., 1, 0] = s
    M_z[..., 0, 1] = -r * s
    M_z[..., 1, 1] = r * c
    return M_x, M_z


def measurement_residual(z, z_hat):
    """``z − ẑ (..., 2)`` with the bearing wrapped."""
    z = np.asarray(z, float)
    z_hat = np.asarray(z_hat, float)
    return np.stack([z[..., 0] - z_hat[..., 0], wrap_angle(z[..., 1] - z_hat[..., 1])], -1)


def to_paper_bearing(bearing):
    """Convert slamcli's bearing (0 ahead) to paper 000's (0 right, π left)."""
    return wrap_angle(np.asarray(bearing, float) + np.pi / 2)


def from_paper_bearing(bearing_paper):
    """Inverse of :func:`to_paper_bearing`."""
    return wrap_angle(np.asarray(bearing_paper, float) - np.pi / 2)


# --------------------------------------------------------------------------------------------------------
# sensor mounting offset: the sensor sits at (a, b) in the body frame (e.g. the Victoria Park laser at
# (3.78, 0.50) m ahead-left of the rear axle), with the body's heading.
#
#     s(x) = x ⊕ [a, b, 0] = [x + a cos θ − b sin θ,  y + a sin θ + b cos θ,  θ]
#     h_o(x, m) = h(s(x), m)            ∂h_o/∂x = ∂h/∂s · ∂s/∂x
#     m = h⁻¹(s(x), z)                  ∂m/∂x   = ∂h⁻¹/∂s · ∂s/∂x
# --------------------------------------------------------------------------------------------------------
def sensor_pose(x, offset_xy):
    """Pose ``(..., 3)`` of a sensor mounted at ``offset_xy = (a, b)`` (body frame) on a robot at ``x (..., 3)``."""
    x = np.asarray(x, float)
    a, b = float(offset_xy[0]), float(offset_xy[1])
    c, s = np.cos(x[..., 2]), np.sin(x[..., 2])
    return np.stack([x[..., 0] + a * c - b * s, x[..., 1] + a * s + b * c, x[..., 2]], -1)


def sensor_pose_jacobian(x, offset_xy):
    """``∂s/∂x (..., 3, 3)``: identity plus ``[−a sin θ − b cos θ, a cos θ − b sin θ, 0]ᵀ`` in column θ."""
    x = np.asarray(x, float)
    a, b = float(offset_xy[0]), float(offset_xy[1])
    c, s = np.cos(x[..., 2]), np.sin(x[..., 2])
    J = np.zeros(x.shape[:-1] + (3, 3))
    J[..., 0, 0] = J[..., 1, 1] = J[..., 2, 2] = 1.0
    J[..., 0, 2] = -a * s - b * c
    J[..., 1, 2] = a * c - b * s
    return J


def body_pose_from_sensor(s, offset_xy):
    """Inverse of :func:`sensor_pose`: the body pose ``(..., 3)`` whose sensor is at ``s (..., 3)``."""
    return sensor_pose(s, (-float(offset_xy[0]), -float(offset_xy[1])))


def range_bearing_offset(x, m, offset_xy):
    """:func:`range_bearing` of landmark(s) ``m (..., 2)`` seen by a sensor mounted at ``offset_xy`` on a robot
    at ``x (..., 3)``; ``(..., 2)``."""
    return range_bearing(sensor_pose(x, offset_xy), m)


def range_bearing_offset_jacobians(x, m, offset_xy):
    """Jacobians of :func:`range_bearing_offset`: ``H_x (..., 2, 3)``, ``H_m (..., 2, 2)``."""
    H_s, H_m = range_bearing_jacobians(sensor_pose(x, offset_xy), m)
    return H_s @ sensor_pose_jacobian(x, offset_xy), H_m


def inverse_range_bearing_offset(x, z, offset_xy):
    """Landmark ``(..., 2)`` at measurement ``z`` of a sensor mounted at ``offset_xy`` on a robot at ``x``."""
    return inverse_range_bearing(sensor_pose(x, offset_xy), z)


def inverse_range_bearing_offset_jacobians(x, z, offset_xy):
    """Jacobians of :func:`inverse_range_bearing_offset`: ``M_x (..., 2, 3)``, ``M_z (..., 2, 2)``."""
    M_s, M_z = inverse_range_bearing_jacobians(sensor_pose(x, offset_xy), z)
    return M_s @ sensor_pose_jacobian(x, offset_xy), M_z


# --------------------------------------------------------------------------------------------------------
# surface-aware model (beyond paper 000): a disc landmark of radius ρ centred at m, seen by a beam sensor.
# A beam from the sensor position p along φ = θ + b (b: the beam's bearing), u = [cos φ, sin φ],
# u⊥ = [−sin φ, cos φ], w = m − p, meets the disc's near surface at
#
#     a = u·w   (along the beam),   s = u⊥·w   (lateral),   q = √(ρ² − s²)   (|s| ≤ ρ)
#     r(x, m, b; ρ) = a − q                               (r = d − ρ for the beam through the centre, s = 0)
#
# Jacobians (∂a/∂m = u, ∂s/∂m = u⊥, ∂a/∂φ = s, ∂s/∂φ = −a, ∂(p, φ)/∂x = I):
#
#     ∂r/∂m = u + (s/q) u⊥        ∂r/∂p = −∂r/∂m        ∂r/∂θ = s − s·a/q        ∂r/∂ρ = −ρ/q
#
# The along-beam distance from the hit point to the foot of the centre is q; averaged over a lateral offset
# uniform on [−ρ, ρ] (a post swept by evenly spaced beams) it is E[q] = π/4 · ρ.
# --------------------------------------------------------------------------------------------------------
def _beam_frame(x, m, bearing):
    """``(a, s, u, u⊥)`` of the beam ``bearing (...,)`` from pose(s) ``x (..., 3)`` towards centre(s) ``m (..., 2)``."""
    x = np.asarray(x, float)
    m = np.asarray(m, float)
    phi = x[..., 2] + np.asarray(bearing, float)
    u = np.stack([np.cos(phi), np.sin(phi)], -1)
    u_perp = np.stack([-u[..., 1], u[..., 0]], -1)
    w = m - x[..., :2]
    return (u * w).sum(-1), (u_perp * w).sum(-1), u, u_perp


def surface_range(x, m, bearing, radius):
    """Range ``(...,)`` along the beam ``bearing`` from pose(s) ``x (..., 3)`` to the surface of the disc(s) of
    radius ``radius`` centred at ``m (..., 2)``; NaN where the beam misses the disc (``|s| > ρ``)."""
    a, s, _, _ = _beam_frame(x, m, bearing)
    rho = np.asarray(radius, float)
    with np.errstate(invalid="ignore"):
        return a - np.sqrt(rho * rho - s * s)


def surface_range_jacobians(x, m, bearing, radius):
    """Jacobians of :func:`surface_range`: ``H_x (..., 3)``, ``H_m (..., 2)``, ``H_rho (...,)`` (NaN / inf where
    the beam misses or grazes the disc)."""
    a, s, u, u_perp = _beam_frame(x, m, bearing)
    rho = np.asarray(radius, float)
    with np.errstate(invalid="ignore", divide="ignore"):
        q = np.sqrt(rho * rho - s * s)
        k = s / q
        H_m = u + k[..., None] * u_perp
        H_x = np.concatenate([-H_m, (s - k * a)[..., None]], -1)
        H_rho = -rho / q
    return H_x, H_m, np.broadcast_to(H_rho, a.shape).copy()


def surface_range_bearing(x, m, radius):
    """``[‖m − p‖ − ρ, bearing to the centre] (..., 2)``: the surface model for the beam through the centre.
    Its Jacobians in ``x`` and ``m`` are those of :func:`range_bearing`; ``∂h/∂ρ = [−1, 0]``."""
    z = range_bearing(x, m)
    return np.stack([z[..., 0] - np.asarray(radius, float), z[..., 1]], -1)


def inverse_surface_range_bearing(x, z, radius):
    """Centre ``(..., 2)`` of a disc of radius ``radius`` whose surface the beam of ``z (..., 2)`` hits through
    the centre: ``p + (r + ρ)·[cos(θ + b), sin(θ + b)]`` (inverse of :func:`surface_range_bearing`)."""
    z = np.asarray(z, float)
    zc = np.stack([z[..., 0] + np.asarray(radius, float), z[..., 1]], -1)
    return inverse_range_bearing(x, zc)


def surface_centre_offset(x, m, bearing, radius):
    """Along-beam distance ``q = √(ρ² − s²) (...,)`` from the surface hit to the foot of the centre ``m`` on the
    beam; 0 where the beam misses the disc (``|s| ≥ ρ``, grazing)."""
    _, s, _, _ = _beam_frame(x, m, bearing)
    rho = np.asarray(radius, float)
    return np.sqrt(np.maximum(rho * rho - s * s, 0.0))


def mean_surface_offset(radius):
    """``E[q] = π/4 · ρ``: the mean of :func:`surface_centre_offset` over a lateral offset uniform on [−ρ, ρ]."""
    return np.pi / 4.0 * np.asarray(radius, float)
