"""Selected inverse of a sparse symmetric positive definite matrix (Takahashi / Erisman–Tinney recurrence).

Marginal covariances of a Gaussian with information (precision) matrix ``H`` are blocks of ``Σ = H⁻¹``.
With the fill-reducing permutation ``P`` and the sparse factorisation ``P H Pᵀ = L D Lᵀ`` (``L`` unit lower
triangular), every entry of ``Σ̃ = (P H Pᵀ)⁻¹`` on the sparsity pattern of ``L`` follows from ``L``, ``D``
and entries of ``Σ̃`` *further down and right* on that same pattern — Takahashi, Fagan & Chen (1973),
Erisman & Tinney (1975)::

    Σ̃ L = L⁻ᵀ D⁻¹            (upper triangular; its diagonal is D⁻¹)

    column j, off-diagonal pattern R = {i > j : L_ij ≠ 0}:
        Σ̃_{R,j} = − Σ̃_{R,R} L_{R,j}
        Σ̃_jj    = 1/d_j − L_{R,j}ᵀ Σ̃_{R,j}

Because the pattern of ``L`` is chordal, ``R ∪ {j}`` is a clique of it, so ``Σ̃_{R,R}`` only needs entries
that were computed before (columns ``> j``). Nothing outside the pattern is ever formed: memory
``O(nnz(L))``, work ``O(Σ_j |R_j|²)`` — the cost of the factorisation itself.

This module runs the recurrence on *supernodes* (maximal runs of columns ``J = j0..j1`` whose pattern is
a dense lower triangle plus one shared row set ``R``), a block version of the same identity::

    Y      = L_{R,J} L_{J,J}⁻¹                                            (|R| × |J|)
    Σ̃_{R,J} = − Σ̃_{R,R} Y
    Σ̃_{J,J} = L_{J,J}⁻ᵀ D_J⁻¹ L_{J,J}⁻¹ − Yᵀ Σ̃_{R,J}

so the work is dense matrix products (BLAS) and the Python overhead is per supernode, not per column.
``Σ̃_{R,R}`` is gathered from the blocks of the ancestor supernodes that own the columns in ``R``
(one ``searchsorted`` per ancestor, SelInv's "relative indices").

The factorisation is CHOLMOD's (``scikit-sparse``, the ``cholmod`` extra): its fill-reducing ordering
(AMD / nested dissection) and its ``L D Lᵀ``. Without CHOLMOD, :func:`factor_ldl` raises ImportError and the
callers use their SciPy path. Shapes: ``H (n, n)`` sparse; ``index_blocks (B, k)`` integer columns of ``H``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp


class NotPositiveDefiniteError(np.linalg.LinAlgError):
    """The factorisation met a pivot ≤ 0; ``column`` is the column of ``H`` (original order) where."""

    def __init__(self, message: str, column: int) -> None:
        super().__init__(message)
        self.column = int(column)


def available() -> bool:
    """Whether CHOLMOD (``scikit-sparse``) can be imported — needed by :func:`factor_ldl`."""
    try:
        import sksparse.cholmod  # noqa: F401
    except ImportError:
        return False
    return True


@dataclass(frozen=True)
class LdlFactor:
    """``P H Pᵀ = L D Lᵀ``.

    L : scipy.sparse.csc_matrix (n, n)  unit lower triangular, rows sorted in every column, diagonal stored.
    d : ndarray (n,)                    the pivots ``D``.
    perm : ndarray (n,)                 ``perm[k]`` = column of ``H`` eliminated ``k``-th (``P H Pᵀ = H[perm][:, perm]``).
    """

    L: sp.csc_matrix
    d: np.ndarray
    perm: np.ndarray


def factor_ldl(H: sp.spmatrix) -> LdlFactor:
    """CHOLMOD's fill-reducing ``L D Lᵀ`` of a symmetric positive definite ``H``.

    Raises
    ------
    ImportError            scikit-sparse is not installed.
    NotPositiveDefiniteError    a pivot ≤ 0 (``H`` is not numerically positive definite).
    """
    from sksparse.cholmod import CholmodNotPositiveDefiniteError, cholesky

    H = sp.csc_matrix(H)
    try:
        F = cholesky(H, mode="supernodal")
    except CholmodNotPositiveDefiniteError as exc:
        col = getattr(exc, "column", None)
        perm = getattr(getattr(exc, "factor", None), "P", lambda: None)()
        where = int(perm[col]) if perm is not None and col is not None and col < len(perm) else int(col or 0)
        raise NotPositiveDefiniteError(f"sparse Cholesky of H: pivot ≤ 0 ({exc})", where) from None
    perm = np.asarray(F.P(), np.int64)
    # F.L() (L Lᵀ) keeps the symbolic pattern, explicit zeros included; F.L_D() would drop them
    L = sp.csc_matrix(F.L())
    L.sort_indices()
    diag = L.data[L.indptr[:-1]]
    if not np.all(L.indices[L.indptr[:-1]] == np.arange(L.shape[0])):
        raise ValueError("CHOLMOD's L does not store its diagonal first")
    if not np.all(diag > 0.0):
        k = int(np.argmin(diag))
        raise NotPositiveDefiniteError(f"pivot ≤ 0 in the sparse Cholesky of H ({diag[k]:.3g})", perm[k])
    L.data /= np.repeat(diag, np.diff(L.indptr))  # unit lower triangular: P H Pᵀ = L D Lᵀ, D = diag²
    d = diag * diag
    return LdlFactor(L, d, perm)


class SelectedInverse:
    """``Σ̃ = (P H Pᵀ)⁻¹`` on the pattern of ``L`` (supernodal Takahashi recurrence, see module doc).

    Build with :meth:`from_matrix` (CHOLMOD) or from any :class:`LdlFactor`; read blocks of ``H⁻¹`` in the
    original order with :meth:`blocks` / :meth:`entries`. Memory: one float per stored entry of the
    supernodal pattern (``≈ nnz(L)``) plus the index arrays.
    """

    def __init__(self, factor: LdlFactor) -> None:
        L = factor.L
        n = L.shape[0]
        ip, ix, lx = L.indptr, L.indices, L.data
        self.n = n
        self._ip, self._ix = ip, ix
        self.perm = factor.perm
        self.iperm = np.empty(n, np.int64)
        self.iperm[factor.perm] = np.arange(n)
        cnt = np.diff(ip)  # entries per column including the diagonal
        if n and (np.any(cnt < 1) or np.any(ix[ip[:-1]] != np.arange(n))):
            raise ValueError("L must store its diagonal first in every column (sorted CSC)")
        # fundamental supernodes: column j+1 continues j's when j's first off-diagonal row is j+1 and
        # pattern(j) = {j} ∪ pattern(j+1)  (chordality makes equal counts sufficient)
        nxt = np.where(cnt > 1, ix[np.minimum(ip[:-1] + 1, max(len(ix) - 1, 0))], -1)
        cont = (nxt[:-1] == np.arange(1, n)) & (cnt[:-1] == cnt[1:] + 1)
        first = np.flatnonzero(np.r_[True, ~cont]) if n else np.zeros(0, np.int64)
        ns = len(first)
        bounds = np.r_[first, n].astype(np.int64)
        width = np.diff(bounds)  # |J|
        nrows = cnt[first]  # |J| + |R|
        self.sn_first, self.sn_width, self.sn_nrows = first, width, nrows
        self.sn_of = np.repeat(np.arange(ns), width)  # supernode of each (permuted) column
        # Σ̃ storage: supernode K is a dense row-major (nrows_K × width_K) block at vals[off[K]:]
        self.off = np.r_[0, np.cumsum(nrows * width)].astype(np.int64)
        self.vals = np.zeros(int(self.off[-1]))
        # (supernode, row) keys of every block row, sorted: the lookup table of :meth:`entries`
        self._keys = (np.repeat(np.arange(ns, dtype=np.int64), nrows) * n
                      + np.concatenate([ix[ip[j] : ip[j + 1]] for j in first]) if ns else np.zeros(0, np.int64))
        self._key_start = np.r_[0, np.cumsum(nrows)[:-1]].astype(np.int64)
        d = factor.d
        # per-supernode views (Python lists: the loop below is per supernode, its overhead matters)
        self._blk = [self.vals[o : o + m * w].reshape(m, w) for o, m, w in
                     zip(self.off[:-1].tolist(), nrows.tolist(), width.tolist())]
        self._snrows = [ix[ip[j] : ip[j + 1]] for j in first.tolist()]
        self._first = first.tolist()
        from scipy.linalg.lapack import dtrtri  # the inverse of a triangular block, without LU's overhead

        for K in range(ns - 1, -1, -1):
            j0, s = self._first[K], int(width[K])
            m = len(self._snrows[K])
            panel = np.zeros((m, s))
            p0 = ip[j0]
            for i in range(s):  # column j0+i holds rows i.. of the panel, stored contiguously
                panel[i:, i] = lx[p0 : p0 + m - i]
                p0 += m - i
            Linv = dtrtri(panel[:s], lower=1, unitdiag=1)[0] if s > 1 else np.ones((1, 1))  # unit lower triangular
            out = self._blk[K]
            SJJ = Linv.T @ (Linv / d[j0 : j0 + s, None])  # L_JJ⁻ᵀ D_J⁻¹ L_JJ⁻¹
            if m > s:
                Y = panel[s:] @ Linv  # L_RJ L_JJ⁻¹   (r × s)
                SRJ = -(self._gather(self._snrows[K][s:]) @ Y)
                SJJ -= Y.T @ SRJ
                out[s:] = SRJ
            out[:s] = 0.5 * (SJJ + SJJ.T)

    @classmethod
    def from_matrix(cls, H: sp.spmatrix, index_blocks=()) -> SelectedInverse:
        """Factor ``H`` with CHOLMOD (:func:`factor_ldl`) and run the recurrence.

        ``index_blocks``: arrays ``(B, k)`` of columns whose ``k × k`` blocks :meth:`blocks` will be asked
        for; their pattern is added to ``H``'s as explicit zeros, so that every such block lies on the
        pattern of the factor even for variables no factor couples (e.g. held-fixed ones)."""
        H = sp.csc_matrix(H)
        extra = [np.asarray(b, np.int64) for b in index_blocks if np.size(b)]
        if extra:
            C = sp.coo_matrix(H)
            r = [C.row] + [np.repeat(b, b.shape[1], axis=1).ravel() for b in extra]
            c = [C.col] + [np.tile(b, (1, b.shape[1])).ravel() for b in extra]
            v = [C.data] + [np.zeros(b.size * b.shape[1]) for b in extra]
            H = sp.csc_matrix((np.concatenate(v), (np.concatenate(r), np.concatenate(c))), shape=H.shape)
        return cls(factor_ldl(H))

    def _sn_rows(self, K: int) -> np.ndarray:
        """Sorted row set ``J ∪ R`` of supernode ``K`` (permuted order)."""
        j0 = self.sn_first[K]
        return self._ix[self._ip[j0] : self._ip[j0 + 1]]

    def entries(self, rows: np.ndarray, cols: np.ndarray) -> np.ndarray:
        """``(H⁻¹)[rows, cols]`` (original order, equal shapes) — each pair must lie on the pattern of the
        factor (true for any two variables that share a factor of the graph, e.g. one pose's x, y, θ)."""
        rows, cols = np.asarray(rows, np.int64), np.asarray(cols, np.int64)
        shape = np.broadcast(rows, cols).shape
        qa, qb = self.iperm[rows.ravel()], self.iperm[cols.ravel()]
        lo, hi = np.minimum(qa, qb), np.maximum(qa, qb)
        K = self.sn_of[lo]
        key = K * self.n + hi
        g = np.searchsorted(self._keys, key)
        found = g < len(self._keys)
        found[found] = self._keys[g[found]] == key[found]
        if not np.all(found):
            raise ValueError("requested entries of H⁻¹ are not on the pattern of the factor")
        p = g - self._key_start[K]  # local row in supernode K's block
        return self.vals[self.off[K] + p * self.sn_width[K] + (lo - self.sn_first[K])].reshape(shape)

    def blocks(self, index_blocks: np.ndarray) -> np.ndarray:
        """Marginal covariance blocks ``(H⁻¹)[idx, idx]`` for each row of ``index_blocks (B, k)`` → ``(B, k, k)``."""
        idx = np.asarray(index_blocks, np.int64)
        B, k = idx.shape
        r = np.broadcast_to(idx[:, :, None], (B, k, k))
        c = np.broadcast_to(idx[:, None, :], (B, k, k))
        return self.entries(r, c)

    def _gather(self, R: np.ndarray) -> np.ndarray:
        """Dense ``Σ̃_{R,R}`` for a sorted row set ``R`` that is a clique of the pattern (already computed).

        ``R`` splits into runs owned by one supernode ``K`` each; a run's columns hold ``Σ̃`` for every row of
        ``R`` from the run on (chordality: they are rows of ``K``), found by one ``searchsorted``."""
        r = len(R)
        S = np.empty((r, r))
        sn = self.sn_of[R]
        cuts = (np.flatnonzero(sn[1:] != sn[:-1]) + 1).tolist()
        for a0, a1 in zip([0] + cuts, cuts + [r]):
            K = int(sn[a0])
            rows = self._snrows[K]
            tail = R[a0:]
            pos = np.searchsorted(rows, tail)
            if pos[-1] >= len(rows) or (rows[pos] != tail).any():
                raise ValueError("the pattern of L is not closed under elimination (not a symbolic factor)")
            X = self._blk[K][pos[:, None], R[a0:a1] - self._first[K]]
            S[a0:, a0:a1] = X
            S[a0:a1, a0:] = X.T  # the diagonal block is symmetric: writing it twice is harmless
        return S
