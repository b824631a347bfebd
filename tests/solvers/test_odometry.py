"""The ``odometry`` baseline against hand-computed and independent (model-chained) references."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from conftest import tiny_dataset

from slamcli.models import motion, observation, se2
from slamcli.solvers.odometry import (
    OdometryParams,
    OdometrySolver,
    compact,
    dead_reckoning,
    greedy_nearest_neighbour,
)
from slamcli.types import Observations, Status


def test_dead_reckoning_equals_chained_increments():
    ds = tiny_dataset(T=60)
    odo = ds.inputs.odometry_xyt
    ref = motion.chain_increments(ds.inputs.x0, motion.odometry_increments(odo))
    got = dead_reckoning(ds.inputs.x0, odo)
    np.testing.assert_allclose(got, ref, atol=1e-12)
    np.testing.assert_allclose(got, odo, atol=1e-12)  # odometry starts at x0 here


def test_dead_reckoning_reanchors_a_shifted_encoder_frame():
    ds = tiny_dataset(T=30)
    odo = ds.inputs.odometry_xyt
    shifted = se2.compose(np.array([10.0, -3.0, 2.0]), odo)  # same increments, other encoder frame
    np.testing.assert_allclose(dead_reckoning(ds.inputs.x0, shifted), odo, atol=1e-10)


def test_greedy_nn_hand_example():
    pts = np.array([[0.0, 0.0], [0.5, 0.0], [5.0, 5.0], [0.2, 0.1], [5.4, 5.0]])
    assert greedy_nearest_neighbour(pts, 1.0).tolist() == [0, 0, 1, 0, 1]
    # threshold 0.3: (0.5,0) is 0.5 from (0,0) -> new; (0.2,0.1) is 0.224 from label 0 and 0.316 from
    # label 1 -> 0; (5.4,5) is 0.4 from (5,5) -> new
    assert greedy_nearest_neighbour(pts, 0.3).tolist() == [0, 1, 2, 0, 3]
    # the running mean moves: after (0,0),(0.9,0) join (mean 0.45), (1.4,0) is 0.95 away -> joins
    assert greedy_nearest_neighbour(np.array([[0.0, 0], [0.9, 0], [1.4, 0]]), 1.0).tolist() == [0, 0, 0]


def test_greedy_nn_per_step_batches():
    pts = np.array([[0.0, 0.0], [0.5, 0.0], [6.0, 0.0], [1.2, 0.0], [6.5, 0.0], [5.8, 0.3]])
    steps = np.array([0, 0, 0, 1, 2, 2])
    # step 0: (0,0) new 0, (0.5,0) joins 0 within the step, (6,0) new 1; step 1: (1.2,0) is 0.95 from the
    # mean (0.25,0) -> 0; step 2: both rows match landmark 1 as it stood after step 1
    assert greedy_nearest_neighbour(pts, 1.0, steps=steps).tolist() == [0, 0, 1, 0, 1, 1]
    # one row per step is the purely sequential algorithm
    rng = np.random.default_rng(1)
    cloud = rng.uniform(0, 20, (300, 2))
    np.testing.assert_array_equal(greedy_nearest_neighbour(cloud, 1.5, steps=np.arange(300)),
                                  greedy_nearest_neighbour(cloud, 1.5))


def test_greedy_nn_seeded_labels_and_buffer_growth():
    pts = np.array([[0.0, 0.0], [10.0, 0.0], [0.1, 0.0], [9.9, 0.0]])
    seeded = np.array([7, 3, -1, -1])
    assert greedy_nearest_neighbour(pts, 0.5, seeded).tolist() == [7, 3, 7, 3]
    many = np.column_stack([np.arange(100) * 10.0, np.zeros(100)])  # 100 distinct landmarks > buffer 16
    assert greedy_nearest_neighbour(many, 1.0).tolist() == list(range(100))


def brute_force_greedy_nn(points, threshold, labels, steps):
    """The labelling rule written out row by row in plain Python floats (the reference for the vectorised
    solver): gate against the previous step's running means, then cluster the rest of the step in row order."""
    thr2 = threshold * threshold
    out = [int(v) for v in labels]
    sums: dict[int, list[float]] = {}
    for i, lab in enumerate(out):
        if lab >= 0:
            s = sums.setdefault(lab, [0.0, 0.0, 0.0])
            s[0] += points[i][0]
            s[1] += points[i][1]
            s[2] += 1.0
    next_id = max(out) + 1 if max(out, default=-1) >= 0 else 0
    todo = [i for i in range(len(out)) if out[i] < 0]
    by_step: dict[int, list[int]] = {}
    for i in todo:
        by_step.setdefault(int(steps[i]), []).append(i)

    def nearest(p, ids):
        best, best_d2 = -1, np.inf
        for k in ids:  # ascending ids: a tie keeps the lower one
            mx, my = sums[k][0] / sums[k][2], sums[k][1] / sums[k][2]
            d2 = (p[0] - mx) * (p[0] - mx) + (p[1] - my) * (p[1] - my)
            if d2 < best_d2:
                best, best_d2 = k, d2
        return best if best_d2 <= thr2 else -1

    for step in sorted(by_step):
        before = sorted(sums)
        gated = {i: nearest(points[i], before) for i in by_step[step]}
        created: list[int] = []
        for i in by_step[step]:
            if gated[i] < 0:
                k = nearest(points[i], created)
                if k < 0:
                    k, next_id = next_id, next_id + 1
                    created.append(k)
                    sums[k] = [0.0, 0.0, 0.0]
                out[i] = k
                sums[k][0] += points[i][0]
                sums[k][1] += points[i][1]
                sums[k][2] += 1.0
        for i, k in gated.items():
            if k >= 0:
                out[i] = k
                sums[k][0] += points[i][0]
                sums[k][1] += points[i][1]
                sums[k][2] += 1.0
    return out


@pytest.mark.parametrize("seed", range(6))
def test_greedy_nn_equals_the_row_by_row_rule_on_random_crowded_steps(seed):
    # crowded steps (up to hundreds of rows), repeated points, tight and spread clusters and seeded ids: every
    # path of the vectorised labelling (gating equal rows once, parts split by gaps, one-cluster parts)
    rng = np.random.default_rng(seed)
    n = int(rng.integers(200, 700))
    centres = rng.uniform(0.0, [5.0, 20.0, 60.0][seed % 3], (int(rng.integers(3, 40)), 2))
    pts = centres[rng.integers(0, len(centres), n)] + rng.normal(0.0, [0.02, 0.3, 0.7][seed % 3], (n, 2))
    pts[rng.random(n) < 0.3] = pts[0]  # repeated rows
    steps = np.sort(rng.integers(0, [1, 4, 30][seed % 3], n))
    labels = np.where(rng.random(n) < 0.1 * (seed % 2), rng.integers(0, 6, n), -1)
    threshold = [0.5, 1.0, 2.0][seed // 2]
    got = greedy_nearest_neighbour(pts, threshold, labels, steps)
    assert got.tolist() == brute_force_greedy_nn(pts.tolist(), threshold, labels, steps)


def test_greedy_nn_of_many_equal_rows_per_step():
    # the shape of a small compressed file declaring millions of observations: equal rows in every step
    # (its speed is measured by python -m benchmarks.faults, not timed here)
    steps = np.repeat(np.arange(40), 20_000)
    pts = np.column_stack([steps * 3.0, np.zeros(steps.size)])
    got = greedy_nearest_neighbour(pts, 1.0, steps=steps)
    np.testing.assert_array_equal(got, steps)


def test_compact_drops_rare_labels_and_renumbers_by_first_sighting():
    assert compact(np.array([5, 2, 5, -1, 9, 2, 5]), 1).tolist() == [0, 1, 0, -1, 2, 1, 0]
    assert compact(np.array([5, 2, 5, -1, 9, 2, 5]), 2).tolist() == [0, 1, 0, -1, -1, 1, 0]
    assert compact(np.array([-1, -1]), 1).tolist() == [-1, -1]


def noise_free(ds):
    """Replace odometry and observations by exact values generated from the true poses."""
    tr = ds.truth
    obs = ds.inputs.observations
    keep = tr.obs_landmark >= 0
    step = obs.step[keep]
    lab = tr.obs_landmark[keep]
    z = observation.range_bearing(tr.poses_xyt[step], tr.landmarks_xy[lab])
    new_obs = Observations(step=step, range_m=z[:, 0], bearing_rad=z[:, 1], sensor=obs.sensor[keep],
                           reported_id=lab * 10 + 3,  # arbitrary sensor ids (not 0..L-1)
                           offsets=Observations.offsets_from_steps(step, ds.inputs.n_poses))
    inputs = dataclasses.replace(ds.inputs, odometry_xyt=tr.poses_xyt.copy(), observations=new_obs)
    return inputs, lab


@pytest.mark.parametrize("use_ids", [True, False])
def test_noise_free_world_recovers_truth(use_ids):
    ds = tiny_dataset(T=40)
    inputs, lab = noise_free(ds)
    res = OdometrySolver(OdometryParams(use_reported_ids=use_ids, nn_threshold=0.5)).solve(
        inputs, rng=np.random.default_rng(0))
    assert res.status is Status.COMPLETED and res.pose_cov is None
    np.testing.assert_allclose(res.poses_xyt, ds.truth.poses_xyt, atol=1e-12)
    # labels are a relabelling of the truth: map each estimated landmark to its true one
    L = len(res.landmarks_xy)
    assert L == len(np.unique(lab))
    true_of_est = np.array([lab[res.assoc == k][0] for k in range(L)])
    assert all((lab[res.assoc == k] == true_of_est[k]).all() for k in range(L))
    np.testing.assert_allclose(res.landmarks_xy, ds.truth.landmarks_xy[true_of_est], atol=1e-9)


def test_noisy_world_landmarks_are_mean_inverse_observations():
    ds = tiny_dataset(T=40, report_ids=True, clutter_every=0)
    res = OdometrySolver().solve(ds.inputs, rng=np.random.default_rng(0))
    obs = ds.inputs.observations
    m = observation.inverse_range_bearing(ds.inputs.odometry_xyt[obs.step], obs.z)
    for k in range(len(res.landmarks_xy)):
        np.testing.assert_allclose(res.landmarks_xy[k], m[res.assoc == k].mean(axis=0), atol=1e-12)
    # with reported ids = true ids, the association is the truth up to renumbering
    for k in range(len(res.landmarks_xy)):
        assert len(np.unique(ds.truth.obs_landmark[res.assoc == k])) == 1
    # errors stay at the noise level over a 4 m drive
    err = np.linalg.norm(res.landmarks_xy - ds.truth.landmarks_xy[
        [ds.truth.obs_landmark[res.assoc == k][0] for k in range(len(res.landmarks_xy))]], axis=1)
    assert err.max() < 0.3


def test_min_support_removes_clutter_singletons():
    ds = tiny_dataset(T=40, clutter_every=7)
    r1 = OdometrySolver(OdometryParams(min_support=1)).solve(ds.inputs, rng=np.random.default_rng(0))
    r3 = OdometrySolver(OdometryParams(min_support=3)).solve(ds.inputs, rng=np.random.default_rng(0))
    assert len(r3.landmarks_xy) < len(r1.landmarks_xy)
    clutter = ds.truth.obs_landmark < 0
    assert (r3.assoc[clutter] == -1).mean() > (r1.assoc[clutter] == -1).mean()


def test_params_validation():
    with pytest.raises(ValueError):
        OdometryParams(nn_threshold=0.0)
    with pytest.raises(ValueError):
        OdometryParams(min_support=0)
