"""Simulation of a wall world (paper 001 §III): DDMR on the corridor route, identified features, ray-cast scans.

Observation table of the dataset:

* sensor 0 — range-bearing observations of the features (corners / mid-points / posts) in range, field of
  view and line of sight, with their identity reported (``reported_id``), noise σ_r, σ_θ of the sensor;
* sensor 1 — the scan: ``sensor.n_beams`` beams at the nominal bearings, ranges from :mod:`sim.raycast`
  against the walls (beam direction perturbed by σ_θ, range noise σ_r); a beam without a wall within
  ``max_range`` reads exactly ``max_range`` (the row is kept: it says "free up to max range").

Truth: poses, features, the wall segments, the true occupancy grid and the step at which each lap ended.
Random streams from :mod:`sim.streams` (the scan uses the *sensor* stream after the feature draws).
"""

from __future__ import annotations

import dataclasses
import math
from typing import Any

import numpy as np

import slamcli
from slamcli.sim import raycast, robot, sensors, walls
from slamcli.sim.config import ClutterConfig, ScenarioConfig, config_to_dict
from slamcli.sim.streams import stream
from slamcli.types import Dataset, GroundTruth, NoiseSpec, Observations, OccupancyGrid, SlamInputs

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
    rng_s = stream("sensor", seed)
    ret = sensors.point_scans(poses, feats, steps, cfg.sensor, ClutterConfig(rate=0.0), rng_s, stream("clutter", seed))
    if len(ret.step):
        p = poses[ret.step]
        d = feats[ret.landmark] - p[:, :2]
        dist = np.hypot(d[:, 0], d[:, 1])
        t_hit, _ = raycast.cast(p[:, :2], np.arctan2(d[:, 1], d[:, 0]), float(cfg.sensor.max_range) + 1.0, segs)
        seen = t_hit >= dist - _LOS_TOL
        ret = sensors.Returns(ret.step[seen], ret.range_m[seen], ret.bearing_rad[seen], ret.landmark[seen])
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
    rid_all = np.concatenate([ret.landmark, np.full((T + 1) * B, -1)])
    order = np.argsort(step_all, kind="stable")
    obs = Observations.from_rows(step_all[order], np.column_stack([rng_all[order], brg_all[order]]), T + 1,
                                 reported_id=rid_all[order], sensor=sensor_all[order])

    s = cfg.sensor
    inputs = SlamInputs(
        dt=float(cfg.dt),
        timestamps=np.arange(T + 1) * float(cfg.dt),
        x0=poses[0].copy(),
        controls=controls,
        odometry_xyt=odometry_xyt,
        observations=obs,
        noise=NoiseSpec(motion_std=np.asarray(cfg.robot.actuation_std, float),
                        odometry_std=np.asarray(cfg.odometry.std, float),
                        range_std=float(s.range_std), bearing_std=float(s.bearing_std)),
        max_range=float(s.max_range),
    )
    occ = walls.true_grid(spec, segs)
    truth = GroundTruth(
        poses_xyt=poses,
        landmarks_xy=feats,
        obs_landmark=rid_all[order].astype(np.int64),
        occupancy=OccupancyGrid(origin_xy=np.asarray(spec.origin_xy, float), resolution=spec.resolution,
                                prob=occ.astype(np.float32)),
        walls_xyxy=segs,
        lap_end_step=laps.astype(np.int64),
    )
    metadata: dict[str, Any] = {
        "generator": "slamcli.sim",
        "slamcli_version": slamcli.__version__,
        "scenario": cfg.name,
        "seed": int(seed),
        "world_seed": int(seed),
        "dt": float(cfg.dt),
        "n_steps": T,
        "sensor_kind": "walls",
        "feature_sensor": FEATURE_SENSOR,
        "scan_sensor": SCAN_SENSOR,
        "n_beams": B,
        "route_length_m": lap_len,
        "config": config_to_dict(dataclasses.replace(cfg, n_steps=T)),
    }
    if progress is not None:
        progress(T, T)
    return Dataset(inputs=inputs, truth=truth, metadata=metadata)
