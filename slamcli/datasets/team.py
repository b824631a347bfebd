"""Multi-robot datasets (:class:`slamcli.types.RobotTeam`): one robot's solo problem, and the shared refusal.

A multi-robot dataset stacks the poses of ``R`` robots robot-major on one time grid (see ``RobotTeam``).
:func:`solo_dataset` cuts robot ``r`` out of it (:func:`slamcli.types.solo_inputs`, which solvers use too) as
an ordinary single-robot dataset — its own poses, controls, odometry and landmark observations, its start pose
as ``x0``, its slice of the truth — so "solo" and "joint" solves of the same robot see exactly the same data,
except the other robots' readings and sightings.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from slamcli.types import Dataset, GroundTruth, SlamInputs, robot_slice, solo_inputs


def solo_dataset(dataset: Dataset, robot: int) -> Dataset:
    """:func:`solo_inputs` plus that robot's slice of the truth and metadata, as a single-robot dataset.

    Landmark indices are kept (the solo truth has all ``L`` landmarks; one robot may see only some).
    """
    inp = dataset.inputs
    a, b, rows = robot_slice(inp, robot)
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
