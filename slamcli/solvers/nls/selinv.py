"""Selected inverse of a sparse symmetric positive definite matrix (Takahashi / Erisman–Tinney recurrence).

Marginal covariances are blocks of ``Σ = H⁻¹``. With the fill-reducing permutation ``P`` and
``P H Pᵀ = L D Lᵀ`` (``L`` unit lower triangular), every entry of ``Σ̃ = (P H Pᵀ)⁻¹`` on the pattern of ``L``
follows from ``L``, ``D`` and entries of ``Σ̃`` further down and right (Takahashi et al. 1973)::

    column j, pattern R = {i > j : L_ij ≠ 0}:   Σ̃_{R,j} = − Σ̃_{R,R} L_{R,j},   Σ̃_jj = 1/d_j − L_{R,j}ᵀ Σ̃_{R,j}

The pattern is chordal, so ``Σ̃_{R,R}`` is known when column ``j`` is reached; memory ``O(nnz(L))``, work
that of the factorisation. Here the recurrence runs on (relaxed, :func:`_amalgamate`) *supernodes*
``J = j0..j1`` sharing one row set ``R``, as dense block products::

    Y = L_{R,J} L_{J,J}⁻¹,   Σ̃_{R,J} = − Σ̃_{R,R} Y,   Σ̃_{J,J} = L_{J,J}⁻ᵀ D_J⁻¹ L_{J,J}⁻¹ − Yᵀ Σ̃_{R,J}

Supernodes of one level of the elimination tree are independent: the recurrence runs level by level from the
root, each level batched into a few buckets padded to one shape (:class:`_Schedule`), so the Python
overhead is per bucket. A child's ``Σ̃_{R,R}`` is a gather from its parent's front ``Σ̃_{J∪R, J∪R}``
(SelInv's relative indices); only two levels of fronts are alive at once.

The factor is CHOLMOD's ``L D Lᵀ`` with its AMD ordering (:mod:`slamcli.solvers.nls.cholmod`), reusing the
LM's symbolic analysis when given (:func:`factor_ldl`'s ``analysis``). Shapes: ``H (n, n)`` sparse;
``index_blocks (B, k)`` integer columns of ``H``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

#: width ratio of the size classes of :class:`_Schedule` (row counts and widths within a factor of this share
#: a class before the cost model merges classes)
CLASS_RATIO = 1.25
#: overhead of one batched bucket of the recurrence (a dozen numpy calls), in units of one padded
#: multiply-add of :func:`_buckets`' cost model — which decides when padding beats another bucket
BUCKET_OVERHEAD = 50_000.0
#: relaxed supernodes (:func:`_amalgamate`): at most this many columns, at most this fraction of explicit zeros
AMALGAMATE_MAX_WIDTH = 12
AMALGAMATE_MAX_ZEROS = 0.5
#: blocks at least this wide are inverted by the blocked triangular inverse (:func:`_unit_lower_inverse_blocked`)
TRTRI_MIN_WIDTH = 128
#: the blocked triangular inverse's leaves: blocks at most this wide go to numpy's batched LU inverse
TRI_LEAF_WIDTH = 32


class NotPositiveDefiniteError(np.linalg.LinAlgError):
    """The factorisation met a pivot ≤ 0; ``column`` is the column of ``H`` (original order) where."""

    def __init__(self, message: str, column: int) -> None:
        super().__init__(message)
        self.column = int(column)


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


def factor_ldl(H: sp.spmatrix, analysis=None) -> LdlFactor:
    """CHOLMOD's fill-reducing ``L D Lᵀ`` (AMD ordering) of a symmetric positive definite ``H``.

    ``H``: the full symmetric matrix or its lower triangle. ``analysis``: a
    :class:`~slamcli.solvers.nls.cholmod.CholmodFactor` of ``H``'s lower pattern, e.g. the LM's:
    its ordering and symbolic factorisation are reused, only the numeric factorisation is paid.

    Raises
    ------
    ImportError                 CHOLMOD (CVXOPT) does not import.
    NotPositiveDefiniteError    a pivot ≤ 0 (``H`` is not numerically positive definite).
    """
    from slamcli.solvers.nls.cholmod import CholmodFactor, lower_csc

    H = H if sp.isspmatrix_csc(H) else sp.csc_matrix(H)
    lo = H if analysis is not None and analysis.matches(H) else lower_csc(H)
    F = analysis if analysis is not None and analysis.matches(lo) else CholmodFactor(lo)
    L = F.ld_at(lo.data)
    if L is None:
        raise NotPositiveDefiniteError("sparse LDLᵀ of H: a pivot ≤ 0", F.failed_column or 0)
    perm = F.perm()
    if not np.all(L.indices[L.indptr[:-1]] == np.arange(L.shape[0])):
        raise ValueError("CHOLMOD's L does not store its diagonal first")
    d = L.data[L.indptr[:-1]].copy()
    L.data[L.indptr[:-1]] = 1.0  # unit lower triangular: P H Pᵀ = L D Lᵀ
    return LdlFactor(L, d, perm)


class _Supernodes:
    """The supernodal pattern of ``L`` (unit lower triangular, sorted CSC, diagonal first in every column),
    with relaxed supernodes.

    Fundamental supernodes (runs of columns with nested patterns) are amalgamated along chains of the
    elimination tree (:func:`_amalgamate`): a supernode absorbs its parent when the parent's columns follow
    its own (postorder) and the zeros this adds to ``L``'s pattern stay few — fewer, wider supernodes and a
    shallower tree for the level-batched recurrence. Supernode ``K``: columns ``first[K] ..
    first[K] + width[K] − 1``, row set ``J ∪ R`` (``nrows[K]`` rows, concatenated in ``rows`` from
    ``key_start[K]``); ``keys`` = sorted ``K·n + row`` of every block row (the lookup of an entry's local row);
    ``off`` = start of ``K``'s row-major ``nrows × width`` block in the storage of :class:`SelectedInverse`;
    ``fmap`` = local row (in its supernode) of every row of every fundamental supernode, ``col_shift`` = where
    a column's stored entries of ``L`` start in ``fmap`` minus where they start in ``L``; ``par`` = parent of
    every supernode in their elimination tree (the owner of its first row below ``J``; −1 at a root)."""

    def __init__(self, L: sp.csc_matrix) -> None:
        n = L.shape[0]
        ip, ix = L.indptr, L.indices
        self.n = n
        cnt = np.diff(ip)  # entries per column including the diagonal
        if n and (np.any(cnt < 1) or np.any(ix[ip[:-1]] != np.arange(n))):
            raise ValueError("L must store its diagonal first in every column (sorted CSC)")
        # fundamental supernodes: column j+1 continues j's when j's first off-diagonal row is j+1 and
        # pattern(j) = {j} ∪ pattern(j+1)  (chordality makes equal counts sufficient)
        nxt = np.where(cnt > 1, ix[np.minimum(ip[:-1] + 1, max(len(ix) - 1, 0))], -1)
        cont = (nxt[:-1] == np.arange(1, n)) & (cnt[:-1] == cnt[1:] + 1)
        ffirst = np.flatnonzero(np.concatenate(([True], ~cont))) if n else np.zeros(0, np.int64)
        fwidth = np.diff(np.append(ffirst, n)).astype(np.int64)
        fnrows = cnt[ffirst].astype(np.int64)
        fsn_of = np.repeat(np.arange(ffirst.size), fwidth)
        is_first = np.zeros(n, bool)
        is_first[ffirst] = True
        frows = ix[np.repeat(is_first, cnt)].astype(np.int64)
        f_rep, f_u, f_starts = _ragged(fnrows)  # every fundamental row's supernode, its place, the run starts
        fkey_start = f_starts[:-1]
        fpar = np.full(ffirst.size, -1, np.int64)
        below = fnrows > fwidth
        fpar[below] = fsn_of[frows[fkey_start[below] + fwidth[below]]]
        group = _amalgamate(fpar, fwidth, fnrows)  # merged supernode of every fundamental one
        starts = np.flatnonzero(np.concatenate(([True], group[1:] != group[:-1]))) if n else np.zeros(0, np.int64)
        top = np.append(starts[1:], ffirst.size) - 1  # last (topmost) member of every merged supernode
        # elimination tree of the merged supernodes: the merged parent of the topmost member's parent (the owner
        # of the first row below J; the other members' parents are members too), −1 at a root
        ptop = fpar[top]
        self.par = np.where(ptop >= 0, group[ptop], -1)
        self.first = ffirst[starts]
        self.width = np.diff(np.append(self.first, n)).astype(np.int64)
        r_top = fnrows[top] - fwidth[top]
        self.nrows = self.width + r_top
        ns = self.first.size
        self.sn_of = np.repeat(np.arange(ns), self.width)  # supernode of each (permuted) column
        self.off = _starts(self.nrows * self.width)
        # merged row set: the supernode's own columns, then the rows below its topmost member
        rep, u, key_starts = _ragged(self.nrows)
        self.key_start = key_starts[:-1]
        w_rep = self.width[rep]
        tk = top[rep]
        self.rows = np.where(u < w_rep, self.first[rep] + u, frows[fkey_start[tk] + fwidth[tk] + u - w_rep])
        self.keys = rep * n + self.rows
        # every fundamental row's place in its merged supernode's row set (entries of L are found through it)
        self.frow_sn = group[f_rep]
        self.fmap = self.local_rows(self.frow_sn, frows[fkey_start[f_rep] + f_u], own=True)
        # per column: where its stored entries start among the fundamental rows (minus its start in L)
        self.col_shift = fkey_start[fsn_of] + (np.arange(n) - ffirst[fsn_of]) - ip[:-1]
        self.cnt = cnt

    def local_rows(self, K: np.ndarray, rows: np.ndarray, own: bool = False) -> np.ndarray:
        """Position of row ``rows[i]`` in the row set of supernode ``K[i]`` (ValueError if it is not there).

        ``own``: every row is ``≥ first[K]`` (a row of a member or child of ``K``, or the larger index of an
        entry in one of ``K``'s columns): those among ``K``'s own columns lie in its row set by construction
        and are placed directly, only the others are searched (and checked)."""
        if own:
            local = rows - self.first[K]
            below = np.flatnonzero(local >= self.width[K])
            if below.size:
                local[below] = self.local_rows(K[below], rows[below])
            return local
        key = K * self.n + rows
        g = np.searchsorted(self.keys, key)
        found = g < len(self.keys)
        found[found] = self.keys[g[found]] == key[found]
        if not np.all(found):
            raise ValueError("requested entries of H⁻¹ are not on the pattern of the factor")
        return g - self.key_start[K]


class SelectedInverse:
    """``Σ̃ = (P H Pᵀ)⁻¹`` on the pattern of ``L`` (supernodal Takahashi recurrence, see module doc).

    Build with :meth:`from_matrix` (CHOLMOD) or from any :class:`LdlFactor`; read blocks of ``H⁻¹`` in the
    original order with :meth:`blocks` / :meth:`entries`. Memory: one float per stored entry of the
    supernodal pattern (``≈ nnz(L)``) plus the index arrays. Only a few blocks wanted (marginals):
    :func:`inverse_blocks`, which keeps no more than those.
    """

    def __init__(self, factor: LdlFactor) -> None:
        sn = _Supernodes(factor.L)
        self.n, self._sn = sn.n, sn
        self.perm = factor.perm
        self.iperm = _inverse_permutation(factor.perm)
        self.sn_first, self.sn_width, self.sn_nrows, self.sn_of, self.off = (
            sn.first, sn.width, sn.nrows, sn.sn_of, sn.off)
        self.vals = np.zeros(int(sn.off[-1]))  # supernode K: dense row-major (nrows × width) at off[K]
        if not sn.n:
            return
        plan = _Schedule(sn)
        K, u, _ = _ragged(sn.nrows * sn.width)  # supernode of every stored entry, its place there (runs at off)
        t, c = u // sn.width[K], u % sn.width[K]  # local row and column of every stored entry
        self.vals[:] = plan.run(factor, *plan.front_index(K, t, c))

    @classmethod
    def from_matrix(cls, H: sp.spmatrix, index_blocks=()) -> SelectedInverse:
        """Factor ``H`` with CHOLMOD (:func:`factor_ldl`) and run the recurrence.

        ``index_blocks``: arrays ``(B, k)`` of columns whose ``k × k`` blocks :meth:`blocks` will be asked
        for; their pattern is added to ``H``'s as explicit zeros (:func:`with_block_pattern`)."""
        return cls(factor_ldl(with_block_pattern(H, index_blocks)))

    def entries(self, rows: np.ndarray, cols: np.ndarray) -> np.ndarray:
        """``(H⁻¹)[rows, cols]`` (original order, equal shapes) — each pair must lie on the pattern of the
        factor (true for any two variables that share a factor of the graph, e.g. one pose's x, y, θ)."""
        rows, cols = np.asarray(rows, np.int64), np.asarray(cols, np.int64)
        shape = np.broadcast(rows, cols).shape
        qa, qb = self.iperm[rows.ravel()], self.iperm[cols.ravel()]
        lo, hi = np.minimum(qa, qb), np.maximum(qa, qb)
        K = self.sn_of[lo]
        p = self._sn.local_rows(K, hi, own=True)  # hi ≥ lo ≥ first[K]
        return self.vals[self.off[K] + p * self.sn_width[K] + (lo - self.sn_first[K])].reshape(shape)

    def blocks(self, index_blocks: np.ndarray) -> np.ndarray:
        """Marginal covariance blocks ``(H⁻¹)[idx, idx]`` for each row of ``index_blocks (B, k)`` → ``(B, k, k)``."""
        idx = np.asarray(index_blocks, np.int64)
        B, k = idx.shape
        r = np.broadcast_to(idx[:, :, None], (B, k, k))
        c = np.broadcast_to(idx[:, None, :], (B, k, k))
        return self.entries(r, c)


def with_block_pattern(H: sp.spmatrix, index_blocks=()) -> sp.csc_matrix:
    """``H`` (CSC) with the ``k × k`` pattern of every row of every ``index_blocks (B, k)`` added as explicit
    zeros, so that each such block lies on the pattern of the factor even for variables no factor couples
    (e.g. held-fixed ones)."""
    H = sp.csc_matrix(H)
    extra = [np.asarray(b, np.int64) for b in index_blocks if np.size(b)]
    if not extra:
        return H
    C = sp.coo_matrix(H)
    r = [C.row] + [np.repeat(b, b.shape[1], axis=1).ravel() for b in extra]
    c = [C.col] + [np.tile(b, (1, b.shape[1])).ravel() for b in extra]
    v = [C.data] + [np.zeros(b.size * b.shape[1]) for b in extra]
    return sp.csc_matrix((np.concatenate(v), (np.concatenate(r), np.concatenate(c))), shape=H.shape)


def inverse_blocks(H: sp.spmatrix, index_blocks, analysis=None) -> list[np.ndarray]:
    """``(H⁻¹)[idx, idx]`` ``(B, k, k)`` for every row of every ``index_blocks (B, k)`` — the marginals —
    by the batched recurrence, keeping only the fronts of two levels and the requested entries (no
    ``nnz(L)`` storage, no lookup table for other entries). ``analysis``: as :func:`factor_ldl`'s.

    ``H`` is factored as it is; only when a block is off the pattern of its factor (a variable no factor
    couples, e.g. a held-fixed one) is it factored again with the blocks' pattern added
    (:func:`with_block_pattern`).

    Raises ImportError (no CHOLMOD) and :class:`NotPositiveDefiniteError` as :func:`factor_ldl`."""
    sets = [np.asarray(b, np.int64) for b in index_blocks]
    tri = [np.nonzero(np.tri(b.shape[1], dtype=bool)) for b in sets]  # each block's lower triangle with diagonal
    factor = factor_ldl(H, analysis)
    try:
        vals = _lower_entries(factor, sets, tri)
    except ValueError:  # a block off the pattern of L
        vals = _lower_entries(factor_ldl(with_block_pattern(H, sets)), sets, tri)
    out, at = [], 0
    for b, (i, j) in zip(sets, tri):
        B, k = b.shape
        blk = np.empty((B, k, k))
        v = vals[at : at + B * i.size].reshape(B, i.size)
        blk[:, i, j] = v
        blk[:, j, i] = v
        out.append(blk)
        at += B * i.size
    return out


def _lower_entries(factor: LdlFactor, sets: list[np.ndarray], tri: list) -> np.ndarray:
    """``H⁻¹`` at the ``tri`` (lower triangle) entries of every block of ``sets``, concatenated; ValueError
    when one is off the pattern of the factor."""
    sn = _Supernodes(factor.L)
    iperm = _inverse_permutation(factor.perm)
    qa = np.concatenate([iperm[b[:, i].ravel()] for b, (i, j) in zip(sets, tri)] + [np.zeros(0, np.int64)])
    qb = np.concatenate([iperm[b[:, j].ravel()] for b, (i, j) in zip(sets, tri)] + [np.zeros(0, np.int64)])
    lo, hi = np.minimum(qa, qb), np.maximum(qa, qb)
    if not sn.n:
        return np.zeros(0)
    K = sn.sn_of[lo]
    where = sn.local_rows(K, hi, own=True)  # hi ≥ lo ≥ first[K]
    plan = _Schedule(sn)
    return plan.run(factor, *plan.front_index(K, where, lo - sn.first[K]))


def _unit_lower_inverse(blocks: np.ndarray) -> np.ndarray:
    """Inverses of unit lower triangular ``(B, w, w)`` blocks: row by row forward substitution batched over
    the blocks (``w − 1`` einsums; a third of the flops of a general inverse and none of its per-matrix
    LAPACK overhead), the blocked inverse (:func:`_unit_lower_inverse_blocked`) from :data:`TRTRI_MIN_WIDTH`
    on or when the blocks are fewer than about 0.6 (w − 1) (chosen by measurement:
    benchmarks/results/design_notes.md)."""
    B, w, _ = blocks.shape
    if w >= TRTRI_MIN_WIDTH or 5 * B < 3 * (w - 1):  # few wide blocks: matrix products beat w − 1 einsums
        return _unit_lower_inverse_blocked(blocks)
    X = np.zeros_like(blocks)
    d = np.arange(w)
    X[:, d, d] = 1.0
    for i in range(1, w):
        X[:, i, :i] = -np.einsum("bk,bkj->bj", blocks[:, i, :i], X[:, :i, :i])
    return X


def _unit_lower_inverse_blocked(blocks: np.ndarray) -> np.ndarray:
    """Inverses of lower triangular ``(B, w, w)`` blocks by the 2 × 2 block formula, recursively,
    ``[[A, 0], [C, D]]⁻¹ = [[A⁻¹, 0], [−D⁻¹ C A⁻¹, D⁻¹]]``;
    leaves of at most :data:`TRI_LEAF_WIDTH` columns by numpy's batched LU inverse (its rounding-level upper
    triangle dropped). Matrix products only: LAPACK's ``trtri`` would cost ``import scipy.linalg`` for no
    gain (measured: benchmarks/results/design_notes.md)."""
    B, w, _ = blocks.shape
    if w <= TRI_LEAF_WIDTH:
        return np.tril(np.linalg.inv(blocks))
    h = w // 2
    A_inv = _unit_lower_inverse_blocked(blocks[:, :h, :h])
    D_inv = _unit_lower_inverse_blocked(blocks[:, h:, h:])
    X = np.zeros_like(blocks)
    X[:, :h, :h] = A_inv
    X[:, h:, h:] = D_inv
    X[:, h:, :h] = -(D_inv @ (blocks[:, h:, :h] @ A_inv))
    return X


def _amalgamate(par: np.ndarray, width: np.ndarray, nrows: np.ndarray) -> np.ndarray:
    """Relaxed supernodes: the merged supernode of every fundamental one (non-decreasing labels).

    Supernode ``k`` may merge with ``k + 1`` when that is its parent (its columns follow, postorder) and the
    explicit zeros the pair's merged lower trapezoid gets stay at most :data:`AMALGAMATE_MAX_ZEROS` of it;
    runs of such links (chains of the tree) are cut into pieces of about :data:`AMALGAMATE_MAX_WIDTH`
    columns. Vectorised: no loop over supernodes."""
    ns = par.size
    if ns < 2 or AMALGAMATE_MAX_WIDTH <= 0:
        return np.arange(ns, dtype=np.int64)
    w, r = width, nrows - width
    extra = (w[1:] + r[1:]) - r[:-1]  # zero rows added to each column of k by merging it into k + 1
    pair = w[:-1] + w[1:]
    ok = (par[:-1] == np.arange(1, ns)) & (extra * w[:-1] <= AMALGAMATE_MAX_ZEROS * pair * (pair + 2 * r[1:] + 1) / 2)
    new_chain = np.concatenate(([True], ~ok))
    chain = np.cumsum(new_chain) - 1
    before = np.cumsum(w) - w  # columns before each supernode
    piece = (before - before[new_chain][chain]) // AMALGAMATE_MAX_WIDTH
    cut = np.concatenate(([True], (chain[1:] != chain[:-1]) | (piece[1:] != piece[:-1])))
    return np.cumsum(cut) - 1


def _inverse_permutation(perm: np.ndarray) -> np.ndarray:
    """``iperm`` with ``iperm[perm[i]] = i``: the permuted position of every original column."""
    iperm = np.empty(len(perm), np.int64)
    iperm[perm] = np.arange(len(perm))
    return iperm


def _starts(sizes: np.ndarray) -> np.ndarray:
    """``[0, cumsum(sizes)]`` as int64: where consecutive runs of ``sizes`` start, and the total."""
    out = np.zeros(len(sizes) + 1, np.int64)
    np.cumsum(sizes, out=out[1:])
    return out


def _ragged(sizes: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """For concatenated runs of ``sizes``: the run of every element, its position in the run, the run starts."""
    sizes = np.asarray(sizes, np.int64)
    starts = _starts(sizes)
    rep = np.repeat(np.arange(sizes.size), sizes)
    return rep, np.arange(starts[-1], dtype=np.int64) - starts[:-1][rep], starts


def _depths(par: np.ndarray) -> np.ndarray:
    """Depth of every node of a forest given by ``par`` (−1 at a root) by pointer jumping: ⌈log₂ height⌉ rounds
    of vector operations instead of a Python loop over the nodes."""
    depth = (par >= 0).astype(np.int64)
    anc = par.copy()
    up = np.flatnonzero(anc >= 0)
    while up.size:  # invariant: depth[K] = distance from K to anc[K] (or to its root when anc[K] = −1)
        a = anc[up]
        depth[up] += depth[a]
        anc[up] = anc[a]
        up = up[anc[up] >= 0]
    return depth


def _buckets(depth: np.ndarray, r: np.ndarray, w: np.ndarray):
    """Supernodes in processing order (level by level, root level first) cut into buckets of one level.

    Within a level, supernodes are sorted by size class (``CLASS_RATIO``) and consecutive classes merged while
    padding all to the larger costs less than another bucket (:data:`BUCKET_OVERHEAD`, in units of one padded
    multiply-add or move of the bucket's products and gathers). Returns ``order``
    (supernodes), ``b_start`` (start of every bucket in ``order``, plus the end) and the buckets' level."""
    lg = np.log(CLASS_RATIO)
    rc, sc = np.floor(np.log1p(r) / lg).astype(np.int64), np.floor(np.log1p(w) / lg).astype(np.int64)
    order = np.lexsort((w, r, sc, rc, depth))
    key = np.stack([depth[order], rc[order], sc[order]])
    gs = np.flatnonzero(np.concatenate(([True], np.any(key[:, 1:] != key[:, :-1], axis=0))))
    gn = np.diff(np.append(gs, order.size)).tolist()
    gr, gw = np.maximum.reduceat(r[order], gs).tolist(), np.maximum.reduceat(w[order], gs).tolist()
    glev = depth[order][gs].tolist()
    starts = []
    cn = cr = cw = 0
    def cost(n, r, w):  # padded cost of the products and gathers of n supernodes padded to r rows, w columns
        return n * (r * r * (w + 1) + r * w * w + w**3 + (r + w) ** 2)

    for g in range(len(gs)):
        n1, r1, w1 = gn[g], gr[g], gw[g]
        if g and glev[g] == glev[g - 1]:  # merged vs apart
            r2, w2 = max(cr, r1), max(cw, w1)
            if cost(cn + n1, r2, w2) <= cost(cn, cr, cw) + cost(n1, r1, w1) + BUCKET_OVERHEAD:
                cn, cr, cw = cn + n1, r2, w2
                continue
        starts.append(int(gs[g]))
        cn, cr, cw = n1, r1, w1
    b_start = np.array(starts + [order.size], np.int64)
    return order, b_start, depth[order][b_start[:-1]]


class _Schedule:
    """The plan of the batched recurrence, from the pattern alone (module docstring).

    Elimination tree of the supernodes (:class:`_Supernodes`' ``par``), levels by depth,
    buckets of one level (:func:`_buckets`) whose members are padded to the bucket's largest row count ``rp``
    and width ``sp``. A supernode's front is ``(sp + rp)²`` row-major, ``J`` rows first, ``R`` rows from
    ``sp``; a level's fronts lie one after another in its buffer from position 1 (position 0 holds the 0
    every padded gather reads)."""

    def __init__(self, sn: _Supernodes) -> None:
        w, m = sn.width, sn.nrows
        ns, r = w.size, m - w
        par = sn.par
        self.depth = depth = _depths(par)
        order, b_start, b_level = _buckets(depth, r, w)
        self.n_levels = int(depth.max()) + 1
        self.level_buckets = np.searchsorted(b_level, np.arange(self.n_levels + 1)).tolist()
        b_count = np.diff(b_start)
        bk, in_bucket, _ = _ragged(b_count)  # bucket of order[i], its place there (runs start at b_start)
        b_rows, b_width = np.maximum.reduceat(r[order], b_start[:-1]), np.maximum.reduceat(w[order], b_start[:-1])
        self.b_count, self.b_rows, self.b_width = b_count.tolist(), b_rows.tolist(), b_width.tolist()
        mp_b = b_rows + b_width
        cum = _starts(b_count * mp_b * mp_b)
        lv_first = np.asarray(self.level_buckets, np.int64)
        front_at = cum[:-1] - cum[lv_first[b_level]] + 1
        self.front_at = front_at.tolist()
        self.level_size = (cum[lv_first[1:]] - cum[lv_first[:-1]]).tolist()
        # per supernode: padded shape, front offset in its level's buffer, place in its bucket
        self.rp, self.sp, self.slot = (np.empty(ns, np.int64) for _ in range(3))
        self.rp[order], self.sp[order] = b_rows[bk], b_width[bk]
        self.slot[order] = in_bucket
        self.bucket = np.empty(ns, np.int64)
        self.bucket[order] = bk
        self.mp = self.rp + self.sp
        self.foff = front_at[self.bucket] + self.slot * self.mp**2
        self.sn, self.par, self.order, self.b_start = sn, par, order, b_start
        # padded L (nb, mp, sp) and D⁻¹ (nb, sp) of every bucket, one after another
        self.l_at = _starts(b_count * mp_b * b_width).tolist()
        # buckets grouped by padded width: group g's supernodes are those of its buckets, in bucket order;
        # bucket b's are at b_group_at[b] of group b_group[b] (its L_JJ⁻¹ and D̂⁻¹ blocks are views there)
        ob = np.argsort(b_width, kind="stable")
        gw, g_of = np.unique(b_width[ob], return_inverse=True)
        at = np.empty(b_count.size, np.int64)
        ob_starts = _starts(b_count[ob])
        at[ob] = ob_starts[:-1] - ob_starts[np.searchsorted(b_width[ob], gw)][g_of]
        self.b_group = np.empty(b_count.size, np.int64)
        self.b_group[ob] = g_of
        self.b_group, self.b_group_at = self.b_group.tolist(), at.tolist()
        self.group_width = gw.tolist()
        self.group_buckets = [ob[g_of == g].tolist() for g in range(gw.size)]
        self.group_sn = [np.concatenate([order[b_start[b] : b_start[b + 1]] for b in bs]) for bs in self.group_buckets]
        self.rel_at, self.rel = self._relative_positions()

    def _relative_positions(self):
        """Position in the parent's front of every row below every supernode, padded to ``rp`` with 0
        (supernode ``order[i]``'s at ``rel_at[i]``): its row in the parent's ``J ∪ R``, ``J`` first, ``R``
        after the parent's padded width; and the same row's start in the previous level's buffer
        (``rel_row``: front offset + row · padded size; 0 on the padding), so that the gather of
        ``Σ̃_{R,R}`` is ``rel_row[a] + rel[b]``. Padded positions read finite values of that buffer that only
        meet zero rows of ``Y``."""
        sn, par = self.sn, self.par
        r = sn.nrows - sn.width
        rep, u, _ = _ragged(r)
        P = par[rep]
        loc = sn.local_rows(P, sn.rows[sn.key_start[rep] + sn.width[rep] + u], own=True)  # the rows below J
        wP = sn.width[P]
        pos = np.where(loc < wP, loc, loc - wP + self.sp[P])
        start = np.empty(r.size, np.int64)
        start[self.order] = _starts(self.rp[self.order])[:-1]
        rel = np.zeros(int(self.rp.sum()), np.int64)
        rel[start[rep] + u] = pos
        self.rel_row = np.zeros(rel.size, np.int64)
        self.rel_row[start[rep] + u] = self.foff[P] + pos * self.mp[P]
        return start[self.order][self.b_start[:-1]].tolist() + [rel.size], rel

    def front_index(self, K, t, c):
        """Where the recurrence leaves ``Σ̃`` at local row ``t``, column ``c < width`` of supernode ``K``:
        positions in the level buffers, grouped by level (``(src, level starts, order)``)."""
        fr = np.where(t < self.sn.width[K], t, t - self.sn.width[K] + self.sp[K])
        pos = self.foff[K] + fr * self.mp[K] + c
        o = np.argsort(self.depth[K], kind="stable")
        at = np.searchsorted(self.depth[K][o], np.arange(self.n_levels + 1))
        return pos[o], at.tolist(), o

    def _padded_factor(self, factor: LdlFactor):
        """``L`` as the buckets' padded ``(nb, mp, sp)`` panels, flat in bucket order (zero on the padding)."""
        sn, L = self.sn, factor.L
        K, w, sp_ = sn.sn_of, sn.width, self.sp
        base = np.asarray(self.l_at)[self.bucket] + self.slot * self.mp * sp_
        # 32-bit positions where they fit: the scatter of L's nnz entries is bound by memory traffic
        it = np.int32 if max(self.l_at[-1], sn.fmap.size, L.data.size) < 2**31 else np.int64
        colbase = (base[K] + (np.arange(sn.n) - sn.first[K])).astype(it)  # row 0 of every column's panel
        G, t = sn.frow_sn, sn.fmap
        rowoff = (np.where(t < w[G], t, t - w[G] + sp_[G]) * sp_[G]).astype(it)  # padded row offsets
        at = np.repeat(sn.col_shift.astype(it), sn.cnt)  # every entry's row among the fundamental rows
        at += np.arange(L.data.size, dtype=it)
        dst = np.repeat(colbase, sn.cnt)
        dst += rowoff[at]
        lpad = np.zeros(self.l_at[-1])
        lpad[dst] = L.data
        return lpad

    def _diagonal_terms(self, lpad: np.ndarray, d: np.ndarray):
        """``L_JJ⁻¹`` (identity on the padding) and ``L_JJ⁻ᵀ D_J⁻¹ L_JJ⁻¹`` (zero on the padding) of every
        supernode, one ``(N, sp, sp)`` array per padded width ``sp`` (:attr:`group_sn`), so that a bucket's
        blocks are a view. They depend on the factor only: batched over all buckets of one width, not per
        bucket."""
        sn = self.sn
        linv, sjj = [], []
        for sp_, Ks, bs in zip(self.group_width, self.group_sn, self.group_buckets):
            a = np.arange(sp_)
            # L_JJ (zero on the padding): the leading rows of the group's padded panels, copied as slices
            blk = np.concatenate([lpad[self.l_at[b] : self.l_at[b + 1]].reshape(self.b_count[b], -1, sp_)[:, :sp_]
                                  for b in bs])
            blk[:, a, a] = 1.0
            inv = _unit_lower_inverse(blk)
            col = sn.first[Ks][:, None] + a
            dinv = np.where(a < sn.width[Ks][:, None], 1.0 / d[np.minimum(col, sn.n - 1)], 0.0)
            linv.append(inv)
            sjj.append(inv.mT @ (inv * dinv[:, :, None]))
        return linv, sjj

    def run(self, factor: LdlFactor, src: np.ndarray, src_at: list, o: np.ndarray) -> np.ndarray:
        """The recurrence, root level first; returns ``Σ̃`` at the front positions ``src`` (of
        :meth:`front_index`) in the caller's order."""
        lpad = self._padded_factor(factor)
        linv, sjj = self._diagonal_terms(lpad, factor.d)
        out = np.empty(src.size)
        # two buffers, levels alternating (position 0 stays 0: the padded gathers' slot)
        buf, prev = np.zeros(max(self.level_size) + 1), np.zeros(max(self.level_size) + 1)
        lb = self.level_buckets
        for lv in range(self.n_levels):
            for b in range(lb[lv], lb[lv + 1]):
                self._bucket(b, buf, prev, lpad, linv, sjj)
            out[src_at[lv] : src_at[lv + 1]] = buf[src[src_at[lv] : src_at[lv + 1]]]
            buf, prev = prev, buf
        res = np.empty_like(out)
        res[o] = out
        return res

    def _bucket(self, b: int, buf, prev, lpad, linv, sjj) -> None:
        """The block recurrence (module docstring) for the ``nb`` supernodes of bucket ``b`` at once, fronts
        written to ``buf``; ``prev`` holds the parents' fronts.

        Padded rows of ``Σ̃_{R,R}`` are gathered from the parent's first row (finite values, not zeros): they
        only ever meet the zero padded rows of ``Y`` and land in padded rows of the front, which no child
        reads."""
        nb, rp, s = self.b_count[b], self.b_rows[b], self.b_width[b]
        mp = rp + s
        g, k0 = self.b_group[b], self.b_group_at[b]
        SJJ = sjj[g][k0 : k0 + nb]  # L_JJ⁻ᵀ D_J⁻¹ L_JJ⁻¹
        f0 = self.front_at[b]
        F = buf[f0 : f0 + nb * mp * mp].reshape(nb, mp, mp)
        if rp:
            Lb = lpad[self.l_at[b] : self.l_at[b + 1]].reshape(nb, mp, s)
            Y = Lb[:, s:] @ linv[g][k0 : k0 + nb]  # L_RJ L_JJ⁻¹
            rel = self.rel[self.rel_at[b] : self.rel_at[b + 1]].reshape(nb, rp)
            S = prev[self.rel_row[self.rel_at[b] : self.rel_at[b + 1]].reshape(nb, rp, 1) + rel[:, None, :]]
            SRJ = S @ Y  # −Σ̃_{R,J}
            SJJ = SJJ + Y.mT @ SRJ
            np.negative(SRJ, out=SRJ)
            F[:, s:, :s] = SRJ
            F[:, :s, s:] = SRJ.mT
            F[:, s:, s:] = S
        F[:, :s, :s] = SJJ  # symmetric up to rounding; every block returned is built from its lower triangle
