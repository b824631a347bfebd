"""SE-Sync dual certificate of planar pose graphs (``slamcli.solvers.graph.certify``).

References independent of the certificate: the κ/τ conversion by hand, the SE-Sync objective evaluated
term by term from its definition, dense eigenvalues, a brute-force multistart for the global minimum of a toy
graph with two stationary points, and finite differences of the objective's gradient.
"""

from __future__ import annotations

import numpy as np
import pytest
from conftest import DATA

from slamcli.models import se2
from slamcli.solvers import nls
from slamcli.solvers.graph import certify


def _hexagon(noise: float, seed: int = 0):
    """Six poses on a unit hexagon, one loop (edges k → k+1 mod 6), measurements with seeded noise."""
    rng = np.random.default_rng(seed)
    th = np.arange(6) * np.pi / 3
    poses = np.column_stack([np.cos(th), np.sin(th), th + np.pi / 2])
    ij = np.array([(k, (k + 1) % 6) for k in range(6)])
    xyt = se2.between(poses[ij[:, 0]], poses[ij[:, 1]]) + noise * rng.normal(size=(6, 3))
    info = np.broadcast_to(np.diag([4.0, 9.0, 25.0]), (6, 3, 3)).copy()
    return poses, ij, xyt, info


def _rot(a: float) -> np.ndarray:
    return np.array([[np.cos(a), -np.sin(a)], [np.sin(a), np.cos(a)]])


def _F_by_definition(poses, ij, xyt, kappa, tau) -> float:
    """Σ κ‖R_j − R_i R̃‖²_F + τ‖t_j − t_i − R_i t̃‖², one edge at a time with 2×2 matrices."""
    F = 0.0
    for (i, j), m, k, t in zip(ij, xyt, kappa, tau):
        Ri, Rj = _rot(poses[i, 2]), _rot(poses[j, 2])
        F += k * np.sum((Rj - Ri @ _rot(m[2])) ** 2)
        F += t * np.sum((poses[j, :2] - poses[i, :2] - Ri @ m[:2]) ** 2)
    return float(F)


def _X_by_definition(poses) -> np.ndarray:
    """X = [t_1 … t_n | R_1 … R_n] (2, 3n)."""
    n = len(poses)
    X = np.zeros((2, 3 * n))
    X[:, :n] = poses[:, :2].T
    for i, a in enumerate(poses[:, 2]):
        X[:, n + 2 * i : n + 2 * i + 2] = _rot(a)
    return X


def _data_matrix_by_definition(n: int, ij, xyt, kappa, tau) -> np.ndarray:
    """Dense M (3n, 3n) = Σ_e κ_e A_e A_eᵀ + τ_e a_e a_eᵀ, columns [t_1 … t_n | R_1 e₁, R_1 e₂, …], one rank-one
    term at a time (A_e e_m = e_{R_j e_m} − E_{R_i} R̃ e_m, a_e = e_{t_j} − e_{t_i} − E_{R_i} t̃)."""
    M = np.zeros((3 * n, 3 * n))
    for (i, j), m, k, t in zip(ij, xyt, kappa, tau):
        for col in range(2):
            v = np.zeros(3 * n)
            v[n + 2 * j + col] += 1.0
            v[n + 2 * i : n + 2 * i + 2] -= _rot(m[2])[:, col]
            M += k * np.outer(v, v)
        v = np.zeros(3 * n)
        v[j] += 1.0
        v[i] -= 1.0
        v[n + 2 * i : n + 2 * i + 2] -= m[:2]
        M += t * np.outer(v, v)
    return M


def _certificate_by_definition(poses, ij, xyt, kappa, tau) -> tuple[np.ndarray, float]:
    """Dense (S, tr Λ) with S = M − blkdiag(0, Λ_1, …, Λ_n), Λ_i = Sym(G_i R_i), G = M Xᵀ (module docstring of
    the certificate), columns as :func:`_data_matrix_by_definition`."""
    n = len(poses)
    M = _data_matrix_by_definition(n, ij, xyt, kappa, tau)
    X = _X_by_definition(poses)
    G = M @ X.T
    S, dual = M.copy(), 0.0
    for i in range(n):
        L = G[n + 2 * i : n + 2 * i + 2] @ X[:, n + 2 * i : n + 2 * i + 2]
        S[n + 2 * i : n + 2 * i + 2, n + 2 * i : n + 2 * i + 2] -= 0.5 * (L + L.T)
        dual += np.trace(L)
    return S, float(dual)


def test_isotropic_weights_by_hand():
    info = np.array([[[4.0, 1.0, 0.5], [1.0, 2.0, 0.0], [0.5, 0.0, 7.0]]])
    kappa, tau = certify.isotropic_weights(info)
    cov = np.linalg.inv(np.array([[4.0, 1.0], [1.0, 2.0]]))  # = [[2, -1], [-1, 4]] / 7
    assert kappa[0] == 7.0
    assert tau[0] == pytest.approx(2.0 / (cov[0, 0] + cov[1, 1]))
    assert tau[0] == pytest.approx(14.0 / 6.0)


def test_objective_agrees_with_the_definition():
    """sesync_cost against F term by term; and the reference data matrix the certificate tests use against the
    same F (F = tr(X M Xᵀ), module docstring of the certificate)."""
    poses, ij, xyt, info = _hexagon(0.2)
    kappa, tau = certify.isotropic_weights(info)
    x = poses + np.random.default_rng(1).normal(scale=0.3, size=poses.shape)
    ref = _F_by_definition(x, ij, xyt, kappa, tau)
    assert certify.sesync_cost(x, ij, xyt, kappa, tau) == pytest.approx(ref, rel=1e-12)
    M = _data_matrix_by_definition(6, ij, xyt, kappa, tau)
    X = _X_by_definition(x)
    assert np.trace(X @ M @ X.T) == pytest.approx(ref, rel=1e-12)


def test_refinement_reaches_a_stationary_point_by_finite_differences():
    poses, ij, xyt, info = _hexagon(0.2)
    kappa, tau = certify.isotropic_weights(info)
    x = certify.refine_sesync(poses, ij, xyt, kappa, tau)
    h = 1e-6
    grad = np.zeros(x.size)
    for k in range(x.size):
        e = np.zeros(x.size)
        e[k] = h
        grad[k] = (certify.sesync_cost((x.ravel() + e).reshape(-1, 3), ij, xyt, kappa, tau)
                   - certify.sesync_cost((x.ravel() - e).reshape(-1, 3), ij, xyt, kappa, tau)) / (2 * h)
    assert np.max(np.abs(grad)) < 1e-6


def test_closed_form_gradient_of_the_sesync_objective_by_finite_differences():
    """The refinement's cost and gradient without Jacobians (``_Edges.cost_gradient``) against ½F by definition
    and its central differences, at a point far from stationary (every term of the gradient non-zero)."""
    poses, ij, xyt, info = _hexagon(0.2)
    kappa, tau = certify.isotropic_weights(info)
    x = poses + np.random.default_rng(2).normal(scale=0.3, size=poses.shape)
    cost, g = certify._Edges(ij, xyt, kappa, tau).cost_gradient(x)
    assert cost == pytest.approx(0.5 * _F_by_definition(x, ij, xyt, kappa, tau), rel=1e-12)
    h = 1e-6
    fd = np.zeros(x.size)
    for k in range(x.size):
        e = np.zeros(x.size)
        e[k] = h
        fd[k] = 0.5 * (_F_by_definition((x.ravel() + e).reshape(-1, 3), ij, xyt, kappa, tau)
                       - _F_by_definition((x.ravel() - e).reshape(-1, 3), ij, xyt, kappa, tau)) / (2 * h)
    assert np.max(np.abs(g - fd)) < 1e-7 * max(1.0, np.max(np.abs(fd)))


def test_closed_form_gauss_newton_matrix_by_finite_difference_jacobian():
    """``_Edges.gauss_newton``'s ``JᵀJ`` (pose 0 held: identity rows) against ``JᵀJ`` of a central-difference
    Jacobian of the residuals, on the hexagon plus two chords (poses with three and more edges)."""
    poses, ij, xyt, info = _hexagon(0.2)
    ij = np.concatenate([ij, [[0, 3], [4, 1]]])
    xyt = np.concatenate([xyt, [[0.3, -1.9, 3.0], [-1.1, 1.6, -2.0]]])
    kappa, tau = certify.isotropic_weights(np.concatenate([info, info[:2] * 2.0]))
    edges = certify._Edges(ij, xyt, kappa, tau)
    asm = nls.Assembler(certify._sesync_problem(6, edges))
    x = poses + np.random.default_rng(3).normal(scale=0.3, size=poses.shape)
    cost, lo, g = edges.gauss_newton(x, asm)
    h = 1e-6
    J = np.zeros((4 * len(ij), x.size))
    for k in range(x.size):
        e = np.zeros(x.size)
        e[k] = h
        J[:, k] = (edges.residuals((x.ravel() + e).reshape(-1, 3)).ravel()
                   - edges.residuals((x.ravel() - e).reshape(-1, 3)).ravel()) / (2 * h)
    ref = J.T @ J
    ref[:3], ref[:, :3] = 0.0, 0.0
    ref[:3, :3] = np.eye(3)
    L = asm.lower_matrix(lo).toarray()
    H = L + L.T - np.diag(np.diag(L))
    assert np.max(np.abs(H - ref)) < 1e-6 * np.max(np.abs(ref))
    assert cost == pytest.approx(0.5 * _F_by_definition(x, ij, xyt, kappa, tau), rel=1e-12)


def test_certifies_the_global_minimum_and_refuses_the_local_one():
    """One loop of six poses has a stationary point per winding number of the rotations: winding 0 is the
    global minimum, winding 1 (each edge's rotation off by ≈ 60°) a local one. A brute-force multistart
    finds the global value independently of the certificate."""
    poses, ij, xyt, info = _hexagon(0.15, seed=2)
    kappa, tau = certify.isotropic_weights(info)
    rng = np.random.default_rng(5)
    starts = [np.column_stack([rng.normal(scale=2, size=(6, 2)), rng.uniform(-np.pi, np.pi, 6)]) for _ in range(40)]
    values = [certify.sesync_cost(certify.refine_sesync(s, ij, xyt, kappa, tau), ij, xyt, kappa, tau) for s in starts]
    f_global = min(values)

    good = certify.certify_pose_graph(poses, ij, xyt, info)
    assert good.certified
    assert good.sesync_cost == pytest.approx(f_global, rel=1e-9)
    assert good.dual_bound == pytest.approx(good.sesync_cost, rel=1e-9)  # zero duality gap
    assert good.lambda_min >= -good.eta

    wound = poses.copy()
    wound[:, 2] += np.arange(6) * np.pi / 3  # rotations wound once more around the loop
    bad = certify.certify_pose_graph(wound, ij, xyt, info)
    assert bad.sesync_cost > f_global + 1.0  # a different, worse stationary point
    assert not bad.certified and np.isnan(bad.suboptimality_bound)
    assert bad.lambda_min < -bad.eta
    # λ_min against the dense spectrum of the certificate matrix built from the definition
    S, _ = _certificate_by_definition(bad.poses_xyt, ij, xyt, kappa, tau)
    assert bad.lambda_min == pytest.approx(np.linalg.eigvalsh(S)[0], rel=1e-8)


@pytest.mark.parametrize("rank_deficit", [0, 4])
@pytest.mark.slow
def test_certified_lambda_min_by_inverse_iteration_equals_the_dense_eigenvalue(rank_deficit):
    """Above the dense size, a certified λ_min comes from inverse iteration with the factorisation of
    S + ηI the test made: against numpy's dense eigvalsh on PSD matrices with and without a null space."""
    import scipy.sparse as sp

    n = certify.DENSE_EIG_MAX + 60
    A = sp.random(n, n - rank_deficit, density=0.01, random_state=5) + sp.eye(n, n - rank_deficit)
    S = (A @ A.T).tocsc() + (0.0 if rank_deficit else 0.3) * sp.eye(n, format="csc")
    eta = certify.ETA_REL * float(np.max(S.diagonal()))
    ok, solve = certify._is_positive_definite((S + eta * sp.identity(n, format="csc")).tocsc())
    assert ok
    lam, method = certify._lambda_min(S, eta, True, solve)
    assert method in ("inverse iteration", "Lanczos")
    ref = np.linalg.eigvalsh(S.toarray())[0]
    assert lam == pytest.approx(ref, abs=1e-9 * float(np.max(S.diagonal())))


def test_refinement_reaches_a_stationary_point_where_the_duality_gap_closes():
    """At a stationary point of F the multipliers make F = tr(Λ) (module docstring); the refinement must get
    there to rounding, not stop where F's decrease merely drops below its rounding (the intel excerpt, from
    a perturbed chordal start)."""

    from slamcli.datasets.g2o import import_graph
    from slamcli.solvers.graph.init import initial_poses, pose_graph_edges

    inp = import_graph(DATA / "intel_excerpt.g2o").inputs
    ij, xyt, info = pose_graph_edges(inp, True)
    start = initial_poses(inp, "chordal") + np.random.default_rng(2).normal(scale=0.01, size=(inp.n_poses, 3))
    cert = certify.certify_pose_graph(start, ij, xyt, info)
    assert cert.certified
    assert abs(cert.sesync_cost - cert.dual_bound) <= 1e-11 * cert.sesync_cost


def test_certificate_matrix_on_the_refinement_pattern_is_the_permuted_definition():
    """S assembled on the refinement's sparsity pattern (pose-interleaved columns [t_i, R_i e₁, R_i e₂]) equals
    M − blkdiag(0, Λ) built densely from the definition (data matrix by its rank-one terms, Λ_i = Sym(G_i R_i))
    after the permutation; tr(Λ) is the dual bound."""
    poses, ij, xyt, info = _hexagon(0.2, seed=3)
    kappa, tau = certify.isotropic_weights(info)
    x = poses + np.random.default_rng(4).normal(scale=0.1, size=poses.shape)
    n = 6
    S, dual = _certificate_by_definition(x, ij, xyt, kappa, tau)
    edges = certify._Edges(ij, xyt, kappa, tau)
    _, asm, _ = certify._refine(poses, edges)
    S_lo, tr_lam = certify._certificate_matrix(asm, x, edges)
    perm = np.ravel(np.column_stack([np.arange(n), n + 2 * np.arange(n), n + 2 * np.arange(n) + 1]))
    got = asm.matrix(asm.full(S_lo)).toarray()
    np.testing.assert_allclose(got, S[np.ix_(perm, perm)], rtol=0, atol=1e-12 * np.abs(S).max())
    assert tr_lam == pytest.approx(dual, rel=1e-12)


# -- certificates that say why -----------------------------------------------------------------------------
def _indefinite(shift: float, n: int = 200, seed: int = 3):
    """A sparse symmetric matrix whose smallest eigenvalue is ``shift`` below that of a PSD one (dense reference)."""
    import scipy.sparse as sp

    A = sp.random(n, n - 3, density=0.02, random_state=seed) + sp.eye(n, n - 3)
    S = (A @ A.T).tocsc() - shift * sp.eye(n, format="csc")
    return S, float(np.linalg.eigvalsh(S.toarray())[0])


@pytest.mark.parametrize(("shift", "certified"), [(0.0, True), (1e-3, False), (0.7, False)])
def test_inertia_bisection_brackets_the_dense_lambda_min(shift, certified):
    """Sylvester's inertia (S − σI factors iff σ < λ_min) brackets λ_min: against numpy's dense eigvalsh, for a
    PSD matrix with a null space (certified) and two indefinite ones."""
    S, ref = _indefinite(shift)
    eta = certify.ETA_REL * float(np.max(S.diagonal()))
    lo, hi = certify._lambda_min_by_inertia(S, eta, certified)
    assert lo <= ref + 1e-12 and ref <= hi + 1e-12
    assert hi - lo <= certify.INERTIA_REL_TOL * max(abs(ref), eta) * 1.01 + 1e-15


def test_a_failed_eigen_solve_is_replaced_by_the_inertia_bracket(monkeypatch):
    """When Lanczos does not converge (forced here), the uncertified λ_min comes from the inertia bisection: a
    finite value within the bracket that holds the dense eigenvalue, and the reason names it — never NaN."""
    import scipy.sparse.linalg as spla

    def no_convergence(*args, **kwargs):
        raise spla.ArpackNoConvergence("forced", np.zeros(0), np.zeros((0, 0)))

    monkeypatch.setattr(certify, "DENSE_EIG_MAX", 10)
    monkeypatch.setattr(spla, "eigsh", no_convergence)
    poses, ij, xyt, info = _hexagon(0.15, seed=2)
    wound = poses.copy()
    wound[:, 2] += np.arange(6) * np.pi / 3  # the local, uncertified stationary point of the test above
    cert = certify.certify_pose_graph(wound, ij, xyt, info)
    assert not cert.certified and np.isfinite(cert.lambda_min)
    assert cert.lambda_method == "inertia bisection"
    kappa, tau = certify.isotropic_weights(info)
    S, _ = _certificate_by_definition(cert.poses_xyt, ij, xyt, kappa, tau)
    ref = np.linalg.eigvalsh(S)[0]
    lo, hi = cert.lambda_bracket
    assert lo <= ref <= hi and ref < -cert.eta
    verdict = cert.verdict()
    assert verdict.startswith("not certified: S + ηI is not positive definite") and "nan" not in verdict
    assert cert.as_extra()["reason"] == cert.reason and cert.as_extra()["lambda_min_bracket"] == [lo, hi]


def test_no_translation_information_is_tau_zero_and_still_certifies():
    """An edge with zero [x, y] information carries no translation term: τ = 2 / tr(Σ_xy) → 0 (not 0/0), and
    the certificate of the rest is as without that term — against the objective evaluated by definition."""
    poses, ij, xyt, info = _hexagon(0.05, seed=1)
    info[2] = np.diag([0.0, 0.0, 25.0])
    kappa, tau = certify.isotropic_weights(info)
    assert tau[2] == 0.0 and tau[0] == pytest.approx(2.0 / (1 / 4 + 1 / 9))
    cert = certify.certify_pose_graph(poses, ij, xyt, info)
    assert np.isfinite(cert.lambda_min) and cert.certified
    assert cert.sesync_cost == pytest.approx(_F_by_definition(cert.poses_xyt, ij, xyt, kappa, tau), rel=1e-12)


@pytest.mark.parametrize(("mutate", "fragment"), [
    (lambda p, i: p.__setitem__((3, 0), np.nan), "the estimate has non-finite poses"),
    (lambda p, i: i.__setitem__((1, 2, 2), np.inf), "edge 1 (1 → 2) has no finite non-negative SE-Sync weights"),
])
def test_a_certificate_that_cannot_be_computed_says_why(mutate, fragment):
    poses, ij, xyt, info = _hexagon(0.05, seed=1)
    mutate(poses, info)
    cert = certify.certify_pose_graph(poses, ij, xyt, info)
    assert not cert.certified and cert.verdict() == f"not certified: {cert.reason}"
    assert fragment in cert.reason
