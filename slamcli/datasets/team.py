"""Multi-robot datasets (:class:`slamcli.types.RobotTeam`): one robot's solo problem, and the shared refusal.

A multi-robot dataset stacks the poses of ``R`` robots robot-major on one time grid (see ``RobotTeam``).
:func:`solo_dataset` cuts robot ``r`` out of it as an ordinary single-robot dataset — its own poses, controls,
odometry and landmark observations, its start pose as ``x0``, its slice of the truth — so "solo" and "joint"
solves of the same robot see exactly the same data, except the other robots' readings and sightings.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from slamcli.types import Dataset, GroundTruth, Observations, SlamInputs


def _robot_slice(inputs: SlamInputs, robot: int) -> tuple[int, int, np.ndarray]:
    team = inputs.robots
    if team is None:
        raise ValueError("a multi-robot dataset is needed (inputs.robots is None)")
    if not 0 <= robot < team.n_robots:
        raise ValueError(f"robot index {robot} out of range 0..{team.n_robots - 1}")
    fp = team.first_pose
    a, b = int(fp[robot]), int(fp[robot + 1])
    obs = inputs.observations
    return a, b, np.arange(int(obs.offsets[a]), int(obs.offsets[b]))


def solo_inputs(inputs: SlamInputs, robot: int) -> SlamInputs:
    """Robot index ``robot`` (0-based, into ``inputs.robots.robot_number``) of a multi-robot problem, alone: its
    poses' timestamps, controls, odometry and landmark observations, its start pose as ``x0``, no robots group.
    Solvers use it for per-robot work (it never touches ground truth)."""
    a, b, rows = _robot_slice(inputs, robot)
    obs = inputs.observations
    solo_obs = Observations.from_rows(obs.step[rows] - a, obs.z[rows], b - a, reported_id=obs.reported_id[rows],
                                      sensor=obs.sensor[rows])
    return dataclasses.replace(
        inputs,
        timestamps=np.asarray(inputs.timestamps)[a:b].copy(),
        x0=np.asarray(inputs.robots.x0_xyt[robot], float).copy(),
        controls=np.asarray(inputs.controls)[a : b - 1].copy(),
        odometry_xyt=np.asarray(inputs.odometry_xyt)[a:b].copy(),
        observations=solo_obs,
        robots=None,
    )


def solo_dataset(dataset: Dataset, robot: int) -> Dataset:
    """:func:`solo_inputs` plus that robot's slice of the truth and metadata, as a single-robot dataset.

    Landmark indices are kept (the solo truth has all ``L`` landmarks; one robot may see only some).
    """
    inp = dataset.inputs
    a, b, rows = _robot_slice(inp, robot)
    inputs = solo_inputs(inp, robot)
    truth = dataset.truth
    if truth is not None:
        truth = GroundTruth(poses_xyt=np.asarray(truth.poses_xyt)[a:b].copy(),
                            landmarks_xy=np.asarray(truth.landmarks_xy).copy(),
                            obs_landmark=np.asarray(truth.obs_landmark)[rows].copy())
    meta = dict(dataset.metadata or {})
    number = int(inp.robots.robot_number[robot])
    meta["scenario"] = f"{meta.get('scenario', 'team')}:solo{number}"
    meta["solo_of_team"] = {"robot_index": int(robot), "robot_number": number, "stacked_poses": [a, b]}
    return Dataset(inputs=inputs, truth=truth, metadata=meta)


def without_robot_readings(inputs: SlamInputs) -> SlamInputs:
    """The same team with no inter-robot readings (the robots still share landmarks)."""
    team = inputs.robots
    if team is None:
        return inputs
    empty = np.zeros(0, np.int64)
    return dataclasses.replace(inputs, robots=dataclasses.replace(
        team, observer_pose=empty, observed_pose=empty.copy(), range_m=np.zeros(0), bearing_rad=np.zeros(0)))
