"""Simulator core: determinism, stream independence, noise statistics, kinematic consistency, point sensor."""

from __future__ import annotations

import numpy as np
import pytest

from slamcli.errors import ConfigError
from slamcli.models import motion
from slamcli.models.angles import angle_diff
from slamcli.models.observation import measurement_residual, range_bearing
from slamcli.sim import (
    config_from_dict,
    config_to_dict,
    known_keys,
    resolve_scenario,
    robot,
    simulate,
    simulate_scenario,
    world,
)
from slamcli.sim.streams import stream


def _arrays(ds):
    i, o, t = ds.inputs, ds.inputs.observations, ds.truth
    return {
        "controls": i.controls, "odometry": i.odometry_xyt, "step": o.step, "range": o.range_m,
        "bearing": o.bearing_rad, "reported": o.reported_id, "offsets": o.offsets, "poses": t.poses_xyt,
        "landmarks": t.landmarks_xy, "obs_landmark": t.obs_landmark, "timestamps": i.timestamps,
    }


def test_same_seed_identical_different_seed_differs():
    a = _arrays(simulate_scenario("loop", seed=7))
    b = _arrays(simulate_scenario("loop", seed=7))
    for k in a:
        np.testing.assert_array_equal(a[k], b[k], err_msg=k)
    c = _arrays(simulate_scenario("loop", seed=8))
    assert not np.array_equal(a["landmarks"], c["landmarks"])
    assert not np.array_equal(a["poses"], c["poses"])


def test_sensor_noise_change_leaves_world_and_trajectory_unchanged():
    a = simulate_scenario("loop", seed=3)
    b = simulate_scenario("loop", seed=3, overrides={"sensor.range_std": 0.3, "sensor.bearing_std": 0.05})
    for x, y in [
        (a.truth.poses_xyt, b.truth.poses_xyt),
        (a.truth.landmarks_xy, b.truth.landmarks_xy),
        (a.inputs.controls, b.inputs.controls),
        (a.inputs.odometry_xyt, b.inputs.odometry_xyt),
        (a.inputs.observations.offsets, b.inputs.observations.offsets),
    ]:
        np.testing.assert_array_equal(x, y)
    # same detections (rows are in scan/bearing order, so compare as (step, landmark) sets)
    ka = np.lexsort((a.truth.obs_landmark, a.inputs.observations.step))
    kb = np.lexsort((b.truth.obs_landmark, b.inputs.observations.step))
    np.testing.assert_array_equal(a.truth.obs_landmark[ka], b.truth.obs_landmark[kb])
    np.testing.assert_array_equal(a.inputs.observations.step[ka], b.inputs.observations.step[kb])
    assert not np.array_equal(a.inputs.observations.range_m, b.inputs.observations.range_m)
    # odometry noise change: trajectory and observations unchanged, odometry changed
    c = simulate_scenario("loop", seed=3, overrides={"odometry.std": "0.02,0.02,0.01"})
    np.testing.assert_array_equal(a.truth.poses_xyt, c.truth.poses_xyt)
    np.testing.assert_array_equal(a.inputs.observations.range_m, c.inputs.observations.range_m)
    assert not np.array_equal(a.inputs.odometry_xyt, c.inputs.odometry_xyt)
    # clutter does not change the noise on true returns
    d = simulate_scenario("loop", seed=3, overrides={"clutter.rate": 2.0})
    true_rows = d.truth.obs_landmark >= 0
    assert np.sum(~true_rows) > 0
    ka = np.lexsort((a.truth.obs_landmark, a.inputs.observations.step))
    kd = np.lexsort((d.truth.obs_landmark[true_rows], d.inputs.observations.step[true_rows]))
    np.testing.assert_array_equal(a.inputs.observations.range_m[ka], d.inputs.observations.range_m[true_rows][kd])


def test_noise_free_observations_match_range_bearing_model():
    ds = simulate_scenario("loop", seed=1, overrides={"sensor.range_std": 0, "sensor.bearing_std": 0})
    o, t = ds.inputs.observations, ds.truth
    assert len(o) > 500
    z_hat = range_bearing(t.poses_xyt[o.step], t.landmarks_xy[t.obs_landmark])
    res = measurement_residual(o.z, z_hat)
    assert np.max(np.abs(res)) < 1e-12


def test_measurement_noise_statistics():
    sr, sb = 0.1, 0.02
    ds = simulate_scenario(
        "loop", seed=5,
        overrides={"n_steps": 3000, "sensor.range_std": sr, "sensor.bearing_std": sb, "sensor.detection_prob": 1},
    )
    o, t = ds.inputs.observations, ds.truth
    res = measurement_residual(o.z, range_bearing(t.poses_xyt[o.step], t.landmarks_xy[t.obs_landmark]))
    assert len(o) > 5000
    assert abs(np.std(res[:, 0]) / sr - 1) < 0.1
    assert abs(np.std(res[:, 1]) / sb - 1) < 0.1
    assert abs(np.mean(res[:, 0])) < 3 * sr / np.sqrt(len(o)) * 3


def test_odometry_increment_error_statistics_and_bias():
    std = (0.01, 0.02, 0.005)
    ds = simulate_scenario("loop", seed=2, overrides={"n_steps": 4000, "odometry.std": std})
    d_true = motion.odometry_increments(ds.truth.poses_xyt)
    d_odo = motion.odometry_increments(ds.inputs.odometry_xyt)
    err = d_odo - d_true
    err[:, 2] = angle_diff(d_odo[:, 2], d_true[:, 2])
    np.testing.assert_allclose(np.std(err, axis=0) / np.array(std), 1.0, atol=0.06)
    # scale bias, no noise: every translation increment is exactly (1+b) times the true one
    b = simulate_scenario("loop", seed=2, overrides={"odometry.std": "0,0,0", "odometry.scale_bias": 0.05})
    d_true = motion.odometry_increments(b.truth.poses_xyt)
    d_odo = motion.odometry_increments(b.inputs.odometry_xyt)
    np.testing.assert_allclose(d_odo[:, :2], 1.05 * d_true[:, :2], atol=1e-9)
    np.testing.assert_allclose(angle_diff(d_odo[:, 2], d_true[:, 2]), 0.0, atol=1e-9)


def test_chain_increments_fast_matches_models():
    rng = np.random.default_rng(0)
    inc = np.column_stack([rng.normal(0.1, 0.05, 300), rng.normal(0, 0.02, 300), rng.normal(0, 0.3, 300)])
    x0 = np.array([1.0, -2.0, 3.0])
    np.testing.assert_allclose(robot.chain_increments_fast(x0, inc)[:, :2], motion.chain_increments(x0, inc)[:, :2],
                               atol=1e-10)
    np.testing.assert_allclose(angle_diff(robot.chain_increments_fast(x0, inc)[:, 2],
                                          motion.chain_increments(x0, inc)[:, 2]), 0.0, atol=1e-10)


def _drive(cfg, seed=0):
    wp = world.make_waypoints(cfg.path, stream("world", seed))
    n = stream("motion", seed).standard_normal((cfg.n_steps, 2)) * np.asarray(cfg.robot.actuation_std)
    x0 = robot.start_pose(cfg.robot, wp)
    return wp, robot.drive(cfg.robot, wp, cfg.path.cyclic, x0, cfg.n_steps, cfg.dt, n)


def test_executed_motion_is_ddmr_model_and_actuation_noise_has_configured_std():
    cfg = resolve_scenario("loop", {"n_steps": 4000, "robot.actuation_std": "0.05,0.03"})
    _, (u_cmd, u_exe, poses, _) = _drive(cfg)
    pred = motion.ddmr_step(poses[:-1], u_exe, cfg.dt)
    np.testing.assert_allclose(pred[:, :2], poses[1:, :2], atol=1e-12)
    assert np.max(np.abs(angle_diff(pred[:, 2], poses[1:, 2]))) < 1e-12
    np.testing.assert_allclose(np.std(u_exe - u_cmd, axis=0) / [0.05, 0.03], 1.0, atol=0.05)
    ds = simulate(cfg, seed=0)
    np.testing.assert_array_equal(ds.inputs.controls, u_cmd)
    np.testing.assert_array_equal(ds.truth.poses_xyt, poses)
    assert np.all(u_cmd[:, 0] >= 0) and np.all(u_cmd[:, 0] <= cfg.robot.v_max)
    assert np.all(np.abs(u_cmd[:, 1]) <= cfg.robot.w_max)


def test_controller_reaches_every_waypoint():
    wps = (0.0, 0.0, 10.0, 0.0, 10.0, 6.0, 2.0, 8.0, -3.0, 3.0)
    cfg = resolve_scenario("loop", {
        "path.kind": "explicit", "path.waypoints": ",".join(map(str, wps)), "path.cyclic": False,
        "robot.actuation_std": "0,0", "n_steps": 600,
    })
    wp, (_, _, poses, reached) = _drive(cfg)
    assert np.all(reached >= 0), reached
    assert np.all(np.diff(reached) > 0)
    for k in range(len(wp)):
        assert np.hypot(*(poses[reached[k], :2] - wp[k])) < cfg.robot.waypoint_tol + 1e-9
    # after the last waypoint the robot stops
    np.testing.assert_allclose(poses[-1], poses[-10])


def test_point_sensor_geometry_and_csr_layout():
    ds = simulate_scenario("loop", seed=4, overrides={"sensor.range_std": 0, "sensor.bearing_std": 0,
                                                      "sensor.detection_prob": 1.0, "sensor.fov_deg": 120,
                                                      "sensor.max_range": 6})
    o, t = ds.inputs.observations, ds.truth
    T = ds.inputs.controls.shape[0]
    assert o.offsets.shape == (T + 2,)
    assert np.all(np.diff(o.step) >= 0)
    for tt in (0, 17, T):
        assert np.all(o.step[o.at(tt)] == tt)
    assert np.all(o.range_m <= 6) and np.all(np.abs(o.bearing_rad) <= np.radians(60) + 1e-12)
    # every landmark inside the sensing region is observed exactly once per step (detection_prob = 1)
    z = range_bearing(t.poses_xyt[:, None, :], t.landmarks_xy[None, :, :])
    vis = (z[..., 0] <= 6) & (z[..., 0] >= 0.1) & (np.abs(z[..., 1]) <= np.radians(60))
    assert len(o) == int(vis.sum())
    np.testing.assert_array_equal(np.bincount(o.step, minlength=T + 1), vis.sum(axis=1))
    np.testing.assert_array_equal(o.reported_id, -1)
    assert np.all(o.sensor == 0)


def test_detection_probability_clutter_and_report_ids():
    ds = simulate_scenario("loop", seed=6, overrides={"n_steps": 2000, "sensor.detection_prob": 0.7,
                                                      "clutter.rate": 1.5, "sensor.report_ids": True})
    o, t = ds.inputs.observations, ds.truth
    clutter = t.obs_landmark < 0
    n_scans = 2001
    assert abs(clutter.sum() / n_scans - 1.5) < 4 * np.sqrt(1.5 / n_scans)
    np.testing.assert_array_equal(o.reported_id, t.obs_landmark)
    assert np.all(o.reported_id[clutter] == -1)
    assert np.all((o.range_m[clutter] >= 0.1) & (o.range_m[clutter] <= 8.0))
    full = simulate_scenario("loop", seed=6, overrides={"n_steps": 2000, "sensor.detection_prob": 1.0})
    rate = np.sum(~clutter) / len(full.inputs.observations)
    assert abs(rate - 0.7) < 0.02


def test_gps_optional():
    ds = simulate_scenario("loop", seed=1, overrides={"n_steps": 3000, "gps.enabled": True, "gps.std": 0.5,
                                                      "gps.period_steps": 2})
    i = ds.inputs
    np.testing.assert_array_equal(i.gps_step, np.arange(0, 3001, 2))
    err = i.gps_xy - ds.truth.poses_xyt[i.gps_step, :2]
    np.testing.assert_allclose(np.std(err, axis=0), 0.5, rtol=0.06)
    assert i.gps_std == 0.5
    assert len(simulate_scenario("loop", seed=1).inputs.gps_step) == 0


def test_noise_spec_timestamps_and_metadata():
    ds = simulate_scenario("loop", seed=9, overrides={"sensor.range_std": 0.2})
    n = ds.inputs.noise
    assert n.range_std == 0.2 and n.bearing_std == 0.01
    np.testing.assert_array_equal(n.motion_std, [0.05, 0.02])
    np.testing.assert_allclose(ds.inputs.timestamps[-1], 500 * 0.1)
    np.testing.assert_array_equal(ds.inputs.x0, ds.truth.poses_xyt[0])
    assert ds.inputs.max_range == 8.0
    md = ds.metadata
    assert md["seed"] == 9 and md["scenario"] == "loop"
    cfg = config_from_dict(md["config"])
    assert cfg == resolve_scenario("loop", {"sensor.range_std": 0.2})
    import json

    json.dumps(md)  # metadata is JSON-serialisable


def test_config_errors_are_one_line_and_helpful():
    with pytest.raises(ConfigError, match=r"unknown key 'sensor\.nope'; did you mean .*\(known: dt, n_steps, world\.layout"):
        resolve_scenario("loop", {"sensor.nope": 1})
    with pytest.raises(ConfigError, match=r"unknown key 'bogus'"):
        resolve_scenario("loop", {"bogus": 1})
    with pytest.raises(ConfigError, match=r"sensor\.max_range: expected a number, got 'far'"):
        resolve_scenario("loop", {"sensor.max_range": "far"})
    with pytest.raises(ConfigError, match=r"n_steps: expected an integer"):
        resolve_scenario("loop", {"n_steps": "1.5"})
    with pytest.raises(ConfigError, match=r"detection_prob must be in \[0, 1\]"):
        resolve_scenario("loop", {"sensor.detection_prob": 1.5})
    with pytest.raises(ConfigError, match=r"sensor\.kind: 'sonar' is not one of point, laser"):
        resolve_scenario("loop", {"sensor.kind": "sonar"})
    with pytest.raises(ConfigError, match=r"unknown scenario 'nope'; known: loop, paper-sim1"):
        resolve_scenario("nope", {})
    for exc_msg in ("unknown key", "expected a number"):
        try:
            resolve_scenario("loop", {"sensor.x": 1} if exc_msg == "unknown key" else {"dt": "x"})
        except ConfigError as exc:
            assert "\n" not in str(exc)
    assert "sensor.max_range" in known_keys() and "robot.actuation_std" in known_keys()


def test_overrides_typed_and_config_roundtrip():
    cfg = resolve_scenario("loop", {"sensor.max_range": "10", "robot.actuation_std": "0.1,0.2", "dt": 0.05,
                                    "sensor.report_ids": "true"})
    assert cfg.sensor.max_range == 10.0 and cfg.robot.actuation_std == (0.1, 0.2)
    assert cfg.dt == 0.05 and cfg.sensor.report_ids is True
    assert config_from_dict(config_to_dict(cfg)) == cfg
    assert resolve_scenario("loop", {}) == resolve_scenario("loop")


def test_random_layout_respects_clearance_and_separation():
    cfg = resolve_scenario("loop")
    wp = world.make_waypoints(cfg.path, stream("world", 0))
    lm = world.make_landmarks(cfg.world, wp, True, stream("world", 0))
    assert lm.shape == (12, 2)
    d = np.hypot(*(lm[:, None] - lm[None]).transpose(2, 0, 1))
    assert np.min(d[np.triu_indices(12, 1)]) >= 2.0
    assert np.min(world._dist_to_polyline(lm, wp, True)) >= 1.0


def test_fixed_world_seed_keeps_map_and_path_across_run_seeds():
    ov = {"world.seed": 11, "path.jitter": 0.5}
    a = simulate_scenario("loop", seed=1, overrides=ov)
    b = simulate_scenario("loop", seed=2, overrides=ov)
    np.testing.assert_array_equal(a.truth.landmarks_xy, b.truth.landmarks_xy)
    assert not np.array_equal(a.truth.poses_xyt, b.truth.poses_xyt)  # motion noise still differs
    assert a.metadata["world_seed"] == b.metadata["world_seed"] == 11
    c = simulate_scenario("loop", seed=11, overrides={"path.jitter": 0.5})
    np.testing.assert_array_equal(a.truth.landmarks_xy, c.truth.landmarks_xy)
    with pytest.raises(ConfigError, match="seed"):
        simulate(resolve_scenario("loop"), seed=-1)


@pytest.mark.slow
def test_progress_callback_reports_during_long_runs():
    calls = []
    simulate(resolve_scenario("loop", {"n_steps": 45_000}), seed=0, progress=lambda d, t: calls.append((d, t)))
    assert calls == [(0, 45_000), (20_000, 45_000), (40_000, 45_000), (45_000, 45_000)]


def test_scan_period_and_laser_report_ids():
    ds = simulate_scenario("loop", seed=1, overrides={"sensor.period_steps": 5, "clutter.rate": 1.0})
    o = ds.inputs.observations
    assert np.all(o.step % 5 == 0) and len(np.unique(o.step)) > 50
    assert np.all(np.diff(o.offsets)[np.arange(501) % 5 != 0] == 0)
    las = simulate_scenario("loop", seed=1, overrides={"sensor.kind": "laser", "sensor.report_ids": True,
                                                       "world.landmark_radius": 0.3, "clutter.rate": 2.0})
    np.testing.assert_array_equal(las.inputs.observations.reported_id, las.truth.obs_landmark)
    assert np.sum(las.truth.obs_landmark >= 0) > 1000
