"""CHOLMOD's sparse Cholesky (Chen, Davis, Hager & Rajamanickam 2008) through CVXOPT, whose binary wheel ships
SuiteSparse and OpenBLAS: ``P H Pᵀ = L Lᵀ`` (supernodal, dense BLAS-3 blocks) or ``P H Pᵀ = L D Lᵀ``
(simplicial) of a sparse symmetric ``H`` given by its lower triangle (CSC, ``(n, n)``); by default CHOLMOD
chooses between them by the flops per entry of ``L``.

The fill-reducing ordering ``P`` (AMD) and the symbolic factorisation are computed once per pattern
(:class:`CholmodFactor`); :meth:`CholmodFactor.refactor` refills the numeric values in place. CVXOPT's factor
is opaque, so what it does not hand out is read through solves with the factor's own pieces::

    P · [0, 1, …, n−1]ᵀ = perm        (perm[k] = column of H eliminated k-th)
    D⁻¹ · 1            = 1 / d        (the pivots of the simplicial LDLᵀ)

and ``L`` itself (:meth:`CholmodFactor.ld_at`) is handed over by turning the numeric factor back into a
symbolic one; the factor refactors its previous values before its next solve.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp

#: CHOLMOD's ``supernodal`` option by mode
_MODES = {"simplicial": 0, "auto": 1, "supernodal": 2}
#: CVXOPT's solve codes: A x = b, D x = b, and Pᵀ x = b (x = P b)
_SYS_A, _SYS_D, _SYS_P = 0, 6, 7


def available() -> bool:
    """Whether CVXOPT's CHOLMOD imports."""
    try:
        import cvxopt.cholmod  # noqa: F401
    except ImportError:
        return False
    return True


def lower_csc(H: sp.spmatrix) -> sp.csc_matrix:
    """The lower triangle of a symmetric ``H`` as canonical CSC (rows sorted, no duplicates), its diagonal
    stored in full (explicit zeros where ``H`` has none)."""
    lo = sp.tril(H, format="coo")
    n = H.shape[0]
    diag = np.arange(n)
    lo = sp.coo_matrix((np.concatenate([lo.data, np.zeros(n)]), (np.concatenate([lo.row, diag]),
                        np.concatenate([lo.col, diag]))), shape=H.shape).tocsc()
    lo.sum_duplicates()
    lo.sort_indices()
    return lo


class CholmodFactor:
    """``P H Pᵀ = L Lᵀ`` (``mode="supernodal"``), ``L D Lᵀ`` (``"simplicial"``) or CHOLMOD's choice (``"auto"``)
    on a fixed lower pattern.

    lower : csc (n, n)   the pattern of ``H``'s lower triangle, canonical (:func:`lower_csc`); its values are
                         not read; it stores every diagonal entry. Every later ``lo_data`` is data on
                         exactly this pattern.
    """

    def __init__(self, lower: sp.csc_matrix, mode: str = "auto") -> None:
        import cvxopt
        from cvxopt import cholmod

        if mode not in _MODES:
            raise ValueError(f"mode must be one of {', '.join(_MODES)}, got {mode!r}")
        self._cvx, self._chol = cvxopt, cholmod
        self.n = int(lower.shape[0])
        self.mode = mode
        self.indptr, self.indices = lower.indptr, lower.indices
        if not (lower.has_canonical_format and np.all(np.diff(lower.indptr) > 0)
                and np.array_equal(lower.indices[lower.indptr[:-1]], np.arange(self.n))):
            raise ValueError("the lower pattern must be canonical CSC (sorted rows, no duplicates, diagonal stored)")
        cols = np.repeat(np.arange(self.n), np.diff(lower.indptr))
        self._M = cvxopt.spmatrix(1.0, lower.indices, cols, (self.n, self.n))  # CSC in the same order
        del cols
        self._analyse()
        self._numeric = False  # whether _F holds the numeric factor of the values in _M
        self._have_values = False
        self.failed_column: int | None = None

    def _options(self) -> None:
        self._chol.options["supernodal"] = _MODES[self.mode]

    def _analyse(self) -> None:
        """The ordering and symbolic factorisation of the pattern (``auto``: CHOLMOD chooses the kind by the
        flops per entry of ``L``; :attr:`ldl` is known after the first numeric factorisation)."""
        self._options()
        self._F = self._chol.symbolic(self._M, uplo="L")
        self._analysed = True
        self._perm = None
        self.ldl = {"simplicial": True, "supernodal": False}.get(self.mode)

    def _is_supernodal(self) -> bool:
        try:
            self._chol.diag(self._F)  # defined for a numeric supernodal LLᵀ only
        except ValueError:
            return False
        return True

    def matches(self, lower: sp.csc_matrix) -> bool:
        """Whether ``lower`` has this factor's pattern (same object arrays or equal)."""
        return lower.shape == (self.n, self.n) and (
            (lower.indices is self.indices and lower.indptr is self.indptr)
            or (np.array_equal(lower.indptr, self.indptr) and np.array_equal(lower.indices, self.indices)))

    def refactor(self, lo_data: np.ndarray) -> bool:
        """Numeric factorisation of ``H`` given by its lower data; whether ``H`` is positive definite (every
        pivot ``d > 0``). When it is not, :attr:`failed_column` names the column of ``H`` where it fails."""
        self.failed_column = None
        self._numeric = False
        if not self._analysed:
            self._analyse()
        self._M.V = self._cvx.matrix(np.asarray(lo_data, dtype=float))
        self._have_values = True
        self._options()
        try:
            self._chol.numeric(self._M, self._F)
        except ArithmeticError as exc:  # a zero pivot (LDLᵀ) or a pivot ≤ 0 (LLᵀ), at elimination step k
            self.failed_column = self._column_at(int(exc.args[0]) if exc.args else 0)
            return False
        self._numeric = True
        if self.ldl is None:
            self.ldl = not self._is_supernodal()
        if self.ldl:
            d = self.pivots()
            bad = np.flatnonzero(~(d > 0.0))
            if bad.size:
                self.failed_column = int(self.perm()[bad[0]])
                return False
        return True

    def _restore(self) -> None:
        if not self._numeric:
            if not self._have_values:
                raise RuntimeError("CHOLMOD factor used before its numeric factorisation")
            if not self._refactor_held():
                raise np.linalg.LinAlgError("matrix is not positive definite")

    def _refactor_held(self) -> bool:
        """:meth:`refactor` of the values the factor holds."""
        values = self._M.V
        return self.refactor(np.asarray(values).ravel())

    def _apply(self, b: np.ndarray, sys: int) -> np.ndarray:
        self._restore()
        b = np.asarray(b, dtype=float)
        B = self._cvx.matrix(b.reshape(self.n, -1))
        self._chol.solve(self._F, B, sys=sys)
        return np.array(B).reshape(b.shape)

    def solve(self, b: np.ndarray) -> np.ndarray:
        """``H⁻¹ b`` for ``b (n,)`` or ``(n, k)``."""
        return self._apply(b, _SYS_A)

    __call__ = solve

    def pivots(self) -> np.ndarray:
        """``d (n,)``: the pivots of the ``LDLᵀ`` in elimination order (simplicial mode)."""
        if not self.ldl:
            raise ValueError("pivots are those of the simplicial LDLᵀ")
        with np.errstate(divide="ignore"):
            return 1.0 / self._apply(np.ones(self.n), _SYS_D)

    def perm(self) -> np.ndarray:
        """``perm (n,)``: ``perm[k]`` is the column of ``H`` eliminated ``k``-th (``P H Pᵀ = H[perm][:, perm]``)."""
        if self._perm is None:
            self._perm = np.rint(self._apply(np.arange(self.n, dtype=float), _SYS_P)).astype(np.int64)
        return self._perm

    def _column_at(self, k: int) -> int:
        """The column of ``H`` eliminated ``k``-th, found without a valid numeric factor: the ordering is
        read from a strictly diagonally dominant matrix of the same pattern (positive definite)."""
        if self._perm is None:
            lo = sp.csc_matrix((np.ones(len(self.indices)), self.indices, self.indptr), shape=(self.n, self.n))
            degree = np.asarray((lo + lo.T).sum(axis=1)).ravel()
            dominant = lo.data
            dominant[self.indptr[:-1]] = degree + 1.0  # the diagonal: first in every column
            saved = self._M.V
            self.refactor(dominant)
            self.perm()
            self._M.V, self._numeric = saved, False
        return int(self._perm[min(k, self.n - 1)])

    def ld_at(self, lo_data: np.ndarray) -> sp.csc_matrix | None:
        """``L`` (unit lower) with ``D`` on its diagonal, ``P H Pᵀ = L D Lᵀ``, of ``H`` given by ``lo_data``, as CSC
        with rows sorted and the symbolic pattern kept (explicit zeros included; from a supernodal ``C Cᵀ``:
        ``d = diag(C)²``, ``L = C diag(C)⁻¹``); None when ``H`` is not positive definite
        (:attr:`failed_column` says where). The factor keeps its earlier values: they are refactored before
        its next solve."""
        saved = self._M.V if self._have_values else None
        if not self.refactor(lo_data):
            self._numeric = False
            if saved is not None:
                self._M.V = saved
            return None
        self.perm()
        # CHOLMOD hands its arrays over: the factor is symbolic again, and a supernodal one simplicial (it is
        # analysed anew before its next factorisation)
        Lc = self._chol.getfactor(self._F)
        self._numeric, self._analysed = False, bool(self.ldl)
        if saved is not None:
            self._M.V = saved
        L = sp.csc_matrix((np.asarray(Lc.V).ravel(), np.asarray(Lc.CCS[1]).ravel(),
                           np.asarray(Lc.CCS[0]).ravel()), shape=(self.n, self.n))
        L.sort_indices()
        if not self.ldl:  # C Cᵀ → L D Lᵀ, column by column
            c = L.diagonal()
            L.data /= np.repeat(c, np.diff(L.indptr))
            L.setdiag(c * c)
        return L


def spd_factor(H: sp.spmatrix) -> CholmodFactor | None:
    """CHOLMOD's factor of a sparse symmetric ``H`` (``mode="auto"``; callable: ``F(b) = H⁻¹b``), or None when
    ``H`` is not positive definite (a pivot ≤ 0)."""
    lo = lower_csc(H)
    F = CholmodFactor(lo)
    return F if F.refactor(lo.data) else None
