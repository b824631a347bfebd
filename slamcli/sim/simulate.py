"""``simulate(config, seed) -> Dataset``: the only producer of ground truth.

Random streams are independent and derived from ``(stream id, seed)`` (:mod:`slamcli.sim.streams`), so
changing e.g. the sensor noise level changes neither the world nor the trajectory, and adding clutter does not
change the noise on true returns. Wall worlds (:mod:`~slamcli.sim.wallworld`) and bounded-noise runs
(:mod:`~slamcli.sim.bounded`) have their own drivers; :func:`simulate` dispatches to them.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Any

import numpy as np

import slamcli
from slamcli.errors import ConfigError
from slamcli.sim import robot, sensors, world
from slamcli.sim.config import ScenarioConfig, config_to_dict
from slamcli.sim.streams import STREAMS, stream
from slamcli.types import Dataset, GroundTruth, NoiseSpec, Observations, SlamInputs

ProgressFn = Callable[[int, int], None]


def noise_spec(cfg: ScenarioConfig) -> NoiseSpec:
    """Noise levels a solver may assume, from the configuration.

    Point sensor: the configured σ_r, σ_b. Laser: returns come from the disc *surface* on beams spread over the
    disc, not from its centre, so the effective values are ``hypot(σ_r, landmark_radius)`` and
    ``hypot(σ_b, beam spacing)``.
    """
    s = cfg.sensor
    if s.kind == "laser":
        r_std = math.hypot(s.range_std, cfg.world.landmark_radius)
        b_std = math.hypot(s.bearing_std, sensors.beam_angles(s)[1])
    else:
        r_std, b_std = s.range_std, s.bearing_std
    return NoiseSpec(
        motion_std=np.asarray(cfg.robot.actuation_std, float),
        odometry_std=np.asarray(cfg.odometry.std, float),
        range_std=float(r_std),
        bearing_std=float(b_std),
    )


def simulate(config: ScenarioConfig, seed: int = 0, progress: ProgressFn | None = None) -> Dataset:
    """Simulate one run.

    Parameters
    ----------
    config : ScenarioConfig
    seed : int
        Root seed (≥ 0) of every stream (the world stream uses ``config.world.seed`` when that is ≥ 0).
    progress : callable(done, total), optional
        Called with ``(0, T)`` once the world is built, every 20 000 steps of the drive loop and with
        ``(T, T)`` at the end.

    Returns
    -------
    Dataset
        ``inputs`` (controls (T,2), odometry_xyt (T+1,3), observations sorted by step with CSR offsets
        (T+2,), NoiseSpec, max_range, optional GPS), ``truth`` (poses_xyt (T+1,3), landmarks_xy (L,2),
        obs_landmark (N,)), ``metadata`` (JSON-serialisable: scenario, seed, resolved config, streams).
    """
    cfg = config
    T = int(cfg.n_steps)
    seed = int(seed)
    if seed < 0:
        raise ConfigError(f"--seed: must be >= 0, got {seed}")
    if cfg.walls.layout != "none":  # paper 001 wall worlds: ray-cast scans + features (sim/wallworld.py)
        from slamcli.sim.wallworld import simulate_walls

        return simulate_walls(cfg, seed, progress)
    if cfg.bounded.enabled:  # paper 004: turn-and-move robot, uniform bounded errors, type labels
        from slamcli.sim.bounded import simulate_bounded

        return simulate_bounded(cfg, seed, progress)

    # 1) world: waypoints, then landmarks (a random layout keeps clear of the path)
    world_seed = seed if cfg.world.seed < 0 else int(cfg.world.seed)
    rng_w = stream("world", world_seed)
    waypoints = world.make_waypoints(cfg.path, rng_w)
    landmarks = world.make_landmarks(cfg.world, waypoints, cfg.path.cyclic, rng_w)

    if progress is not None:
        progress(0, T)  # the world is valid: the run starts

    # 2) robot: commanded controls from the tracking controller, executed with actuation noise
    x0 = robot.start_pose(cfg.robot, waypoints)
    n_act = stream("motion", seed).standard_normal((T, 2)) * np.asarray(cfg.robot.actuation_std, float)
    controls, _executed, poses, _reached = robot.drive(
        cfg.robot, waypoints, cfg.path.cyclic, x0, T, cfg.dt, n_act, progress
    )

    # 3) encoder odometry (eq. 16 increments of the true motion, noisy and biased)
    odometry_xyt, _ = robot.encoder_odometry(cfg.odometry, poses, stream("odometry", seed))

    # 4) exteroceptive sensor
    scan_steps = np.arange(0, T + 1, cfg.sensor.period_steps, dtype=np.int64)
    rng_s, rng_c = stream("sensor", seed), stream("clutter", seed)
    if cfg.sensor.kind == "laser":
        ret = sensors.laser_scans(
            poses, landmarks, cfg.world.landmark_radius, scan_steps, cfg.sensor, cfg.clutter, rng_s, rng_c
        )
    else:
        ret = sensors.point_scans(poses, landmarks, scan_steps, cfg.sensor, cfg.clutter, rng_s, rng_c)
    reported = np.where(ret.landmark >= 0, ret.landmark, -1) if cfg.sensor.report_ids else np.full(len(ret.step), -1)
    obs = Observations.from_rows(
        ret.step, np.column_stack([ret.range_m, ret.bearing_rad]), T + 1, reported_id=reported
    )

    # 5) optional GPS
    gps_step = np.zeros(0, np.int64)
    gps_xy = np.zeros((0, 2))
    if cfg.gps.enabled:
        gps_step = np.arange(0, T + 1, cfg.gps.period_steps, dtype=np.int64)
        gps_xy = poses[gps_step, :2] + stream("gps", seed).normal(0.0, cfg.gps.std, (len(gps_step), 2))

    inputs = SlamInputs(
        dt=float(cfg.dt),
        timestamps=np.arange(T + 1) * float(cfg.dt),
        x0=poses[0].copy(),
        controls=controls,
        odometry_xyt=odometry_xyt,
        observations=obs,
        noise=noise_spec(cfg),
        max_range=float(cfg.sensor.max_range),
        gps_step=gps_step,
        gps_xy=gps_xy,
        gps_std=float(cfg.gps.std) if cfg.gps.enabled else 0.0,
    )
    truth = GroundTruth(poses_xyt=poses, landmarks_xy=landmarks, obs_landmark=ret.landmark.astype(np.int64))
    metadata: dict[str, Any] = {
        "generator": "slamcli.sim",
        "slamcli_version": slamcli.__version__,
        "scenario": cfg.name,
        "seed": seed,
        "world_seed": world_seed,
        "dt": float(cfg.dt),
        "n_steps": T,
        "sensor_kind": cfg.sensor.kind,
        "config": config_to_dict(cfg),
        "streams": dict(STREAMS),
    }
    if progress is not None:
        progress(T, T)
    return Dataset(inputs=inputs, truth=truth, metadata=metadata)


def simulate_scenario(
    name: str, seed: int = 0, overrides: dict[str, Any] | None = None, progress: ProgressFn | None = None
) -> Dataset:
    """``simulate(resolve_scenario(name, overrides), seed)``."""
    from slamcli.sim.scenarios import resolve_scenario

    return simulate(resolve_scenario(name, overrides or {}), seed, progress=progress)
