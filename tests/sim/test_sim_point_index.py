"""The point sensor's KD-tree visibility query returns exactly what the all-pairs query returned (issue 17)."""

from __future__ import annotations

import numpy as np
import pytest

from slamcli.sim import sensors, simulate_scenario


def _all_pairs(self, poses_xyt, r_min, r_max):
    """The previous implementation: every scan × landmark pair (``sensors._candidates``)."""
    return sensors._candidates(poses_xyt, self.landmarks_xy, r_min, r_max)


def test_candidates_equal_all_pairs_including_borderline_ranges():
    rng = np.random.default_rng(0)
    poses = np.c_[rng.uniform(0, 50, (300, 2)), rng.uniform(-np.pi, np.pi, 300)]
    lm = rng.uniform(-10, 60, (400, 2))
    r_min, r_max = 0.7, 8.0
    # landmarks exactly at r_min and r_max from some poses (and one ulp either side)
    ang = rng.uniform(-np.pi, np.pi, 40)
    for k, r in enumerate((r_min, r_max)):
        for eps in (-1e-12, 0.0, 1e-12):
            p = poses[k * 13 : k * 13 + 40, :2]
            lm = np.r_[lm, p + (r + eps) * np.c_[np.cos(ang), np.sin(ang)]]
    index = sensors._LandmarkIndex(lm, r_max)
    got = index.candidates(poses, r_min, r_max)
    ref = sensors._candidates(poses, lm, r_min, r_max)
    assert len(ref[0]) > 1000
    for g, r in zip(got, ref):
        assert g.dtype == r.dtype
        np.testing.assert_array_equal(g, r)


@pytest.mark.parametrize(
    "scenario,seed,overrides",
    [
        ("loop", 0, {}),
        ("loop", 7, {"sensor.report_ids": True, "sensor.fov_deg": 360.0, "sensor.detection_prob": 0.9,
                     "clutter.rate": 0.5}),
        ("paper-sim1", 3, {"sensor.kind": "point", "n_steps": 600, "sensor.max_range": 12.0, "sensor.min_range": 2.0}),
    ],
)
def test_simulated_point_sensor_is_byte_identical_to_all_pairs(monkeypatch, scenario, seed, overrides):
    new = simulate_scenario(scenario, seed=seed, overrides=overrides)
    monkeypatch.setattr(sensors._LandmarkIndex, "candidates", _all_pairs)
    old = simulate_scenario(scenario, seed=seed, overrides=overrides)
    a, b = new.inputs.observations, old.inputs.observations
    assert len(a) > 100
    for name in ("step", "range_m", "bearing_rad", "sensor", "reported_id", "offsets"):
        x, y = getattr(a, name), getattr(b, name)
        assert x.dtype == y.dtype and x.tobytes() == y.tobytes(), name
    assert new.truth.obs_landmark.tobytes() == old.truth.obs_landmark.tobytes()
    assert new.truth.poses_xyt.tobytes() == old.truth.poses_xyt.tobytes()
