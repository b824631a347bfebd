"""A tiny, fully deterministic SLAM world built directly from ``slamcli.models`` (no simulator needed).

Used by the io, solve, CLI and solver-contract tests. A robot drives an arc at 1 m/s while a point
range-bearing sensor sees landmarks within ``max_range``; a few clutter returns (truth label -1) are added.
"""

from __future__ import annotations

import numpy as np

from slamcli.models import motion, observation
from slamcli.types import Dataset, GroundTruth, NoiseSpec, Observations, SlamInputs


def tiny_dataset(
    T: int = 40,
    n_landmarks: int = 6,
    seed: int = 0,
    *,
    clutter_every: int = 7,
    report_ids: bool = False,
    gps_every: int = 0,
    max_range: float = 6.0,
) -> Dataset:
    rng = np.random.default_rng(seed)
    dt = 0.1
    x0 = np.array([0.0, 0.0, 0.0])
    controls = np.column_stack([np.full(T, 1.0), np.full(T, 0.25)])
    motion_std = np.array([0.02, 0.01])
    executed = controls + rng.normal(0.0, 1.0, controls.shape) * motion_std
    truth_poses = motion.integrate(x0, executed, dt)
    odo_std = np.array([0.005, 0.005, 0.002])
    inc = motion.odometry_increments(truth_poses) + rng.normal(0.0, 1.0, (T, 3)) * odo_std
    odometry = motion.chain_increments(x0, inc)
    # landmarks scattered around the driven arc
    ang = np.linspace(0.0, 2 * np.pi, n_landmarks, endpoint=False)
    landmarks = np.column_stack([2.0 + 3.0 * np.cos(ang), 1.0 + 3.0 * np.sin(ang)])
    range_std, bearing_std = 0.05, 0.01
    steps, z_rows, labels = [], [], []
    for t in range(T + 1):
        z = observation.range_bearing(truth_poses[t], landmarks)
        for j in np.flatnonzero(z[:, 0] <= max_range):
            zn = z[j] + rng.normal(0.0, 1.0, 2) * [range_std, bearing_std]
            steps.append(t)
            z_rows.append(zn)
            labels.append(j)
        if clutter_every and t % clutter_every == 3:
            steps.append(t)
            z_rows.append([rng.uniform(0.5, max_range), rng.uniform(-np.pi, np.pi)])
            labels.append(-1)
    labels_arr = np.asarray(labels, np.int64)
    obs = Observations.from_rows(
        steps, z_rows, T + 1, reported_id=labels_arr if report_ids else None
    )
    if gps_every:
        gps_step = np.arange(0, T + 1, gps_every, dtype=np.int64)
        gps_xy = truth_poses[gps_step, :2] + rng.normal(0.0, 0.3, (len(gps_step), 2))
    else:
        gps_step, gps_xy = np.zeros(0, np.int64), np.zeros((0, 2))
    inputs = SlamInputs(
        dt=dt,
        timestamps=np.arange(T + 1) * dt,
        x0=x0,
        controls=controls,
        odometry_xyt=odometry,
        observations=obs,
        noise=NoiseSpec(motion_std=motion_std, odometry_std=odo_std, range_std=range_std, bearing_std=bearing_std),
        max_range=max_range,
        gps_step=gps_step,
        gps_xy=gps_xy,
        gps_std=0.3 if gps_every else 0.0,
    )
    truth = GroundTruth(poses_xyt=truth_poses, landmarks_xy=landmarks, obs_landmark=labels_arr)
    metadata = {
        "seed": seed,
        "scenario": "tiny-test",
        "scenario_params": {"T": T, "n_landmarks": n_landmarks, "max_range": max_range},
        "sensor": {"kind": "point", "range_std": range_std, "bearing_std": bearing_std},
        "robot": {"v": 1.0, "omega": 0.25},
    }
    return Dataset(inputs=inputs, truth=truth, metadata=metadata)
