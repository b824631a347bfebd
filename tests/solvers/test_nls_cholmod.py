"""The CHOLMOD adapter (:mod:`slamcli.solvers.nls.cholmod`) against dense linear algebra: the permutation and
pivots it reads through solves, the factor it hands over, and the refusal of indefinite matrices."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse as sp

from slamcli.solvers.nls import cholmod

#: dense reference vs sparse factor, relative to the matrix scale
REL_TOL = 1e-10


def _spd(n: int, seed: int, density: float = 0.08) -> sp.csc_matrix:
    rng = np.random.default_rng(seed)
    A = sp.random(n, n, density, random_state=rng, format="csc")
    return (A @ A.T + sp.eye(n) * 0.3).tocsc()


def _unit_lower_ldl(M: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Dense ``M = L D Lᵀ`` without pivoting (``L`` unit lower), from numpy's Cholesky ``M = C Cᵀ``."""
    C = np.linalg.cholesky(M)
    c = np.diag(C)
    return C / c, c * c


@pytest.mark.parametrize("mode", ["simplicial", "supernodal"])
def test_solve_equals_the_dense_solve(mode):
    H = _spd(60, 0)
    F = cholmod.CholmodFactor(cholmod.lower_csc(H), mode=mode)
    assert F.refactor(cholmod.lower_csc(H).data)
    b = np.random.default_rng(1).normal(size=(60, 3))
    ref = np.linalg.solve(H.toarray(), b)
    assert np.abs(F.solve(b) - ref).max() <= REL_TOL * np.abs(ref).max()
    assert np.abs(F(b[:, 0]) - ref[:, 0]).max() <= REL_TOL * np.abs(ref).max()


@pytest.mark.parametrize("mode", ["simplicial", "supernodal", "auto"])
def test_permutation_pivots_and_factor_equal_the_dense_ldl_of_the_permuted_matrix(mode):
    H = _spd(80, 2)
    lo = cholmod.lower_csc(H)
    F = cholmod.CholmodFactor(lo, mode=mode)
    L = F.ld_at(lo.data)
    perm = F.perm()
    assert sorted(perm.tolist()) == list(range(80))
    L_ref, d_ref = _unit_lower_ldl(H.toarray()[np.ix_(perm, perm)])
    d = L.diagonal()
    assert np.abs(d - d_ref).max() <= REL_TOL * d_ref.max()
    L_unit = L.toarray()
    np.fill_diagonal(L_unit, 1.0)
    assert np.abs(L_unit - L_ref).max() <= REL_TOL * np.abs(L_ref).max()
    if F.ldl:
        assert np.abs(F.pivots() - d_ref).max() <= REL_TOL * d_ref.max()


@pytest.mark.parametrize("mode", ["simplicial", "supernodal"])
def test_ld_at_keeps_the_factor_of_the_earlier_values(mode):
    # the selected inverse borrows the optimiser's factor: the optimiser's next solve must still be its own, and
    # a second borrow (CHOLMOD turns a supernodal factor it hands over into a simplicial one) the same factor
    H1, H2 = _spd(50, 3), _spd(50, 3) * 4.0
    lo1, lo2 = cholmod.lower_csc(H1), cholmod.lower_csc(H2)
    F = cholmod.CholmodFactor(lo1, mode=mode)
    assert F.refactor(lo1.data)
    b = np.ones(50)
    for _ in range(2):
        L = F.ld_at(lo2.data)
        perm = F.perm()
        d = L.diagonal()
        L_unit = L.toarray()
        np.fill_diagonal(L_unit, 1.0)
        P_H2_P = H2.toarray()[np.ix_(perm, perm)]
        assert np.abs(L_unit @ np.diag(d) @ L_unit.T - P_H2_P).max() <= REL_TOL * np.abs(P_H2_P).max()
        ref = np.linalg.solve(H1.toarray(), b)
        assert np.abs(F.solve(b) - ref).max() <= REL_TOL * np.abs(ref).max()


@pytest.mark.parametrize("pivot", [-2.0, 0.0])
def test_an_indefinite_or_singular_matrix_is_refused_at_its_column(pivot):
    # diagonal but for one coupled pair: every elimination order meets the bad pivot at column 7 itself
    n = 12
    H = sp.lil_matrix(np.diag(np.full(n, 3.0)))
    H[7, 7] = pivot
    H[2, 3] = H[3, 2] = 1.0
    H = H.tocsc()
    lo = cholmod.lower_csc(H)
    for mode in ("simplicial", "supernodal", "auto"):
        F = cholmod.CholmodFactor(lo, mode=mode)
        assert not F.refactor(lo.data)
        assert F.failed_column == 7
    assert cholmod.spd_factor(H) is None


def test_lower_csc_stores_the_whole_diagonal():
    H = sp.csc_matrix(np.array([[0.0, 1.0], [1.0, 0.0]]))
    lo = cholmod.lower_csc(H)
    assert lo.nnz == 3 and np.array_equal(lo.diagonal(), [0.0, 0.0])
    with pytest.raises(ValueError, match="diagonal"):
        cholmod.CholmodFactor(sp.tril(H, format="csc"))
