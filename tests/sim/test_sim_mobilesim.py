"""The MobileSim-like robot base (acceleration limits) and the ``paper-sim1-mobilesim`` scenario of issue 12."""

from __future__ import annotations

import numpy as np
import pytest

from slamcli.models.motion import ddmr_step
from slamcli.sim import robot
from slamcli.sim.config import RobotConfig
from slamcli.sim.scenarios import resolve_scenario


def _drive(cfg, T=400, dt=0.1, seed=0):
    wp = np.array([[0.0, 0.0], [5.0, 0.0], [5.0, 5.0], [0.0, 5.0]])
    noise = np.random.default_rng(seed).normal(0, 0.01, (T, 2))
    x0 = robot.start_pose(cfg, wp)
    return robot.drive(cfg, wp, True, x0, T, dt, noise), noise


def test_acceleration_limits_bound_the_executed_velocity_changes():
    dt = 0.1
    cfg = RobotConfig(v_max=1.0, w_max=1.0, accel_max=(0.3, 1.74), decel_max=(0.6, 1.74), actuation_std=(0.0, 0.0))
    (controls, executed, poses, _), _ = _drive(cfg, dt=dt)
    np.testing.assert_allclose(ddmr_step(poses[:-1], executed, dt), poses[1:], atol=1e-9)
    prev = np.vstack([[0.0, 0.0], executed[:-1]])
    dv = np.diff(np.vstack([[0.0, 0.0], executed]), axis=0)
    speeding = np.abs(executed) > np.abs(prev)
    assert np.all(np.abs(dv[:, 0][speeding[:, 0]]) <= 0.3 * dt + 1e-12)
    assert np.all(np.abs(dv[:, 0][~speeding[:, 0]]) <= 0.6 * dt + 1e-12)
    assert np.all(np.abs(dv[:, 1]) <= 1.74 * dt + 1e-12)
    assert executed[0, 0] == pytest.approx(min(controls[0, 0], 0.03))  # from rest: at most a·dt after one step
    lag = np.abs(controls - executed).max(axis=0)
    assert lag[0] > 0.1 and lag[1] > 0.1  # the motion really lags the command


def test_no_limits_executes_command_plus_noise_bit_identically():
    cfg = RobotConfig(v_max=1.0, w_max=1.0)
    (controls, executed, poses, _), noise = _drive(cfg)
    np.testing.assert_array_equal(executed, controls + noise)


def test_mobilesim_scenario_has_the_documented_values():
    c = resolve_scenario("paper-sim1-mobilesim")
    base = resolve_scenario("paper-sim1")
    assert c.robot.accel_max == (0.3, 1.74) and c.robot.decel_max == (0.6, 1.74)
    assert c.odometry.scale_bias == 0.0075 and c.odometry.turn_bias == 0.0075
    assert c.sensor.range_std == pytest.approx(0.005 / np.sqrt(3)) and c.sensor.bearing_std == pytest.approx(
        0.0007 / np.sqrt(3))
    assert c.sensor.n_beams == 181 and c.sensor.fov_deg == 180.0 and c.sensor.max_range == 32.0
    assert c.world == base.world and c.path == base.path and c.robot.v_max == base.robot.v_max
