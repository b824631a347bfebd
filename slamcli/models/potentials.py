"""Residuals of the ICM-SLAM Gibbs energy (paper 000, eqs. 3-5 and 16), with Jacobians.

The energy is ``H = Σ r_motionᵀ R r_motion + Σ r_odoᵀ S r_odo + Σ r_obsᵀ Q r_obs (+ map potential)``, where
``‖a‖²_Σ = aᵀ Σ a`` (the paper's Mahalanobis-style norm with a *weight* matrix Σ). Shared by the ICM solver
and by the graph solver's ``model="paper"`` so both minimise literally the same function.
"""

from __future__ import annotations

import numpy as np

from slamcli.models import motion, observation, se2
from slamcli.models.angles import wrap_angle, wrap_pose_error


def motion_residual(x_prev, u_prev, x, dt: float):
    """``r = g(x_{t-1}, u_{t-1}) − x_t (..., 3)``, heading wrapped (eq. 3)."""
    return wrap_pose_error(motion.ddmr_step(x_prev, u_prev, dt) - np.asarray(x, float))


def motion_residual_jacobians(x_prev, u_prev, x, dt: float):
    """``(∂r/∂x_{t-1}, ∂r/∂x_t)``, each ``(..., 3, 3)``."""
    G_x, _ = motion.ddmr_jacobians(x_prev, u_prev, dt)
    J_x = np.broadcast_to(-np.eye(3), G_x.shape).copy()
    return G_x, J_x


def odometry_residual(x_prev, x, odo_prev, odo):
    """``r = τ(θ_{t-1})(x_t − x_{t-1}) − τ(θ̃_{t-1})(x̃_t − x̃_{t-1}) (..., 3)``, heading wrapped (eq. 16)."""
    return wrap_pose_error(se2.between(x_prev, x) - se2.between(odo_prev, odo))


def odometry_residual_jacobians(x_prev, x):
    """``(∂r/∂x_{t-1}, ∂r/∂x_t)``, each ``(..., 3, 3)``."""
    return se2.between_jacobians(x_prev, x)


def observation_residual(x, z, m):
    """``r = h⁻¹(x_t, z_{t,i}) − m_{c_{t,i}} (..., 2)``: landmark-space residual of paper 000's potentials."""
    return observation.inverse_range_bearing(x, z) - np.asarray(m, float)


def observation_residual_jacobians(x, z):
    """``(∂r/∂x (..., 2, 3), ∂r/∂m (..., 2, 2))``."""
    M_x, _ = observation.inverse_range_bearing_jacobians(x, z)
    J_m = np.broadcast_to(-np.eye(2), M_x.shape[:-2] + (2, 2)).copy()
    return M_x, J_m


def range_bearing_residual(x, z, m):
    """``r = h(x_t, m_{c_{t,i}}) − z_{t,i} (..., 2)``: the measurement-space residual ``[r̂ − r, wrap(b̂ − b)]``
    of the range-bearing model :func:`slamcli.models.observation.range_bearing`."""
    e = observation.range_bearing(x, m) - np.asarray(z, float)
    e[..., 1] = wrap_angle(e[..., 1])
    return e


def range_bearing_residual_jacobians(x, m):
    """``(∂r/∂x (..., 2, 3), ∂r/∂m (..., 2, 2))`` of :func:`range_bearing_residual` (those of ``h``)."""
    return observation.range_bearing_jacobians(x, m)


def cauchy_sum(s2, k: float) -> float:
    """``Σ k² log(1 + s²/k²)`` over whitened squared norms ``s2 (F,)``: twice the Cauchy kernel
    ``ρ(s) = ½ k² log(1 + s²/k²)`` (GTSAM's ``mEstimator.Cauchy``), so that it equals ``Σ s²`` to second order
    — the scale of a quadratic potential ``rᵀ Σ⁻¹ r`` of the ICM energy."""
    k2 = float(k) * float(k)
    return float(k2 * np.sum(np.log1p(np.asarray(s2, float) / k2)))


def weighted_sq(r, W):
    """``Σ rᵀ W r`` over all leading dimensions of ``r (..., k)`` with ``W (k, k)``."""
    W = np.asarray(W, float)
    r = np.asarray(r, float).reshape(-1, W.shape[0])
    return float(np.einsum("ni,ij,nj->", r, W, r))
