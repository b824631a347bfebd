"""``graph`` against GTSAM on the same factor graph: optimum, cost and Laplace marginals (issue 3, item 5).

The GTSAM graph is built here from GTSAM's own types (PriorFactorPose2, BetweenFactorPose2 with
increments computed by ``Pose2.between``, BearingRangeFactor2D with a Gaussian noise model), independently
of ``slamcli.solvers.graph``; both optimisers start from the same initial values.
"""

from __future__ import annotations

import numpy as np
import pytest

from slamcli.models.angles import angle_diff
from slamcli.solvers import frontend, graph
from slamcli.types import Status

gtsam = pytest.importorskip("gtsam")
from gtsam.symbol_shorthand import L, X  # noqa: E402 - after the importorskip guard


def _dataset():
    """The simulator's small ``loop`` scenario with sensor-reported ids (fallback: the tiny test world)."""
    try:
        from slamcli.sim import simulate_scenario

        return simulate_scenario("loop", seed=1, overrides={"sensor.report_ids": True})
    except ImportError:
        from conftest import tiny_dataset

        return tiny_dataset(T=200, n_landmarks=8, seed=1, report_ids=True, clutter_every=0)


def _gtsam_graph(inputs, assoc, prior_std, robust_k=None):
    g = gtsam.NonlinearFactorGraph()
    g.add(
        gtsam.PriorFactorPose2(
            X(0), gtsam.Pose2(*inputs.x0), gtsam.noiseModel.Diagonal.Sigmas(np.array(prior_std))
        )
    )
    odo = [gtsam.Pose2(*p) for p in inputs.odometry_xyt]
    odo_noise = gtsam.noiseModel.Diagonal.Sigmas(np.asarray(inputs.noise.odometry_std, float))
    for t in range(len(odo) - 1):
        g.add(gtsam.BetweenFactorPose2(X(t), X(t + 1), odo[t].between(odo[t + 1]), odo_noise))
    sr, sb = inputs.noise.range_std, inputs.noise.bearing_std
    br = gtsam.noiseModel.Gaussian.Covariance(np.diag([sb**2, sr**2]))  # GTSAM order: [bearing, range]
    if robust_k is not None:
        br = gtsam.noiseModel.Robust.Create(gtsam.noiseModel.mEstimator.Huber.Create(robust_k), br)
    obs = inputs.observations
    for k in np.flatnonzero(assoc >= 0):
        g.add(
            gtsam.BearingRangeFactor2D(
                X(int(obs.step[k])),
                L(int(assoc[k])),
                gtsam.Rot2(float(obs.bearing_rad[k])),
                float(obs.range_m[k]),
                br,
            )
        )
    return g


def _values(poses, landmarks):
    v = gtsam.Values()
    for t, p in enumerate(poses):
        v.insert(X(t), gtsam.Pose2(*p))
    for j, m in enumerate(landmarks):
        v.insert(L(j), np.asarray(m, float))
    return v


def _unpack(v, n_poses, n_lm):
    poses = np.array(
        [[v.atPose2(X(t)).x(), v.atPose2(X(t)).y(), v.atPose2(X(t)).theta()] for t in range(n_poses)]
    )
    lms = np.array([v.atPoint2(L(j)) for j in range(n_lm)])
    return poses, lms


def _lm_params():
    p = gtsam.LevenbergMarquardtParams()
    p.setRelativeErrorTol(1e-14)
    p.setAbsoluteErrorTol(1e-14)
    p.setMaxIterations(200)
    return p


@pytest.fixture(scope="module")
def problem():
    ds = _dataset()
    inputs = ds.inputs
    assoc = frontend.associate_reported(inputs.observations)
    n_lm = int(assoc.max()) + 1
    poses0 = graph.odometry_initial_poses(inputs)
    lm0 = frontend.landmarks_from_observations(poses0, inputs.observations, assoc, n_lm)
    return inputs, assoc, n_lm, poses0, lm0


def test_graph_matches_gtsam_levenberg_marquardt_optimum_and_marginals(problem):
    inputs, assoc, n_lm, poses0, lm0 = problem
    params = graph.GraphParams(association="reported")
    res = graph.GraphSlam(params).solve(inputs, rng=np.random.default_rng(0))
    assert res.status == Status.CONVERGED
    np.testing.assert_array_equal(res.assoc, assoc)

    g = _gtsam_graph(inputs, assoc, params.prior_std)
    v0 = _values(poses0, lm0)
    opt = gtsam.LevenbergMarquardtOptimizer(g, v0, _lm_params())
    vg = opt.optimize()
    gt_poses, gt_lms = _unpack(vg, inputs.n_poses, n_lm)

    v_ours = _values(res.poses_xyt, res.landmarks_xy)
    cost_ours_by_gtsam = g.error(v_ours)
    cost_gtsam = g.error(vg)
    assert g.error(v0) > 2.0 * cost_gtsam  # the problem is not trivially at its optimum
    # same optimum: cost by GTSAM's graph.error, our own final cost, and the states
    assert abs(cost_ours_by_gtsam - cost_gtsam) <= 1e-6 * cost_gtsam
    assert abs(res.extra["final_cost"] - cost_gtsam) <= 1e-6 * cost_gtsam
    assert abs(res.extra["final_cost"] - cost_ours_by_gtsam) <= 1e-9 * cost_gtsam  # identical cost functions
    assert np.abs(res.poses_xyt[:, :2] - gt_poses[:, :2]).max() < 1e-6
    assert np.abs(angle_diff(res.poses_xyt[:, 2], gt_poses[:, 2])).max() < 1e-6
    assert np.abs(res.landmarks_xy - gt_lms).max() < 1e-6

    # Laplace marginals: GTSAM's Pose2 marginal is in the body frame → world via J = blkdiag(R(θ), 1)
    marg = gtsam.Marginals(g, vg)
    worst = 0.0
    for t in range(inputs.n_poses):
        Sb = marg.marginalCovariance(X(t))
        th = gt_poses[t, 2]
        J = np.array([[np.cos(th), -np.sin(th), 0.0], [np.sin(th), np.cos(th), 0.0], [0.0, 0.0, 1.0]])
        Sw = J @ Sb @ J.T
        worst = max(worst, np.linalg.norm(res.pose_cov[t] - Sw) / np.linalg.norm(Sw))
    assert worst < 1e-4
    worst_l = max(
        np.linalg.norm(res.landmark_cov[j] - marg.marginalCovariance(L(j)))
        / np.linalg.norm(marg.marginalCovariance(L(j)))
        for j in range(n_lm)
    )
    assert worst_l < 1e-4
    # the frame conversion matters: without it a turned pose disagrees by far more than the tolerance
    turned = int(np.argmax(np.abs(np.sin(gt_poses[:, 2]))))
    Sb = marg.marginalCovariance(X(turned))
    assert np.linalg.norm(res.pose_cov[turned] - Sb) / np.linalg.norm(Sb) > 1e-2


def test_graph_huber_matches_gtsam_robust_huber(problem):
    inputs, assoc, n_lm, poses0, lm0 = problem
    k = 1.0
    params = graph.GraphParams(association="reported", robust="huber", huber_k=k, covariance=False)
    res = graph.GraphSlam(params).solve(inputs, rng=np.random.default_rng(0))
    assert res.status == Status.CONVERGED
    g = _gtsam_graph(inputs, assoc, params.prior_std, robust_k=k)
    vg = gtsam.LevenbergMarquardtOptimizer(g, _values(poses0, lm0), _lm_params()).optimize()
    gt_poses, gt_lms = _unpack(vg, inputs.n_poses, n_lm)
    cost_gtsam = g.error(vg)
    assert abs(g.error(_values(res.poses_xyt, res.landmarks_xy)) - cost_gtsam) <= 1e-6 * cost_gtsam
    assert abs(res.extra["final_cost"] - cost_gtsam) <= 1e-6 * cost_gtsam
    assert np.abs(res.poses_xyt[:, :2] - gt_poses[:, :2]).max() < 1e-5
    assert np.abs(res.landmarks_xy - gt_lms).max() < 1e-5


def test_stored_final_cost_equals_gtsams_recomputation_also_with_a_landmark_on_a_pose(problem):
    """Issue 10, item 4: the stalled Victoria Park result stored a cost 1.75e-5 below the one GTSAM recomputes
    on the stored solution (2 751 818.88 vs 2 751 867.04). The whole difference (48.16) was one bearing-range
    factor whose landmark sat within 1e-5 m of its pose: GTSAM defines that bearing as 0 (``Rot2::
    relativeBearing``), we took ``atan2`` of the tiny offset. Now the factor follows GTSAM; checked here on a
    state with a landmark put 1e-7 m from a pose, and on non-converged solver results (stopped early)."""
    inputs, assoc, n_lm, poses0, lm0 = problem
    gp = graph.build_gtsam_problem(inputs, assoc, poses0, lm0, graph.GraphParams())
    g = _gtsam_graph(inputs, assoc, graph.GraphParams().prior_std)
    k = int(np.flatnonzero(assoc >= 0)[0])
    lms = lm0.copy()
    lms[assoc[k]] = poses0[inputs.observations.step[k], :2] + [1e-7, 0.0]  # landmark on top of the pose
    from slamcli.solvers import nls

    x = graph.pack_state(poses0, lms)
    ours = nls.evaluate_cost(gp.problem, x)
    theirs = g.error(_values(poses0, lms))
    assert abs(ours - theirs) <= 1e-10 * theirs
    for method in ("lm", "gn", "dogleg"):
        res = graph.GraphSlam(graph.GraphParams(method=method, max_iterations=2, covariance=False)).solve(
            inputs, rng=np.random.default_rng(0)
        )
        assert res.status == Status.MAX_ITERATIONS
        recomputed = g.error(_values(res.poses_xyt, res.landmarks_xy))
        assert abs(res.extra["final_cost"] - recomputed) <= 1e-10 * recomputed, method
