"""Differential-drive (DDMR) kinematics and encoder-odometry increments.

Motion model (paper 000, §4), forward Euler over one sampling period ``dt``::

    g(x, u) = x + dt · [v cos θ, v sin θ, ω]ᵀ          (heading wrapped)

Odometry (paper 000, eq. 16): the encoder pose sequence ``x̃_t`` drifts, so only its increments are
trusted, rotated into the body frame of the previous pose::

    d_t = τ(x̃_{t-1,θ}) (x̃_t − x̃_{t-1}),   τ(θ) = [[cos θ, sin θ, 0], [−sin θ, cos θ, 0], [0, 0, 1]]

with the heading component wrapped. That is the SE(2) ``between`` of consecutive poses.
"""

from __future__ import annotations

import numpy as np

from slamcli.models import se2
from slamcli.models.angles import wrap_angle


def ddmr_step(x, u, dt: float):
    """One step of the DDMR kinematic model ``g(x, u)``.

    Parameters
    ----------
    x : ndarray (..., 3)
        Pose ``[x, y, theta]`` at time t-1.
    u : ndarray (..., 2)
        Control ``[v, omega]`` applied over ``dt``.
    dt : float
        Sampling period, seconds.

    Returns
    -------
    ndarray (..., 3): the predicted pose at time t.
    """
    x = np.asarray(x, float)
    u = np.asarray(u, float)
    th = x[..., 2]
    v, w = u[..., 0], u[..., 1]
    return np.stack(
        [x[..., 0] + dt * v * np.cos(th), x[..., 1] + dt * v * np.sin(th), wrap_angle(th + dt * w)], -1
    )


def ddmr_jacobians(x, u, dt: float):
    """Jacobians of :func:`ddmr_step`.

    Returns
    -------
    G_x : ndarray (..., 3, 3)   ∂g/∂x
    G_u : ndarray (..., 3, 2)   ∂g/∂u
    """
    x = np.asarray(x, float)
    u = np.asarray(u, float)
    th = x[..., 2]
    c, s = np.cos(th), np.sin(th)
    v = u[..., 0]
    lead = np.broadcast_shapes(x.shape[:-1], u.shape[:-1])
    G_x = np.zeros(lead + (3, 3))
    G_x[..., 0, 0] = 1.0
    G_x[..., 1, 1] = 1.0
    G_x[..., 2, 2] = 1.0
    G_x[..., 0, 2] = -dt * v * s
    G_x[..., 1, 2] = dt * v * c
    G_u = np.zeros(lead + (3, 2))
    G_u[..., 0, 0] = dt * c
    G_u[..., 1, 0] = dt * s
    G_u[..., 2, 1] = dt
    return G_x, G_u


def integrate(x0, controls, dt: float):
    """Dead-reckon a pose sequence from ``x0 (3,)`` through ``controls (T, 2)``.

    Returns
    -------
    poses_xyt : ndarray (T+1, 3)
    """
    controls = np.asarray(controls, float)
    T = controls.shape[0]
    poses = np.empty((T + 1, 3))
    poses[0] = x0
    # The recursion is inherently sequential; each step is O(1), so a plain loop over T is the cost floor.
    x, y, th = float(x0[0]), float(x0[1]), float(x0[2])
    vs, ws = controls[:, 0], controls[:, 1]
    for t in range(T):
        x += dt * vs[t] * np.cos(th)
        y += dt * vs[t] * np.sin(th)
        th = wrap_angle(th + dt * ws[t])
        poses[t + 1] = (x, y, th)
    return poses


def odometry_increments(poses_xyt):
    """Body-frame increments ``d_t = τ(θ_{t-1})(x_t − x_{t-1})`` of a pose sequence (eq. 16).

    Parameters
    ----------
    poses_xyt : ndarray (T+1, 3)

    Returns
    -------
    ndarray (T, 3)
    """
    p = np.asarray(poses_xyt, float)
    return se2.between(p[:-1], p[1:])


def odometry_increment_jacobians(x_prev, x_next):
    """Jacobians of the increment w.r.t. the previous and next pose, each ``(..., 3, 3)``."""
    return se2.between_jacobians(x_prev, x_next)


def apply_increment(x_prev, d):
    """Inverse of :func:`odometry_increments` for one step: ``x_t = x_{t-1} + τ(θ_{t-1})ᵀ d``."""
    return se2.compose(x_prev, d)


def chain_increments(x0, increments):
    """Rebuild poses ``(T+1, 3)`` from ``x0`` and increments ``(T, 3)``."""
    inc = np.asarray(increments, float)
    poses = np.empty((inc.shape[0] + 1, 3))
    poses[0] = x0
    for t in range(inc.shape[0]):
        poses[t + 1] = se2.compose(poses[t], inc[t])
    return poses
