"""Ackermann (bicycle) car kinematics as used with the Victoria Park and ACFR car-park recordings.

Vehicle geometry (Guivant & Nebot, "Optimization of the simultaneous localization and map-building algorithm
for real-time implementation", IEEE T-RA 2001; the ACFR dataset documentation)::

    body frame: origin at the centre of the rear axle, x forward, y left
    L  wheelbase (rear axle → front axle), m
    H  lateral offset of the rear-LEFT wheel carrying the speed encoder from the body origin, m
    (a, b)  a body-frame point whose pose the state tracks (the laser in Guivant & Nebot: a = 3.78, b = 0.50)

Controls ``u = [v_e, α]``: speed measured at the rear-left encoder (m/s) and front steering angle (rad).
The encoder wheel runs on a larger (left-turn) radius than the axle centre, so the centre speed is::

    v_c = v_e / (1 − tan(α) · H / L)                 ω = v_c · tan(α) / L

Motion of the point (a, b), forward Euler over ``dt`` (rigid-body velocity of a point of the car)::

    x' = x + dt · (v_c cos φ − ω (a sin φ + b cos φ))
    y' = y + dt · (v_c sin φ + ω (a cos φ − b sin φ))
    φ' = wrap(φ + dt · ω)

With (a, b) = (0, 0) this is the differential-drive model ``ddmr_step`` driven by the twist ``(v_c, ω)``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from slamcli.models.angles import wrap_angle

#: motion-model tags of the dataset schema (``SlamInputs.motion_model``)
MOTION_MODELS = ("ddmr", "ackermann")


@dataclass(frozen=True)
class AckermannParams:
    """Car geometry (defaults: the Victoria Park / ACFR utility vehicle).

    Attributes
    ----------
    wheelbase_m : float       L, rear axle to front axle, m.
    encoder_offset_m : float  H, lateral offset of the rear-left encoder wheel from the rear-axle centre, m.
    ref_x_m : float           a of the body point whose pose the motion model propagates (0 = rear axle), m.
    ref_y_m : float           b of that point (positive = left), m.
    """

    wheelbase_m: float = 2.83
    encoder_offset_m: float = 0.76
    ref_x_m: float = 0.0
    ref_y_m: float = 0.0

    def __post_init__(self) -> None:
        if not (np.isfinite(self.wheelbase_m) and self.wheelbase_m > 0):
            raise ValueError(f"wheelbase_m must be > 0, got {self.wheelbase_m}")
        for name in ("encoder_offset_m", "ref_x_m", "ref_y_m"):
            if not np.isfinite(getattr(self, name)):
                raise ValueError(f"{name} must be finite, got {getattr(self, name)}")


#: Victoria Park (Guivant & Nebot): L = 2.83 m, H = 0.76 m; laser at (a, b) = (3.78 m, 0.50 m).
VICTORIA_PARK = AckermannParams(wheelbase_m=2.83, encoder_offset_m=0.76)
VICTORIA_PARK_LASER_XY = (3.78, 0.50)


def centre_twist(u, params: AckermannParams):
    """Rear-axle-centre speed and yaw rate from encoder speed and steering.

    Parameters
    ----------
    u : ndarray (..., 2)   ``[v_e, α]``.

    Returns
    -------
    v_c : ndarray (...)   ``v_e / (1 − tan α · H/L)``, m/s.
    omega : ndarray (...) ``v_c tan α / L``, rad/s.
    """
    u = np.asarray(u, float)
    L, H = params.wheelbase_m, params.encoder_offset_m
    tan_a = np.tan(u[..., 1])
    v_c = u[..., 0] / (1.0 - tan_a * H / L)
    return v_c, v_c * tan_a / L


def _twist_and_derivatives(u, params: AckermannParams):
    """``v_c, ω`` and their derivatives w.r.t. ``v_e`` and ``α`` (each ``(...)``)."""
    L, H = params.wheelbase_m, params.encoder_offset_m
    v_e, alpha = u[..., 0], u[..., 1]
    tan_a = np.tan(alpha)
    sec2 = 1.0 + tan_a * tan_a
    k = 1.0 / (1.0 - tan_a * H / L)  # ∂v_c/∂v_e
    v_c = v_e * k
    dvc_dve = k
    dvc_da = v_e * k * k * sec2 * H / L  # d/dα [v_e (1 − tanα H/L)⁻¹]
    w = v_c * tan_a / L
    dw_dve = k * tan_a / L
    dw_da = (dvc_da * tan_a + v_c * sec2) / L
    return v_c, w, dvc_dve, dvc_da, dw_dve, dw_da


def ackermann_step(x, u, dt, params: AckermannParams):
    """One Euler step of the car model for the tracked point ``(ref_x_m, ref_y_m)``.

    Parameters
    ----------
    x : ndarray (..., 3)   pose ``[x, y, φ]`` of the tracked point (heading = the car's heading).
    u : ndarray (..., 2)   ``[v_e, α]`` held over ``dt``.
    dt : float or ndarray (...)

    Returns
    -------
    ndarray (..., 3): the pose after ``dt``.
    """
    x = np.asarray(x, float)
    u = np.asarray(u, float)
    a, b = params.ref_x_m, params.ref_y_m
    v_c, w = centre_twist(u, params)
    c, s = np.cos(x[..., 2]), np.sin(x[..., 2])
    A = a * s + b * c
    B = a * c - b * s
    return np.stack([x[..., 0] + dt * (v_c * c - w * A), x[..., 1] + dt * (v_c * s + w * B),
                     wrap_angle(x[..., 2] + dt * w)], -1)


def ackermann_jacobians(x, u, dt, params: AckermannParams):
    """Jacobians of :func:`ackermann_step`.

    With ``A = a sin φ + b cos φ``, ``B = a cos φ − b sin φ`` (so ``∂A/∂φ = B``, ``∂B/∂φ = −A``)::

        ∂x'/∂φ = dt (−v_c sin φ − ω B)        ∂y'/∂φ = dt (v_c cos φ − ω A)
        ∂x'/∂u = dt (∂v_c/∂u cos φ − ∂ω/∂u A)  ∂y'/∂u = dt (∂v_c/∂u sin φ + ∂ω/∂u B)   ∂φ'/∂u = dt ∂ω/∂u

    Returns
    -------
    G_x : ndarray (..., 3, 3)   ∂g/∂x
    G_u : ndarray (..., 3, 2)   ∂g/∂[v_e, α]
    """
    x = np.asarray(x, float)
    u = np.asarray(u, float)
    a, b = params.ref_x_m, params.ref_y_m
    v_c, w, dvc_dve, dvc_da, dw_dve, dw_da = _twist_and_derivatives(u, params)
    c, s = np.cos(x[..., 2]), np.sin(x[..., 2])
    A = a * s + b * c
    B = a * c - b * s
    lead = np.broadcast_shapes(x.shape[:-1], u.shape[:-1])
    G_x = np.zeros(lead + (3, 3))
    G_x[..., 0, 0] = 1.0
    G_x[..., 1, 1] = 1.0
    G_x[..., 2, 2] = 1.0
    G_x[..., 0, 2] = dt * (-v_c * s - w * B)
    G_x[..., 1, 2] = dt * (v_c * c - w * A)
    G_u = np.zeros(lead + (3, 2))
    for j, (dvc, dw) in enumerate(((dvc_dve, dw_dve), (dvc_da, dw_da))):
        G_u[..., 0, j] = dt * (dvc * c - dw * A)
        G_u[..., 1, j] = dt * (dvc * s + dw * B)
        G_u[..., 2, j] = dt * dw
    return G_x, G_u


def integrate_ackermann(x0, controls, dt: float, params: AckermannParams):
    """Dead-reckon the tracked point from ``x0 (3,)`` through ``controls (T, 2)`` = ``[v_e, α]`` rows.

    Returns
    -------
    poses_xyt : ndarray (T+1, 3)
    """
    controls = np.asarray(controls, float).reshape(-1, 2)
    v_c, w = centre_twist(controls, params)
    a, b = params.ref_x_m, params.ref_y_m
    T = controls.shape[0]
    poses = np.empty((T + 1, 3))
    poses[0] = x0
    x, y, th = float(x0[0]), float(x0[1]), float(x0[2])
    # sequential recursion, O(1) per step
    for t in range(T):
        c, s = np.cos(th), np.sin(th)
        x += dt * (v_c[t] * c - w[t] * (a * s + b * c))
        y += dt * (v_c[t] * s + w[t] * (a * c - b * s))
        th = float(wrap_angle(th + dt * w[t]))
        poses[t + 1] = (x, y, th)
    return poses

