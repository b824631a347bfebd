"""Variance-component estimation (slamcli.solvers.nls.variance) against closed forms.

* redundancy: ρ_g = Σ_{i∈g} (1 − h_ii) with the hat-matrix diagonal h_ii = ‖Q_i‖² of a thin QR of J
  (independent of the H⁻¹ trace the module computes); Σ_g ρ_g = m − n.
* iterated VCE on a seeded linear Gaussian problem with two groups of known σ recovers them: the estimate's
  relative standard deviation is ≈ 1/√(2ρ_g) (1.3 % and 1.6 % here), the tolerance 4 of those.
"""

import numpy as np
import pytest
import scipy.sparse as sp

from slamcli.solvers.nls import selinv
from slamcli.solvers.nls.variance import variance_components


def _sparse_problem(rng, n, m, per_row):
    rows = np.repeat(np.arange(m), per_row)
    cols = np.concatenate([rng.choice(n, per_row, replace=False) for _ in range(m)])
    J = sp.csr_matrix((rng.normal(size=m * per_row), (rows, cols)), shape=(m, n))
    return J


def _hat_redundancy(J, group, G):
    Q, _ = np.linalg.qr(J.toarray())
    return np.bincount(group, weights=1.0 - np.sum(Q * Q, axis=1), minlength=G)


@pytest.mark.parametrize("dense", [True, False])
def test_redundancy_matches_hat_matrix(dense):
    if not dense and not selinv.available():
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


def test_iterated_vce_recovers_true_sigmas():
    rng = np.random.default_rng(2026)
    n = 25
    sigma_true = np.array([0.3, 2.0])
    m_g = (3000, 2000)
    x_true = rng.normal(size=n)
    A = [rng.normal(size=(k, n)) for k in m_g]
    y = [a @ x_true + s * rng.normal(size=a.shape[0]) for a, s in zip(A, sigma_true)]
    group = np.repeat([0, 1], m_g)
    sigma = np.array([1.0, 1.0])  # the assumed σ: wrong by 3.3x and 0.5x
    for _ in range(30):
        Jw = np.vstack([a / s for a, s in zip(A, sigma)])
        yw = np.concatenate([b / s for b, s in zip(y, sigma)])
        x = np.linalg.lstsq(Jw, yw, rcond=None)[0]
        vc = variance_components(Jw, yw - Jw @ x, group, dense=True)
        sigma = sigma * np.sqrt(vc.ratio)
        if np.all(np.abs(vc.ratio - 1) < 1e-10):
            break
    np.testing.assert_allclose(vc.ratio, 1.0, atol=1e-8)
    rel_sd = 1 / np.sqrt(2 * vc.redundancy)
    assert np.all(np.abs(sigma / sigma_true - 1) < 4 * rel_sd)


def test_bad_input():
    with pytest.raises(ValueError, match="one entry per Jacobian row"):
        variance_components(np.eye(3), np.zeros(2), np.zeros(3, int))
    with pytest.raises(ValueError, match="no redundancy"):
        variance_components(np.eye(3), np.zeros(3), np.zeros(3, int))
    with pytest.raises(ValueError, match="exact or approx"):
        variance_components(np.ones((4, 1)), np.zeros(4), np.zeros(4, int), method="helmert")
