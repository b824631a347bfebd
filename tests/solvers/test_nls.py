"""The sparse NLS engine and the graph factors, checked against finite differences, scipy and dense algebra."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.optimize as so
from conftest import tiny_dataset

from slamcli.models import se2
from slamcli.solvers import graph, nls
from slamcli.types import Status


def _num_jac(f, x, eps=1e-6):
    """Central differences of ``f: (n,) -> (m,)`` at ``x``."""
    x = np.asarray(x, float)
    cols = []
    for i in range(x.size):
        d = np.zeros_like(x)
        d[i] = eps
        cols.append((f(x + d) - f(x - d)) / (2 * eps))
    return np.stack(cols, -1)


def _small_problem(model="gtsam", T=25, n_landmarks=5, seed=3, **kw):
    ds = tiny_dataset(T=T, n_landmarks=n_landmarks, seed=seed, report_ids=True, clutter_every=0, **kw)
    inp = ds.inputs
    from slamcli.solvers import frontend

    assoc = frontend.associate_reported(inp.observations)
    L = int(assoc.max()) + 1
    p0 = graph.odometry_initial_poses(inp)
    lm0 = frontend.landmarks_from_observations(p0, inp.observations, assoc, L)
    if model == "gtsam":
        gp = graph.build_gtsam_problem(
            inp, assoc, p0, lm0, graph.GraphParams(use_controls=True, estimate_range_bias=True)
        )
    else:
        R = np.diag([2.0, 3.0, 5.0])
        S = np.array([[4.0, 1.0, 0.0], [1.0, 3.0, 0.5], [0.0, 0.5, 2.0]])
        Q = np.array([[1.5, 0.2], [0.2, 1.0]])
        gp = graph.build_paper_problem(inp, assoc, R, S, Q, p0, lm0)
    return ds, gp


# ---------------------------------------------------------------------------------------------------------
# Jacobians
# ---------------------------------------------------------------------------------------------------------
def test_log_jacobian_matches_finite_differences_including_small_angles():
    rng = np.random.default_rng(0)
    # (finite differences of se2.log are only trustworthy where its (1−cos w)/w is: |w| ≫ 1e-6 or w ≈ 0)
    pts = np.column_stack([rng.normal(0, 2, 8), rng.normal(0, 2, 8), np.r_[rng.uniform(-3, 3, 6), 0.0, 2e-8]])
    for p in pts:
        Jn = _num_jac(se2.log, p, eps=1e-7 if abs(p[2]) > 1e-3 else 1e-9)
        np.testing.assert_allclose(graph.log_jacobian(p), Jn, atol=2e-7)
    # the small-angle series branch joins the closed form continuously at its switch (|w| = 1e-4)
    lo = graph.log_jacobian(np.array([1.3, -0.7, 0.999999e-4]))
    hi = graph.log_jacobian(np.array([1.3, -0.7, 1.000001e-4]))
    np.testing.assert_allclose(lo, hi, atol=1e-10)


def _fd_wrt(fun, args, which):
    """Central-difference Jacobian of ``fun(*args)[0][0]`` w.r.t. ``args[which][0]`` (single-factor arrays)."""

    def f(v):
        a = list(args)
        a[which] = v[None]
        return fun(*a)[0][0]

    return _num_jac(f, args[which][0])


def test_factor_error_jacobians_match_finite_differences():
    rng = np.random.default_rng(1)
    F = 6
    xi = np.column_stack([rng.normal(0, 3, F), rng.normal(0, 3, F), rng.uniform(-3, 3, F)])
    xj = np.column_stack([rng.normal(0, 3, F), rng.normal(0, 3, F), rng.uniform(-3, 3, F)])
    meas = np.column_stack([rng.normal(0, 1, F), rng.normal(0, 1, F), rng.uniform(-1, 1, F)])
    m = rng.normal(0, 4, (F, 2))
    z = np.column_stack([rng.uniform(1, 5, F), rng.uniform(-3, 3, F)])
    _, Ji, Jj = graph.between_error(xi, xj, meas)
    _, Jp = graph.prior_error(xi, meas)
    _, Jx, Jm = graph.bearing_range_error(xi, m, z)
    for f in range(F):
        s = slice(f, f + 1)
        np.testing.assert_allclose(Ji[f], _fd_wrt(graph.between_error, (xi[s], xj[s], meas[s]), 0), atol=1e-6)
        np.testing.assert_allclose(Jj[f], _fd_wrt(graph.between_error, (xi[s], xj[s], meas[s]), 1), atol=1e-6)
        np.testing.assert_allclose(Jp[f], _fd_wrt(graph.prior_error, (xi[s], meas[s]), 0), atol=1e-6)
        np.testing.assert_allclose(
            Jx[f], _fd_wrt(graph.bearing_range_error, (xi[s], m[s], z[s]), 0), atol=1e-6
        )
        np.testing.assert_allclose(
            Jm[f], _fd_wrt(graph.bearing_range_error, (xi[s], m[s], z[s]), 1), atol=1e-6
        )


def test_between_error_is_zero_at_the_measurement_and_equals_log():
    xi = np.array([[1.0, 2.0, 0.3]])
    d = np.array([[0.5, -0.2, 0.4]])
    xj = se2.compose(xi, d)
    e, _, _ = graph.between_error(xi, xj, d)
    np.testing.assert_allclose(e, 0.0, atol=1e-12)
    # a known non-zero: measured identity → error is Log(between)
    e, _, _ = graph.between_error(xi, xj, np.zeros((1, 3)))
    np.testing.assert_allclose(e, se2.log(d), atol=1e-12)


@pytest.mark.parametrize("model", ["gtsam", "paper"])
def test_every_block_jacobian_matches_finite_differences(model):
    _, gp = _small_problem(model, T=12, n_landmarks=4, gps_every=4)
    x = gp.x0 + np.random.default_rng(2).normal(0, 0.05, gp.x0.size)
    names = set()
    for b in gp.problem.blocks:
        names.add(b.name)
        _, J = b.evaluate(x)
        for f in range(0, b.n_factors, max(1, b.n_factors // 7)):
            cols = b.cols[f]

            def rf(v, f=f, cols=cols, b=b):
                xx = x.copy()
                xx[cols] = v
                return b.evaluate(xx)[0][f]

            np.testing.assert_allclose(J[f], _num_jac(rf, x[cols]), atol=2e-6, err_msg=f"{b.name} factor {f}")
    expected = (
        {"prior", "odometry", "motion", "bearing_range", "gps"}
        if model == "gtsam"
        else {"motion", "odometry", "observation"}
    )
    assert names == expected


def test_body_chart_jacobians_match_finite_differences_of_the_retraction():
    """``evaluate_body`` (the between factors' and the prior's fused body-chart Jacobians) against central
    differences of the residual under GTSAM's retraction ``x_p ⊕ Exp(ξ)`` of each pose, and the residuals equal
    ``evaluate``'s."""
    _, gp = _small_problem("gtsam", T=12, n_landmarks=4)
    x = gp.x0 + np.random.default_rng(6).normal(0, 0.3, gp.x0.size)
    fused = [b for b in gp.problem.blocks if b.evaluate_body is not None]
    assert {b.name for b in fused} >= {"prior", "odometry"}
    for b in fused:
        r, J = b.evaluate_body(x)
        np.testing.assert_allclose(r, b.evaluate(x)[0], rtol=0, atol=1e-15)
        for f in range(b.n_factors):
            for o in range(0, b.cols.shape[1], 3):  # one pose per column triplet
                c = b.cols[f, o : o + 3]

                def rf(xi, f=f, c=c, b=b):
                    xx = x.copy()
                    xx[c] = se2.compose(x[c], se2.exp(xi))
                    return b.evaluate(xx)[0][f]

                np.testing.assert_allclose(J[f][:, o : o + 3], _num_jac(rf, np.zeros(3)), atol=2e-6,
                                           err_msg=f"{b.name} factor {f}")


# ---------------------------------------------------------------------------------------------------------
# optimiser
# ---------------------------------------------------------------------------------------------------------
def test_lm_and_gn_reach_the_same_optimum_and_it_equals_scipy_least_squares():  # incl. a range-bias variable
    _, gp = _small_problem("gtsam", T=20, n_landmarks=5)
    lm = nls.solve(gp.problem, gp.x0, nls.NlsParams(method="lm"))
    gn = nls.solve(gp.problem, gp.x0, nls.NlsParams(method="gn"))
    assert lm.status == Status.CONVERGED and gn.status == Status.CONVERGED
    assert lm.cost_trace[0] > 1.5 * lm.cost  # it actually optimised something
    assert np.all(np.diff(lm.cost_trace) <= 1e-9 * lm.cost_trace[0])  # LM only accepts decreases
    np.testing.assert_allclose(lm.x, gn.x, atol=1e-8)
    assert abs(lm.cost - gn.cost) <= 1e-10 * lm.cost

    ref = so.least_squares(
        lambda v: nls.residual_vector(gp.problem, v),
        gp.x0,
        jac=lambda v: nls.jacobian_matrix(gp.problem, v).toarray(),
        method="lm",
        xtol=1e-15,
        ftol=1e-15,
        gtol=1e-15,
    )
    assert abs(ref.cost - lm.cost) <= 1e-9 * lm.cost
    np.testing.assert_allclose(lm.x, ref.x, atol=1e-7)


def test_paper_model_cost_is_the_weighted_energy_and_lm_matches_scipy():
    ds, gp = _small_problem("paper", T=15, n_landmarks=4)
    res = nls.solve(gp.problem, gp.x0)
    assert res.status == Status.CONVERGED
    free = np.setdiff1d(np.arange(gp.x0.size), gp.problem.fixed_cols)
    assert free.size == gp.x0.size - 3  # x_0 is held fixed (known start pose)

    def full(v):
        x = gp.x0.copy()
        x[free] = v
        return x

    ref = so.least_squares(
        lambda v: nls.residual_vector(gp.problem, full(v)),
        gp.x0[free],
        jac=lambda v: nls.jacobian_matrix(gp.problem, full(v)).toarray()[:, free],
        method="lm",
        xtol=1e-15,
        ftol=1e-15,
        gtol=1e-15,
    )
    np.testing.assert_array_equal(res.x[:3], gp.x0[:3])
    assert abs(ref.cost - res.cost) <= 1e-9 * res.cost
    np.testing.assert_allclose(res.x[free], ref.x, atol=1e-7)
    # the cost is the paper's energy Σ rᵀWr computed independently from slamcli.models.potentials
    from slamcli.models import potentials
    from slamcli.solvers import frontend

    inp = ds.inputs
    P, lm = gp.unpack(res.x)
    assoc = frontend.associate_reported(inp.observations)
    R = np.diag([2.0, 3.0, 5.0])
    S = np.array([[4.0, 1.0, 0.0], [1.0, 3.0, 0.5], [0.0, 0.5, 2.0]])
    Q = np.array([[1.5, 0.2], [0.2, 1.0]])
    obs = inp.observations
    E = (
        potentials.weighted_sq(potentials.motion_residual(P[:-1], inp.controls, P[1:], inp.dt), R)
        + potentials.weighted_sq(
            potentials.odometry_residual(P[:-1], P[1:], inp.odometry_xyt[:-1], inp.odometry_xyt[1:]), S
        )
        + potentials.weighted_sq(potentials.observation_residual(P[obs.step], obs.z, lm[assoc]), Q)
    )
    assert res.cost == pytest.approx(E, rel=1e-12)
    assert graph.paper_energy(inp, assoc, R, S, Q, P, lm) == pytest.approx(E, rel=1e-12)


def test_huber_irls_equals_scipy_huber_loss_on_scalar_residuals():
    """Robust line fit y = a + b t with outliers; scalar residuals → per-factor Huber = scipy's 'huber'."""
    rng = np.random.default_rng(4)
    t = np.linspace(0, 10, 60)
    y = 1.0 + 0.5 * t + rng.normal(0, 0.1, t.size)
    y[::9] += 5.0
    sigma, k = 0.1, 1.345

    def ev(x):
        r = (x[0] + x[1] * t - y)[:, None]
        J = np.stack([np.ones_like(t), t], -1)[:, None, :]
        return r, J

    block = nls.FactorBlock("line", np.tile([0, 1], (t.size, 1)), ev, np.array([[1.0 / sigma]]), robust=True)
    prob = nls.NlsProblem(2, [block])
    res = nls.solve(prob, np.zeros(2), nls.NlsParams(robust="huber", huber_k=k, max_iterations=200))
    assert res.status == Status.CONVERGED
    ref = so.least_squares(
        lambda x: (x[0] + x[1] * t - y) / sigma,
        np.zeros(2),
        loss="huber",
        f_scale=k,
        xtol=1e-15,
        ftol=1e-15,
        gtol=1e-15,
    )
    np.testing.assert_allclose(res.x, ref.x, atol=1e-7)
    assert res.cost == pytest.approx(ref.cost, rel=1e-9)
    # the plain L2 fit is pulled by the outliers; Huber is close to the truth
    l2 = nls.solve(prob, np.zeros(2))
    assert abs(res.x[0] - 1.0) < abs(l2.x[0] - 1.0)


def test_fixed_columns_do_not_move():
    _, gp = _small_problem("gtsam", T=10, n_landmarks=3)
    prob = gp.problem
    fixed = np.array([3, 4, 5, 3 * gp.n_poses])  # pose 1 and landmark 0's x
    prob2 = nls.NlsProblem(prob.n_vars, prob.blocks, prob.angle_cols, fixed_cols=fixed, chain=prob.chain)
    x0 = gp.x0.copy()
    res = nls.solve(prob2, x0)
    np.testing.assert_array_equal(res.x[fixed], x0[fixed])
    free = nls.solve(prob, x0)
    assert res.cost >= free.cost - 1e-9


# ---------------------------------------------------------------------------------------------------------
# linear algebra: chain/Schur solver and marginals vs dense
# ---------------------------------------------------------------------------------------------------------
def test_chain_solver_equals_dense_solve():
    _, gp = _small_problem("gtsam", T=30, n_landmarks=6)
    asm = nls.Assembler(gp.problem)
    _, data, g = asm.linearize(gp.x0, nls.NlsParams())
    cs = nls.ChainSolver(asm, gp.n_poses, 3)
    assert cs.ok
    H = asm.matrix(data).toarray()
    np.testing.assert_allclose(cs.solve(data, -g), np.linalg.solve(H, -g), rtol=1e-9, atol=1e-12)


def test_marginal_covariances_equal_blocks_of_the_dense_inverse():
    _, gp = _small_problem("gtsam", T=30, n_landmarks=6)
    res = nls.solve(gp.problem, gp.x0)
    H = res.information
    Hinv = np.linalg.inv(H.toarray())
    ip, il = gp.pose_cols(), gp.landmark_cols()
    ref_p = Hinv[ip[:, :, None], ip[:, None, :]]
    ref_l = Hinv[il[:, :, None], il[:, None, :]]
    scale_p, scale_l = np.abs(ref_p).max(), np.abs(ref_l).max()
    # general sparse column solves (small batches exercise the batching)
    mp = nls.marginal_covariances(H, ip, batch_size=16)
    ml = nls.marginal_covariances(H, il, batch_size=16)
    assert np.abs(mp - ref_p).max() <= 1e-10 * scale_p
    assert np.abs(ml - ref_l).max() <= 1e-10 * scale_l
    # chain + border elimination
    cp, border = nls.marginals_chain_border(H, gp.n_poses, 3)
    assert np.abs(cp - ref_p).max() <= 1e-10 * scale_p
    n = 3 * gp.n_poses
    assert np.abs(border - Hinv[n:, n:]).max() <= 1e-10 * np.abs(Hinv[n:, n:]).max()
    # and the graph helper picks these blocks
    pose_cov, lm_cov = graph.laplace_marginals(gp, H)
    assert np.abs(pose_cov - ref_p).max() <= 1e-10 * scale_p
    assert np.abs(lm_cov - ref_l).max() <= 1e-10 * scale_l
    # marginal ≠ conditional: the conditional (H_ii)⁻¹ is smaller (overconfident)
    cond = np.linalg.inv(H.toarray()[ip[-1][:, None], ip[-1][None, :]])
    assert np.trace(pose_cov[-1]) > 2 * np.trace(cond)


# ---------------------------------------------------------------------------------------------------------
# numerically indefinite normal equations (MRCLAM robot 5: a landmark estimated on top of a pose makes the
# bearing Jacobian ∝ 1/r explode, H gets entries of 1e24 next to 1e4 and the banded Cholesky breaks down)
# ---------------------------------------------------------------------------------------------------------
def _exploding_chain(n=6, d0=1e-24):
    """Chain ``x_0..x_{n-1}`` (k = 1): prior ``x_0 = 0``, odometry ``x_{i+1} − x_i = 1`` and one nonlinear
    factor ``r = √|x_2 − x_1| − 1`` whose Jacobian ``±1 / (2√|x_2 − x_1|)`` explodes as the gap closes — as a
    bearing does at range → 0. Started with a gap ``d0 = 1e-24`` it puts ``≈ 2.5e23`` into the 2×2 block
    of ``H`` next to entries of order 1: in double precision the block is rank 1 and the banded Cholesky
    meets a zero pivot, although ``J`` has full column rank. The optimum is ``x_i = i`` (zero cost)."""

    def ev_prior(x):
        return x[:1, None], np.ones((1, 1, 1))

    def ev_odo(x):
        return (x[1:] - x[:-1] - 1.0)[:, None], np.tile(np.array([[[-1.0, 1.0]]]), (n - 1, 1, 1))

    def ev_gap(x):
        d = x[2] - x[1]
        dr = np.sign(d) / (2.0 * np.sqrt(abs(d)))
        return np.array([[np.sqrt(abs(d)) - 1.0]]), np.array([[[-dr, dr]]])

    blocks = [
        nls.FactorBlock("prior", np.array([[0]]), ev_prior, np.eye(1)),
        nls.FactorBlock("odometry", np.column_stack([np.arange(n - 1), np.arange(1, n)]), ev_odo, np.eye(1)),
        nls.FactorBlock("gap", np.array([[1, 2]]), ev_gap, np.eye(1)),
    ]
    x0 = np.zeros(n)
    x0[2] = d0
    return nls.NlsProblem(n_vars=n, blocks=blocks, chain=(n, 1)), x0


def test_banded_cholesky_breakdown_falls_back_and_gauss_newton_takes_damped_steps():
    prob, x0 = _exploding_chain()
    asm = nls.Assembler(prob)
    _, data, g = asm.linearize(x0, nls.NlsParams())
    assert nls.ChainSolver(asm, 6, 1).solve(data, -g) is None  # the breakdown this test is about
    # before the fix GN stopped at x0 with FAILED "singular normal equations"
    gn = nls.solve(prob, x0, nls.NlsParams(method="gn", linear_solver="chain"))
    assert gn.status == Status.CONVERGED and np.all(np.isfinite(gn.x))
    np.testing.assert_allclose(gn.x, np.arange(6.0), atol=1e-8)
    assert any("banded Cholesky" in n for n in gn.notes) and any("damped" in n for n in gn.notes)
    if nls.cholmod_available():  # the default solver meets the same breakdown and falls back the same way
        gn2 = nls.solve(prob, x0, nls.NlsParams(method="gn", linear_solver="cholmod"))
        np.testing.assert_allclose(gn2.x, np.arange(6.0), atol=1e-8)
        assert any("CHOLMOD" in n for n in gn2.notes)
    lm = nls.solve(prob, x0, nls.NlsParams(method="lm"))
    assert lm.status == Status.CONVERGED
    np.testing.assert_allclose(lm.x, np.arange(6.0), atol=1e-8)


def test_iterations_are_accepted_steps_and_the_message_says_so():
    """An iteration = one accepted step (GTSAM's count); rejected LM trials do not use up the budget.
    Before the fix the budget counted linear solves, so a run could say "stopped after 5 iterations" with
    one accepted step in its trace (Victoria Park: "71 iterations" in the trace vs "stopped after 100")."""

    def ev(x):  # Rosenbrock: LM from (−1.2, 1) with λ₀ = 1e-5 rejects many trial steps
        return np.array([[10 * (x[1] - x[0] ** 2), 1 - x[0]]]), np.array([[[-20 * x[0], 10.0], [-1.0, 0.0]]])

    prob = nls.NlsProblem(n_vars=2, blocks=[nls.FactorBlock("rosenbrock", np.array([[0, 1]]), ev, np.eye(2))])
    seen = []
    res = nls.solve(
        prob, np.array([-1.2, 1.0]), nls.NlsParams(max_iterations=5), callback=lambda k, x, c: seen.append(k)
    )
    assert res.status == Status.MAX_ITERATIONS and res.message.startswith("stopped after 5 iterations")
    assert res.iterations == 5 == len(res.cost_trace) - 1 == len(res.time_trace) - 1
    assert seen == [0, 1, 2, 3, 4, 5]
    assert res.linear_solves > res.iterations  # rejected steps happened and were not counted
    assert np.all(np.diff(res.cost_trace) < 0)
    full = nls.solve(prob, np.array([-1.2, 1.0]))
    assert full.status == Status.CONVERGED and full.iterations == len(full.cost_trace) - 1
    np.testing.assert_allclose(full.x, [1.0, 1.0], atol=1e-8)


def test_marginals_refuse_an_indefinite_information_matrix():
    prob, x0 = _exploding_chain()
    asm = nls.Assembler(prob)
    H = asm.matrix(asm.linearize(x0, nls.NlsParams())[1])  # H at the near-singular start
    with pytest.raises(nls.NotPositiveDefiniteError) as exc:
        nls.marginals_chain_border(H, 6, 1)
    assert exc.value.column == 2  # x_2: the 2×2 block of the gap factor is numerically rank 1
    with pytest.raises(np.linalg.LinAlgError):
        nls.factorize_information(H, require_positive_definite=True)
    # at the optimum the same problem is well conditioned and its marginals are those of the dense inverse
    Hopt = nls.solve(prob, x0).information
    cov, _ = nls.marginals_chain_border(Hopt, 6, 1)
    np.testing.assert_allclose(cov[:, 0, 0], np.diag(np.linalg.inv(Hopt.toarray())), rtol=1e-12)
    # covariance blocks: accepted only if finite and positive definite
    good = np.array([[[2.0, 0.5], [0.5, 1.0]]] * 3)
    nls.check_covariance_blocks(good, "landmark")
    bad = good.copy()
    bad[1] = [[1.0, 2.0], [2.0, 1.0]]  # eigenvalues 3, −1
    with pytest.raises(np.linalg.LinAlgError, match=r"landmark 1: .*eigenvalue -1 ≤ 0"):
        nls.check_covariance_blocks(bad, "landmark")
    bad[1] = np.nan
    with pytest.raises(np.linalg.LinAlgError, match="landmark 1: non-finite"):
        nls.check_covariance_blocks(bad, "landmark")


@pytest.mark.parametrize("small_block", [4096, 0])  # batched einsum path / per-pair buffer path
def test_assembled_normal_equations_equal_the_dense_jacobian_products(monkeypatch, small_block):
    """H and g (full and lower-triangle assembly) against JᵀJ and Jᵀr of the stacked sparse Jacobian, on a
    problem mixing a landmark graph with a factor that touches one column twice (counts twice in H)."""
    from slamcli.solvers.nls import linear

    monkeypatch.setattr(linear, "SMALL_BLOCK", small_block)
    _, gp = _small_problem("gtsam", T=12, n_landmarks=4)
    rng = np.random.default_rng(3)
    cols = np.array([[3, 3, 7], [5, 9, 5]], np.int64)
    A = rng.normal(size=(2, 2, 3))

    def ev(x):
        return np.einsum("fkn,fn->fk", A, x[cols]), A

    L = np.triu(rng.normal(size=(2, 2, 2))) + 2.0 * np.eye(2)  # per-factor square-root information
    twice = nls.FactorBlock("twice", cols, ev, L)
    prob = nls.NlsProblem(gp.problem.n_vars, [*gp.problem.blocks, twice], gp.problem.angle_cols)
    x = gp.x0 + 0.01 * rng.normal(size=gp.x0.size)
    params = nls.NlsParams(pose_chart="world")
    asm = nls.Assembler(prob)
    _, data, g = asm.linearize(x, params)
    J = nls.jacobian_matrix(prob, x).toarray()
    r = nls.residual_vector(prob, x)
    np.testing.assert_allclose(asm.matrix(data).toarray(), J.T @ J, rtol=1e-12, atol=1e-9)
    np.testing.assert_allclose(g, J.T @ r, rtol=1e-12, atol=1e-9)
    lo = asm.linearize_lower(x, params)[1]
    np.testing.assert_array_equal(asm.full(lo), data)
    np.testing.assert_array_equal(asm.lower(data), lo)
    np.testing.assert_allclose(asm.lower_matrix(lo).toarray(), np.tril(J.T @ J), rtol=1e-12, atol=1e-9)


def test_assembler_on_another_assemblers_pattern_gives_the_same_normal_equations():
    """``Assembler(problem, like=other)``: a problem whose H fits in ``other``'s pattern (here the problem
    without its prior block) reuses that pattern and assembles JᵀJ, Jᵀr of its own stacked Jacobian (explicit
    zeros where only ``other`` has entries); a problem with an entry outside the pattern gets its own."""
    _, gp = _small_problem("gtsam", T=12, n_landmarks=4)
    big = nls.Assembler(gp.problem)
    sub = nls.NlsProblem(gp.problem.n_vars, [b for b in gp.problem.blocks if b.name != "prior"],
                         gp.problem.angle_cols, fixed_cols=np.arange(3))
    x = gp.x0 + 0.01 * np.random.default_rng(4).normal(size=gp.x0.size)
    params = nls.NlsParams(pose_chart="world")
    asm = nls.Assembler(sub, like=big)
    assert asm.lo_indices is big.lo_indices
    own = nls.Assembler(sub)
    for a in (asm, own):
        _, lo, g = a.linearize_lower(x, params)
        J = nls.jacobian_matrix(sub, x).toarray()
        J[:, :3] = 0.0  # held columns: identity rows in H, zero gradient
        ref = J.T @ J
        ref[:3, :3] = np.eye(3)
        np.testing.assert_allclose(a.matrix(a.full(lo)).toarray(), ref, rtol=1e-12, atol=1e-9)
        np.testing.assert_allclose(g, J.T @ nls.residual_vector(sub, x), rtol=1e-12, atol=1e-9)
    pattern = own.matrix(np.ones(own.nnz)).toarray() != 0
    a, b = np.argwhere(~pattern)[0]  # two columns no factor couples
    far = nls.FactorBlock("far", np.array([[a, b]]), lambda v: (v[None, [a, b]], np.ones((1, 2, 2))), np.eye(2))
    wider = nls.Assembler(nls.NlsProblem(sub.n_vars, [*sub.blocks, far], sub.angle_cols), like=own)
    assert wider.lo_indices is not own.lo_indices and wider.lo_nnz > own.lo_nnz


def test_assembler_on_stacked_blocks_of_another_pattern_gives_the_same_normal_equations():
    """A block whose factors are those of consecutive blocks of ``like`` (the certificate's one block of all
    edges over the LM problem's odometry and loop-closure blocks) takes ``like``'s scatter positions without a
    search: same pattern object, H and g equal to JᵀJ and Jᵀr of the dense Jacobian, scatter positions equal
    to the searched ones."""
    from slamcli.solvers.nls import linear

    _, gp = _small_problem("gtsam", T=12, n_landmarks=4)
    odo = next(b for b in gp.problem.blocks if b.name == "odometry")
    k = odo.n_factors // 2

    def part(sl):
        return nls.FactorBlock("half", odo.cols[sl], lambda v: tuple(a[sl] for a in odo.evaluate(v)), odo.sqrt_info)

    split = nls.NlsProblem(gp.problem.n_vars, [b if b is not odo else p for b in gp.problem.blocks
                                               for p in ((part(slice(0, k)), part(slice(k, None))) if b is odo else (b,))],
                           gp.problem.angle_cols)
    like = nls.Assembler(split)
    asm = nls.Assembler(gp.problem, like=like)
    assert asm.lo_indices is like.lo_indices
    sizes = [a.size * c.shape[0] for c, (a, _) in zip(asm.cols, asm.pairs)] + [asm.D]
    key = asm._keys(np.cumsum([0] + sizes))
    np.testing.assert_array_equal(linear._positions_by_blocks(like, asm.cols), linear._positions_in(like, key))
    x = gp.x0 + 0.01 * np.random.default_rng(5).normal(size=gp.x0.size)
    _, lo, g = asm.linearize_lower(x, nls.NlsParams(pose_chart="world"))
    J = nls.jacobian_matrix(gp.problem, x).toarray()
    np.testing.assert_allclose(asm.matrix(asm.full(lo)).toarray(), J.T @ J, rtol=1e-12, atol=1e-9)
    np.testing.assert_allclose(g, J.T @ nls.residual_vector(gp.problem, x), rtol=1e-12, atol=1e-9)


@pytest.mark.skipif(not nls.cholmod_available(), reason="needs CVXOPT's CHOLMOD")
def test_a_workspace_reuses_the_last_pattern_and_analysis_and_still_reaches_scipys_optimum():
    """``nls.solve(..., workspace=ws)``: a second problem whose H fits in the first one's pattern (the problem
    without its prior block) is solved on the first one's pattern and CHOLMOD analysis, and reaches scipy's
    ``least_squares`` optimum of its own residuals; a problem with a new entry gets a fresh analysis."""
    _, gp = _small_problem("gtsam", T=12, n_landmarks=4)
    sub = nls.NlsProblem(gp.problem.n_vars, [b for b in gp.problem.blocks if b.name != "prior"],
                         gp.problem.angle_cols, fixed_cols=np.arange(3))
    ws = nls.Workspace()
    nls.solve(gp.problem, gp.x0, workspace=ws)
    first = ws.lin.F
    x0 = gp.x0 + 0.02 * np.random.default_rng(6).normal(size=gp.x0.size)
    x0[:3] = gp.x0[:3]
    res = nls.solve(sub, x0, nls.NlsParams(rel_cost_tol=1e-14), workspace=ws)
    assert (ws.solves, ws.analyses) == (2, 1) and ws.lin.F is first
    free = np.arange(3, gp.x0.size)

    def full(v):
        x = x0.copy()
        x[free] = v
        return x

    ref = so.least_squares(lambda v: nls.residual_vector(sub, full(v)), x0[free],
                           jac=lambda v: nls.jacobian_matrix(sub, full(v)).toarray()[:, free], method="lm",
                           xtol=1e-15, ftol=1e-15, gtol=1e-15)
    assert res.status == Status.CONVERGED and abs(ref.cost - res.cost) <= 1e-9 * ref.cost
    np.testing.assert_allclose(res.x[free], ref.x, atol=1e-7)
    a, b = np.argwhere(ws.asm.matrix(np.ones(ws.asm.nnz)).toarray() == 0)[0]  # two columns no factor couples
    far = nls.FactorBlock("far", np.array([[a, b]]), lambda v: (v[None, [a, b]], np.ones((1, 2, 2))), np.eye(2))
    nls.solve(nls.NlsProblem(sub.n_vars, [*sub.blocks, far], sub.angle_cols, fixed_cols=np.arange(3)), x0,
              workspace=ws)
    assert (ws.solves, ws.analyses) == (3, 2) and ws.lin.F is not first


def test_residual_only_evaluation_equals_the_residuals_of_evaluate():
    """The Jacobian-free residuals LM's trial steps use are the ones ``evaluate`` returns, bit for bit
    (odometry, loop closures, bearing-range with a landmark on top of a pose)."""
    _, gp = _small_problem("gtsam", T=12, n_landmarks=4)
    x = gp.x0.copy()
    x[3 * gp.n_poses : 3 * gp.n_poses + 2] = x[3:5]  # landmark 0 on pose 1: GTSAM's zero-bearing branch
    with_residual = [b for b in gp.problem.blocks if b.residual is not None]
    assert {b.name for b in with_residual} >= {"prior", "odometry", "bearing_range"}
    for b in with_residual:
        np.testing.assert_array_equal(b.residuals(x), b.evaluate(x)[0])


@pytest.mark.skipif(not nls.cholmod_available(), reason="CHOLMOD does not import")
def test_cholmod_factor_refuses_an_indefinite_matrix_and_solves_a_definite_one():
    """The LDLᵀ factorisation runs through negative pivots, so the solver must test D: a matrix with one
    negative eigenvalue is refused (as LLᵀ's pivot failure was), the definite one solves as the dense solve."""
    _, gp = _small_problem("gtsam", T=12, n_landmarks=4)
    asm = nls.Assembler(gp.problem)
    _, data, g = asm.linearize(gp.x0, nls.NlsParams())
    lin = nls.make_linear_solver(asm, nls.NlsParams(linear_solver="cholmod"))
    H = asm.matrix(data).toarray()
    assert lin.factorize(data)
    np.testing.assert_allclose(lin.solve(g), np.linalg.solve(H, g), rtol=1e-9, atol=1e-12)
    shifted = data.copy()
    shifted[asm.diag_pos] -= 1.01 * np.linalg.eigvalsh(H)[0] + 1e-3 * np.abs(np.diag(H)).max()  # λ_min < 0
    assert np.linalg.eigvalsh(asm.matrix(shifted).toarray())[0] < 0
    assert not lin.factorize(shifted)


@pytest.mark.parametrize("small_block", [4096, 0])
def test_world_information_from_the_body_chart_equals_the_world_linearisation(monkeypatch, small_block):
    """``H_world = M H_body Mᵀ`` (M = blkdiag(R(θ), 1) per pose) against a linearisation in world coordinates."""
    from slamcli.solvers.nls import linear

    monkeypatch.setattr(linear, "SMALL_BLOCK", small_block)
    _, gp = _small_problem("gtsam", T=12, n_landmarks=4)
    x = gp.x0 + 0.05 * np.random.default_rng(5).normal(size=gp.x0.size)
    asm = nls.Assembler(gp.problem)
    body = asm.linearize(x, nls.NlsParams(pose_chart="body"))[1]
    world = asm.linearize(x, nls.NlsParams(pose_chart="world"))[1]
    np.testing.assert_allclose(asm.body_to_world(body, x), world, rtol=1e-10, atol=1e-8)


def test_fused_bearing_range_jacobian_equals_the_separate_one():
    """``bearing_range_jacobian`` (one array) against ``bearing_range_error`` (two), bit for bit, with a
    landmark on a pose (GTSAM's zero-bearing branch)."""
    from slamcli.solvers.graph.factors import bearing_range_error, bearing_range_jacobian

    rng = np.random.default_rng(6)
    x = rng.normal(size=(50, 3))
    m = rng.normal(size=(50, 2))
    m[7] = x[7, :2]
    z = rng.normal(size=(50, 2))
    with np.errstate(divide="ignore", invalid="ignore"):  # range Jacobian 0/0 at the coincident pair
        e, Jx, Jm = bearing_range_error(x, m, z)
        e2, J = bearing_range_jacobian(x, m, z)
    np.testing.assert_array_equal(e2, e)
    np.testing.assert_array_equal(J, np.concatenate([Jx, Jm], axis=2))


@pytest.mark.parametrize("k", [3, 2])
def test_pose_block_pattern_equals_the_sorted_pattern_and_assembles_the_dense_products(monkeypatch, k):
    """Blocks on whole poses of ``k`` columns (a prior on one pose; two-pose factors with a chain, loops in both
    directions, a repeated edge and an edge from a pose to itself): the pattern derived from the pose level
    (:func:`linear._pose_block_pattern`) is the one sorting every local pair gives, array for array, and the
    assembled H and g equal JᵀJ and Jᵀr of the stacked dense Jacobian. An untouched pose falls back to sorting."""
    from slamcli.solvers.nls import linear

    rng = np.random.default_rng(7)
    N = 9
    ij = np.array([(p, p + 1) for p in range(N - 1)] + [(6, 1), (0, 5), (2, 7), (6, 1), (4, 4), (8, 3)])
    cols2 = np.concatenate([k * ij[:, :1] + np.arange(k), k * ij[:, 1:] + np.arange(k)], axis=1)

    def block(name, cols, m):
        A = rng.normal(size=(cols.shape[0], m, cols.shape[1]))
        return nls.FactorBlock(name, cols, lambda x, A=A, c=cols: (np.einsum("fkn,fn->fk", A, x[c]), A), np.eye(m))

    def problem(n_poses, blocks):
        return nls.NlsProblem(k * n_poses, blocks)

    blocks = [block("prior", np.arange(k)[None, :], k), block("edges", cols2[:10], k), block("more", cols2[10:], k + 1)]
    x = rng.normal(size=k * N)
    params = nls.NlsParams(pose_chart="world")
    for prob, derived in ((problem(N, blocks), True), (problem(N + 1, blocks), False)):  # pose N: untouched
        assert (linear._pose_block_pattern([np.asarray(b.cols) for b in prob.blocks],
                                           [linear._local_pairs(b.cols.shape[1]) for b in prob.blocks],
                                           prob.n_vars) is not None) is derived
        fast = nls.Assembler(prob)
        monkeypatch.setattr(linear, "_pose_block_pattern", lambda *a: None)
        ref = nls.Assembler(prob)
        monkeypatch.undo()
        for name in ("lo_indices", "lo_indptr", "lo_diag_pos", "_scatter_all"):
            a, b = getattr(fast, name), getattr(ref, name)
            assert a.dtype == b.dtype
            np.testing.assert_array_equal(a, b)
        xx = np.concatenate([x, np.zeros(prob.n_vars - x.size)])
        _, lo, g = fast.linearize_lower(xx, params)
        J = nls.jacobian_matrix(prob, xx).toarray()
        np.testing.assert_allclose(fast.matrix(fast.full(lo)).toarray(), J.T @ J, rtol=1e-12, atol=1e-12)
        np.testing.assert_allclose(g, J.T @ nls.residual_vector(prob, xx), rtol=1e-12, atol=1e-12)


def test_bearing_range_jacobians_on_the_pose_follow_gtsams_convention():
    """A landmark exactly on its pose: range Jacobian [1, 1] w.r.t. the landmark (GTSAM's norm2 convention
    below 1e-10 m, −[1, 1] w.r.t. the position), zero bearing row (Rot2::relativeBearing), no NaN; a landmark
    1 m away keeps the closed-form Jacobian (m − p)/r."""
    import warnings

    from slamcli.solvers.graph.factors import bearing_range_error, bearing_range_jacobian

    x = np.array([[1.0, 2.0, 0.3], [1.0, 2.0, 0.3]])
    m = np.array([[1.0, 2.0], [1.6, 2.8]])  # on the pose; 1 m away along (0.6, 0.8)
    z = np.array([[0.5, 0.1], [0.5, 0.1]])
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        _, J = bearing_range_jacobian(x, m, z)
        _, J_x, J_m = bearing_range_error(x, m, z)
    for jm, jp in ((J[:, :, 3:], J[:, :, :2]), (J_m, J_x[:, :, :2])):
        np.testing.assert_array_equal(jm[0], [[1.0, 1.0], [0.0, 0.0]])
        np.testing.assert_array_equal(jp[0], [[-1.0, -1.0], [0.0, 0.0]])
        np.testing.assert_allclose(jm[1, 0], [0.6, 0.8], rtol=1e-12)
