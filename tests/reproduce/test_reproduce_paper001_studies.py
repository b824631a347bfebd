"""The data-association faults of the wall world (clutter, wrong ids) and the helpers of paper 001's claim
studies, against counts, binomial/Poisson bounds and closed forms."""

from __future__ import annotations

import numpy as np
import pytest

from slamcli.reproduce.paper001_studies import gamma_at_laps, gamma_from_median
from slamcli.sim.simulate import simulate_scenario
from slamcli.sim.wallworld import wrong_ids
from slamcli.solvers.hybrid import HybridParams, HybridSlam

SMALL = {"walls.width": 40, "walls.height": 40, "walls.corridor": 8, "walls.resolution": 1.0,
         "sensor.n_beams": 20, "walls.laps": 1}


def test_wrong_ids_rate_never_own_id_and_clutter_kept():
    rng = np.random.default_rng(3)
    lm = rng.integers(0, 16, 20_000)
    lm[::10] = -1  # clutter rows
    out = wrong_ids(lm, 16, 0.05, np.random.default_rng(4))
    true_rows = lm >= 0
    assert np.array_equal(out[~true_rows], lm[~true_rows])
    flipped = out[true_rows] != lm[true_rows]
    n = true_rows.sum()
    assert abs(flipped.sum() - 0.05 * n) < 5 * np.sqrt(n * 0.05 * 0.95)  # binomial, 5σ
    assert out.min() >= -1 and out.max() < 16
    # with no fault rate nothing changes and nothing is drawn (the stream stays where it was)
    g = np.random.default_rng(5)
    assert np.array_equal(wrong_ids(lm, 16, 0.0, g), lm)
    assert g.random() == np.random.default_rng(5).random()


def _feature_rows(ds):
    o = ds.inputs.observations
    f = np.asarray(o.sensor) == 0
    return o.step[f], o.range_m[f], o.bearing_rad[f], o.reported_id[f], ds.truth.obs_landmark[f]


def test_simulated_faults_change_only_what_they_say():
    clean = _feature_rows(simulate_scenario("hybrid-map1", 2, SMALL))
    wrong = _feature_rows(simulate_scenario("hybrid-map1", 2, {**SMALL, "walls.wrong_id_prob": 0.2}))
    for a, b in zip(clean[:3] + clean[4:], wrong[:3] + wrong[4:]):  # steps, ranges, bearings, truth: unchanged
        assert np.array_equal(a, b)
    diff = wrong[3] != wrong[4]
    n = len(diff)
    assert abs(diff.sum() - 0.2 * n) < 5 * np.sqrt(n * 0.2 * 0.8) and np.array_equal(clean[3], clean[4])
    ds_c = simulate_scenario("hybrid-map1", 2, {**SMALL, "clutter.rate": 1.5})
    cl = _feature_rows(ds_c)
    false = cl[4] < 0
    n_steps = ds_c.inputs.n_poses
    assert abs(false.sum() - 1.5 * n_steps) < 5 * np.sqrt(1.5 * n_steps)  # Poisson, 5σ
    assert np.all(cl[3][false] == -1)  # the sensor reports no id for a false return
    for a, b in zip(clean, cl):  # the true rows are those of the clean run
        assert np.array_equal(a, b[~false])
    assert np.all((cl[1][false] >= 0.1) & (cl[1][false] <= 40.0))


def test_ekf_part_does_not_see_the_scan():
    """The NEES Monte-Carlo simulates 2 beams: the EKF's output equals the full-scan run's."""
    p = HybridParams()
    a = simulate_scenario("hybrid-map1-noisy", 7, {**SMALL, "sensor.n_beams": 60})
    b = simulate_scenario("hybrid-map1-noisy", 7, {**SMALL, "sensor.n_beams": 2})
    ra = HybridSlam(p).bayesian_part(a.inputs, np.random.default_rng(0))
    rb = HybridSlam(p).bayesian_part(b.inputs, np.random.default_rng(0))
    assert np.array_equal(ra.poses_xyt, rb.poses_xyt) and np.array_equal(ra.pose_cov, rb.pose_cov)


def test_gamma_at_laps_closed_form():
    clock = np.array([0.0, 100.0, 100.0, 100.0])  # the never-updated cell is left out of the median
    assert gamma_at_laps(clock, 2, 0.5, 0.6) == pytest.approx([0.5 * 50 ** -0.6, 0.5 * 100 ** -0.6])
    assert gamma_at_laps(np.zeros(3), 2, 0.5, 0.6) == []


@pytest.mark.slow
def test_mapping_from_given_poses_snapshots_at_lap_ends_and_walls_occupied():
    """The laser (σ_r = 1 cm) mapped from the dataset's odometry poses (``map_poses = "odometry"``), the odometry
    noise-free so that they are the true poses: snapshots at the lap ends asked for; cells holding a wall end up
    occupied (P > 0.5) and the free corridor cells the beams cross empty (P < 0.5), the truth read by this test
    only."""
    ds = simulate_scenario("hybrid-map1", 1, {**SMALL, "sensor.n_beams": 60, "walls.laps": 2,
                                              "odometry.std": [0.0, 0.0, 0.0]})
    assert np.abs(ds.inputs.odometry_xyt - ds.truth.poses_xyt).max() < 1e-9
    laps = tuple(int(k) for k in ds.truth.lap_end_step)
    p = HybridParams(resolution=1.0, map_poses="odometry", snapshot_steps=laps, baseline=False)
    res = HybridSlam(p).solve(ds.inputs, rng=np.random.default_rng(0))
    grid = res.grids["frequentist"]
    assert "logodds" not in res.grids and np.array_equal(grid.snapshot_step, laps)
    count = grid.observed.ravel()
    tr = ds.truth.occupancy
    # the estimate's cell centres, looked up in the truth grid (same 1 m cells, maybe shifted origin)
    H, W = grid.prob.shape
    ij = np.argwhere(count.reshape(H, W) > 20)
    xy = grid.origin_xy + (ij[:, ::-1] + 0.5) * grid.resolution
    tij = np.floor((xy - tr.origin_xy) / tr.resolution).astype(int)
    ok = (tij >= 0).all(axis=1) & (tij[:, 1] < tr.prob.shape[0]) & (tij[:, 0] < tr.prob.shape[1])
    truth = tr.prob[tij[ok, 1], tij[ok, 0]] > 0.5
    est = grid.prob[ij[ok, 0], ij[ok, 1]] > 0.5
    assert truth.sum() > 50 and (~truth).sum() > 200
    assert np.mean(est[truth]) > 0.9 and np.mean(~est[~truth]) > 0.97


def test_gamma_from_median_is_gamma_at_laps_of_the_clock():
    clock = np.array([0.0, 30.0, 100.0, 300.0])  # median of the updated cells: 100
    assert gamma_from_median(100.0, 2, 0.5, 0.6) == pytest.approx([0.5 * 50 ** -0.6, 0.5 * 100 ** -0.6])
    assert gamma_at_laps(clock, 2, 0.5, 0.6) == gamma_from_median(100.0, 2, 0.5, 0.6)
    assert gamma_from_median(None, 2, 0.5, 0.6) == []


@pytest.mark.slow
def test_mapping_false_is_the_bayesian_part_and_mean_mode_maps_the_ekf_mean():
    """``mapping = false`` returns the EKF part alone (no grids); ``map_poses = "mean"`` maps from the EKF mean,
    the same grid as ``map_poses = "odometry"`` on inputs whose odometry is replaced by that mean."""
    import dataclasses

    ds = simulate_scenario("hybrid-map1-noisy", 3, {**SMALL, "sensor.n_beams": 20})
    ekf = HybridSlam(HybridParams()).bayesian_part(ds.inputs, np.random.default_rng(0))
    only = HybridSlam(HybridParams(mapping=False)).solve(ds.inputs, rng=np.random.default_rng(0))
    assert not only.grids and np.array_equal(only.poses_xyt, ekf.poses_xyt)
    assert np.array_equal(only.pose_cov, ekf.pose_cov) and "mapping = false" in only.message
    common = {"resolution": 1.0, "baseline": False, "snapshot_steps": (40, int(ds.inputs.n_poses - 1))}
    mean = HybridSlam(HybridParams(map_poses="mean", **common)).solve(ds.inputs, rng=np.random.default_rng(0))
    given = dataclasses.replace(ds.inputs, odometry_xyt=ekf.poses_xyt)
    odo = HybridSlam(HybridParams(map_poses="odometry", **common)).solve(given, rng=np.random.default_rng(1))
    g1, g2 = mean.grids["frequentist"], odo.grids["frequentist"]
    assert np.array_equal(g1.snapshots, g2.snapshots) and np.array_equal(g1.observed, g2.observed)
    belief = HybridSlam(HybridParams(**common)).solve(ds.inputs, rng=np.random.default_rng(0))
    assert not np.array_equal(belief.grids["frequentist"].prob, g1.prob)  # the sigma points spread the scans
    assert mean.extra["clock_median"] > 0
