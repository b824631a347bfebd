"""``graph`` with ``init=robust`` (issue 10, the Victoria Park full row): the warm start from a Cauchy-kernel
solve of the same graph, checked against GTSAM's LM with the same kernel, and the Gaussian optimum reached
from it.

Why the option exists (measured in ``benchmarks/bench_graph_real.py`` on GTSAM's full victoria_park.txt, which
is too large for the test suite): 10 of its 3640 sightings are labelled with the wrong tree; from the
drifted odometry chain the Gaussian LM of both GTSAM and slamcli stalls at λ = 1e5 with a cost ~150× the
optimum, while the same graph started from the Cauchy estimate converges in 8 iterations. The data here is
the 1600-pose prefix (tests/data/victoria_park_1600.txt), on which both starts reach the same optimum: the
test checks both passes against GTSAM's LM on the same graph.
"""

from __future__ import annotations

import numpy as np
import pytest
from conftest import DATA

from slamcli.datasets.g2o import import_graph
from slamcli.errors import SolverError
from slamcli.solvers import frontend, graph
from slamcli.types import Status

#: the NoiseSpec bearing-range model (not the file's per-edge Cartesian one), as the GTSAM graph below
PARAMS = dict(edge_info=False, covariance=False, rel_cost_tol=1e-10, max_iterations=500)


@pytest.fixture(scope="module")
def victoria():
    inputs = import_graph(DATA / "victoria_park_1600.txt").inputs
    assoc, _ = frontend.compact_labels(frontend.associate_reported(inputs.observations), 1)
    return inputs, assoc


def _solve(inputs, **kw):
    return graph.GraphSlam(graph.GraphParams(**{**PARAMS, **kw})).solve(inputs, rng=np.random.default_rng(0))


def _gtsam_lm(inputs, assoc, p, start_poses, cauchy: bool):
    """GTSAM's LM (relative tolerance 1e-10, ≤ 500 iterations) on the same graph in its own types — Cauchy
    (k = ``p.cauchy_k``) on the sightings when ``cauchy`` — from ``start_poses`` (landmarks from their first
    sighting). Returns ``(optimizer, graph, values)``."""
    gtsam = pytest.importorskip("gtsam")
    from gtsam.symbol_shorthand import L, X

    from slamcli.models import motion

    g = gtsam.NonlinearFactorGraph()
    prior = gtsam.noiseModel.Diagonal.Sigmas(np.asarray(p.prior_std, float))
    g.add(gtsam.PriorFactorPose2(X(0), gtsam.Pose2(*inputs.x0), prior))
    odo = gtsam.noiseModel.Diagonal.Sigmas(np.asarray(inputs.noise.odometry_std, float))
    for t, d in enumerate(motion.odometry_increments(inputs.odometry_xyt)):
        g.add(gtsam.BetweenFactorPose2(X(t), X(t + 1), gtsam.Pose2(*d), odo))
    obs = inputs.observations
    n_lm = int(assoc.max()) + 1
    steps, labels, z = graph.group_returns(np.asarray(obs.step), assoc, obs.z, n_lm)
    sr, sb = inputs.noise.range_std, inputs.noise.bearing_std
    br = gtsam.noiseModel.Gaussian.Covariance(np.diag([sb**2, sr**2]))  # GTSAM order: [bearing, range]
    if cauchy:
        br = gtsam.noiseModel.Robust.Create(gtsam.noiseModel.mEstimator.Cauchy.Create(p.cauchy_k), br)
    for s, j, (r, b) in zip(steps, labels, z):
        g.add(gtsam.BearingRangeFactor2D(X(int(s)), L(int(j)), gtsam.Rot2(float(b)), float(r), br))
    lm0 = frontend.landmarks_from_observations(start_poses, obs, assoc, n_lm)
    v0 = gtsam.Values()
    for t, q in enumerate(start_poses):
        v0.insert(X(t), gtsam.Pose2(*q))
    for j, m in enumerate(lm0):
        v0.insert(L(j), np.asarray(m, float))
    lp = gtsam.LevenbergMarquardtParams()
    lp.setRelativeErrorTol(1e-10)
    lp.setAbsoluteErrorTol(0.0)
    lp.setMaxIterations(500)
    opt = gtsam.LevenbergMarquardtOptimizer(g, v0, lp)
    return opt, g, opt.optimize()


@pytest.mark.slow
def test_robust_warm_start_equals_gtsams_cauchy_lm(victoria):
    gtsam = pytest.importorskip("gtsam")
    from gtsam.symbol_shorthand import X

    inputs, assoc = victoria
    p = graph.GraphParams(**PARAMS)
    poses0 = graph.odometry_initial_poses(inputs)
    poses, res = graph.robust_initial_poses(inputs, assoc, poses0, p)
    assert res.status == Status.CONVERGED
    opt, g, v = _gtsam_lm(inputs, assoc, p, poses0, cauchy=True)
    assert isinstance(v, gtsam.Values)
    assert opt.iterations() == res.iterations  # both count accepted steps
    assert abs(g.error(v) - res.cost) <= 1e-9 * res.cost
    gt_poses = np.array([[v.atPose2(X(t)).x(), v.atPose2(X(t)).y()] for t in range(inputs.n_poses)])
    assert np.max(np.abs(gt_poses - poses[:, :2])) < 1e-6


@pytest.mark.slow
def test_init_robust_reaches_the_gaussian_optimum_from_inside_its_basin(victoria):
    inputs, _ = victoria
    odo = _solve(inputs)
    rob = _solve(inputs, init="robust")
    for r in (odo, rob):
        assert r.status == Status.CONVERGED
        assert r.extra["robust"] == "none"  # the final model is the Gaussian one
    # same Gaussian optimum, reached in 4 iterations from the warm start instead of 58 from the chain; the
    # reference is GTSAM's LM on the Gaussian graph from the same warm start
    p = graph.GraphParams(**PARAMS)
    warm, _ = graph.robust_initial_poses(inputs, victoria[1], graph.odometry_initial_poses(inputs), p)
    _, g, v = _gtsam_lm(inputs, victoria[1], p, warm, cauchy=False)
    assert odo.extra["final_cost"] == pytest.approx(g.error(v), rel=1e-9)
    assert rob.extra["final_cost"] == pytest.approx(odo.extra["final_cost"], rel=1e-9)
    assert odo.extra["iterations"] >= 50 and rob.extra["iterations"] <= 6
    assert np.max(np.abs(rob.poses_xyt - odo.poses_xyt)) < 1e-5
    assert rob.extra["init"] == "robust"
    opt_c, g_c, v_c = _gtsam_lm(inputs, victoria[1], p, graph.odometry_initial_poses(inputs), cauchy=True)
    assert rob.extra["robust_init"] == {
        "status": "converged",
        "iterations": opt_c.iterations(),
        "cost": pytest.approx(g_c.error(v_c), rel=1e-8),
    }
    assert "robust_init" not in odo.extra


def test_init_robust_needs_the_gtsam_model(victoria):
    inputs, _ = victoria
    with pytest.raises(ValueError, match="init=robust needs model=gtsam"):
        _solve(inputs, init="robust", model="paper")
    with pytest.raises(ValueError, match="init=incremental builds a nearest-neighbour association"):
        graph.GraphParams(init="incremental", association="reported")


# ---------------------------------------------------------------------------------------------------------
# init=incremental (unknown correspondences): association window by window on the current estimate
# ---------------------------------------------------------------------------------------------------------
def test_incremental_init_with_one_window_is_the_robust_solve_of_the_batch_association():
    """With a window longer than the run, the incremental pass is one NN association on the odometry chain
    followed by one Cauchy solve from it — exactly ``robust_initial_poses`` on that association."""
    import dataclasses

    from conftest import tiny_dataset

    inputs = tiny_dataset(T=60, n_landmarks=6, seed=3).inputs
    p = graph.GraphParams(incremental_window=1e3)
    odo = graph.odometry_initial_poses(inputs)
    inc = graph.incremental_initial_poses(inputs, odo, p)
    assoc, _ = frontend.associate_nearest_neighbour(
        odo,
        inputs.observations,
        inputs.noise.obs_cov,
        gate_prob=p.gate_prob,
        odometry_std=inputs.noise.odometry_std,
        segment_dist=p.nn_segment_dist,
    )
    assoc, _ = frontend.compact_labels(assoc, 1)
    ref, res = graph.robust_initial_poses(inputs, assoc, odo, dataclasses.replace(p, rel_cost_tol=1e-6))
    assert res.iterations > 0 and np.max(np.abs(ref - odo)) > 1e-3  # the solve moved the poses
    np.testing.assert_allclose(inc, ref, rtol=0, atol=1e-12)


@pytest.mark.slow
def test_incremental_init_on_the_victoria_park_excerpt(tmp_path):
    """End to end on the first 60 s of Victoria Park (tests/data/victoria_park_excerpt): windows of 3 s,
    GPS ATE (aligned) below dead reckoning's 1.37 m and at the batch front end's level (0.85 m measured; on
    the first 300 s, where the batch association is built from 26 m of drift, it is 21.3 m against
    1.38 m with init=incremental — too long for the suite, measured for issue 10)."""
    import json

    from typer.testing import CliRunner

    from slamcli.cli import app

    runner = CliRunner()
    data, out = tmp_path / "vp.h5", tmp_path / "g.h5"
    vp = DATA / "victoria_park_excerpt"
    assert runner.invoke(app, ["import", "victoria-park", str(vp), "-q", "-o", str(data)]).exit_code == 0
    r = runner.invoke(
        app, ["solve", str(data), "-m", "graph", "-p", "init=incremental", "-p", "robust=cauchy", "-q", "-o", str(out)]
    )
    assert r.exit_code == 0, r.output
    r = runner.invoke(app, ["evaluate", str(out), "-q", "-o", str(tmp_path / "ev")])
    assert r.exit_code == 0, r.output
    m = json.loads((tmp_path / "ev" / "metrics.json").read_text())
    assert m["odometry_gps_ate_aligned_rmse_m"] == pytest.approx(1.369, abs=2e-3)
    assert m["gps_ate_aligned_rmse_m"] < 0.9


def test_incremental_init_refuses_known_correspondences(victoria):
    inputs, _ = victoria  # the graph file's landmark ids are reported ids
    with pytest.raises(SolverError, match="init=incremental builds a nearest-neighbour association"):
        _solve(inputs, init="incremental")


def test_stall_rule_on_hand_built_traces():
    from slamcli.solvers.graph import solver as gs
    from slamcli.solvers.graph.params import STALL_REL_DECREASE, STALL_WINDOW

    class _Res:
        status = Status.MAX_ITERATIONS

    flat = gs._Run(assoc=np.zeros(0, np.int64), rounds=0, budget=1, paper_Q=None, res=_Res())
    flat.objective = [100.0] * 5 + [50.0] + [50.0 * (1 - 0.1 * STALL_REL_DECREASE * k / STALL_WINDOW)
                                              for k in range(1, STALL_WINDOW + 1)]
    assert gs._stalled(flat)
    falling = gs._Run(assoc=np.zeros(0, np.int64), rounds=0, budget=1, paper_Q=None, res=_Res())
    falling.objective = [100.0 - k for k in range(STALL_WINDOW + 2)]  # still 10 % lower over the window
    assert not gs._stalled(falling)
    _Res.status = Status.CONVERGED
    assert not gs._stalled(flat)  # converged runs are never re-solved


@pytest.mark.slow
def test_stalled_landmark_graph_is_re_solved_from_init_robust(victoria, monkeypatch):
    """The restart wiring: a run judged stalled is re-solved from init=robust, the lower cost is kept and the
    message says so; the result is the Gaussian optimum that the converged run from the chain reaches."""
    from slamcli.solvers.graph import solver as gs

    inputs, _ = victoria
    reference = _solve(inputs, restart="off")  # converges from the chain (58 iterations)
    monkeypatch.setattr(gs, "_stalled", lambda run: run.res.iterations < 20)  # cap the first run, judge it
    capped = _solve(inputs, max_iterations=15)
    assert capped.extra["restart"]["from"] == "robust" and "kept" not in capped.extra["restart"]
    assert capped.extra["restart"]["first_cost"] > capped.extra["final_cost"]
    assert "LM stalled at the iteration cap from the odometry start" in capped.message
    assert capped.extra["final_cost"] == pytest.approx(reference.extra["final_cost"], rel=1e-9)


@pytest.mark.slow
def test_a_restart_that_cannot_help_is_skipped_and_said(victoria, monkeypatch):
    """A converged run judged stalled: init=robust's start costs more than the estimate and the cost rises all
    the way to it (its basin), so the solve stops and says why — and forcing that restart indeed ends at the
    first run's cost (what skipping saves is a whole second solve)."""
    from slamcli.solvers.graph import solver as gs

    inputs, _ = victoria
    reference = _solve(inputs, restart="off")
    monkeypatch.setattr(gs, "_stalled", lambda run: True)
    judged = _solve(inputs)
    rst = judged.extra["restart"]
    assert rst["from"] == "robust" and "same basin" in rst["skipped"] and rst["start_cost"] > rst["first_cost"]
    assert "stopped without re-solving from init=robust: its start costs more" in judged.message
    assert judged.extra["final_cost"] == reference.extra["final_cost"]
    monkeypatch.setattr(gs.GraphSlam, "_restart_skip", lambda self, *args: "")
    forced = _solve(inputs)
    assert forced.extra["restart"]["restart_cost"] == pytest.approx(reference.extra["final_cost"], rel=1e-9)
