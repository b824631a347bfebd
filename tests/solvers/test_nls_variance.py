"""Variance-component estimation (slamcli.solvers.nls.variance) against closed forms.

* redundancy: ρ_g = Σ_{i∈g} (1 − h_ii) with the hat-matrix diagonal h_ii = ‖Q_i‖² of a thin QR of J
  (independent of the H⁻¹ trace the module computes); Σ_g ρ_g = m − n.
* iterated VCE (:func:`iterate_variance_components`) on a seeded linear Gaussian problem with two groups of
  known σ recovers them: the estimate's relative standard deviation is ≈ 1/√(2ρ_g) (1.3 % and 1.6 % here), the
  tolerance 4 of those; one round is the closed form σ·√r of the first solve's factors.
* groups whose contributions to H cancel exactly keep their pairs on the selected inverse's pattern.
"""

import numpy as np
import pytest
import scipy.sparse as sp

from slamcli.solvers.nls import cholmod_available, selinv
from slamcli.solvers.nls.variance import iterate_variance_components, variance_components


def _sparse_problem(rng, n, m, per_row):
    rows = np.repeat(np.arange(m), per_row)
    cols = np.concatenate([rng.choice(n, per_row, replace=False) for _ in range(m)])
    J = sp.csr_matrix((rng.normal(size=m * per_row), (rows, cols)), shape=(m, n))
    return J


def _hat_redundancy(J, group, G):
    Q, _ = np.linalg.qr(J.toarray())
    return np.bincount(group, weights=1.0 - np.sum(Q * Q, axis=1), minlength=G)


@pytest.mark.parametrize("dense", [True, False])
@pytest.mark.slow
def test_redundancy_matches_hat_matrix(dense):
    if not dense and not cholmod_available():
        pytest.skip("CHOLMOD (scikit-sparse) not installed")
    rng = np.random.default_rng(7)
    n, m = 120, 400
    J = _sparse_problem(rng, n, m, 4)
    group = rng.integers(0, 3, m)
    e = rng.normal(size=m)
    vc = variance_components(J, e, group, dense=dense)
    ref = _hat_redundancy(J, group, 3)
    np.testing.assert_allclose(vc.redundancy, ref, rtol=1e-9, atol=1e-9)
    assert vc.redundancy.sum() == pytest.approx(m - n, abs=1e-8)
    np.testing.assert_allclose(vc.ssr, np.bincount(group, weights=e * e, minlength=3))
    np.testing.assert_allclose(vc.ratio, vc.ssr / ref, rtol=1e-9)


def test_rows_outside_groups_and_approx():
    rng = np.random.default_rng(3)
    n, m = 30, 200
    J = _sparse_problem(rng, n, m, 3)
    group = np.where(np.arange(m) < 20, -1, np.arange(m) % 2)  # 20 rows (a "prior") in no group
    vc = variance_components(J, rng.normal(size=m), group, dense=True)
    ref = _hat_redundancy(J, np.where(group < 0, 2, group), 3)
    np.testing.assert_allclose(vc.redundancy, ref[:2], rtol=1e-9)
    ap = variance_components(J, rng.normal(size=m), group, method="approx")
    np.testing.assert_allclose(ap.redundancy, ap.n_obs * (1 - n / m))
    assert list(ap.n_obs) == [90, 90]


def _linear_two_groups(rng, sigma_true, m_g, n=25):
    x_true = rng.normal(size=n)
    A = [rng.normal(size=(k, n)) for k in m_g]
    y = [a @ x_true + s * rng.normal(size=a.shape[0]) for a, s in zip(A, sigma_true)]
    sigma0 = np.array([1.0, 1.0])  # the assumed σ: wrong by 3.3x and 0.5x

    def solve_at(scale):
        sigma = sigma0 * scale
        Jw = np.vstack([a / s for a, s in zip(A, sigma)])
        yw = np.concatenate([b / s for b, s in zip(y, sigma)])
        x = np.linalg.lstsq(Jw, yw, rcond=None)[0]
        return Jw, yw - Jw @ x, np.repeat([0, 1], m_g)

    return sigma0, solve_at


@pytest.mark.slow
def test_iterated_vce_recovers_true_sigmas():
    sigma_true = np.array([0.3, 2.0])
    sigma0, solve_at = _linear_two_groups(np.random.default_rng(2026), sigma_true, (3000, 2000))
    it = iterate_variance_components(solve_at, 2, tol=1e-10, max_reweights=30)
    assert it.converged
    vc = it.rounds[-1].components
    np.testing.assert_allclose(vc.ratio, 1.0, atol=1e-8)
    rel_sd = 1 / np.sqrt(2 * vc.redundancy)  # of σ̂: 1.3 % and 1.6 % here
    assert np.all(np.abs(sigma0 * it.scale / sigma_true - 1) < 4 * rel_sd)


@pytest.mark.slow
def test_one_round_scales_by_the_square_root_of_the_first_factors():
    """``max_reweights=1``: the second solve's σ are the first solve's ``σ·√r`` (the closed form of one round);
    nothing converges at a tolerance no round can meet, and exactly two rounds are measured."""
    sigma0, solve_at = _linear_two_groups(np.random.default_rng(5), np.array([0.3, 2.0]), (400, 300))
    seen = []
    it = iterate_variance_components(solve_at, 2, tol=1e-12, max_reweights=1, on_round=seen.append)
    assert len(it.rounds) == 2 and not it.converged and seen == list(it.rounds)
    J, e, g = solve_at(np.ones(2))
    r0 = variance_components(J, e, g, 2, dense=True).ratio
    np.testing.assert_allclose(it.rounds[0].scale, 1.0)
    np.testing.assert_allclose(it.scale, np.sqrt(r0), rtol=1e-12)
    # a tolerance the first solve already meets: one round, no re-weighting
    assert len(iterate_variance_components(solve_at, 2, tol=1e3, max_reweights=5).rounds) == 1


def test_groups_cancelling_in_H_keep_the_exact_redundancy():
    """Two groups whose cross terms cancel exactly in H = Σ J_gᵀJ_g (odometry x and lateral rows of equal σ
    do): the selected inverse still gets every pair a group touches; same ρ as the hat matrix."""
    if not cholmod_available():
        pytest.skip("CHOLMOD (scikit-sparse) not installed")
    rng = np.random.default_rng(11)
    n, m = 40, 160
    A = _sparse_problem(rng, n, m, 3).toarray()
    A[A[:, 0] != 0, 1] = 0.0  # no row of A couples columns 0 and 1 ...
    # ... and the two extra rows couple them with opposite signs: H[0, 1] = 0, H_g[0, 1] = ±1
    a = np.zeros((2, n))
    a[0, :2] = [1.0, 1.0]
    a[1, :2] = [1.0, -1.0]
    J = sp.csr_matrix(np.vstack([A, a]))
    group = np.concatenate([rng.integers(0, 2, m), [0, 1]])
    H = sp.csc_matrix(J.T @ J)
    with pytest.raises(ValueError, match="not on the pattern"):  # what the plain JᵀJ pattern gave
        selinv.SelectedInverse.from_matrix(H).entries(np.array([0]), np.array([1]))
    vc = variance_components(J, rng.normal(size=m + 2), group)
    np.testing.assert_allclose(vc.redundancy, _hat_redundancy(J, group, 2), rtol=1e-9, atol=1e-9)


def test_bad_input():
    with pytest.raises(ValueError, match="one entry per Jacobian row"):
        variance_components(np.eye(3), np.zeros(2), np.zeros(3, int))
    with pytest.raises(ValueError, match="no redundancy"):
        variance_components(np.eye(3), np.zeros(3), np.zeros(3, int))
    with pytest.raises(ValueError, match="exact or approx"):
        variance_components(np.ones((4, 1)), np.zeros(4), np.zeros(4, int), method="helmert")


def test_one_implementation():
    """The metrics layer names the solvers-layer estimator; it has no copy of its own."""
    import slamcli.metrics.variance as metrics_variance

    assert metrics_variance.variance_components is variance_components
