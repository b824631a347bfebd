"""SE(2) pose algebra on ``[x, y, theta]`` arrays, vectorised over leading dimensions.

``compose(a, b)`` is ``a ⊕ b`` (b expressed in a's frame), ``between(a, b) = a⁻¹ ⊕ b`` is b in a's frame.
``log``/``exp`` are the SE(2) Lie-group maps with tangent ordering ``[v_x, v_y, omega]`` (GTSAM's Pose2
convention), used by the between factors that must match GTSAM exactly.
"""

from __future__ import annotations

import numpy as np

from slamcli.models.angles import angle_diff, wrap_angle


def rot2(theta):
    """Rotation matrices ``(..., 2, 2)`` for angles ``(...)``."""
    c, s = np.cos(theta), np.sin(theta)
    return np.stack([np.stack([c, -s], -1), np.stack([s, c], -1)], -2)


def compose(a, b):
    """``a ⊕ b`` for poses ``(..., 3)``."""
    a = np.asarray(a, float)
    b = np.asarray(b, float)
    c, s = np.cos(a[..., 2]), np.sin(a[..., 2])
    x = a[..., 0] + c * b[..., 0] - s * b[..., 1]
    y = a[..., 1] + s * b[..., 0] + c * b[..., 1]
    return np.stack([x, y, wrap_angle(a[..., 2] + b[..., 2])], -1)


def inverse(a):
    """``a⁻¹`` for poses ``(..., 3)``."""
    a = np.asarray(a, float)
    c, s = np.cos(a[..., 2]), np.sin(a[..., 2])
    x = -c * a[..., 0] - s * a[..., 1]
    y = s * a[..., 0] - c * a[..., 1]
    return np.stack([x, y, wrap_angle(-a[..., 2])], -1)


def between(a, b):
    """``a⁻¹ ⊕ b``: pose b expressed in the frame of pose a, ``(..., 3)``.

    Its translation part is ``τ(θ_a)(p_b − p_a)`` with ``τ(θ) = R(θ)ᵀ`` — exactly the rotated odometry
    increment of paper 000, eq. (16).
    """
    a = np.asarray(a, float)
    b = np.asarray(b, float)
    c, s = np.cos(a[..., 2]), np.sin(a[..., 2])
    dx = b[..., 0] - a[..., 0]
    dy = b[..., 1] - a[..., 1]
    return np.stack([c * dx + s * dy, -s * dx + c * dy, wrap_angle(b[..., 2] - a[..., 2])], -1)


def between_jacobians(a, b):
    """Jacobians of :func:`between` (as a plain 3-vector function) w.r.t. ``a`` and ``b``.

    Returns
    -------
    J_a, J_b : ndarray (..., 3, 3)
    """
    a = np.asarray(a, float)
    b = np.asarray(b, float)
    c, s = np.cos(a[..., 2]), np.sin(a[..., 2])
    dx = b[..., 0] - a[..., 0]
    dy = b[..., 1] - a[..., 1]
    shape = a.shape[:-1] + (3, 3)
    J_a = np.zeros(shape)
    J_b = np.zeros(shape)
    J_a[..., 0, 0] = -c
    J_a[..., 0, 1] = -s
    J_a[..., 0, 2] = -s * dx + c * dy
    J_a[..., 1, 0] = s
    J_a[..., 1, 1] = -c
    J_a[..., 1, 2] = -c * dx - s * dy
    J_a[..., 2, 2] = -1.0
    J_b[..., 0, 0] = c
    J_b[..., 0, 1] = s
    J_b[..., 1, 0] = -s
    J_b[..., 1, 1] = c
    J_b[..., 2, 2] = 1.0
    return J_a, J_b


def adjoint(p):
    """Adjoint ``Ad_p (..., 3, 3)`` on tangents ``[v_x, v_y, ω]``: ``log(p g p⁻¹) = Ad_p log(g)``,
    ``Ad_p = [[c, −s, y], [s, c, −x], [0, 0, 1]]`` (GTSAM's ``Pose2.AdjointMap``)."""
    p = np.asarray(p, float)
    A = np.zeros(p.shape[:-1] + (3, 3))
    A[..., :2, :2] = rot2(p[..., 2])
    A[..., 0, 2] = p[..., 1]
    A[..., 1, 2] = -p[..., 0]
    A[..., 2, 2] = 1.0
    return A


def _series_patched(w, threshold: float, closed, series):
    """``closed(w)`` (a tuple of arrays) with ``series(w)`` patched in where ``|w| < threshold``: the one
    evaluation of :func:`_sinc_terms` and :func:`log_terms`. The closed forms run everywhere (0/0 gives NaN
    where the series replaces them); a 0-d ``w`` goes through as one element and comes back 0-d."""
    w = np.asarray(w, float)
    w1 = np.atleast_1d(w)  # ufuncs of 0-d arrays return scalars, which the patch cannot index
    small = np.abs(w1) < threshold
    with np.errstate(divide="ignore", invalid="ignore"):
        out = closed(w1)
    if small.any():
        for o, s in zip(out, series(w1[small])):
            o[small] = s
    return tuple(o.reshape(w.shape) for o in out)


def _sinc_terms(w):
    """``A = sin(w)/w`` and ``B = (1 - cos(w))/w`` with series near zero."""
    return _series_patched(w, 1e-6, lambda v: (np.sin(v) / v, (1.0 - np.cos(v)) / v),
                           lambda v: (1.0 - v**2 / 6.0, v / 2.0 - v**3 / 24.0))


def exp(xi):
    """SE(2) exponential: tangent ``[v_x, v_y, omega] (..., 3)`` → pose ``(..., 3)``."""
    xi = np.asarray(xi, float)
    w = xi[..., 2]
    A, B = _sinc_terms(w)
    x = A * xi[..., 0] - B * xi[..., 1]
    y = B * xi[..., 0] + A * xi[..., 1]
    return np.stack([x, y, wrap_angle(w)], -1)


def log(p):
    """SE(2) logarithm: pose ``(..., 3)`` → tangent ``[v_x, v_y, omega] (..., 3)``, omega in [-pi, pi)."""
    p = np.asarray(p, float)
    return log_of(p[..., 0], p[..., 1], wrap_angle(p[..., 2]))


def log_of(x, y, w, alpha=None):
    """:func:`log` of the pose ``(x, y, w)`` given as its coordinates, ``w`` already wrapped → ``(..., 3)``:
    ``[α x + (w/2) y, −(w/2) x + α y, w]`` with ``α = (w/2) cot(w/2)`` (:func:`log_terms`; ``alpha`` when the
    caller has it already) — ``V(w)⁻¹ [x, y]`` for ``V = [[A, −B], [B, A]]``, ``A = sin w / w``,
    ``B = (1 − cos w)/w``, whose inverse ``[[A, B], [−B, A]] / (A² + B²)`` is that in half angles."""
    if alpha is None:
        alpha = log_terms(w)[0]
    hw = 0.5 * w
    return np.stack([alpha * x + hw * y, alpha * y - hw * x, w], -1)


def log_terms(w):
    """``(α, α')`` of the SE(2) logarithm at the wrapped angle ``w``: ``α = (w/2) cot(w/2)`` and its derivative
    ``α' = ½ cot(w/2) − (w/4) / sin²(w/2)`` (for the logarithm's Jacobian); series ``1 − w²/12`` and
    ``−w/6 − w³/180`` below ``|w| < 1e-4``."""
    return _series_patched(w, 1e-4, _log_terms_closed, lambda v: (1.0 - v**2 / 12.0, -v / 6.0 - v**3 / 180.0))


def _log_terms_closed(w):
    """The closed forms of :func:`log_terms` (NaN at ``w = 0``)."""
    half = 0.5 * w
    sh = np.sin(half)
    cot = np.cos(half) / sh
    return half * cot, 0.5 * cot - 0.25 * w / sh**2


def interpolate_poses(t_rows: np.ndarray, xyt_rows: np.ndarray, t: np.ndarray) -> np.ndarray:
    """Interpolate a pose track at times ``t``: x, y linearly, θ along the shorter arc.

    ``p(t) = p_i + w · (p_{i+1} − p_i)``, ``θ(t) = wrap(θ_i + w · angle_diff(θ_{i+1}, θ_i))``,
    ``w = (t − t_i)/(t_{i+1} − t_i)`` with ``i`` the last stamp ``≤ t`` (the first or last segment outside the
    track, so there it extrapolates linearly: callers keep ``t`` inside or mask it, as
    :func:`slamcli.api.interop.trajectory_at` does). The one pose-track interpolation of the package (the
    MRCLAM importer's ground truth, imported trajectories).

    Parameters
    ----------
    t_rows : ndarray (G,)       strictly increasing stamps (G ≥ 2).
    xyt_rows : ndarray (G, 3)   poses.
    t : ndarray (n,)            query times within ``[t_rows[0], t_rows[-1]]``.

    Returns
    -------
    ndarray (n, 3)
    """
    t_rows = np.asarray(t_rows, float)
    p = np.asarray(xyt_rows, float)
    t = np.asarray(t, float)
    i = np.clip(np.searchsorted(t_rows, t, side="right") - 1, 0, len(t_rows) - 2)
    w = (t - t_rows[i]) / (t_rows[i + 1] - t_rows[i])
    xy = p[i, :2] + w[:, None] * (p[i + 1, :2] - p[i, :2])
    th = wrap_angle(p[i, 2] + w * angle_diff(p[i + 1, 2], p[i, 2]))
    return np.column_stack([xy, th])
