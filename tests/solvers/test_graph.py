"""The ``graph`` solver end to end, its front end, and the paper-energy entry point used by ICM."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
import scipy.stats
from conftest import tiny_dataset

from slamcli.errors import SolverError
from slamcli.params import build_params
from slamcli.solvers import frontend, graph
from slamcli.types import Status


def _solve(inputs, init=None, **kw):
    return graph.GraphSlam(graph.GraphParams(**kw)).solve(inputs, init=init, rng=np.random.default_rng(0))


@pytest.fixture(scope="module")
def world():
    return tiny_dataset(T=80, n_landmarks=6, seed=2, report_ids=True)


def test_reported_ids_result_shapes_trace_and_accuracy(world):
    inp, truth = world.inputs, world.truth
    res = _solve(inp)
    assert res.solver == "graph" and res.status == Status.CONVERGED
    assert res.extra["association"] == "reported"
    T1, N = inp.n_poses, len(inp.observations)
    assert res.poses_xyt.shape == (T1, 3) and res.landmarks_xy.shape == (6, 2)
    assert res.assoc.shape == (N,)
    np.testing.assert_array_equal(res.assoc < 0, truth.obs_landmark < 0)  # clutter has no reported id
    assert res.pose_cov.shape == (T1, 3, 3) and res.landmark_cov.shape == (6, 2, 2)
    assert np.all(np.linalg.eigvalsh(res.pose_cov) > 0) and np.all(np.linalg.eigvalsh(res.landmark_cov) > 0)
    # trace: one entry per accepted iteration plus the start, cost decreasing, landmarks per iteration
    tr = res.trace
    assert len(tr) == len(tr.landmark_offsets) - 1 >= 2
    assert np.all(np.diff(tr.objective) <= 0) and tr.objective[-1] == pytest.approx(res.extra["final_cost"])
    np.testing.assert_array_equal(tr.landmarks_at(len(tr) - 1), res.landmarks_xy)
    assert tr.map_change[0] == 0.0 and tr.map_change[1] > 0.0
    # accuracy vs the truth: labels are in order of first sighting, map them back through the reported ids
    obs = inp.observations
    ok = res.assoc >= 0
    true_of_label = np.zeros(6, np.int64)
    true_of_label[res.assoc[ok]] = obs.reported_id[ok]
    lm_err = np.linalg.norm(res.landmarks_xy - truth.landmarks_xy[true_of_label], axis=1)
    assert lm_err.max() < 0.05
    pos_err = np.linalg.norm(res.poses_xyt[:, :2] - truth.poses_xyt[:, :2], axis=1)
    odo_err = np.linalg.norm(inp.odometry_xyt[:, :2] - truth.poses_xyt[:, :2], axis=1)
    assert pos_err.max() < 0.06 and pos_err.mean() < odo_err.mean()
    # the start pose is pinned by the prior (gauge)
    np.testing.assert_allclose(res.poses_xyt[0], inp.x0, atol=1e-6)
    assert np.all(np.diag(res.pose_cov[0]) < 1e-7)


def test_same_input_same_result_and_lm_equals_gn(world):
    a, b = _solve(world.inputs), _solve(world.inputs)
    np.testing.assert_array_equal(a.poses_xyt, b.poses_xyt)
    np.testing.assert_array_equal(a.pose_cov, b.pose_cov)
    gn = _solve(world.inputs, method="gn")
    np.testing.assert_allclose(gn.poses_xyt, a.poses_xyt, atol=1e-8)
    assert gn.extra["final_cost"] == pytest.approx(a.extra["final_cost"], rel=1e-10)


def test_params_parse_from_cli_strings():
    p = build_params(
        graph.GraphParams, ["method=gn", "robust=huber", "prior_std=1e-3,1e-3,1e-2", "model=paper"]
    )
    assert (
        p.method == "gn" and p.robust == "huber" and p.prior_std == (1e-3, 1e-3, 1e-2) and p.model == "paper"
    )
    p = build_params(graph.GraphParams, ["paper_Q=[[1,0],[0,1]]"])
    assert p.paper_Q == ((1.0, 0.0), (0.0, 1.0))


def test_chi2_gate_equals_scipy_quantile():
    for p in (0.9, 0.99, 0.999):
        assert frontend.gate_threshold(p) == pytest.approx(scipy.stats.chi2.ppf(p, 2), rel=1e-12)
    with pytest.raises(SolverError):
        frontend.gate_threshold(1.0)


def test_compact_labels_order_and_min_obs():
    assoc = np.array([7, 3, 7, -1, 3, 9, 7])
    out, old = frontend.compact_labels(assoc)
    np.testing.assert_array_equal(out, [0, 1, 0, -1, 1, 2, 0])
    np.testing.assert_array_equal(old, [7, 3, 9])
    out, old = frontend.compact_labels(assoc, min_obs=2)
    np.testing.assert_array_equal(out, [0, 1, 0, -1, 1, -1, 0])



def test_compact_labels_of_huge_ids_allocate_nothing_sized_by_the_id():
    """ISSUE: a legal reported_id of 2^31 made graph and isam allocate a 16 GiB lookup table (2^40: 8 TiB).
    The ids are remapped densely; the same labels shifted by 2^62 give the same answer (reference: the small
    labels above), and a table of 2^62 entries could not even be asked for."""
    assoc = np.array([7, 3, 7, -1, 3, 9, 7])
    for shift in (2**31, 2**40, 2**62):
        big = np.where(assoc >= 0, assoc + shift, -1)
        for min_obs in (1, 2):
            out_small, old_small = frontend.compact_labels(assoc, min_obs)
            out, old = frontend.compact_labels(big, min_obs)
            np.testing.assert_array_equal(out, out_small)
            np.testing.assert_array_equal(old, old_small + shift)


def test_graph_solves_a_dataset_whose_reported_ids_are_huge():
    ds = tiny_dataset(T=40, n_landmarks=5, seed=3)
    obs = ds.inputs.observations
    rid = np.where(obs.reported_id >= 0, obs.reported_id + 2**40, -1)
    inputs = dataclasses.replace(ds.inputs, observations=dataclasses.replace(obs, reported_id=rid))
    small = _solve(ds.inputs)
    big = _solve(inputs)
    np.testing.assert_array_equal(big.assoc, small.assoc)
    np.testing.assert_allclose(big.poses_xyt, small.poses_xyt, rtol=0, atol=1e-12)


def test_nearest_neighbour_front_end_recovers_identities_and_rejects_clutter():
    ds = tiny_dataset(T=80, n_landmarks=6, seed=5, report_ids=False, clutter_every=5)
    inp, truth = ds.inputs, ds.truth
    res = _solve(inp, association="nn", min_obs=3)
    assert res.extra["association"] == "nn" and res.status == Status.CONVERGED
    tl = truth.obs_landmark
    ok = res.assoc >= 0
    # clutter returns are isolated → dropped by min_obs
    assert np.all(res.assoc[tl < 0] == -1)
    # purity: every kept label is one true landmark, and nearly every real return is kept
    for lab in np.unique(res.assoc[ok]):
        assert len(np.unique(tl[res.assoc == lab])) == 1
    assert ok[tl >= 0].mean() > 0.97
    # landmarks of the main labels are accurate
    for lab in np.unique(res.assoc[ok]):
        j = tl[res.assoc == lab][0]
        assert np.linalg.norm(res.landmarks_xy[lab] - truth.landmarks_xy[j]) < 0.1


def test_init_association_reproduces_the_labelled_optimum(world):
    inp = world.inputs
    ref = _solve(inp)
    # relabel: reverse the landmark order in a fake "init" result
    perm = np.arange(6)[::-1]
    init = dataclasses.replace(
        ref,
        assoc=np.where(ref.assoc >= 0, perm[np.maximum(ref.assoc, 0)], -1),
        landmarks_xy=ref.landmarks_xy[::-1],
    )
    res = _solve(inp, init=init)
    assert res.extra["association"] == "init"
    assert res.extra["final_cost"] == pytest.approx(ref.extra["final_cost"], rel=1e-10)
    np.testing.assert_allclose(res.poses_xyt, ref.poses_xyt, atol=1e-8)
    # labels are compacted in order of first sighting, so they come back identical
    np.testing.assert_array_equal(res.assoc, ref.assoc)
    # start from the init result's poses as well
    res2 = _solve(inp, init=init, init_from="init")
    assert res2.extra["final_cost"] == pytest.approx(ref.extra["final_cost"], rel=1e-10)
    assert len(res2.trace) <= 3  # already at the optimum


def test_bad_init_and_missing_ids_are_one_line_errors(world):
    with pytest.raises(SolverError, match="needs an --init"):
        _solve(world.inputs, association="init")
    ref = _solve(world.inputs)
    short = dataclasses.replace(ref, assoc=ref.assoc[:-3])
    with pytest.raises(SolverError, match="association labels"):
        _solve(world.inputs, init=short)
    no_ids = tiny_dataset(T=10, n_landmarks=4, seed=0, report_ids=False)
    with pytest.raises(SolverError, match="reported_id"):
        _solve(no_ids.inputs, association="reported")


def test_huber_limits_the_damage_of_wrong_associations():
    ds = tiny_dataset(T=80, n_landmarks=6, seed=3, report_ids=True, clutter_every=0)
    inp, truth = ds.inputs, ds.truth
    obs = inp.observations
    rng = np.random.default_rng(0)
    bad = rng.choice(len(obs), size=len(obs) // 12, replace=False)
    rid = obs.reported_id.copy()
    rid[bad] = (rid[bad] + rng.integers(1, 6, bad.size)) % 6  # 8 % of the labels point at a wrong landmark
    corrupted = dataclasses.replace(inp, observations=dataclasses.replace(obs, reported_id=rid))
    errs = {}
    for robust in ("none", "huber"):
        res = _solve(corrupted, robust=robust, huber_k=1.0, covariance=False)
        assert res.status == Status.CONVERGED
        errs[robust] = np.linalg.norm(res.poses_xyt[:, :2] - truth.poses_xyt[:, :2], axis=1).mean()
    assert errs["huber"] < 0.5 * errs["none"]


def test_paper_energy_optimum_is_a_minimum_of_the_potentials_energy(world):
    inp = world.inputs
    assoc = frontend.associate_reported(inp.observations)
    p0 = graph.odometry_initial_poses(inp)
    lm0 = frontend.landmarks_from_observations(p0, inp.observations, assoc, 6)
    R, S, Q = np.eye(3), np.eye(3) * 4.0, np.eye(2)
    poses, lms, E = graph.optimize_paper_energy(inp, assoc, R, S, Q, p0, lm0)
    np.testing.assert_array_equal(poses[0], p0[0])  # x_0 is the known start pose
    assert E == pytest.approx(graph.paper_energy(inp, assoc, R, S, Q, poses, lms), rel=1e-12)
    assert E < graph.paper_energy(inp, assoc, R, S, Q, p0, lm0)
    # a stationary minimum: no single-coordinate perturbation lowers it
    rng = np.random.default_rng(1)
    for _ in range(20):
        P, M = poses.copy(), lms.copy()
        if rng.random() < 0.5:
            P[rng.integers(1, len(P)), rng.integers(0, 3)] += rng.choice([-1, 1]) * 1e-4
        else:
            M[rng.integers(0, 6), rng.integers(0, 2)] += rng.choice([-1, 1]) * 1e-4
        assert graph.paper_energy(inp, assoc, R, S, Q, P, M) >= E - 1e-12 * E
    # a zero weight drops its potential (S = 0 ≠ S = 4I optimum)
    _, _, E0 = graph.optimize_paper_energy(inp, assoc, R, np.zeros((3, 3)), Q, p0, lm0)
    assert E0 < E


def test_paper_model_through_the_solver(world):
    res = _solve(
        world.inputs, model="paper", paper_R=((1, 0, 0), (0, 1, 0), (0, 0, 1)), paper_Q=((1, 0), (0, 1))
    )
    assert res.status == Status.CONVERGED and res.extra["model"] == "paper"
    np.testing.assert_array_equal(res.poses_xyt[0], world.inputs.x0)
    assert np.all(res.pose_cov[0] == 0.0) and np.all(np.linalg.eigvalsh(res.pose_cov[1:]) > 0)
    assoc = res.assoc
    R, Q = np.eye(3), np.eye(2)
    S = graph.default_paper_weights(world.inputs)[1]
    E = graph.paper_energy(world.inputs, assoc, R, S, Q, res.poses_xyt, res.landmarks_xy)
    assert res.extra["final_cost"] == pytest.approx(E, rel=1e-12)


# ---------------------------------------------------------------------------------------------------------
# front end: drift model, segmentation, grouping, loop closure by merging
# ---------------------------------------------------------------------------------------------------------
def test_drift_covariance_equals_the_dead_reckoning_chain_jacobians():
    """Σ_rel(a, t) from prefix sums = Σ_k (∂x_t/∂d_k) Q (∂x_t/∂d_k)ᵀ with the Jacobians by finite differences
    of the chained composition, mapped to a landmark by ∂h⁻¹/∂x of slamcli.models.observation."""
    from slamcli.models import motion, observation

    rng = np.random.default_rng(0)
    T = 12
    d = np.column_stack([rng.uniform(0.5, 1.0, T), rng.normal(0, 0.1, T), rng.normal(0.2, 0.3, T)])
    poses = motion.chain_increments(np.array([1.0, -2.0, 0.4]), d)
    q_std = np.array([0.02, 0.01, 0.005])
    model = frontend._DriftModel(poses, q_std)
    a, t = 3, 11

    def x_t(flat):
        return motion.chain_increments(poses[a], flat.reshape(-1, 3))[-1]

    base = d[a:t].ravel()
    Jn = np.stack(
        [(x_t(base + e) - x_t(base - e)) / 2e-6 for e in 1e-6 * np.eye(base.size)], -1
    )  # (3, 3(t-a))
    Sigma = Jn @ np.kron(np.eye(t - a), np.diag(q_std**2)) @ Jn.T
    mu = np.array([[4.0, 3.0], [-1.0, 2.5]])
    z = observation.range_bearing(poses[t], mu)
    Mx, _ = observation.inverse_range_bearing_jacobians(np.broadcast_to(poses[t], (2, 3)), z)
    ref = Mx @ Sigma @ np.swapaxes(Mx, 1, 2)
    got = model.landmark_cov(np.array([a, a]), t, mu)
    np.testing.assert_allclose(got, ref, rtol=1e-6, atol=1e-14)
    assert np.all(model.landmark_cov(np.array([t]), t, mu[:1]) == 0.0)


def test_segment_returns_groups_adjacent_close_returns_only():
    pts = np.array([[3.0, 0.0], [3.0, 0.05], [3.0, 0.1], [3.0, 2.0], [0.0, 3.0]])
    brg = np.array([0.0, 0.0167, 0.0333, 0.59, 1.57])
    np.testing.assert_array_equal(frontend.segment_returns(pts, brg, 0.5), [0, 0, 0, 1, 2])
    np.testing.assert_array_equal(frontend.segment_returns(pts, brg, 0.0), [0, 1, 2, 3, 4])
    # close in space but far apart in bearing: not one detection
    np.testing.assert_array_equal(frontend.segment_returns(pts[:2], np.array([0.0, 0.3]), 0.5), [0, 1])


def test_group_returns_averages_range_and_circular_bearing():
    steps = np.array([4, 4, 4, 2])
    labels = np.array([1, 1, 0, 1])
    z = np.array([[3.0, np.pi - 0.01], [3.2, -np.pi + 0.03], [5.0, 0.2], [1.0, 0.1]])
    s, lab, zz = graph.group_returns(steps, labels, z, 2)
    np.testing.assert_array_equal(s, [2, 4, 4])
    np.testing.assert_array_equal(lab, [1, 0, 1])
    np.testing.assert_allclose(zz[2], [3.1, -np.pi + 0.01], atol=1e-12)  # mean across the ±π seam
    np.testing.assert_allclose(zz[:2], [[1.0, 0.1], [5.0, 0.2]])


@pytest.mark.slow
def test_loop_closure_by_drift_gating_and_by_merging():
    from slamcli.sim import simulate_scenario

    ds = simulate_scenario("loop", seed=0)
    inp, tl = ds.inputs, ds.truth.obs_landmark
    n_true = ds.truth.landmarks_xy.shape[0]

    def run(**kw):
        res = _solve(inp, covariance=False, **kw)
        labels = range(res.extra["n_landmarks"])
        pure = all(len(np.unique(tl[res.assoc == lab])) == 1 for lab in labels)
        return res, pure

    plain, pure = run(nn_drift=False, merge_rounds=0)
    assert pure and plain.extra["n_landmarks"] > n_true + 5  # dead-reckoning drift → duplicates on revisit
    merged, pure = run(nn_drift=False)
    assert pure and merged.extra["n_landmarks"] == n_true and merged.extra["merged_landmarks"] > 5
    full, pure = run()
    assert pure and full.extra["n_landmarks"] == n_true
    assert full.extra["final_cost"] == pytest.approx(merged.extra["final_cost"], rel=1e-8)


def test_co_observed_labels_are_never_merged(world):
    from slamcli.solvers import nls
    from slamcli.types import Observations

    inp = world.inputs
    obs = inp.observations
    assoc = frontend.associate_reported(obs)
    # label 6: an exact copy of every row of landmark 0 → same position, but co-observed at every pose
    rows0 = np.flatnonzero(assoc == 0)
    idx = np.concatenate([np.arange(len(obs)), rows0])
    lab = np.concatenate([assoc, np.full(rows0.size, 6)])
    order = np.argsort(obs.step[idx], kind="stable")
    idx, lab = idx[order], lab[order]
    obs2 = Observations(
        step=obs.step[idx],
        range_m=obs.range_m[idx],
        bearing_rad=obs.bearing_rad[idx],
        sensor=obs.sensor[idx],
        reported_id=obs.reported_id[idx],
        offsets=Observations.offsets_from_steps(obs.step[idx], inp.n_poses),
    )
    inp2 = dataclasses.replace(inp, observations=obs2)
    # label 7: the second half (in time) of landmark 1's rows → same landmark, never co-observed
    rows1 = np.flatnonzero(lab == 1)
    lab[rows1[rows1.size // 2 :]] = 7
    p0 = graph.odometry_initial_poses(inp2)
    lm0 = frontend.landmarks_from_observations(p0, obs2, lab, 8)
    gp = graph.build_gtsam_problem(inp2, lab, p0, lm0, graph.GraphParams(group_returns=False))
    res = nls.solve(gp.problem, gp.x0)
    lms = gp.unpack(res.x)[1]
    assert np.linalg.norm(lms[0] - lms[6]) < 1e-9  # identical data → identical estimates
    pairs = graph.merge_candidates(gp, res.information, lms, obs2, lab, 0.999, merge_dist=1.0).tolist()
    assert [1, 7] in pairs
    assert [0, 6] not in pairs


@pytest.mark.slow
def test_laplace_covariances_are_consistent_monte_carlo():
    """30 independent tiny worlds (known ids): the average NEES of the last pose (3 DoF, world frame) and of
    the first-seen landmark (2 DoF) lie inside the two-sided 95 % χ² band of the 30-run average
    (EVALUATION-METHOD §A1/§A2). Uses ground truth — as a metric only."""
    from slamcli.models.angles import wrap_pose_error
    from slamcli.solvers import nls

    n_runs = 30
    pose_nees, lm_nees = [], []
    for s in range(n_runs):
        ds = tiny_dataset(T=40, n_landmarks=5, seed=300 + s, report_ids=True, clutter_every=0)
        inp = ds.inputs
        # the solver's own pipeline without its result bookkeeping (keeps 30 runs fast)
        assoc = frontend.associate_reported(inp.observations)
        p0 = graph.odometry_initial_poses(inp)
        lm0 = frontend.landmarks_from_observations(p0, inp.observations, assoc, int(assoc.max()) + 1)
        gp = graph.build_gtsam_problem(inp, assoc, p0, lm0)
        opt = nls.solve(gp.problem, gp.x0)
        poses, lms = gp.unpack(opt.x)
        pose_cov, lm_cov = graph.laplace_marginals(gp, opt.information)
        e = wrap_pose_error(poses[-1] - ds.truth.poses_xyt[-1])
        pose_nees.append(e @ np.linalg.solve(pose_cov[-1], e))
        first = int(inp.observations.reported_id[assoc == 0][0])  # label 0 = first sighted
        el = lms[0] - ds.truth.landmarks_xy[first]
        lm_nees.append(el @ np.linalg.solve(lm_cov[0], el))
    lo3, hi3 = scipy.stats.chi2.ppf([0.025, 0.975], 3 * n_runs) / n_runs
    lo2, hi2 = scipy.stats.chi2.ppf([0.025, 0.975], 2 * n_runs) / n_runs
    assert lo3 < np.mean(pose_nees) < hi3
    assert lo2 < np.mean(lm_nees) < hi2


def test_edge_cases_single_pose_no_observations_and_bad_weights():
    from slamcli.types import Observations

    one = tiny_dataset(T=0, n_landmarks=4, seed=0, report_ids=True).inputs
    res = _solve(one)
    assert res.poses_xyt.shape == (1, 3) and res.pose_cov.shape == (1, 3, 3)
    np.testing.assert_allclose(res.pose_cov[0], np.diag(np.square(graph.GraphParams().prior_std)), atol=1e-15)
    inp = tiny_dataset(T=15, n_landmarks=4, seed=0).inputs
    empty = Observations(
        step=np.zeros(0, np.int64),
        range_m=np.zeros(0),
        bearing_rad=np.zeros(0),
        sensor=np.zeros(0, np.int16),
        reported_id=np.zeros(0, np.int64),
        offsets=np.zeros(inp.n_poses + 1, np.int64),
    )
    res = _solve(dataclasses.replace(inp, observations=empty))
    assert res.landmarks_xy.shape == (0, 2) and res.status == Status.CONVERGED
    # odometry only: the optimum is the chained odometry itself, covariance grows along the chain
    np.testing.assert_allclose(res.poses_xyt, graph.odometry_initial_poses(inp), atol=1e-9)
    assert np.all(np.diff(np.trace(res.pose_cov, axis1=1, axis2=2)) > 0)
    with pytest.raises(SolverError, match="paper Q must be symmetric"):
        _solve(inp, model="paper", paper_Q=((1, 2), (3, 4)))


def test_range_bias_estimate_recovers_a_constant_range_offset():
    ds = tiny_dataset(T=250, n_landmarks=6, seed=7, report_ids=True, clutter_every=0)  # one full circle
    inp, truth = ds.inputs, ds.truth
    obs = inp.observations
    shifted = dataclasses.replace(inp, observations=dataclasses.replace(obs, range_m=obs.range_m - 0.15))
    plain = _solve(shifted)
    est = _solve(shifted, estimate_range_bias=True)
    assert "range_bias" not in plain.extra
    assert est.extra["range_bias"] == pytest.approx(0.15, abs=0.01)
    ok = est.assoc >= 0
    true_of = np.zeros(6, np.int64)
    true_of[est.assoc[ok]] = obs.reported_id[ok]
    err_est = np.linalg.norm(est.landmarks_xy - truth.landmarks_xy[true_of], axis=1).mean()
    err_plain = np.linalg.norm(plain.landmarks_xy - truth.landmarks_xy[true_of], axis=1).mean()
    assert err_est < 0.05 < err_plain
    assert est.landmark_cov.shape == (6, 2, 2) and est.pose_cov.shape == (inp.n_poses, 3, 3)


def _with_gross_outliers(ds, landmark, steps, range_m=5.0):
    """``ds`` plus misread rows at ``steps`` reporting ``landmark`` at ``range_m`` on the OPPOSITE side
    (true bearing + π) — like MRCLAM robot 5's misread barcodes."""
    from slamcli.models import observation
    from slamcli.types import Observations

    obs = ds.inputs.observations
    tb = observation.range_bearing(ds.truth.poses_xyt[steps], ds.truth.landmarks_xy[[landmark] * len(steps)])
    step = np.concatenate([obs.step, steps])
    order = np.argsort(step, kind="stable")
    n = len(steps)
    new = Observations(
        step=step[order],
        range_m=np.concatenate([obs.range_m, np.full(n, range_m)])[order],
        bearing_rad=np.concatenate([obs.bearing_rad, observation.wrap_angle(tb[:, 1] + np.pi)])[order],
        sensor=np.concatenate([obs.sensor, np.zeros(n, np.int16)])[order],
        reported_id=np.concatenate([obs.reported_id, np.full(n, landmark)])[order],
        offsets=Observations.offsets_from_steps(step[order], ds.inputs.n_poses),
    )
    return dataclasses.replace(ds.inputs, observations=new)


def test_gross_outliers_that_pull_a_landmark_onto_a_pose_give_no_covariances_not_a_crash(world):
    """Regression (MRCLAM robot 5, ``LinAlgError: leading minor not positive definite`` in
    ``cholesky_banded``): landmark 1 passes 0.55 m from pose 59; five misread rows at poses 57-61 see it 5 m
    away on the opposite side. The bearing residuals pull the landmark through the pose, where the bearing
    Jacobian ∝ 1/r explodes: the dogleg (and, before issue 10, LM with Marquardt scaling) ends with landmark 1
    within 1e-5 m of a pose, where H was not numerically positive definite. The solve must finish with
    finite poses, and report no covariances with the reason in ``message`` and ``extra``, or valid ones —
    never invalid ones (with GTSAM's bearing convention, flat within 1e-5 m, H now stays positive definite;
    the refusal itself is tested in test_nls.py). LM with GTSAM's λI damping stops earlier, 4 cm from the pose, when λ reaches its upper bound
    1e5 (as GTSAM's would); its covariances, if reported, must be valid."""
    truth = world.truth
    d = np.linalg.norm(truth.poses_xyt[:, :2] - truth.landmarks_xy[1], axis=1)
    assert d.argmin() == 59 and d.min() == pytest.approx(0.5535, abs=1e-3)
    inp = _with_gross_outliers(world, 1, np.arange(57, 62))
    lm = _solve(inp)
    assert lm.status == Status.CONVERGED and np.all(np.isfinite(lm.poses_xyt))
    if lm.pose_cov is not None:
        assert np.all(np.linalg.eigvalsh(lm.pose_cov) > 0) and np.all(np.linalg.eigvalsh(lm.landmark_cov) > 0)
    res = _solve(inp, method="dogleg")
    assert res.status == Status.CONVERGED
    assert np.all(np.isfinite(res.poses_xyt)) and np.all(np.isfinite(res.landmarks_xy))
    lab = res.assoc[np.flatnonzero(inp.observations.reported_id == 1)[0]]
    gap = np.linalg.norm(res.poses_xyt[:, :2] - res.landmarks_xy[lab], axis=1)
    # the near-singular configuration this test is about: the landmark at the pose, up to GTSAM's 1e-5 m
    # bearing cut-off (within it the bearing factor is flat, so the landmark stops at its edge)
    assert gap.min() < 2e-5
    if res.pose_cov is None:  # H not numerically positive definite: no covariances, and the reason
        assert res.landmark_cov is None
        assert "no covariances" in res.message and "not numerically positive definite" in res.message
        assert res.extra["covariance_error"] in res.message
        # the factorisation broke down at one of the two variables that coincide
        assert any(
            f"{v}:" in res.extra["covariance_error"] for v in (f"pose {int(gap.argmin())}", f"landmark {lab}")
        )
    else:  # since issue 10 (GTSAM's flat bearing within 1e-5 m) H stays positive definite here: valid blocks
        assert np.all(np.linalg.eigvalsh(res.pose_cov) > 0) and np.all(
            np.linalg.eigvalsh(res.landmark_cov) > 0
        )
    # the outliers cost accuracy, but the trajectory is still an estimate, not garbage
    assert np.abs(res.poses_xyt[:, :2] - truth.poses_xyt[:, :2]).max() < 0.6
    # Gauss-Newton and Huber on the same data complete as well; Huber keeps the landmark off the pose and
    # then has valid covariances
    gn = _solve(inp, method="gn")
    assert gn.status != Status.FAILED and np.all(np.isfinite(gn.poses_xyt))
    hub = _solve(inp, robust="huber")
    assert hub.pose_cov is not None and np.all(np.linalg.eigvalsh(hub.pose_cov) > 0)
    assert np.abs(hub.poses_xyt[:, :2] - truth.poses_xyt[:, :2]).max() < 0.1


def test_message_status_trace_and_progress_agree_on_the_iteration_count(world):
    """Victoria Park printed "71 iterations" (trace) next to "stopped after 100 iterations" (status): the
    budget counted LM's rejected trial steps too. Now an iteration is an accepted step everywhere. The
    outlier world makes LM reject trial steps early (before the fix: "stopped after 5 iterations" with
    two accepted steps in the trace)."""
    inp = _with_gross_outliers(world, 1, np.arange(57, 62))
    seen = []
    res = graph.GraphSlam(graph.GraphParams(max_iterations=3, covariance=False)).solve(
        inp, rng=np.random.default_rng(0), progress=lambda done, total: seen.append((done, total))
    )
    assert res.extra["iterations"] == 3 == len(res.trace) - 1  # trace row 0 is the start
    assert res.status == Status.MAX_ITERATIONS
    assert res.message == "stopped after 3 iterations (max_iterations)"
    assert [d for d, _ in seen] == [0, 1, 2, 3, 3] and {t for _, t in seen} == {3}
    full = _solve(world.inputs)
    assert full.status == Status.CONVERGED and full.extra["iterations"] == len(full.trace) - 1


def test_solve_and_info_print_the_same_iteration_count_as_the_status(world, tmp_path):
    from typer.testing import CliRunner

    from slamcli.cli import app
    from slamcli.io import write_dataset

    data, out = tmp_path / "d.h5", tmp_path / "r.h5"
    write_dataset(
        data, dataclasses.replace(world, inputs=_with_gross_outliers(world, 1, np.arange(57, 62)), truth=None)
    )
    runner = CliRunner()
    r = runner.invoke(app, ["solve", str(data), "-m", "graph", "-p", "max_iterations=3", "-o", str(out)])
    assert r.exit_code == 0, r.output
    text = " ".join(r.stdout.split())
    assert (
        "max_iterations graph" in text and ", 3 iterations:" in text and "stopped after 3 iterations" in text
    )
    r = runner.invoke(app, ["info", str(out)])
    row = next(ln for ln in r.stdout.splitlines() if "│ iterations " in ln)
    assert row.split("│")[2].strip() == "3"
