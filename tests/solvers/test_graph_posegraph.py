"""Pose graphs with loop closures: between-factors, initialisation, robust kernels, χ² outlier counts.

Data: ``tests/data/intel_excerpt.g2o`` (first 300 poses of Intel, 25 loop closures) and
``tests/data/mit_excerpt.g2o`` (first 500 poses of MIT Killian Court, 13 loop closures); see
PROVENANCE-graphs.txt. The GTSAM graph is built here from the imported dataset, independently of our factors.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from conftest import DATA

from slamcli.api.solve import solve_dataset
from slamcli.datasets.g2o import import_graph
from slamcli.io import read_dataset, write_dataset
from slamcli.models import motion, se2
from slamcli.solvers import graph, nls
from slamcli.solvers.graph import init as pose_init
from slamcli.types import NoiseSpec, Observations, PoseConstraints, SlamInputs

INTEL = DATA / "intel_excerpt.g2o"
MIT = DATA / "mit_excerpt.g2o"


def _gtsam_solve(inputs, init_poses, prior_std=(1e-4, 1e-4, 1e-4)):
    """GTSAM LM on the dataset's pose graph (prior, odometry with its information, loop closures)."""
    gtsam = pytest.importorskip("gtsam")
    g = gtsam.NonlinearFactorGraph()
    g.add(gtsam.PriorFactorPose2(0, gtsam.Pose2(*inputs.x0), gtsam.noiseModel.Diagonal.Sigmas(np.array(prior_std))))
    d = motion.odometry_increments(inputs.odometry_xyt)
    c = inputs.constraints
    for t in range(len(d)):
        g.add(gtsam.BetweenFactorPose2(t, t + 1, gtsam.Pose2(*d[t]), gtsam.noiseModel.Gaussian.Information(c.odometry_info[t])))
    for (i, j), m, info in zip(c.between_ij, c.between_xyt, c.between_info):
        g.add(gtsam.BetweenFactorPose2(int(i), int(j), gtsam.Pose2(*m), gtsam.noiseModel.Gaussian.Information(info)))
    v = gtsam.Values()
    for t, p in enumerate(init_poses):
        v.insert(t, gtsam.Pose2(*p))
    prm = gtsam.LevenbergMarquardtParams()
    prm.setRelativeErrorTol(1e-12)
    prm.setAbsoluteErrorTol(0.0)
    prm.setMaxIterations(200)
    out = gtsam.LevenbergMarquardtOptimizer(g, v, prm).optimize()
    poses = np.array([[out.atPose2(t).x(), out.atPose2(t).y(), out.atPose2(t).theta()] for t in range(len(init_poses))])
    return g, poses, float(g.error(out))


def _error_of(g, poses):
    import gtsam

    v = gtsam.Values()
    for t, p in enumerate(poses):
        v.insert(t, gtsam.Pose2(*p))
    return float(g.error(v))


@pytest.mark.parametrize("init", ["odometry", "chordal", "spanning_tree"])
def test_intel_excerpt_reaches_gtsams_optimum(init):
    ds = import_graph(INTEL)
    inp = ds.inputs
    assert inp.n_poses == 300 and ds.metadata["n_loop_closures"] == 25 == inp.constraints.n_between
    res = solve_dataset(inp, "graph", {"init": init, "covariance": False})
    assert res.status.value == "converged"
    g, gt_poses, gt_cost = _gtsam_solve(inp, graph.initial_poses(inp, init))
    ours_by_gtsam = _error_of(g, res.poses_xyt)
    assert abs(res.extra["final_cost"] - gt_cost) <= 1e-6 * gt_cost
    assert abs(ours_by_gtsam - gt_cost) <= 1e-6 * gt_cost
    np.testing.assert_allclose(res.poses_xyt[:, :2], gt_poses[:, :2], atol=1e-5)
    assert gt_cost > 0.1  # loop closures make the graph inconsistent: a cost of 0 would test nothing


@pytest.mark.parametrize("path", [INTEL, MIT])
def test_pose_graph_lm_stops_on_the_predicted_decrease_within_1e_10_of_gtsams_optimum(path, monkeypatch):
    """The default pose-graph LM stops before a step whose predicted decrease is below ``pred_cost_tol`` (1e-10
    relative): its cost is GTSAM's fully converged one (relative tolerance 1e-12, from the same chordal start) to
    within 1e-10, in no more iterations than the run that polishes to ``rel_cost_tol`` (``pred_cost_tol=0``). The
    test by the previous iterate's factorisation stops where the one by a new factorisation does (both without
    the simplified-Newton steps, whose iterates differ)."""
    from slamcli.solvers.graph import params as graph_params
    from slamcli.solvers.nls import optimize

    inp = import_graph(path).inputs
    res = solve_dataset(inp, "graph", {"covariance": False})
    assert "(last factorisation)" in res.message
    monkeypatch.setattr(graph_params, "POSE_GRAPH_FROZEN_STEP_REL", 0.0)
    plain = solve_dataset(inp, "graph", {"covariance": False})
    monkeypatch.setattr(optimize, "LAST_FACTOR_REGIME", -1.0)  # the exact test only
    exact = solve_dataset(inp, "graph", {"covariance": False})
    monkeypatch.undo()
    assert "(last factorisation)" in plain.message
    assert "(last factorisation)" not in exact.message and exact.extra["iterations"] == plain.extra["iterations"]
    np.testing.assert_array_equal(exact.poses_xyt, plain.poses_xyt)
    full = solve_dataset(inp, "graph", {"covariance": False, "pred_cost_tol": 0.0})
    g, _, gt_cost = _gtsam_solve(inp, graph.initial_poses(inp, "chordal"))
    assert "predicted cost decrease below pred_cost_tol" in res.message
    assert "predicted" not in full.message
    assert abs(_error_of(g, res.poses_xyt) - gt_cost) <= 1e-10 * gt_cost
    assert abs(res.extra["final_cost"] - gt_cost) <= 1e-10 * gt_cost
    assert res.extra["iterations"] <= full.extra["iterations"]
    assert res.extra["certificate"]["certified"] is True


@pytest.mark.slow
def test_mit_excerpt_lm_from_odometry_stalls_chordal_does_not():
    """LM from the odometry chain ends in a local minimum on MIT; chordal initialisation reaches GTSAM's
    optimum from the same start (and GTSAM from the odometry start stalls too: the minimum is real)."""
    inp = import_graph(MIT).inputs
    odo = solve_dataset(inp, "graph", {"init": "odometry", "covariance": False, "restart": "off"})
    cho = solve_dataset(inp, "graph", {"init": "chordal", "covariance": False})
    assert cho.extra["init"] == "chordal" and "init" not in odo.extra
    g, _, gt_cho = _gtsam_solve(inp, graph.initial_poses(inp, "chordal"))
    _, _, gt_odo = _gtsam_solve(inp, graph.initial_poses(inp, "odometry"))
    assert abs(cho.extra["final_cost"] - gt_cho) <= 1e-6 * gt_cho
    assert odo.extra["final_cost"] > 10 * cho.extra["final_cost"]
    assert gt_odo > 10 * gt_cho  # GTSAM's LM from the odometry chain stalls in the same way
    assert abs(odo.extra["final_cost"] - gt_odo) <= 1e-4 * gt_odo
    # the stall is not certified; from the odometry start the solver notices and re-solves from the chordal one
    assert odo.extra["certificate"]["certified"] is False and odo.extra["certificate"]["lambda_min"] < 0
    rst = solve_dataset(inp, "graph", {"init": "odometry", "covariance": False})
    assert rst.extra["restart"]["from"] == "chordal" and rst.extra["certificate"]["certified"] is True
    assert abs(rst.extra["final_cost"] - gt_cho) <= 1e-6 * gt_cho and "certified global optimum" in rst.message
    # the defaults (init=auto) start a pose graph with loop closures from the chordal relaxation: no restart
    dflt = solve_dataset(inp, "graph", {"covariance": False})
    assert dflt.extra["init"] == "chordal" and "restart" not in dflt.extra and "chordal relaxation" in dflt.message
    assert dflt.extra["certificate"]["certified"] is True and abs(dflt.extra["final_cost"] - gt_cho) <= 1e-6 * gt_cho


def _loop_world(n=60, seed=3):
    """Poses on two laps of a circle, odometry chain + loop closures, exact (noise-free) measurements."""
    rng = np.random.default_rng(seed)
    th = np.linspace(0, 4 * np.pi, n)
    poses = np.column_stack([5 * np.cos(th), 5 * np.sin(th), th + np.pi / 2])
    poses[:, 2] = np.arctan2(np.sin(poses[:, 2]), np.cos(poses[:, 2]))
    T = n - 1
    pairs = np.array([(i, j) for i in range(n) for j in range(i + 2, n) if np.hypot(*(poses[i, :2] - poses[j, :2])) < 1.0])
    meas = se2.between(poses[pairs[:, 0]], poses[pairs[:, 1]])
    A = rng.normal(size=(len(pairs), 3, 3))
    info = A @ np.swapaxes(A, 1, 2) + 3 * np.eye(3)
    odo_info = np.broadcast_to(np.diag([100.0, 400.0, 900.0]), (T, 3, 3)).copy()
    inputs = SlamInputs(
        dt=1.0,
        timestamps=np.arange(n, dtype=float),
        x0=poses[0].copy(),
        controls=np.zeros((T, 2)),
        odometry_xyt=poses.copy(),
        observations=Observations.from_rows(np.zeros(0, np.int64), np.zeros((0, 2)), n),
        noise=NoiseSpec(motion_std=np.array([0.1, 0.1]), odometry_std=np.array([0.1, 0.05, 0.03]), range_std=0.1, bearing_std=0.1),
        constraints=PoseConstraints(between_ij=pairs, between_xyt=meas, between_info=info, odometry_info=odo_info),
    )
    return inputs, poses


def test_chordal_and_spanning_tree_are_exact_on_consistent_measurements():
    inputs, poses = _loop_world()
    assert inputs.constraints.n_between >= 10
    for method in ("chordal", "spanning_tree"):
        p = graph.initial_poses(inputs, method)
        np.testing.assert_allclose(p[:, :2], poses[:, :2], atol=1e-9)
        np.testing.assert_allclose(np.angle(np.exp(1j * (p[:, 2] - poses[:, 2]))), 0, atol=1e-9)


def test_chordal_beats_odometry_under_heading_drift():
    """A 0.02 rad/step heading bias on the odometry: the chained start is far off; chordal uses the loop
    closures and lands much nearer the truth (and at a lower cost)."""
    inputs, poses = _loop_world(n=80)
    d = motion.odometry_increments(inputs.odometry_xyt)
    d[:, 2] += 0.02
    import dataclasses

    biased = dataclasses.replace(inputs, odometry_xyt=motion.chain_increments(inputs.x0, d))
    e_odo = np.max(np.hypot(*(graph.initial_poses(biased, "odometry")[:, :2] - poses[:, :2]).T))
    e_cho = np.max(np.hypot(*(graph.initial_poses(biased, "chordal")[:, :2] - poses[:, :2]).T))
    assert e_cho < 0.5 * e_odo


def test_unconnected_pose_is_one_line_error():
    inputs, _ = _loop_world(n=20)
    with pytest.raises(ValueError, match="pose 5 is not connected"):
        pose_init.spanning_tree_poses(6, np.array([[0, 1], [1, 2], [2, 3], [3, 4]]), np.zeros((4, 3)), np.zeros(3))
    with pytest.raises(ValueError, match="pose 5 is not connected"):
        pose_init.chordal_poses(6, np.array([[0, 1], [1, 2], [2, 3], [3, 4]]), np.zeros((4, 3)),
                                np.broadcast_to(np.eye(3), (4, 3, 3)), np.zeros(3))


def test_constraints_round_trip_and_validation(tmp_path):
    import h5py

    ds = import_graph(INTEL)
    f = tmp_path / "intel.h5"
    write_dataset(f, ds)
    back = read_dataset(f).inputs.constraints
    c = ds.inputs.constraints
    np.testing.assert_array_equal(back.between_ij, c.between_ij)
    np.testing.assert_array_equal(back.between_xyt, c.between_xyt)
    np.testing.assert_array_equal(back.between_info, c.between_info)
    np.testing.assert_array_equal(back.odometry_info, c.odometry_info)
    with h5py.File(f, "r+") as h:
        h["inputs/constraints/between_info"][3] = -np.eye(3)
    from slamcli.errors import SchemaError

    with pytest.raises(SchemaError, match="inputs/constraints/between_info: matrix 3 is not positive definite"):
        read_dataset(f)


def test_landmark_offset_jacobians_match_finite_differences():
    rng = np.random.default_rng(0)
    x = rng.normal(size=(5, 3))
    m = rng.normal(size=(5, 2)) * 4
    z = rng.normal(size=(5, 2))
    _, Jx, Jm = graph.landmark_offset_error(x, m, z)
    h = 1e-6
    for k in range(3):
        dx = np.zeros(3)
        dx[k] = h
        num = (graph.landmark_offset_error(x + dx, m, z)[0] - graph.landmark_offset_error(x - dx, m, z)[0]) / (2 * h)
        np.testing.assert_allclose(Jx[:, :, k], num, atol=1e-8)
    for k in range(2):
        dm = np.zeros(2)
        dm[k] = h
        num = (graph.landmark_offset_error(x, m + dm, z)[0] - graph.landmark_offset_error(x, m - dm, z)[0]) / (2 * h)
        np.testing.assert_allclose(Jm[:, :, k], num, atol=1e-8)
    # e = R(θ)ᵀ(m − p) − z by hand for one factor
    c, s = math.cos(x[0, 2]), math.sin(x[0, 2])
    d = m[0] - x[0, :2]
    np.testing.assert_allclose(graph.landmark_offset_error(x, m, z)[0][0], [c * d[0] + s * d[1] - z[0, 0], -s * d[0] + c * d[1] - z[0, 1]])


@pytest.mark.parametrize(("kind", "k"), [("huber", 1.345), ("cauchy", 2.3849), ("geman_mcclure", 1.0)])
def test_robust_kernels_match_gtsam_and_their_derivative(kind, k):
    s = np.array([0.0, 0.3, 1.0, 1.5, 3.0, 10.0])
    rho, w = nls.robust_kernel(s**2, kind, k)
    # IRLS weight is ρ'(s)/s (central differences)
    h = 1e-6
    dr = (nls.robust_kernel((s[1:] + h) ** 2, kind, k)[0] - nls.robust_kernel((s[1:] - h) ** 2, kind, k)[0]) / (2 * h)
    np.testing.assert_allclose(w[1:], dr / s[1:], rtol=1e-6)
    assert nls.robust_kernel(np.array([1e-6]), kind, k)[0][0] == pytest.approx(0.5e-6, rel=1e-5)  # ½ s² near 0
    gtsam = pytest.importorskip("gtsam")
    est = {"huber": gtsam.noiseModel.mEstimator.Huber, "cauchy": gtsam.noiseModel.mEstimator.Cauchy,
           "geman_mcclure": gtsam.noiseModel.mEstimator.GemanMcClure}[kind].Create(k)
    np.testing.assert_allclose(rho, [est.loss(v) for v in s], rtol=1e-12, atol=1e-15)
    np.testing.assert_allclose(w, [est.weight(v) for v in s], rtol=1e-12)


@pytest.mark.parametrize("kind", ["cauchy", "geman_mcclure"])
def test_robust_graph_cost_matches_gtsam_robust_graph(kind):
    """A pose graph with one wrong loop closure: our robust cost at the GTSAM robust optimum and GTSAM's
    robust cost at ours agree, and the kernel keeps the wrong closure from bending the trajectory."""
    gtsam = pytest.importorskip("gtsam")
    import dataclasses

    inputs, poses = _loop_world(n=40)
    c = inputs.constraints
    meas = c.between_xyt.copy()
    meas[0] = [3.0, -2.0, 1.0]  # an outlier closure
    inputs = dataclasses.replace(inputs, constraints=dataclasses.replace(c, between_xyt=meas))
    params = {"robust": kind, "covariance": False}
    res = solve_dataset(inputs, "graph", params)
    k = graph.GraphParams().cauchy_k if kind == "cauchy" else graph.GraphParams().geman_mcclure_c
    est = (gtsam.noiseModel.mEstimator.Cauchy if kind == "cauchy" else gtsam.noiseModel.mEstimator.GemanMcClure).Create(k)
    g = gtsam.NonlinearFactorGraph()
    g.add(gtsam.PriorFactorPose2(0, gtsam.Pose2(*inputs.x0), gtsam.noiseModel.Diagonal.Sigmas(np.full(3, 1e-4))))
    d = motion.odometry_increments(inputs.odometry_xyt)
    for t in range(len(d)):
        g.add(gtsam.BetweenFactorPose2(t, t + 1, gtsam.Pose2(*d[t]), gtsam.noiseModel.Gaussian.Information(c.odometry_info[t])))
    for (i, j), m, info in zip(c.between_ij, meas, c.between_info):
        g.add(gtsam.BetweenFactorPose2(int(i), int(j), gtsam.Pose2(*m),
                                       gtsam.noiseModel.Robust.Create(est, gtsam.noiseModel.Gaussian.Information(info))))
    assert abs(_error_of(g, res.poses_xyt) - res.extra["final_cost"]) <= 1e-9 * res.extra["final_cost"]
    plain = solve_dataset(inputs, "graph", {"covariance": False})
    err_robust = np.max(np.hypot(*(res.poses_xyt[:, :2] - poses[:, :2]).T))
    err_plain = np.max(np.hypot(*(plain.poses_xyt[:, :2] - poses[:, :2]).T))
    assert err_robust < 0.25 * err_plain  # the kernel discounts the wrong closure


def test_chi2_outlier_counts_by_hand():
    inputs, _ = _loop_world(n=40)
    import dataclasses

    c = inputs.constraints
    meas = c.between_xyt.copy()
    meas[0] = [3.0, -2.0, 1.0]
    inputs = dataclasses.replace(inputs, constraints=dataclasses.replace(c, between_xyt=meas))
    res = solve_dataset(inputs, "graph", {"robust": "cauchy", "covariance": False})
    counts = res.extra["chi2_outliers"]
    # hand computation: whitened squared residuals of the loop closures at the estimate, against χ²₃
    e, _, _ = graph.between_error(res.poses_xyt[c.between_ij[:, 0]], res.poses_xyt[c.between_ij[:, 1]], meas)
    s2 = np.einsum("fi,fij,fj->f", e, c.between_info, e)
    assert counts["loop_closure"] == {"factors": len(meas), "dof": 3, "over_95": int(np.sum(s2 > 7.814727903251178)),
                                      "over_99": int(np.sum(s2 > 11.344866730144373))}
    assert counts["loop_closure"]["over_99"] >= 1 and counts["odometry"]["factors"] == 39


def test_robust_auto_is_cauchy_only_for_real_sensor_ids(tmp_path):
    """``robust=auto`` (the default): Cauchy for ids read by a real sensor (MRCLAM barcodes, which can be
    misread), none for simulated ids, graph files and nearest-neighbour association; the source survives a
    write/read and the kernel used is reported."""
    from slamcli.datasets.mrclam import import_mrclam
    from slamcli.sim import simulate_scenario

    assert graph.resolve_robust("auto", "reported", "sensor") == "cauchy"
    assert graph.resolve_robust("auto", "reported", "unknown") == "none"
    assert graph.resolve_robust("auto", "reported", "file") == "none"
    assert graph.resolve_robust("auto", "nn", "sensor") == "none"
    assert graph.resolve_robust("huber", "nn", "unknown") == "huber"
    ds = import_mrclam(DATA / "mrclam_excerpt", 1, dt=0.1)
    f = tmp_path / "m.h5"
    write_dataset(f, ds)
    inp = read_dataset(f).inputs
    assert inp.reported_id_source == "sensor"
    auto = solve_dataset(inp, "graph", {"covariance": False})
    cau = solve_dataset(inp, "graph", {"covariance": False, "robust": "cauchy"})
    none = solve_dataset(inp, "graph", {"covariance": False, "robust": "none"})
    assert auto.extra["robust"] == "cauchy" and none.extra["robust"] == "none"
    assert auto.extra["final_cost"] == cau.extra["final_cost"] != none.extra["final_cost"]
    sim = simulate_scenario("loop", seed=1, overrides={"sensor.report_ids": True})
    assert sim.inputs.reported_id_source == "unknown"
    r = solve_dataset(sim.inputs, "graph", {"covariance": False})
    assert r.extra["association"] == "reported" and r.extra["robust"] == "none"


def test_a_restart_runs_only_from_another_basin_or_a_lower_cost():
    """The restart gate on MIT's two minima (GTSAM reaches both: the chordal start's global one and the
    odometry chain's local one, cost > 10×, test above). From the global minimum a restart at the local one
    costs more but lies beyond a ridge (another basin): it may run. A start a small step from the global
    minimum costs more and lies in its basin: skipped, and LM from there indeed returns to the same cost."""
    from types import SimpleNamespace

    from slamcli.solvers.graph import solver as gs
    from slamcli.solvers.graph.build import build_gtsam_problem

    inp = import_graph(MIT).inputs
    glob = solve_dataset(inp, "graph", {"init": "chordal", "covariance": False})
    loc = solve_dataset(inp, "graph", {"init": "odometry", "covariance": False, "restart": "off"})
    assert loc.extra["final_cost"] > 10 * glob.extra["final_cost"]
    assert "not certified: S + ηI is not positive definite" in loc.message and "nan" not in loc.message
    solver = gs.GraphSlam(graph.GraphParams(covariance=False))
    p = solver.params
    assoc, none = np.zeros(0, np.int64), np.zeros((0, 2))
    gp = build_gtsam_problem(inp, assoc, glob.poses_xyt, none, p)
    nparams = p.nls_params("none", p.kernel_scale("none"), pose_graph=True)
    run = SimpleNamespace(res=SimpleNamespace(x=gp.x0, cost=nls.evaluate_cost(gp.problem, gp.x0, nparams)),
                          gp=SimpleNamespace(n_landmarks=0))
    assert run.res.cost == pytest.approx(glob.extra["final_cost"], rel=1e-9)
    record: dict = {}
    assert solver._restart_skip(inp, run, assoc, loc.poses_xyt, none, "none", record) == ""
    assert record["start_cost"] == pytest.approx(loc.extra["final_cost"], rel=1e-9)
    near = glob.poses_xyt + np.random.default_rng(1).normal(scale=0.02, size=glob.poses_xyt.shape)
    why = solver._restart_skip(inp, run, assoc, near, none, "none", record)
    assert record["start_cost"] > run.res.cost and "same basin" in why
    from_near = gs.GraphSlam(graph.GraphParams(covariance=False, restart="off", certify=False))
    res = from_near._optimise(inp, assoc, near, none, "reported", "none", None).res
    assert res.cost == pytest.approx(glob.extra["final_cost"], rel=1e-6)
