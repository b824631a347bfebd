"""Multi-beam laser hitting landmark discs, its preprocessing (paper 000 §5), and the paper scenarios."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from slamcli.models.observation import inverse_range_bearing
from slamcli.sim import (
    ClutterConfig,
    SensorConfig,
    resolve_scenario,
    sensors,
    simulate,
    simulate_scenario,
    world,
)

R = 0.15
LASER = SensorConfig(kind="laser", max_range=30.0, min_range=0.1, fov_deg=180.0, n_beams=181, range_std=0.0,
                     bearing_std=0.0, detection_prob=1.0, drop_max_range=True, drop_isolated=True)
NO_CLUTTER = ClutterConfig(rate=0.0)


def _scan(landmarks, sensor=LASER, clutter=NO_CLUTTER, pose=(0.0, 0.0, 0.0), n_scans=1, seed=0):
    poses = np.tile(np.asarray(pose, float), (n_scans, 1))
    return sensors.laser_scans(
        poses, np.asarray(landmarks, float).reshape(-1, 2), R, np.arange(n_scans), sensor, clutter,
        np.random.default_rng([3, seed]), np.random.default_rng([4, seed]),
    )


def test_disc_at_moderate_range_gives_adjacent_returns_on_its_surface():
    m = np.array([5.0, 0.0])
    r = _scan([m])
    # the disc subtends ±asin(0.15/5) = ±1.72°: beams at -1°, 0°, +1°
    assert len(r.step) == 3
    np.testing.assert_allclose(np.degrees(r.bearing_rad), [-1.0, 0.0, 1.0], atol=1e-9)
    hits = inverse_range_bearing(np.zeros(3), np.column_stack([r.range_m, r.bearing_rad]))
    np.testing.assert_allclose(np.hypot(*(hits - m).T), R, atol=1e-9)  # every return lies on the disc surface
    np.testing.assert_allclose(r.range_m[1], 5.0 - R, atol=1e-12)
    np.testing.assert_array_equal(r.landmark, 0)
    # rotated robot and rotated landmark: same ranges
    th = 0.7
    r2 = _scan([[5 * np.cos(th + np.radians(30)), 5 * np.sin(th + np.radians(30))]], pose=(0, 0, th))
    np.testing.assert_allclose(np.degrees(r2.bearing_rad), [29.0, 30.0, 31.0], atol=1e-6)
    np.testing.assert_allclose(r2.range_m, r.range_m, atol=1e-9)


@pytest.mark.parametrize("m", [[35.0, 0.0], [30.2, 0.0], [-5.0, 0.0], [-3.0, -4.0]])
def test_no_returns_beyond_max_range_or_outside_fov(m):
    r = _scan([m], sensor=dataclasses.replace(LASER, drop_isolated=False))
    assert len(r.step) == 0


def test_fov_edge_and_all_round_scan():
    r = _scan([[0.0, 5.0]])  # bearing +90°, the last beam of a 180° scan
    np.testing.assert_allclose(np.degrees(r.bearing_rad), [89.0, 90.0], atol=1e-9)
    full = dataclasses.replace(LASER, fov_deg=360.0, n_beams=360)
    r = _scan([[-5.0, 0.0]], sensor=full)  # straight behind: beams at ±179° and -180° (wrap-around neighbours)
    assert sorted(np.round(np.degrees(r.bearing_rad)).tolist()) == [-180.0, -179.0, 179.0]
    hits = inverse_range_bearing(np.zeros(3), np.column_stack([r.range_m, r.bearing_rad]))
    np.testing.assert_allclose(np.hypot(*(hits - [-5.0, 0.0]).T), R, atol=1e-9)


def test_nearest_hit_per_beam_occludes():
    r = _scan([[5.0, 0.0], [8.0, 0.0], [8.0, 3.0]])
    assert set(r.landmark.tolist()) == {0, 2}  # landmark 1 is hidden behind landmark 0
    assert np.all(r.range_m[r.landmark == 0] < 5.0)


def test_drop_isolated_removes_single_beam_returns():
    # at 20 m the disc subtends ±0.43°: only the 0° beam hits, an isolated return
    keep = _scan([[20.0, 0.0]], sensor=dataclasses.replace(LASER, drop_isolated=False))
    assert len(keep.step) == 1 and keep.landmark[0] == 0
    assert len(_scan([[20.0, 0.0]]).step) == 0
    # a return is also isolated when its neighbours are at a very different range
    # (beams -1°, 0°, +1° on a disc at 5 m: the outer ones read 27.2 mm longer than the centre one)
    assert len(_scan([[5.0, 0.0]], sensor=dataclasses.replace(LASER, isolation_gap=0.027)).step) == 0
    assert len(_scan([[5.0, 0.0]], sensor=dataclasses.replace(LASER, isolation_gap=0.028)).step) == 3


def test_clutter_rows_are_minus_one_and_mostly_isolated():
    n = 400
    lm = [[5.0, 0.0], [6.0, 4.0]]
    raw = _scan(lm, sensor=dataclasses.replace(LASER, drop_isolated=False), clutter=ClutterConfig(rate=3.0),
                n_scans=n)
    clutter = raw.landmark < 0
    assert abs(clutter.sum() / n - 3.0) < 0.3  # a few clutter beams fall on occupied beams and lose
    assert np.all((raw.range_m[clutter] >= 0.1) & (raw.range_m[clutter] <= 30.0))
    filt = _scan(lm, clutter=ClutterConfig(rate=3.0), n_scans=n)
    assert np.sum(filt.landmark < 0) < 0.05 * clutter.sum()
    # true returns farther than any clutter are unaffected by preprocessing
    assert np.sum(filt.landmark >= 0) >= 0.9 * np.sum(raw.landmark >= 0)


def test_max_range_readings_kept_when_not_dropped():
    r = _scan([[5.0, 0.0]], sensor=dataclasses.replace(LASER, drop_max_range=False), n_scans=2)
    assert len(r.step) == 2 * 181
    empty = r.landmark < 0
    assert empty.sum() == 2 * 178
    np.testing.assert_array_equal(r.range_m[empty], 30.0)
    assert np.all(np.diff(r.step) >= 0)


def test_beam_dropout_and_range_noise_statistics():
    s = dataclasses.replace(LASER, detection_prob=0.8, range_std=0.02, drop_isolated=False)
    n = 3000
    r = _scan([[5.0, 0.0]], sensor=s, n_scans=n)
    assert abs(len(r.step) / (3 * n) - 0.8) < 0.02
    centre = np.abs(r.bearing_rad) < 1e-9
    assert abs(np.std(r.range_m[centre] - (5.0 - R)) / 0.02 - 1) < 0.1


def test_paper_scenarios_laser_consistency():
    cfg = resolve_scenario("paper-sim1", {"n_steps": 300, "sensor.range_std": 0, "clutter.rate": 0})
    assert cfg.dt == 0.1 and cfg.sensor.kind == "laser" and cfg.sensor.n_beams == 181
    ds = simulate(cfg, seed=2)
    o, t = ds.inputs.observations, ds.truth
    assert t.landmarks_xy.shape == (63, 2)
    assert t.landmarks_xy[:, 0].max() - t.landmarks_xy[:, 0].min() > 38
    assert np.all(t.obs_landmark >= 0) and len(o) > 1000
    rad = cfg.world.landmark_radius
    hits = inverse_range_bearing(t.poses_xyt[o.step], o.z)
    np.testing.assert_allclose(np.hypot(*(hits - t.landmarks_xy[t.obs_landmark]).T), rad, atol=1e-9)
    # each kept return has an adjacent-beam companion, as in the paper's preprocessing
    per_scan_lm = np.unique(np.column_stack([o.step, t.obs_landmark]), axis=0, return_counts=True)[1]
    assert per_scan_lm.min() >= 1 and np.mean(per_scan_lm >= 2) > 0.95
    assert ds.inputs.noise.range_std == pytest.approx(rad)  # hypot(0, R): surface returns, not centres
    sim2 = resolve_scenario("paper-sim2")
    assert sim2.sensor.max_range == 10.0 and resolve_scenario("paper-sim1").sensor.max_range == 30.0
    d2 = simulate(dataclasses.replace(cfg, sensor=dataclasses.replace(cfg.sensor, max_range=10.0)), seed=2)
    assert np.max(d2.inputs.observations.range_m) <= 10.0
    np.testing.assert_array_equal(d2.truth.poses_xyt, ds.truth.poses_xyt)


def test_octagon_geometry():
    cfg = resolve_scenario("octagon")
    assert cfg.dt == 0.1 and cfg.n_steps * cfg.dt == pytest.approx(183.0)
    lm = world.make_landmarks(cfg.world, np.zeros((2, 2)), True, np.random.default_rng(0))
    assert lm.shape == (11, 2)
    np.testing.assert_allclose(np.hypot(*lm[:8].T), 7.12, atol=1e-12)
    side = np.hypot(*(lm[:8] - np.roll(lm[:8], 1, axis=0)).T)
    np.testing.assert_allclose(side, 2 * 7.12 * np.sin(np.pi / 8), atol=1e-12)
    np.testing.assert_allclose(lm[8], [0.0, 0.0], atol=1e-12)
    ds = simulate_scenario("octagon", seed=0)
    np.testing.assert_array_equal(ds.truth.landmarks_xy, lm)
    seen = np.unique(ds.truth.obs_landmark[ds.truth.obs_landmark >= 0])
    assert len(seen) == 11
    # the robot circles outside the cones
    assert np.min(np.hypot(*ds.truth.poses_xyt[:, :2].T)) > 7.12 + 1.0
