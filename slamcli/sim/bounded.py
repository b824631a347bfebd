"""Bounded-error "turn and move" runs (paper 004 §6): the truth producer for set-membership SLAM.

The robot starts at ``robot.start`` and, for each of ``n_steps`` legs, turns in place towards the next
waypoint of ``path`` and drives straight to it (one pose per waypoint)::

    α_t = wrap(atan2(w_y − y_t, w_x − x_t) − θ_t),   d_t = ‖w − p_t‖
    θ_{t+1} = θ_t + α_t,   p_{t+1} = p_t + d_t·[cos θ_{t+1}, sin θ_{t+1}]

Every error is uniform within its ± bound (``BoundedConfig``): odometry reads ``d̃ = d + u_d``,
``α̃ = α + u_α`` and is chained into ``odometry_xyt`` (so the increment of pose t → t+1 encodes
``(d̃, α̃)`` exactly); the point sensor reports ``[r + u_r, wrap(b + u_b)]`` and the landmark's type label.
The declared bounds (``declared_scale ×`` the true ones) go into ``SlamInputs.noise_bounds`` and the
dataset metadata; a Gaussian ``NoiseSpec`` with the uniform's standard deviation ``h/√3`` is recorded too, so
least-squares solvers run on the same data.

Heading conventions: ours is the usual mathematical one (θ from +x, counter-clockwise; x₂ − x₁ = d·cos θ).
Paper 004 (Fig. 2) measures θ from +y clockwise (x₂ − x₁ = d·sin θ, y₂ − y₁ = d·cos θ);
:func:`heading_from_paper004` is the one place that converts.
"""

from __future__ import annotations

import math

import numpy as np

from slamcli.models.angles import wrap_angle
from slamcli.sim import world
from slamcli.sim.assemble import simulated_inputs, simulated_metadata
from slamcli.sim.config import ScenarioConfig
from slamcli.sim.streams import stream
from slamcli.types import Dataset, GroundTruth, NoiseBounds, NoiseSpec, Observations, ProgressFn


def heading_from_paper004(theta_paper):
    """Paper 004 heading (from +y, clockwise: x₂−x₁ = d·sin θ, y₂−y₁ = d·cos θ) → ours (from +x, CCW).

    ``θ_ours = π/2 − θ_paper`` (not wrapped, so interval bounds swap: ``[a, b]`` → ``[π/2 − b, π/2 − a]``).
    """
    return np.pi / 2 - np.asarray(theta_paper, float)


def drive_legs(start_xyt: np.ndarray, waypoints_xy: np.ndarray, n_legs: int, cyclic: bool):
    """True poses ``(n_legs+1, 3)`` and legs ``(n_legs, 2)`` = ``[d_t, α_t]`` of the turn-and-move robot.

    Leg t goes to waypoint ``(t+1) mod K`` (the first waypoint is the start position); without ``cyclic``
    the robot stays at the last waypoint (``d = α = 0``).
    """
    K = len(waypoints_xy)
    poses = np.zeros((n_legs + 1, 3))
    poses[0] = start_xyt
    legs = np.zeros((n_legs, 2))
    for t in range(n_legs):
        k = t + 1
        w = waypoints_xy[k % K] if cyclic else waypoints_xy[min(k, K - 1)]
        p, th = poses[t, :2], poses[t, 2]
        delta = w - p
        d = float(np.hypot(*delta))
        alpha = float(wrap_angle(math.atan2(delta[1], delta[0]) - th)) if d > 1e-12 else 0.0
        legs[t] = d, alpha
        poses[t + 1] = [w[0], w[1], wrap_angle(th + alpha)]
    return poses, legs


def chain_legs(start_xyt: np.ndarray, legs: np.ndarray) -> np.ndarray:
    """Poses ``(T+1, 3)`` from measured legs ``(T, 2)`` = ``[d̃, α̃]`` (turn, then move along the new heading)."""
    out = np.zeros((len(legs) + 1, 3))
    out[0] = start_xyt
    for t, (d, a) in enumerate(legs):
        th = wrap_angle(out[t, 2] + a)
        out[t + 1] = [out[t, 0] + d * math.cos(th), out[t, 1] + d * math.sin(th), th]
    return out


def legs_from_odometry(odometry_xyt: np.ndarray) -> np.ndarray:
    """Inverse of :func:`chain_legs`: ``[d̃, α̃]`` ``(T, 2)`` from the odometry poses (exact up to rounding)."""
    odo = np.asarray(odometry_xyt, float)
    d = np.hypot(*(odo[1:, :2] - odo[:-1, :2]).T)
    a = wrap_angle(odo[1:, 2] - odo[:-1, 2])
    return np.column_stack([d, a])


def closest_visible(pose_xyt: np.ndarray, landmarks_xy: np.ndarray, min_range: float, max_range: float,
                    fov_rad: float, closest_only: bool) -> np.ndarray:
    """Indices of the landmarks the sensor reports at one pose (the nearest visible one, or all visible);
    ties within 1 nm go to the landmark with the smallest |bearing|."""
    if len(landmarks_xy) == 0:
        return np.zeros(0, np.int64)
    d = landmarks_xy - pose_xyt[:2]
    r = np.hypot(d[:, 0], d[:, 1])
    b = wrap_angle(np.arctan2(d[:, 1], d[:, 0]) - pose_xyt[2])
    ok = (r >= min_range) & (r <= max_range) & (np.abs(b) <= fov_rad / 2 + 1e-12)
    idx = np.flatnonzero(ok)
    if closest_only and idx.size:
        # the closest one; an exact tie (the room's even poses are equidistant from two landmarks) goes to
        # the landmark nearest to straight ahead
        near = idx[r[idx] <= r[idx].min() + 1e-9]
        idx = near[[int(np.argmin(np.abs(b[near])))]]
    return idx.astype(np.int64)


def _loop_closure_readings(poses, landmarks, obs, obs_lm, err_r: float, err_b: float, rng: np.random.Generator):
    """``(range_m, bearing_rad)`` with the loop-closing sightings (the first-seen landmark seen after pose 0)
    replaced by the true reading ± exactly ``err_r`` (m) / ``err_b`` (rad), random signs from ``rng``."""
    rows = np.flatnonzero((obs_lm == obs_lm[0]) & (np.asarray(obs.step) > 0))
    P = poses[obs.step[rows]]
    d = landmarks[obs_lm[rows]] - P[:, :2]
    sr, sb = rng.choice([-1.0, 1.0], size=(2, len(rows)))
    rng_m, brg = obs.range_m.copy(), obs.bearing_rad.copy()
    rng_m[rows] = np.hypot(d[:, 0], d[:, 1]) + sr * err_r
    brg[rows] = np.arctan2(d[:, 1], d[:, 0]) - P[:, 2] + sb * err_b
    return rng_m, brg


def simulate_bounded(cfg: ScenarioConfig, seed: int, progress: ProgressFn | None = None) -> Dataset:
    """Simulate one bounded-noise turn-and-move run (see the module docstring); ``Dataset`` like ``simulate``."""
    b = cfg.bounded
    T = int(cfg.n_steps)
    world_seed = seed if cfg.world.seed < 0 else int(cfg.world.seed)
    rng_w = stream("world", world_seed)
    waypoints = world.make_waypoints(cfg.path, rng_w)
    landmarks = world.make_landmarks(cfg.world, waypoints, cfg.path.cyclic, rng_w)
    types = np.zeros(len(landmarks), np.int64)
    if b.landmark_types:
        n = min(len(b.landmark_types), len(landmarks))
        types[:n] = np.asarray(b.landmark_types[:n], np.int64)
    if progress is not None:
        progress(0, T)

    if cfg.robot.start:
        x0 = np.array([cfg.robot.start[0], cfg.robot.start[1], wrap_angle(cfg.robot.start[2])], float)
    else:
        x0 = np.array([waypoints[0, 0], waypoints[0, 1], 0.0])
    poses, legs = drive_legs(x0, waypoints, T, cfg.path.cyclic)

    h_d, h_a = float(b.odometry_d), math.radians(b.odometry_turn_deg)
    h_r, h_b = float(b.range), math.radians(b.bearing_deg)
    on = 0.0 if b.exact_readings else 1.0  # exact readings: zero errors, bounds still declared
    u = stream("odometry", seed).uniform(-1.0, 1.0, (T, 2)) * [h_d, h_a] * on
    legs_meas = legs + u
    legs_meas[:, 0] = np.maximum(legs_meas[:, 0], 0.0)  # a distance reading is never negative
    odometry_xyt = chain_legs(x0, legs_meas)

    rng_s = stream("sensor", seed)
    s = cfg.sensor
    rows_step, rows_z, rows_lm = [], [], []
    for t in range(T + 1):
        for j in closest_visible(poses[t], landmarks, s.min_range, s.max_range, s.fov_rad, b.closest_only):
            d = landmarks[j] - poses[t, :2]
            r = float(np.hypot(*d)) + rng_s.uniform(-h_r, h_r) * on
            br = math.atan2(d[1], d[0]) - poses[t, 2] + rng_s.uniform(-h_b, h_b) * on
            rows_step.append(t)
            rows_z.append([max(r, 0.0), br])
            rows_lm.append(int(j))
    obs_lm = np.asarray(rows_lm, np.int64)
    # ``sensor.report_ids``: the sensor also reports each landmark's identity (Porta's setting, paper 004 §1)
    obs = Observations.from_rows(np.asarray(rows_step, np.int64), np.asarray(rows_z, float).reshape(-1, 2), T + 1,
                                 reported_id=obs_lm.copy() if cfg.sensor.report_ids else None)
    rng_m, brg = obs.range_m, obs.bearing_rad
    if b.loop_closure_error > 0 and len(obs_lm):
        rng_m, brg = _loop_closure_readings(poses, landmarks, obs, obs_lm, h_r * b.loop_closure_error,
                                            h_b * b.loop_closure_error, np.random.default_rng(seed))
    obs = Observations(step=obs.step, range_m=rng_m, bearing_rad=brg, sensor=obs.sensor,
                       reported_id=obs.reported_id, offsets=obs.offsets, landmark_type=types[obs_lm])

    scale = float(b.declared_scale)
    # the closest-landmark sensor's negative information is declared only for a 360° field of view (with a
    # narrower one, "closer" would also need "inside the field of view")
    closest = bool(b.closest_only) and s.fov_rad >= 2 * math.pi - 1e-12
    bounds = NoiseBounds(odometry_model="turn_move", odometry_half_width=np.array([h_d, h_a]) * scale,
                         range_half_width=h_r * scale, bearing_half_width=h_b * scale, closest_only=closest,
                         min_range=float(s.min_range), min_separation=float(b.declared_separation))
    max_leg = float(legs[:, 0].max()) if T else 0.0
    noise = NoiseSpec(  # the uniform errors' standard deviations h/√3, for least-squares solvers
        motion_std=np.zeros(2),
        odometry_std=np.array([h_d, max_leg * h_a, h_a]) * scale / math.sqrt(3.0),
        range_std=h_r * scale / math.sqrt(3.0),
        bearing_std=h_b * scale / math.sqrt(3.0),
    )
    # controls: the commanded [d, α] per leg, as rates over one leg
    inputs = simulated_inputs(cfg, T, poses, legs / float(cfg.dt), odometry_xyt, obs, noise, noise_bounds=bounds)
    truth = GroundTruth(poses_xyt=poses, landmarks_xy=landmarks, obs_landmark=obs_lm)
    metadata = simulated_metadata(
        cfg, seed=seed, world_seed=world_seed, n_steps=T, sensor_kind="point", generator="slamcli.sim.bounded",
        noise_bounds={"odometry_model": "turn_move", "odometry_d_m": h_d * scale,
                      "odometry_turn_rad": h_a * scale, "range_m": h_r * scale, "bearing_rad": h_b * scale,
                      "closest_only": closest, "min_range_m": float(s.min_range),
                      "min_separation_m": float(b.declared_separation)},
        landmark_types=types.tolist(),
    )
    if progress is not None:
        progress(T, T)
    return Dataset(inputs=inputs, truth=truth, metadata=metadata)
