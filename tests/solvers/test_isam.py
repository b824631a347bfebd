"""The incremental smoother (``--method isam``): with its final batch step it ends at batch ``graph`` LM's
optimum (same factors, same association) within 1e-6 on ``loop`` and on the MRCLAM excerpt; without it, its
own estimate is checked against the batch optimum and its association against the simulator's truth."""

from __future__ import annotations

import numpy as np
import pytest
from conftest import DATA

from slamcli.models.angles import angle_diff
from slamcli.sim import simulate_scenario
from slamcli.solvers.graph import GraphParams, GraphSlam
from slamcli.solvers.isam import IsamParams, IsamSlam

EXCERPT = DATA / "mrclam_excerpt"
TOL = 1e-6


def _same_optimum(a, b) -> None:
    assert np.abs(a.poses_xyt[:, :2] - b.poses_xyt[:, :2]).max() <= TOL
    assert np.abs(angle_diff(a.poses_xyt[:, 2], b.poses_xyt[:, 2])).max() <= TOL
    assert a.landmarks_xy.shape == b.landmarks_xy.shape
    assert np.abs(a.landmarks_xy - b.landmarks_xy).max() <= TOL
    assert np.array_equal(a.assoc, b.assoc)


@pytest.fixture(scope="module")
def loop_ids():
    return simulate_scenario("loop", seed=1, overrides={"sensor.report_ids": True})


@pytest.mark.slow
def test_final_batch_equals_graph_lm_on_loop_with_reported_ids(loop_ids):
    rng = np.random.default_rng(0)
    inc = IsamSlam(IsamParams(final_batch=True)).solve(loop_ids.inputs, rng=rng)
    bat = GraphSlam(GraphParams(association="reported")).solve(loop_ids.inputs, rng=rng)
    _same_optimum(inc, bat)
    assert abs(inc.extra["final_cost"] - bat.extra["final_cost"]) <= TOL * bat.extra["final_cost"]


@pytest.fixture(scope="module")
def loop_nn():
    """``loop`` with unknown association and isam's final-batch result on it."""
    ds = simulate_scenario("loop", seed=1)
    return ds, IsamSlam(IsamParams(final_batch=True)).solve(ds.inputs, rng=np.random.default_rng(0))


@pytest.mark.slow
def test_unknown_association_on_loop_finds_every_landmark_once_and_ends_at_graphs_optimum(loop_nn):
    ds, inc = loop_nn
    rng = np.random.default_rng(0)
    assert inc.extra["association"] == "nn"
    # every label is one true landmark and every true landmark one label (truth read here, not by the solver)
    true_lm = np.asarray(ds.truth.landmarks_xy, float)
    d = np.linalg.norm(inc.landmarks_xy[:, None, :] - true_lm[None], axis=2)
    assert inc.landmarks_xy.shape[0] == true_lm.shape[0]
    assert sorted(np.argmin(d, axis=1).tolist()) == list(range(true_lm.shape[0]))
    bat = GraphSlam(GraphParams(association="init")).solve(ds.inputs, init=inc, rng=rng)
    _same_optimum(inc, bat)


@pytest.mark.slow
def test_smoother_estimate_without_final_batch_is_near_the_batch_optimum(loop_ids):
    """Keyframes end at the keyframe graph's optimum (end batch step); the poses between keyframes follow
    odometry, so they are near, not at, the full graph's optimum."""
    rng = np.random.default_rng(0)
    inc = IsamSlam(IsamParams()).solve(loop_ids.inputs, rng=rng)
    bat = GraphSlam(GraphParams(association="reported")).solve(loop_ids.inputs, rng=rng)
    err = np.linalg.norm(inc.poses_xyt[:, :2] - bat.poses_xyt[:, :2], axis=1)
    assert np.median(err) < 1e-5
    assert err.max() < 0.05
    assert np.abs(inc.landmarks_xy - bat.landmarks_xy).max() < 1e-3


def test_final_batch_equals_graph_lm_on_the_mrclam_excerpt():
    from slamcli.datasets.mrclam import import_mrclam

    ds = import_mrclam(EXCERPT, 1, dt=0.1)
    rng = np.random.default_rng(0)
    inc = IsamSlam(IsamParams(final_batch=True)).solve(ds.inputs, rng=rng)
    bat = GraphSlam(GraphParams()).solve(ds.inputs, rng=rng)
    assert inc.extra["association"] == "reported" and inc.extra["robust"] == bat.extra["robust"] == "cauchy"
    _same_optimum(inc, bat)


def test_params_are_validated():
    with pytest.raises(ValueError):
        IsamParams(lag_s=0.0)
    with pytest.raises(ValueError):
        IsamParams(gate_prob=1.0)


def _brute_force_window_system(sm, x):
    """Dense Gauss-Newton system of EVERY factor of the store linearised at ``x`` (whitened Jacobian by
    :func:`slamcli.solvers.nls.jacobian_matrix`), Schur-complemented onto the window's variables in the
    window's order: the closed form the window's cached factors + prior must reproduce."""
    from slamcli.solvers import nls
    from slamcli.solvers.isam.factors import keyframe_problem

    w, fs = sm.win, sm.fs
    K, L = w.K, w.lm_x.n
    prob = keyframe_problem(fs, K, L, np.arange(K - 1), np.arange(fs.br_z.n), True)
    J = nls.jacobian_matrix(prob, x).toarray()
    r = nls.residual_vector(prob, x)
    H, g = J.T @ J, J.T @ r
    win = np.concatenate([np.arange(3 * w.w0, 3 * K), (3 * K + 2 * w.act_lm[:, None] + np.arange(2)).ravel()])
    out = np.setdiff1d(np.arange(H.shape[0]), win)
    X = np.linalg.solve(H[np.ix_(out, out)], np.column_stack([H[np.ix_(out, win)], g[out]]))
    return H[np.ix_(win, win)] - H[np.ix_(win, out)] @ X[:, :-1], g[win] - H[np.ix_(win, out)] @ X[:, -1]


@pytest.mark.slow
def test_window_prior_is_the_exact_schur_complement_of_the_marginalised_factors(loop_ids):
    """Never relinearising (threshold ∞) keeps every factor at the point it was created at; the window's
    system (its factors + the Schur prior built one keyframe at a time) must then equal the closed-form
    marginal of the whole graph at those points. After a batch step the same holds at the new estimate."""
    from slamcli.solvers.isam import IncrementalSmoother

    p = IsamParams(relin_threshold=np.inf, reactivate=False, batch_every_s=1e9, end_batch=False)
    sm = IncrementalSmoother(loop_ids.inputs, p, "reported", "none", 1.0)
    for i in range(150):  # the first part of the loop: no landmark is seen again after it left the window
        sm.update(i)
    assert sm.win.w0 > 50 and sm.n_deferred == 0 and sm.n_batches == 0
    x_lin = np.concatenate([sm.win.kf_lin.view.ravel(), sm.win.lm_lin.view.ravel()])
    H_ref, g_ref = _brute_force_window_system(sm, x_lin)
    H, g = sm.win.assemble()
    scale = np.abs(H_ref).max()
    assert np.abs(H - H_ref).max() <= 1e-9 * scale
    assert np.abs(g - g_ref).max() <= 1e-9 * max(np.abs(g_ref).max(), 1.0) + 1e-9 * scale
    sm.batch_step()
    x = np.concatenate([sm.win.kf_x.view.ravel(), sm.win.lm_x.view.ravel()])
    H_ref, g_ref = _brute_force_window_system(sm, x)
    H, g = sm.win.assemble()
    assert np.abs(H - H_ref).max() <= 1e-9 * np.abs(H_ref).max()
    assert np.abs(g - g_ref).max() <= 1e-6 * max(np.abs(g_ref).max(), 1.0)


# --------------------------------------------------------------------------------------- noise="vce" (issue 25)
def _batch_with_sigmas(inputs, res, start):
    """``graph``'s batch LM on ``inputs`` with the σ ``res`` reports (``vce_sigma``) on ``res``'s association,
    started from another estimate ``start`` (same labels): Gaussian factors, NoiseSpec σ, no GPS."""
    import dataclasses

    from slamcli.solvers.graph import NOISE_GROUPS, noise_with_sigmas

    sig = [res.extra["vce_sigma"][g] for g in NOISE_GROUPS]
    inp = dataclasses.replace(inputs, noise=noise_with_sigmas(inputs.noise, sig))
    gp = GraphParams(association="init", robust="none", use_gps=False, edge_info=False, covariance=False)
    return GraphSlam(gp).solve(inp, init=start, rng=np.random.default_rng(0))


def _check_vce(inputs, plain=None):
    """``noise=vce`` on ``inputs`` against ``plain``, isam's final-batch result with the dataset's σ."""
    rng = np.random.default_rng(0)
    plain = plain or IsamSlam(IsamParams(final_batch=True)).solve(inputs, rng=rng)
    vce = IsamSlam(IsamParams(noise="vce")).solve(inputs, rng=rng)
    assert np.array_equal(vce.assoc, plain.assoc)  # the association is the on-line pass's, unchanged
    assert vce.extra["noise"] == "vce" and "re-estimated by VCE" in vce.message
    assert vce.extra["vce_converged"] and 1 <= vce.extra["vce_rounds"] <= IsamParams().vce_max_rounds
    assert all(abs(r - 1) <= IsamParams().vce_tol for r in vce.extra["vce_ratio"].values())
    # the σ moved away from the dataset's (else this checks nothing) ...
    assert max(abs(np.log(f)) for f in vce.extra["vce_factor"].values()) > np.log(1.1)
    # ... and the result is the batch optimum under them: LM from the default-noise optimum lands on it
    _same_optimum(vce, _batch_with_sigmas(inputs, vce, plain))
    return vce


@pytest.mark.slow
def test_vce_noise_on_loop_keeps_the_association_and_is_the_batch_optimum_of_its_sigmas(loop_nn):
    ds, plain = loop_nn
    _check_vce(ds.inputs, plain)


@pytest.mark.slow
def test_vce_noise_on_the_victoria_park_excerpt():
    from slamcli.datasets.victoria_park import import_victoria_park
    from slamcli.solvers.sensor_frame import to_sensor_frame

    ds = import_victoria_park(DATA / "victoria_park_excerpt", duration=30.0)
    vce = _check_vce(to_sensor_frame(ds.inputs))
    assert vce.extra["association"] == "nn"


def test_vce_noise_refuses_a_robust_kernel():
    from slamcli.errors import SolverError

    ds = simulate_scenario("loop", seed=1, overrides={"sensor.report_ids": True, "n_steps": 100})
    with pytest.raises(SolverError, match="noise=vce .* needs robust=none"):
        IsamSlam(IsamParams(noise="vce", robust="cauchy")).solve(ds.inputs, rng=np.random.default_rng(0))
    with pytest.raises(ValueError):
        IsamParams(noise="given")
    with pytest.raises(ValueError):
        IsamParams(vce_max_rounds=0)
