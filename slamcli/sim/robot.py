"""Differential-drive robot: waypoint-tracking controller, executed motion and encoder odometry.

The controller is a sequential feedback loop (each command depends on the pose it produced), so it runs as a
plain-Python scalar loop with ``math`` — about 1 µs per step; everything else is vectorised.
"""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np

from slamcli.models import motion
from slamcli.models.angles import wrap_angle, wrap_angle_fast
from slamcli.sim.config import OdometryConfig, RobotConfig

_TWO_PI = 2.0 * math.pi
_PROGRESS_EVERY = 20_000


def start_pose(cfg: RobotConfig, waypoints_xy: np.ndarray) -> np.ndarray:
    """Start pose ``(3,)``: ``cfg.start`` or the first waypoint facing the second."""
    if cfg.start:
        return np.array([cfg.start[0], cfg.start[1], wrap_angle(cfg.start[2])], float)
    p0 = waypoints_xy[0]
    p1 = waypoints_xy[1] if len(waypoints_xy) > 1 else p0 + [1.0, 0.0]
    return np.array([p0[0], p0[1], math.atan2(p1[1] - p0[1], p1[0] - p0[0])])


def _ramp(prev: float, target: float, up: float, down: float) -> float:
    """``prev`` moved towards ``target`` by at most ``up`` when |speed| grows, ``down`` when it shrinks
    (0 = no limit)."""
    d = target - prev
    lim = up if abs(target) > abs(prev) else down
    if lim > 0.0:
        d = lim if d > lim else (-lim if d < -lim else d)
    return prev + d


def drive(
    cfg: RobotConfig,
    waypoints_xy: np.ndarray,
    cyclic: bool,
    x0: np.ndarray,
    n_steps: int,
    dt: float,
    actuation_noise: np.ndarray,
    progress: Callable[[int, int], None] | None = None,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Run the tracking controller and the noisy plant for ``n_steps`` steps.

    Per step (pose x_t, current waypoint w)::

        e   = wrap(atan2(w_y − y_t, w_x − x_t) − θ_t)
        u_t = [v_max · max(0, cos e),  clip(k_heading · e, ±w_max)]      (commanded, seen by solvers)
        x_{t+1} = g(x_t, u_t + n_t)                                        (executed, paper 000 §4)

    With ``cfg.accel_max`` / ``cfg.decel_max`` the executed velocity ``ũ_t`` moves from ``ũ_{t-1}`` (rest at
    t = 0) towards ``u_t + n_t`` by at most ``accel·dt`` (speeding up) or ``decel·dt`` (slowing down) per
    component, and ``x_{t+1} = g(x_t, ũ_t)``.

    ``g`` is the scalar form of :func:`slamcli.models.motion.ddmr_step` (the tests check
    ``ddmr_step(poses[:-1], u_exec, dt) == poses[1:]``).

    Parameters
    ----------
    actuation_noise : ndarray (T, 2)   pre-drawn ``n_t`` (m/s, rad/s).

    Returns
    -------
    controls : ndarray (T, 2)        commanded ``u_t``.
    executed : ndarray (T, 2)        ``u_t + n_t``.
    poses_xyt : ndarray (T+1, 3)     true poses.
    waypoint_reached : ndarray (K,) int64   step at which each waypoint was first reached (−1 = never).
    """
    T = int(n_steps)
    wp = [(float(a), float(b)) for a, b in np.asarray(waypoints_xy, float)]
    K = len(wp)
    reached = [-1] * K
    noise = np.asarray(actuation_noise, float).tolist()
    v_max, w_max, k_h, tol = float(cfg.v_max), float(cfg.w_max), float(cfg.k_heading), float(cfg.waypoint_tol)
    acc = [float(a) * dt for a in getattr(cfg, "accel_max", (0.0, 0.0))]
    dec = [float(a) * dt for a in getattr(cfg, "decel_max", (0.0, 0.0))]
    limited = any(acc) or any(dec)
    ve_prev = we_prev = 0.0
    executed: list[tuple[float, float]] = []
    x, y, th = float(x0[0]), float(x0[1]), float(x0[2])
    poses = [(x, y, th)]
    u_cmd: list[tuple[float, float]] = []
    i = 1 if K > 1 and math.hypot(wp[0][0] - x, wp[0][1] - y) < tol else 0
    if i == 1:
        reached[0] = 0
    done = False
    cos, sin, atan2, hypot, pi, two_pi = math.cos, math.sin, math.atan2, math.hypot, math.pi, _TWO_PI
    wrap = wrap_angle_fast
    next_report = _PROGRESS_EVERY - 1 if progress is not None else -1
    for t in range(T):
        if not done:
            wx, wy = wp[i]
            hops = 0
            while hypot(wx - x, wy - y) < tol and hops <= K:  # hops: no endless loop if all are within tol
                hops += 1
                if reached[i] < 0:
                    reached[i] = t
                i += 1
                if i >= K:
                    if cyclic:
                        i = 0
                    else:
                        done = True
                        break
                wx, wy = wp[i]
        if done:
            v = w = 0.0
        else:
            e = wrap(atan2(wy - y, wx - x) - th)
            if e >= pi:  # rounding guard of the half-open interval
                e -= two_pi
            w = k_h * e
            w = w_max if w > w_max else (-w_max if w < -w_max else w)
            c = cos(e)
            v = v_max * c if c > 0.0 else 0.0
        nv, nw = noise[t]
        ve = v + nv
        we = w + nw
        if limited:
            ve = _ramp(ve_prev, ve, acc[0], dec[0])
            we = _ramp(we_prev, we, acc[1], dec[1])
            ve_prev, we_prev = ve, we
        executed.append((ve, we))
        # g(x, u) = x + dt·[v cos θ, v sin θ, ω]  (heading wrapped)
        x += dt * ve * cos(th)
        y += dt * ve * sin(th)
        th = wrap(th + dt * we)
        if th >= pi:
            th -= two_pi
        u_cmd.append((v, w))
        poses.append((x, y, th))
        if t == next_report:
            progress(t + 1, T)  # type: ignore[misc]
            next_report += _PROGRESS_EVERY
    controls = np.array(u_cmd, float).reshape(T, 2)
    return (
        controls,
        np.array(executed, float).reshape(T, 2),  # u_t + n_t (bit-identical), or its ramped version
        np.array(poses, float).reshape(T + 1, 3),
        np.array(reached, np.int64),
    )


def chain_increments_fast(x0: np.ndarray, increments: np.ndarray) -> np.ndarray:
    """Vectorised :func:`slamcli.models.motion.chain_increments`: poses ``(T+1, 3)`` from ``x0`` and body-frame
    increments ``(T, 3)``.

    ``θ_t = θ_0 + Σ_{s<t} d_θ,s``,  ``p_{t+1} = p_t + R(θ_t) d_xy,t``  (cumulative sums; equal to the sequential
    SE(2) composition up to rounding).
    """
    d = np.asarray(increments, float)
    T = d.shape[0]
    th = x0[2] + np.concatenate([[0.0], np.cumsum(d[:, 2])])  # unwrapped headings (T+1,)
    c, s = np.cos(th[:-1]), np.sin(th[:-1])
    step_xy = np.stack([c * d[:, 0] - s * d[:, 1], s * d[:, 0] + c * d[:, 1]], -1)
    out = np.empty((T + 1, 3))
    out[0, :2] = x0[:2]
    out[1:, :2] = x0[:2] + np.cumsum(step_xy, axis=0)
    out[:, 2] = wrap_angle(th)
    return out


def encoder_odometry(
    cfg: OdometryConfig, poses_xyt: np.ndarray, rng: np.random.Generator
) -> tuple[np.ndarray, np.ndarray]:
    """Noisy, optionally biased odometry.

    ``d_t = τ(θ_t)(x_{t+1} − x_t)`` (eq. 16, ``models.motion.odometry_increments``) of the true motion, then
    ``d̃_t = diag(1+scale_bias, 1+scale_bias, 1+turn_bias) d_t + n_t``, ``n_t ~ N(0, diag(std²))``, chained
    from the true start pose.

    Returns
    -------
    odometry_xyt : ndarray (T+1, 3)
    increments_noisy : ndarray (T, 3)
    """
    d = motion.odometry_increments(poses_xyt)
    scale = np.array([1.0 + cfg.scale_bias, 1.0 + cfg.scale_bias, 1.0 + cfg.turn_bias])
    d_noisy = d * scale + rng.normal(0.0, 1.0, size=d.shape) * np.asarray(cfg.std, float)
    return chain_increments_fast(poses_xyt[0], d_noisy), d_noisy
