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

#: most gather positions (int64) of the recurrence computed at once (memory ≈ 8 bytes × 3 × this)
GATHER_CHUNK = 1 << 22
#: supernodes with at most this many rows below them get precomputed (vectorised) gather positions; larger
#: row sets are gathered run by run (:meth:`SelectedInverse._gather`), where the r² index arithmetic costs
#: more than the Python overhead it saves (City10000: 0.25 s with every supernode vectorised, 0.15 s run by
#: run, 0.14 s with 16-32 here; intel 0.021 / 0.018 s run by run / 24)
GATHER_MAX_ROWS = 24


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
        # AMD alone: CHOLMOD's default also tries METIS when AMD's fill is high, which on these matrices
        # costs time and keeps AMD's ordering (City10000's H: 0.108 → 0.087 s, the same L)
        F = cholesky(H, mode="supernodal", ordering_method="amd")
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
        nrows = cnt[first].astype(np.int64)  # |J| + |R|
        self.sn_first, self.sn_width, self.sn_nrows = first, width, nrows
        self.sn_of = np.repeat(np.arange(ns), width)  # supernode of each (permuted) column
        # Σ̃ storage: supernode K is a dense row-major (nrows_K × width_K) block at vals[off[K]:]
        self.off = np.r_[0, np.cumsum(nrows * width)].astype(np.int64)
        self.vals = np.zeros(int(self.off[-1]))
        # row sets J ∪ R of all supernodes, concatenated (supernode K's at _key_start[K]), and the sorted
        # (supernode, row) keys of every block row: the lookup table of :meth:`entries` and of the gathers
        is_first = np.zeros(n, bool)
        is_first[first] = True
        self._rows = ix[np.repeat(is_first, cnt)].astype(np.int64)
        self._key_start = np.r_[0, np.cumsum(nrows)[:-1]].astype(np.int64)
        self._keys = np.repeat(np.arange(ns, dtype=np.int64), nrows) * n + self._rows
        self._recurrence(self._panels(lx, cnt), factor.d)

    def _panels(self, lx: np.ndarray, cnt: np.ndarray) -> np.ndarray:
        """``L``'s entries laid out as :attr:`vals` (supernode K's columns as a row-major ``nrows × width``
        panel at ``off[K]``, zero above the diagonal), by one vectorised scatter: column ``j0 + i`` of a
        supernode holds its rows ``i..`` contiguously in ``lx`` (fundamental supernode)."""
        n = self.n
        col = np.repeat(np.arange(n), cnt)  # column of every stored entry
        K = self.sn_of[col]
        i = col - self.sn_first[K]  # local column
        t = np.arange(lx.size) - np.repeat(self._ip[:-1].astype(np.int64), cnt)  # position within the column
        panels = np.zeros(self.vals.size)
        panels[self.off[K] + (i + t) * self.sn_width[K] + i] = lx
        return panels

    def _gather_index(self, K0: int, K1: int) -> tuple[np.ndarray, np.ndarray]:
        """Flat positions in :attr:`vals` of ``Σ̃_{R,R}`` (dense ``r × r``, row-major) for the supernodes
        ``K0 ≤ K < K1`` (``R`` = rows below the supernode), concatenated, and the start of each.

        Entry ``(a, b)`` of ``Σ̃`` (``lo = min(a, b)``, ``hi = max``) is stored by the supernode owning column
        ``lo``, at the local row of ``hi`` (found in the sorted keys: SelInv's "relative indices"); chordality
        makes every such pair a stored entry."""
        Ks = np.arange(K0, K1)
        r = self.sn_nrows[Ks] - self.sn_width[Ks]
        r = np.where(r <= GATHER_MAX_ROWS, r, 0)  # larger row sets: :meth:`_gather`
        sizes = r * r
        starts = np.r_[0, np.cumsum(sizes)]
        T = int(starts[-1])
        rep = np.repeat(np.arange(Ks.size), sizes)
        u = np.arange(T, dtype=np.int64) - starts[:-1][rep]
        rr = r[rep]
        rs = (self._key_start[Ks] + self.sn_width[Ks])[rep]
        a, b = self._rows[rs + u // rr], self._rows[rs + u % rr]
        lo, hi = np.minimum(a, b), np.maximum(a, b)
        Kp = self.sn_of[lo]
        key = Kp * self.n + hi
        g = np.minimum(np.searchsorted(self._keys, key), max(self._keys.size - 1, 0))
        if T and not np.array_equal(self._keys[g], key):
            raise ValueError("the pattern of L is not closed under elimination (not a symbolic factor)")
        idx = self.off[Kp] + (g - self._key_start[Kp]) * self.sn_width[Kp] + (lo - self.sn_first[Kp])
        return idx, starts

    def _diagonal_terms(self, panels: np.ndarray, d: np.ndarray):
        """``L_JJ⁻¹`` and ``L_JJ⁻ᵀ D_J⁻¹ L_JJ⁻¹`` of every supernode (``s × s`` row-major, at ``soff[K]`` of two
        flat arrays), batched over the supernodes of one width: they depend on the factor only, not on Σ̃."""
        w = self.sn_width
        soff = np.r_[0, np.cumsum(w * w)].astype(np.int64)
        linv, sjj = np.empty(int(soff[-1])), np.empty(int(soff[-1]))
        for s in np.unique(w).tolist():
            Ks = np.flatnonzero(w == s)
            at = (soff[Ks][:, None] + np.arange(s * s)).ravel()
            blocks = panels[(self.off[Ks][:, None] + np.arange(s * s)).ravel()].reshape(-1, s, s)  # L_JJ, unit lower
            inv = np.linalg.inv(blocks) if s > 1 else np.ones((Ks.size, 1, 1))
            dj = d[self.sn_first[Ks][:, None] + np.arange(s)]
            linv[at] = inv.ravel()
            sjj[at] = (np.swapaxes(inv, 1, 2) @ (inv / dj[:, :, None])).ravel()
        return soff, linv, sjj

    def _recurrence(self, panels: np.ndarray, d: np.ndarray) -> None:
        """The supernodal Takahashi recurrence (module docstring), last supernode first. The gather positions
        of ``Σ̃_{R,R}`` are computed in vectorised chunks of at most :data:`GATHER_CHUNK` entries and the
        diagonal-block terms beforehand (:meth:`_diagonal_terms`), so the loop body is a few dense products
        per supernode."""
        ns = len(self.sn_first)
        soff, linv, sjj = self._diagonal_terms(panels, d)
        width, nrows, off, so_l = (a.tolist() for a in (self.sn_width, self.sn_nrows, self.off, soff))
        r = self.sn_nrows - self.sn_width
        csize = np.r_[0, np.cumsum(np.where(r <= GATHER_MAX_ROWS, r * r, 0))]
        vals = self.vals
        K_lo = ns
        for K in range(ns - 1, -1, -1):
            if K < K_lo:  # next chunk of gather positions: supernodes K_lo..K
                K_lo = max(0, min(int(np.searchsorted(csize, csize[K + 1] - GATHER_CHUNK)), K))
                gidx, gstart = self._gather_index(K_lo, K + 1)
            s, m, o, so = width[K], nrows[K], off[K], so_l[K]
            SJJ = sjj[so : so + s * s].reshape(s, s)  # L_JJ⁻ᵀ D_J⁻¹ L_JJ⁻¹
            out = vals[o : o + m * s].reshape(m, s)
            if m > s:
                Y = panels[o + s * s : o + m * s].reshape(m - s, s) @ linv[so : so + s * s].reshape(s, s)  # L_RJ L_JJ⁻¹
                q = K - K_lo
                if m - s <= GATHER_MAX_ROWS:  # Σ̃_{R,R}, computed before
                    S = vals[gidx[gstart[q] : gstart[q + 1]]].reshape(m - s, m - s)
                else:
                    S = self._gather(self._sn_rows(K)[s:])
                SRJ = -(S @ Y)
                SJJ = SJJ - Y.T @ SRJ
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
        k0 = int(self._key_start[K])
        return self._rows[k0 : k0 + int(self.sn_nrows[K])]

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
            rows = self._sn_rows(K)
            tail = R[a0:]
            pos = np.searchsorted(rows, tail)
            if pos[-1] >= len(rows) or (rows[pos] != tail).any():
                raise ValueError("the pattern of L is not closed under elimination (not a symbolic factor)")
            o, w = int(self.off[K]), int(self.sn_width[K])
            X = self.vals[o : o + len(rows) * w].reshape(len(rows), w)[pos[:, None], R[a0:a1] - self.sn_first[K]]
            S[a0:, a0:a1] = X
            S[a0:a1, a0:] = X.T  # the diagonal block is symmetric: writing it twice is harmless
        return S
