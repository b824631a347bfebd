"""Simulation of a wall world (paper 001 §III): DDMR on the corridor route, identified features, ray-cast scans.

Observation table of the dataset:

* sensor 0 — range-bearing observations of the features (corners / mid-points / posts) in range, field of
  view and line of sight, with their identity reported (``reported_id``), noise σ_r, σ_θ of the sensor;
  plus ``clutter.rate`` false returns per step (id −1, no line-of-sight test) and, with probability
  ``walls.wrong_id_prob`` per true row, the id of another feature reported instead of its own (both drawn
  from the *clutter* stream, the wrong ids after the false returns; the truth keeps the real feature);
* sensor 1 — the scan: ``sensor.n_beams`` beams at the nominal bearings, ranges from :mod:`sim.raycast`
  against the walls (beam direction perturbed by σ_θ, range noise σ_r); a beam without a wall within
  ``max_range`` reads exactly ``max_range`` (the row is kept: it says "free up to max range").

Truth: poses, features, the wall segments, the true occupancy grid and the step at which each lap ended.
Random streams from :mod:`sim.streams` (the scan uses the *sensor* stream after the feature draws).
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from slamcli.sim import raycast, robot, sensors, walls
from slamcli.sim.assemble import simulated_inputs, simulated_metadata
from slamcli.sim.config import ScenarioConfig
from slamcli.sim.streams import stream
from slamcli.types import Dataset, GroundTruth, NoiseSpec, Observations, OccupancyGrid

FEATURE_SENSOR = 0
SCAN_SENSOR = 1
_LOS_TOL = 0.3  # m: a feature is in sight when the ray towards it travels this close to it


def build_world(cfg: ScenarioConfig) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(segments (W, 4), features (F, 2), route waypoints (K, 2))`` of the configured wall world."""
    w = cfg.walls
    segs = walls.ladder_segments(w.width, w.height, w.block_rows, w.block_cols, w.corridor)
    if w.features == "posts":
        feats = walls.post_features(w.width, w.height, w.block_rows, w.block_cols, w.corridor, w.post_spacing)
    else:
        feats = walls.corner_features(segs, with_midpoints=w.features == "corners+mid")
        if w.features == "corners+mid":  # + the outer walls' points opposite every corridor stretch's mid-point
            extra = walls.corridor_wall_midpoints(w.width, w.height, w.block_rows, w.block_cols, w.corridor)
            gap = np.hypot(extra[:, None, 0] - feats[None, :, 0], extra[:, None, 1] - feats[None, :, 1]).min(axis=1)
            feats = np.vstack([feats, extra[gap > 1e-6]])
    route = walls.ladder_route(w.width, w.height, w.block_rows, w.block_cols, w.corridor)
    return segs, feats, route


def wrong_ids(landmark: np.ndarray, n_features: int, prob: float, rng: np.random.Generator) -> np.ndarray:
    """The reported ids: each true row (``landmark ≥ 0``) reports, with probability ``prob``, another feature
    drawn uniformly from the ``n_features − 1`` others; clutter rows keep −1. Draws nothing when ``prob = 0``."""
    out = np.asarray(landmark, np.int64).copy()
    if prob <= 0 or n_features < 2:
        return out
    rows = np.flatnonzero(out >= 0)
    flip = rows[rng.random(len(rows)) < prob]
    shift = rng.integers(1, n_features, len(flip))  # 1 … F−1: never the row's own feature
    out[flip] = (out[flip] + shift) % n_features
    return out


def simulate_walls(cfg: ScenarioConfig, seed: int, progress=None) -> Dataset:
    """Simulate one run in a wall world (called by :func:`slamcli.sim.simulate.simulate`)."""
    segs, feats, route = build_world(cfg)
    spec = walls.grid_spec_for(segs, cfg.walls.resolution, cfg.walls.grid_margin)
    v = cfg.robot.v_max
    lap_len = walls.route_length(route)
    if cfg.walls.laps > 0:
        T = int(math.ceil(cfg.walls.laps * lap_len / (v * cfg.dt) * 1.3)) + 20  # drive long, cut at the lap end
    else:
        T = int(cfg.n_steps)
    if progress is not None:
        progress(0, T)
    x0 = robot.start_pose(cfg.robot, route)
    n_act = stream("motion", seed).standard_normal((T, 2)) * np.asarray(cfg.robot.actuation_std, float)
    controls, _exe, poses, _reached = robot.drive(cfg.robot, route, True, x0, T, cfg.dt, n_act)
    min_gap = int(0.5 * lap_len / (v * cfg.dt))
    laps = walls.lap_end_steps(poses, route[0], max(cfg.robot.waypoint_tol, 1.0), min_gap)
    if cfg.walls.laps > 0:
        if len(laps) >= cfg.walls.laps:
            T = int(laps[cfg.walls.laps - 1])
        laps = laps[: cfg.walls.laps]
        controls, poses = controls[:T], poses[: T + 1]
    laps = laps[laps <= T]
    odometry_xyt, _ = robot.encoder_odometry(cfg.odometry, poses, stream("odometry", seed))
    steps = np.arange(T + 1, dtype=np.int64)

    # sensor 0: features (point sensor query, then line of sight against the walls)
    rng_s, rng_c = stream("sensor", seed), stream("clutter", seed)
    ret = sensors.point_scans(poses, feats, steps, cfg.sensor, cfg.clutter, rng_s, rng_c)
    true_row = ret.landmark >= 0
    if len(ret.step):
        p = poses[ret.step]
        d = feats[np.maximum(ret.landmark, 0)] - p[:, :2]
        dist = np.hypot(d[:, 0], d[:, 1])
        t_hit, _ = raycast.cast(p[:, :2], np.arctan2(d[:, 1], d[:, 0]), float(cfg.sensor.max_range) + 1.0, segs)
        seen = (t_hit >= dist - _LOS_TOL) | ~true_row  # clutter is no feature: no line-of-sight test
        ret = sensors.Returns(ret.step[seen], ret.range_m[seen], ret.bearing_rad[seen], ret.landmark[seen])
    reported = wrong_ids(ret.landmark, len(feats), cfg.walls.wrong_id_prob, rng_c)
    if progress is not None:
        progress(T // 10, T)

    # sensor 1: the ray-cast scan, in chunks of poses
    alphas, _ = sensors.beam_angles(cfg.sensor)
    B = len(alphas)
    scan_r = np.empty((T + 1, B))
    chunk = max(1, 20_000 // B)
    for a in range(0, T + 1, chunk):
        b = min(T + 1, a + chunk)
        scan_r[a:b], _ = raycast.scan(poses[a:b], alphas, float(cfg.sensor.max_range), cfg.sensor.range_std,
                                      cfg.sensor.bearing_std, rng_s, segs)
        if progress is not None:
            progress(T // 10 + int(0.9 * b * T / (T + 1)), T)

    # one table: per step the feature rows (sensor 0) then the scan (sensor 1)
    n_f = len(ret.step)
    step_all = np.concatenate([ret.step, np.repeat(steps, B)])
    rng_all = np.concatenate([ret.range_m, scan_r.reshape(-1)])
    brg_all = np.concatenate([ret.bearing_rad, np.tile(alphas, T + 1)])
    sensor_all = np.concatenate([np.full(n_f, FEATURE_SENSOR), np.full((T + 1) * B, SCAN_SENSOR)])
    rid_all = np.concatenate([reported, np.full((T + 1) * B, -1)])
    truth_all = np.concatenate([ret.landmark, np.full((T + 1) * B, -1)])
    order = np.argsort(step_all, kind="stable")
    obs = Observations.from_rows(step_all[order], np.column_stack([rng_all[order], brg_all[order]]), T + 1,
                                 reported_id=rid_all[order], sensor=sensor_all[order])

    s = cfg.sensor
    noise = NoiseSpec(motion_std=np.asarray(cfg.robot.actuation_std, float),
                      odometry_std=np.asarray(cfg.odometry.std, float),
                      range_std=float(s.range_std), bearing_std=float(s.bearing_std))
    inputs = simulated_inputs(cfg, T, poses, controls, odometry_xyt, obs, noise)
    occ = walls.true_grid(spec, segs)
    truth = GroundTruth(
        poses_xyt=poses,
        landmarks_xy=feats,
        obs_landmark=truth_all[order].astype(np.int64),
        occupancy=OccupancyGrid(origin_xy=np.asarray(spec.origin_xy, float), resolution=spec.resolution,
                                prob=occ.astype(np.float32)),
        walls_xyxy=segs,
        lap_end_step=laps.astype(np.int64),
    )
    metadata = simulated_metadata(cfg, seed=seed, world_seed=seed, n_steps=T, sensor_kind="walls",
                                  config=dataclasses.replace(cfg, n_steps=T), with_streams=False,
                                  feature_sensor=FEATURE_SENSOR, scan_sensor=SCAN_SENSOR, n_beams=B,
                                  route_length_m=lap_len)
    if progress is not None:
        progress(T, T)
    return Dataset(inputs=inputs, truth=truth, metadata=metadata)
