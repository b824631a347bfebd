"""Solvers on a synthetic car world (Ackermann controls, laser mounted at (3.78, 0.50) m): ekf and graph recover
the true poses and landmarks with known identities, agree with each other, and ignoring the mounting offset
fails visibly; the EKF predict is exactly the car model of the laser point."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from conftest import car_world

from slamcli.api.solve import solve_dataset
from slamcli.errors import SolverError
from slamcli.metrics.reference import trajectory_against
from slamcli.models.ackermann import VICTORIA_PARK, VICTORIA_PARK_LASER_XY, integrate_ackermann
from slamcli.models.observation import body_pose_from_sensor, sensor_pose
from slamcli.types import Observations

OFF = np.array(VICTORIA_PARK_LASER_XY)


@pytest.fixture(scope="module")
def world():
    return car_world()


def _errors(res, ds):
    pos = np.linalg.norm(res.poses_xyt[:, :2] - ds.truth.poses_xyt[:, :2], axis=1)
    lm_ids = np.unique(ds.truth.obs_landmark)
    est = np.array([res.landmarks_xy[np.bincount(res.assoc[ds.truth.obs_landmark == j][res.assoc[ds.truth.obs_landmark == j] >= 0]).argmax()] for j in lm_ids])
    return np.sqrt(np.mean(pos**2)), np.linalg.norm(est - ds.truth.landmarks_xy[lm_ids], axis=1).max()


def test_ekf_predict_is_the_car_model_of_the_laser_point(world):
    inp = dataclasses.replace(world.inputs, observations=Observations.from_rows([], np.zeros((0, 2)), world.inputs.n_poses))
    res = solve_dataset(inp, "ekf", {"association": "known"})
    laser = integrate_ackermann(sensor_pose(inp.x0, OFF), inp.controls, inp.dt,
                                dataclasses.replace(VICTORIA_PARK, ref_x_m=OFF[0], ref_y_m=OFF[1]))
    np.testing.assert_allclose(res.poses_xyt, body_pose_from_sensor(laser, OFF), atol=1e-9)
    # the laser-point Euler recursion and the rear-axle one describe the same car motion up to the O(dt)
    # discretisation: 4 cm after 60 m here
    assert np.abs(res.poses_xyt[:, :2] - inp.odometry_xyt[:, :2]).max() < 0.1
    assert np.all(np.diff(res.pose_cov[:, 0, 0] + res.pose_cov[:, 1, 1]) >= -1e-12)  # no update: grows


def test_ekf_and_graph_recover_the_car_world_and_agree(world):
    ekf = solve_dataset(world.inputs, "ekf", {"association": "known"})
    graph = solve_dataset(world.inputs, "graph", {"association": "reported"})
    odo = solve_dataset(world.inputs, "odometry", {})
    e_ate, e_lm = _errors(ekf, world)
    g_ate, g_lm = _errors(graph, world)
    o_ate, _ = _errors(odo, world)
    assert e_ate < 0.06 and g_ate < 0.06 and e_lm < 0.12 and g_lm < 0.12, (e_ate, g_ate, e_lm, g_lm)
    assert e_ate < o_ate and g_ate < o_ate
    ag = trajectory_against(ekf.poses_xyt, graph.poses_xyt, ekf.landmarks_xy, graph.landmarks_xy, cutoff_m=1.0)
    assert ag["against_ate_rmse_m"] < 0.25 and ag["against_lm_matched"] == len(graph.landmarks_xy)
    # ignoring the 3.8 m laser offset maps the same rows far from the truth
    wrong = dataclasses.replace(world.inputs, sensor_offset_xy=np.zeros(2))
    _, w_lm = _errors(solve_dataset(wrong, "graph", {"association": "reported"}), world)
    assert w_lm > 2.0


def test_unsupported_solver_refuses_in_one_line(world):
    with pytest.raises(SolverError, match="supports the motion model"):
        solve_dataset(world.inputs, "hybrid", {})


@pytest.mark.parametrize("version", [1, 2])
def test_fastslam_car_model(world, version):
    """FastSLAM 1.0 (sampled car model) and 2.0 (linearised car model) reach the EKF's accuracy class."""
    res = solve_dataset(world.inputs, "fastslam", {"association": "known", "version": version, "n_particles": 30},
                        seed=3)
    ate, lm = _errors(res, world)
    odo_ate, _ = _errors(solve_dataset(world.inputs, "odometry", {}), world)
    assert ate < 0.07 and lm < 0.15, (ate, lm)
    assert ate < 2 * odo_ate
