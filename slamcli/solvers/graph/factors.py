"""GTSAM-exact factor errors and Jacobians in world coordinates ``[x, y, θ]``, vectorised over factors,
and the square-root information helpers of the noise models.
"""

from __future__ import annotations

import numpy as np

from slamcli.errors import SolverError
from slamcli.models import observation, se2
from slamcli.models.angles import wrap_angle

#: GTSAM's ``norm2``: below this distance (m) the range Jacobian ``(m − p)/r`` is replaced by ``[1, 1]``
ON_THE_POSE_M = 1e-10


# ----------------------------------------------------------------------------------------------------------
# GTSAM-exact factor errors and Jacobians (world coordinates [x, y, θ]), vectorised over factors
# ----------------------------------------------------------------------------------------------------------
def log_jacobian(p: np.ndarray) -> np.ndarray:
    """Jacobian ``(..., 3, 3)`` of :func:`slamcli.models.se2.log` w.r.t. the pose coordinates ``[x, y, θ]``.

    ``Log(x, y, θ) = [α x + (θ/2) y, −(θ/2) x + α y, θ]`` with ``α = (θ/2) cot(θ/2)``, hence
    ``∂/∂(x, y, θ) = [[α, θ/2, α' x + y/2], [−θ/2, α, −x/2 + α' y], [0, 0, 1]]``,
    ``α' = ½ cot(θ/2) − (θ/4) / sin²(θ/2)`` (series ``1 − θ²/12``, ``−θ/6 − θ³/180`` near 0).
    """
    p = np.asarray(p, float)
    w = wrap_angle(p[..., 2])
    alpha, dalpha = se2.log_terms(w)
    x, y = p[..., 0], p[..., 1]
    J = np.zeros(p.shape[:-1] + (3, 3))
    J[..., 0, 0] = alpha
    J[..., 0, 1] = 0.5 * w
    J[..., 0, 2] = dalpha * x + 0.5 * y
    J[..., 1, 0] = -0.5 * w
    J[..., 1, 1] = alpha
    J[..., 1, 2] = -0.5 * x + dalpha * y
    J[..., 2, 2] = 1.0
    return J


def between_error(x_i, x_j, measured, meas_cs=None):
    """GTSAM ``BetweenFactorPose2`` error ``e = Log(d⁻¹ ⊕ (x_i⁻¹ ⊕ x_j))`` and its Jacobians.

    The products of :func:`log_jacobian`, ``∂(a ⊕ b)/∂b = blkdiag(R(θ_a), 1)`` and
    :func:`slamcli.models.se2.between_jacobians` written out entry by entry (one pass over the factors, no
    3×3 matrix products; the hot loop of every graph linearisation). With ``b = x_i⁻¹ ⊕ x_j``,
    ``p = d⁻¹ ⊕ b = (R(−δθ)(b_t − d_t), b_θ − δθ)``, ``A = ∂Log/∂p · blkdiag(R(−δθ), 1)`` and
    ``R_iᵀ = R(θ_i)ᵀ``::

        J_j = [[A₂ R_iᵀ, a], [0, 1]]      J_i = [[−A₂ R_iᵀ, A₂ [b_y, −b_x]ᵀ − a], [0, −1]]

    (``A₂`` the upper-left 2×2 block of ``A``, ``a`` its upper-right column).

    Parameters
    ----------
    x_i, x_j, measured : ndarray (F, 3)
    meas_cs : (cos δθ, sin δθ) of the measurements, optional (precomputed per factor block)

    Returns
    -------
    e : ndarray (F, 3);  J_i, J_j : ndarray (F, 3, 3)  (w.r.t. world coordinates of x_i, x_j)
    """
    x_i = np.asarray(x_i, float)
    e, (a00, a01, a02, a10, a11, a12), (ci, si, bx, by) = _between_a(x_i, x_j, measured, meas_cs)
    shape = x_i.shape[:-1] + (3, 3)
    Jj, Ji = np.zeros(shape), np.zeros(shape)
    Jj[..., 0, 0], Jj[..., 0, 1] = a00 * ci - a01 * si, a00 * si + a01 * ci  # A₂ R_iᵀ
    Jj[..., 1, 0], Jj[..., 1, 1] = a10 * ci - a11 * si, a10 * si + a11 * ci
    Jj[..., 0, 2], Jj[..., 1, 2], Jj[..., 2, 2] = a02, a12, 1.0
    Ji[..., :2, :2] = -Jj[..., :2, :2]
    Ji[..., 0, 2] = a00 * by - a01 * bx - a02
    Ji[..., 1, 2] = a10 * by - a11 * bx - a12
    Ji[..., 2, 2] = -1.0
    return e, Ji, Jj


def _between_a(x_i, x_j, measured, meas_cs=None):
    """``(e, A, (cos θ_i, sin θ_i, b_x, b_y))`` shared by :func:`between_error` and :func:`between_error_body`:
    the error and the entries ``(a00, a01, a02, a10, a11, a12)`` of ``A = ∂Log/∂p · blkdiag(R(−δθ), 1)``."""
    ci, si, bx, by, cd, sd, px, py, w = _between_parts(x_i, x_j, measured, meas_cs)
    alpha, dalpha = se2.log_terms(w)  # ∂Log/∂p (log_jacobian)
    e = se2.log_of(px, py, w, alpha)
    hw = 0.5 * w
    # R(−δθ) = [[cd, sd], [−sd, cd]]
    a00, a01 = alpha * cd - hw * sd, alpha * sd + hw * cd
    a10, a11 = -hw * cd - alpha * sd, alpha * cd - hw * sd
    a02, a12 = dalpha * px + 0.5 * py, dalpha * py - 0.5 * px
    return e, (a00, a01, a02, a10, a11, a12), (ci, si, bx, by)


def _between_parts(x_i, x_j, measured, meas_cs=None):
    """The intermediate terms of :func:`between_error`: ``cos θ_i, sin θ_i``, ``b_t`` of ``b = x_i⁻¹ ⊕ x_j``,
    ``cos δθ, sin δθ`` of the measurement (``meas_cs`` when given: they are constants of a factor block) and
    ``p = d⁻¹ ⊕ b`` as ``(p_x, p_y, p_θ)`` (``p_θ`` wrapped)."""
    x_i, x_j, d = (np.asarray(v, float) for v in (x_i, x_j, measured))
    ci, si = np.cos(x_i[..., 2]), np.sin(x_i[..., 2])
    dxw, dyw = x_j[..., 0] - x_i[..., 0], x_j[..., 1] - x_i[..., 1]
    bx, by = ci * dxw + si * dyw, ci * dyw - si * dxw
    cd, sd = (np.cos(d[..., 2]), np.sin(d[..., 2])) if meas_cs is None else meas_cs
    ux, uy = bx - d[..., 0], by - d[..., 1]
    px, py = cd * ux + sd * uy, cd * uy - sd * ux  # R(−δθ)(b_t − d_t)
    w = wrap_angle(x_j[..., 2] - x_i[..., 2] - d[..., 2])
    return ci, si, bx, by, cd, sd, px, py, w


def between_residual(x_i, x_j, measured, meas_cs=None):
    """The error ``e (F, 3)`` of :func:`between_error` without its Jacobians (the same arithmetic;
    ``meas_cs``: ``(cos δθ, sin δθ)`` of the measurements, precomputed)."""
    *_, px, py, w = _between_parts(x_i, x_j, measured, meas_cs)
    return se2.log_of(px, py, w)


def between_error_body(x_i, x_j, measured, meas_cs=None):
    """:func:`between_error` with both poses' Jacobians in GTSAM's body chart (``x ← x ⊕ Exp(ξ)``,
    ``∂/∂ξ = ∂/∂x · blkdiag(R(θ), 1)``), as one ``(F, 3, 6)`` array ``[J_i | J_j]`` — what the assembler's
    body-chart rotation makes of :func:`between_error`'s, without the rotation pass. With its notation::

        J_i = [[−A₂, A₂ [b_y, −b_x]ᵀ − a], [0, −1]]      J_j = [[A₂ R(θ_j − θ_i), a], [0, 1]]

    (``R_iᵀ R_i = I`` on the left; ``R_iᵀ R_j = R(θ_j − θ_i)`` on the right). ``meas_cs``: ``(cos δθ,
    sin δθ)`` of the measurements, precomputed."""
    x_i, x_j = np.asarray(x_i, float), np.asarray(x_j, float)
    e, (a00, a01, a02, a10, a11, a12), (ci, si, bx, by) = _between_a(x_i, x_j, measured, meas_cs)
    cj, sj = np.cos(x_j[..., 2]), np.sin(x_j[..., 2])
    c, s = ci * cj + si * sj, ci * sj - si * cj  # cos, sin of θ_j − θ_i
    J = np.zeros(x_i.shape[:-1] + (3, 6))
    J[..., 0, 0], J[..., 0, 1], J[..., 1, 0], J[..., 1, 1] = -a00, -a01, -a10, -a11
    J[..., 0, 2] = a00 * by - a01 * bx - a02
    J[..., 1, 2] = a10 * by - a11 * bx - a12
    J[..., 2, 2] = -1.0
    J[..., 0, 3], J[..., 0, 4] = a00 * c + a01 * s, a01 * c - a00 * s
    J[..., 1, 3], J[..., 1, 4] = a10 * c + a11 * s, a11 * c - a10 * s
    J[..., 0, 5], J[..., 1, 5], J[..., 2, 5] = a02, a12, 1.0
    return e, J


def prior_error(x, prior):
    """GTSAM ``PriorFactorPose2`` error ``e = Log(p⁻¹ ⊕ x)`` and Jacobian ``(F, 3, 3)``: the between error of
    ``(p, x)`` with an identity measurement (:func:`between_error`'s one pass; a prior block of one factor is
    all per-call overhead, and it is evaluated at every linearisation and trial cost)."""
    x = np.asarray(x, float)
    e, _, J = between_error(np.broadcast_to(np.asarray(prior, float), x.shape), x, np.zeros(x.shape))
    return e, J


def prior_residual(x, prior):
    """The error ``e (F, 3)`` of :func:`prior_error` without its Jacobian (the same arithmetic)."""
    x = np.asarray(x, float)
    return between_residual(np.broadcast_to(np.asarray(prior, float), x.shape), x, np.zeros(x.shape))


def bearing_range_error(x, m, z):
    """Range-bearing error ``e = [r̂ − r, wrap(b̂ − b)]`` (GTSAM's ``BearingRangeFactor2D`` up to row order).

    As in GTSAM (``Rot2::relativeBearing``), a landmark within 1e-5 m of the pose has bearing ``b̂ = 0`` and a
    zero bearing Jacobian: the bearing is undefined there, and a solution that put a landmark on a pose
    (misread ids, a stalled optimisation) must have the cost GTSAM recomputes for it.

    Parameters
    ----------
    x : ndarray (F, 3);  m : ndarray (F, 2);  z : ndarray (F, 2) as ``[range, bearing]``

    Returns
    -------
    e : ndarray (F, 2);  J_x : ndarray (F, 2, 3);  J_m : ndarray (F, 2, 2)
    """
    e, near, r = _bearing_range_residual(x, m, z)
    with np.errstate(divide="ignore", invalid="ignore"):  # a landmark on the pose: patched below
        J_x, J_m = observation.range_bearing_jacobians(x, m)
    if np.any(near):  # GTSAM's Rot2::relativeBearing: within 1e-5 m the bearing is 0, its Jacobian zero
        J_x[near, 1] = 0.0
        J_m[near, 1] = 0.0
        _range_row_on_the_pose(r, J_x[:, 0, :2], J_m[:, 0])
    return e, J_x, J_m


def _range_row_on_the_pose(r, Jr_x, Jr_m) -> None:
    """Range row of the factors whose predicted range ``r (F,)`` is within ``ON_THE_POSE_M``, where
    ``∂r/∂m = (m − p)/r`` is undefined (0/0): GTSAM's ``norm2`` convention ``∂r/∂m = [1, 1]``,
    ``∂r/∂p = −[1, 1]``, instead of NaN."""
    on = r <= ON_THE_POSE_M
    Jr_m[on] = 1.0
    Jr_x[on] = -1.0


def bearing_range_jacobian(x, m, z):
    """:func:`bearing_range_error` with its Jacobians in one array: ``e (F, 2)``, ``J (F, 2, 5) = [J_x | J_m]``
    (the same values; the intermediates are computed once and no concatenation copies ``J``)."""
    x = np.asarray(x, float)
    m = np.asarray(m, float)
    e, near, _ = _bearing_range_residual(x, m, z)
    dx = m[:, 0] - x[:, 0]
    dy = m[:, 1] - x[:, 1]
    q = dx * dx + dy * dy
    r = np.sqrt(q)
    J = np.empty((x.shape[0], 2, 5))
    with np.errstate(divide="ignore", invalid="ignore"):  # a landmark on the pose: patched below
        J[:, 0, 3] = dx / r
        J[:, 0, 4] = dy / r
        J[:, 1, 3] = -dy / q
        J[:, 1, 4] = dx / q
    np.negative(J[:, :, 3:], out=J[:, :, :2])
    J[:, 0, 2] = 0.0
    J[:, 1, 2] = -1.0
    if np.any(near):  # as bearing_range_error: no bearing Jacobian within 1e-5 m
        J[near, 1] = 0.0
        _range_row_on_the_pose(r, J[:, 0, :2], J[:, 0, 3:])
    return e, J


def bearing_range_residual(x, m, z):
    """The error ``e (F, 2)`` of :func:`bearing_range_error` without its Jacobians (the same arithmetic)."""
    return _bearing_range_residual(x, m, z)[0]


def _bearing_range_residual(x, m, z):
    """``(e (F, 2), near (F,), r̂ (F,))``: the error, the factors within 1e-5 m of their pose (bearing 0) and
    the predicted ranges."""
    zh = observation.range_bearing(x, m)
    e = np.stack([zh[:, 0] - z[:, 0], wrap_angle(zh[:, 1] - z[:, 1])], -1)
    near = zh[:, 0] <= 1e-5
    if np.any(near):
        e[near, 1] = wrap_angle(-z[near, 1])
    return e, near, zh[:, 0]


def landmark_offset_error(x, m, z_xy):
    """g2o ``EDGE_SE2_XY`` error ``e = R(θ)ᵀ (m − p) − z`` (landmark in the body frame) and its Jacobians.

    Parameters
    ----------
    x : ndarray (F, 3);  m : ndarray (F, 2);  z_xy : ndarray (F, 2) measured offset in the body frame

    Returns
    -------
    e : ndarray (F, 2);  J_x : ndarray (F, 2, 3);  J_m : ndarray (F, 2, 2)
        ``∂e/∂p = −R(θ)ᵀ``, ``∂e/∂θ = [[−s, c], [−c, −s]] (m − p)``, ``∂e/∂m = R(θ)ᵀ``.
    """
    c, s = np.cos(x[:, 2]), np.sin(x[:, 2])
    dx, dy = m[:, 0] - x[:, 0], m[:, 1] - x[:, 1]
    e = np.stack([c * dx + s * dy - z_xy[:, 0], -s * dx + c * dy - z_xy[:, 1]], -1)
    Jm = np.empty((x.shape[0], 2, 2))
    Jm[:, 0, 0], Jm[:, 0, 1], Jm[:, 1, 0], Jm[:, 1, 1] = c, s, -s, c
    Jx = np.empty((x.shape[0], 2, 3))
    Jx[:, :, :2] = -Jm
    Jx[:, 0, 2] = -s * dx + c * dy
    Jx[:, 1, 2] = -c * dx - s * dy
    return e, Jx, Jm


def robot_range_bearing_error(x_i, x_j, z):
    """Inter-robot range-bearing error: robot ``i`` at pose ``x_i`` measures robot ``j``'s body origin.

    ``e = [‖p_j − p_i‖ − r,  wrap(atan2(p_j − p_i) − θ_i − b)]`` — :func:`bearing_range_error` with the
    landmark replaced by the position of another pose; the heading of ``x_j`` does not enter, so the last
    column of ``J_j`` is zero (multi-robot MRCLAM).

    Parameters
    ----------
    x_i, x_j : ndarray (F, 3);  z : ndarray (F, 2) as ``[range, bearing]``

    Returns
    -------
    e : ndarray (F, 2);  J_i : ndarray (F, 2, 3);  J_j : ndarray (F, 2, 3)
    """
    x_j = np.asarray(x_j, float)
    e, J_i, J_m = bearing_range_error(np.asarray(x_i, float), x_j[:, :2], z)
    J_j = np.concatenate([J_m, np.zeros((J_m.shape[0], 2, 1))], axis=2)
    return e, J_i, J_j


def sqrt_info_batch(info: np.ndarray) -> np.ndarray:
    """``L (F, k, k)`` with ``LᵀL = Λ`` for each information matrix of ``info (F, k, k)``."""
    return np.swapaxes(np.linalg.cholesky(np.asarray(info, float)), 1, 2)


# ----------------------------------------------------------------------------------------------------------
# problem construction
# ----------------------------------------------------------------------------------------------------------
def sqrt_info_from_cov(cov: np.ndarray) -> np.ndarray:
    """``L`` with ``LᵀL = Σ⁻¹``."""
    return np.linalg.cholesky(np.linalg.inv(np.asarray(cov, float))).T


def sqrt_of_weight(W: np.ndarray, name: str = "weight") -> np.ndarray | None:
    """``L`` with ``LᵀL = 2W`` for a symmetric PSD weight ``W`` (so ``½‖L r‖² = rᵀ W r``); None if W = 0."""
    W = np.asarray(W, float)
    if not np.all(np.isfinite(W)):
        raise SolverError(f"graph: paper {name} has non-finite entries")
    if not np.any(W):
        return None
    if not np.allclose(W, W.T, atol=1e-12 * max(1.0, np.abs(W).max())):
        raise SolverError(f"graph: paper {name} must be symmetric, got {W.tolist()}")
    lam, V = np.linalg.eigh(0.5 * (W + W.T))
    if lam.min() < -1e-12 * max(1.0, lam.max()):
        raise SolverError(f"graph: paper {name} must be positive semi-definite (eigenvalues {lam.tolist()})")
    return np.sqrt(2.0 * np.clip(lam, 0.0, None))[:, None] * V.T


def group_returns(steps: np.ndarray, labels: np.ndarray, z: np.ndarray, n_landmarks: int):
    """One measurement per (pose, landmark) pair: mean range and circular-mean bearing of its rows.

    A laser gives several returns from one post at one pose (surface points spread over the post's width);
    treating each as an independent point measurement of the centre would overweight that pose-landmark pair
    and put the spread into the bearing residuals. Point sensors have one row per pair, so nothing changes.

    Returns
    -------
    steps (G,), labels (G,), z (G, 2) of the groups, ordered by (step, label).
    """
    key = steps * max(n_landmarks, 1) + labels
    ukey, inv = np.unique(key, return_inverse=True)
    if ukey.size == key.size:
        order = np.argsort(key, kind="stable")
        return steps[order], labels[order], z[order]
    cnt = np.bincount(inv).astype(float)
    r = np.bincount(inv, z[:, 0]) / cnt
    b = np.arctan2(np.bincount(inv, np.sin(z[:, 1])), np.bincount(inv, np.cos(z[:, 1])))
    return ukey // max(n_landmarks, 1), ukey % max(n_landmarks, 1), np.stack([r, wrap_angle(b)], -1)
