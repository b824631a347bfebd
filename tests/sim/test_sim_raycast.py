"""Ray caster (sim/raycast.py) against hand-computed ranges, and the disc laser as its special case."""

import math

import numpy as np
import pytest

from slamcli.sim import raycast, sensors
from slamcli.sim.config import ClutterConfig, SensorConfig


def _cast1(angle, segs=None, discs=None, radius=0.0, origin=(0.0, 0.0), max_range=40.0):
    r, hit = raycast.cast(np.array([origin]), np.array([angle]), max_range, segs, discs, radius)
    return float(r[0]), int(hit[0])


def test_wall_at_known_angles():
    wall = np.array([[5.0, -10.0, 5.0, 10.0]])  # the line x = 5 for |y| <= 10
    assert _cast1(0.0, wall) == (pytest.approx(5.0), 0)
    assert _cast1(math.radians(30), wall)[0] == pytest.approx(5.0 / math.cos(math.radians(30)))
    # 60°: meets x = 5 at y = 5 tan 60° = 8.66 (on the wall) → r = 10
    assert _cast1(math.radians(60), wall)[0] == pytest.approx(10.0)
    # 70°: y = 13.7 is past the wall's end → no hit → max range, hit −1
    assert _cast1(math.radians(70), wall) == (40.0, -1)
    # behind the origin: no hit
    assert _cast1(math.pi, wall) == (40.0, -1)
    # a tilted wall: the line x + y = 6 (segment (6,0)-(0,6)); the beam at 0° meets it at x = 6
    tilted = np.array([[6.0, 0.0, 0.0, 6.0]])
    assert _cast1(0.0, tilted)[0] == pytest.approx(6.0)
    # at 45° it meets it at (3, 3): r = 3√2
    assert _cast1(math.pi / 4, tilted)[0] == pytest.approx(3 * math.sqrt(2))


def test_corner_and_nearest_wall():
    corner = np.array([[5.0, -5.0, 5.0, 5.0], [5.0, 5.0, -5.0, 5.0]])  # two walls meeting at (5, 5)
    r, hit = _cast1(math.pi / 4, corner)
    assert r == pytest.approx(5 * math.sqrt(2))
    assert hit in (0, 1)
    # two parallel walls: the nearer one wins whatever the order
    walls = np.array([[9.0, -1.0, 9.0, 1.0], [4.0, -1.0, 4.0, 1.0]])
    assert _cast1(0.0, walls) == (pytest.approx(4.0), 1)


def test_grazing_rays():
    wall = np.array([[1.0, 0.0, 100.0, 0.0]])  # the line y = 0 for x in [1, 100]
    # collinear with the wall: parallel to it, no crossing → passes (max range)
    assert _cast1(0.0, wall, origin=(0.0, 0.0), max_range=200.0) == (200.0, -1)
    # a beam 0.01 rad off a wall 1 m away meets it at r = 1 / sin(0.01)
    wall2 = np.array([[0.0, 1.0, 150.0, 1.0]])
    assert _cast1(0.01, wall2, max_range=200.0)[0] == pytest.approx(1.0 / math.sin(0.01), rel=1e-12)
    # ... which is beyond a 40 m max range
    assert _cast1(0.01, wall2)[0] == 40.0
    # touching the end point of a segment exactly counts as a hit (s = 1)
    assert _cast1(0.0, np.array([[3.0, -2.0, 3.0, 0.0]]))[0] == pytest.approx(3.0)


def test_discs_and_walls_together():
    disc = np.array([[10.0, 0.0]])
    assert _cast1(0.0, discs=disc, radius=1.0) == (pytest.approx(9.0), -2)
    # a beam through the disc off centre by 0.6 m: t = d cos δ − sqrt(R² − d² sin² δ)
    d, rho, delta = 10.0, 1.0, math.asin(0.06)
    assert _cast1(delta, discs=disc, radius=rho)[0] == pytest.approx(d * math.cos(delta) - math.sqrt(rho**2 - (d * math.sin(delta)) ** 2))
    wall = np.array([[5.0, -1.0, 5.0, 1.0]])
    assert _cast1(0.0, wall, disc, 1.0) == (pytest.approx(5.0), 0)  # the wall occludes the disc


def test_disc_laser_is_the_casters_special_case():
    rng = np.random.default_rng(3)
    lms = rng.uniform(-15, 15, (25, 2))
    poses = np.column_stack([rng.uniform(-5, 5, 6), rng.uniform(-5, 5, 6), rng.uniform(-3, 3, 6)])
    cfg = SensorConfig(kind="laser", max_range=20.0, min_range=0.0, fov_deg=180.0, n_beams=181, range_std=0.0,
                       bearing_std=0.0, detection_prob=1.0, drop_max_range=False, drop_isolated=False)
    ret = sensors.laser_scans(poses, lms, 0.3, np.arange(6), cfg, ClutterConfig(0.0), np.random.default_rng(0),
                              np.random.default_rng(1))
    alphas, _ = sensors.beam_angles(cfg)
    r, hit = raycast.scan(poses, alphas, 20.0, 0.0, 0.0, np.random.default_rng(0), None, lms, 0.3)
    # same table: per step the beams in bearing order; the disc laser's landmark id = −2 − caster hit id
    got = r.reshape(-1)
    assert len(ret.range_m) == got.size
    np.testing.assert_allclose(ret.range_m, got, atol=1e-9)
    lm = np.where(hit.reshape(-1) <= -2, -2 - hit.reshape(-1), -1)
    np.testing.assert_array_equal(ret.landmark, lm)
