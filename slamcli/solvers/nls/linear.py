"""Normal equations and their linear solvers: the sparse assembler (structure once, values by scatter)
and CHOLMOD / SuperLU / banded-chain factorisations refilled in place (see :mod:`slamcli.solvers.nls`).
"""

from __future__ import annotations

import functools
from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from slamcli.solvers.nls.kernels import kernel_cost, whiten
from slamcli.solvers.nls.problem import NlsParams, NlsProblem, pose_offsets

# ----------------------------------------------------------------------------------------------------------
# assembly
# ----------------------------------------------------------------------------------------------------------
#: blocks of at most this many factors are assembled with batched einsum calls (Python overhead per call
#: dominates small blocks), larger ones with per-pair vector operations on buffers (memory traffic dominates)
SMALL_BLOCK = 4096


class Assembler:
    """Sparse structure of ``H`` computed once; every call scatters new values with ``np.bincount``.

    Only the lower triangle is assembled (``i ≥ j``, CSC: what CHOLMOD reads): each factor of a block with
    ``n`` columns contributes its ``n(n+1)/2`` local pairs ``a ≤ b`` at ``(max(c_a, c_b), min(c_a, c_b))``.
    The scatter position of every pair is computed once, by one sort of the int64 keys ``col·D + row``
    (:func:`_unique_inverse`; int32 positions when they fit). :meth:`full` mirrors lower data into the full
    symmetric pattern (``indices`` / ``indptr`` / ``nnz`` / ``diag_pos``) by a precomputed gather, for
    :meth:`matrix`, SuperLU and the chain solver; :meth:`linearize` returns full data as it always did,
    :meth:`linearize_lower` the lower data the optimiser works with.
    """

    def __init__(self, problem: NlsProblem, like: Assembler | None = None) -> None:
        """``like``: an assembler whose pattern holds every entry of ``problem``'s ``H`` (e.g. another
        problem on the same variables and factor graph): its pattern is reused — the scatter positions are
        ``like``'s own when each block stacks consecutive blocks of ``like`` (:func:`_positions_by_blocks`),
        else looked up in its sorted keys instead of sorting anew — so a linear solver analysed for ``like``
        factorises this problem's ``H`` too. Without it, or when an entry is missing, the pattern is
        ``problem``'s own."""
        D = problem.n_vars
        self.problem, self.D = problem, D
        self.cols = [np.asarray(b.cols, np.int64) for b in problem.blocks]
        self.pairs = [_local_pairs(c.shape[1]) for c in self.cols]  # local (a, b), a ≤ b
        self._pair_flat = [ia * c.shape[1] + ib for c, (ia, ib) in zip(self.cols, self.pairs)]  # into (n·n, F)
        self._cols_t = [c.T.ravel() for c in self.cols]  # column of every (a, f), a-major: the gradient's scatter
        # an off-diagonal local pair on one column (a factor touching a column twice) counts twice in H
        self.twice = [_repeated_pairs(c, ia, ib) for c, (ia, ib) in zip(self.cols, self.pairs)]
        sizes = [ia.size * c.shape[0] for c, (ia, _) in zip(self.cols, self.pairs)] + [D]
        bounds = np.cumsum([0] + sizes)
        inv = _positions_by_blocks(like, self.cols) if like is not None and like.D == D else None
        key = None
        if inv is None and like is not None and like.D == D:
            key = self._keys(bounds)
            inv = _positions_in(like, key)
        own = inv is None
        block_pattern = _pose_block_pattern(self.cols, self.pairs, D) if own else None
        if block_pattern is not None:  # the pattern of whole pose blocks, from the pose-level one
            lo_indices, lo_indptr, inv = block_pattern
        elif own:
            ukey, inv = _unique_inverse(self._keys(bounds) if key is None else key)
            lo_indices, lo_indptr = (ukey % D).astype(np.int32), _indptr(ukey // D, D)
            del ukey
        del key
        self.lo_scatter = [inv[s:e] for s, e in zip(bounds[:-2], bounds[1:-1])]
        self._scatter_all = inv[: bounds[-2]]  # the blocks' pairs, in the order of the work buffer below
        self._bounds = bounds[:-1]
        self._work: dict = {}  # buffers reused by every linearisation (no fresh pages per iteration)
        self.lo_diag_pos = inv[bounds[-2]:].astype(np.int64)
        del inv
        if own:
            self.lo_nnz, self.lo_indices, self.lo_indptr = int(lo_indices.size), lo_indices, lo_indptr
        else:
            self.lo_nnz, self.lo_indices, self.lo_indptr = like.lo_nnz, like.lo_indices, like.lo_indptr
        self._full_of = None if own else like  # the full pattern: built on first use (CHOLMOD reads the lower)
        self._full: tuple | None = None
        self.pose_offsets = [pose_offsets(c, problem.se2_poses) for c in self.cols]
        # blocks whitened by L = I (the certificate's SE-Sync residuals): no products with L
        self.identity_info = [_is_identity(b.sqrt_info) for b in problem.blocks]
        fixed = np.asarray(problem.fixed_cols, np.int64)
        self.fixed = fixed
        if fixed.size:
            is_fixed = np.zeros(D, bool)
            is_fixed[fixed] = True
            self.lo_fixed_mask = is_fixed[self.lo_indices] | np.repeat(is_fixed, np.diff(self.lo_indptr))
            self.lo_fixed_diag = self.lo_diag_pos[fixed]

    def _keys(self, bounds: np.ndarray) -> np.ndarray:
        """Lower-triangle CSC keys ``col·D + row`` of every local pair (per block pair-major ``(P, F)``),
        then the diagonal ``i·D + i``."""
        D = self.D
        key = np.empty(int(bounds[-1]), np.int64)
        for c, (ia, ib), s in zip(self.cols, self.pairs, bounds[:-1]):
            F = c.shape[0]
            for p, (a, b) in enumerate(zip(ia, ib)):
                out = key[s + p * F : s + (p + 1) * F]
                np.minimum(c[:, a], c[:, b], out=out)
                out *= D
                out += np.maximum(c[:, a], c[:, b])
        key[bounds[-2]:] = np.arange(D, dtype=np.int64) * (D + 1)
        return key

    def _full_parts(self) -> tuple:
        """``(indices, indptr, nnz, diag_pos, full_src)`` of the full pattern, built once on first use (a
        solve with CHOLMOD never needs it) or shared with the ``like`` assembler whose pattern this one uses."""
        if self._full is None:
            self._full = self._full_of._full_parts() if self._full_of is not None else self._full_pattern()
        return self._full

    indices = property(lambda self: self._full_parts()[0], doc="row indices of the full symmetric pattern (CSC)")
    indptr = property(lambda self: self._full_parts()[1], doc="column pointers of the full pattern")
    nnz = property(lambda self: self._full_parts()[2], doc="entries of the full pattern")
    diag_pos = property(lambda self: self._full_parts()[3], doc="position of each diagonal entry in the full data")
    full_src = property(lambda self: self._full_parts()[4], doc="full data = lower data[full_src]")

    def _full_pattern(self) -> tuple:
        """The full symmetric CSC pattern and ``full_src``: full data = lower data[full_src]."""
        D = self.D
        tag = sp.csc_matrix((np.arange(1, self.lo_nnz + 1, dtype=float), self.lo_indices, self.lo_indptr),
                            shape=(D, D))
        full = (tag + tag.T).tocsc()  # disjoint off the diagonal; the diagonal tags are doubled
        full.sort_indices()
        src = full.data
        del tag
        indices = full.indices.astype(np.int32)
        indptr = full.indptr.astype(np.int32)
        # column j of the full pattern: the upper entries (lower row j, off the diagonal), then (j, j)
        diag_pos = indptr[:-1].astype(np.int64) + np.bincount(self.lo_indices, minlength=D) - 1
        src[diag_pos] *= 0.5
        full_src = (src - 1.0).astype(self.lo_scatter[0].dtype if self.lo_scatter else np.int64)
        return indices, indptr, int(indices.size), diag_pos, full_src

    def full(self, lo_data: np.ndarray) -> np.ndarray:
        """Data of the full symmetric pattern from lower-triangle data."""
        return lo_data[self.full_src]

    def lower(self, data: np.ndarray) -> np.ndarray:
        """Lower-triangle data from data of the full pattern (the inverse of :meth:`full`)."""
        if not hasattr(self, "_lo_in_full"):
            col = np.repeat(np.arange(self.D, dtype=np.int32), np.diff(self.indptr))
            at = np.flatnonzero(self.indices >= col)
            self._lo_in_full = np.empty(self.lo_nnz, np.int64)
            self._lo_in_full[self.full_src[at]] = at
        return data[self._lo_in_full]

    def body_to_world(self, data: np.ndarray, x: np.ndarray) -> np.ndarray | None:
        """Full data of ``H`` in world coordinates from full data in GTSAM's body chart at ``x``:
        ``J_body = J_world M`` with ``M = blkdiag(R(θ_p), 1, …, I)``, so ``H_world = M H_body Mᵀ`` — a 2×2
        rotation of the ``[x, y]`` rows and then columns of every pose, in place on a copy (no
        relinearisation). None when a pose column is held fixed (its identity row must not be rotated) or
        the pattern does not hold whole pose blocks."""
        n = self.problem.se2_poses
        P = 3 * n
        if n <= 0 or np.any(np.asarray(self.fixed) < P):
            return None
        out = np.array(data, float, copy=True)
        th = np.asarray(x, float)[2:P:3]
        c, s = np.cos(th), np.sin(th)
        rows = self.indices
        q0 = np.flatnonzero((rows < P) & (rows % 3 == 0))  # entries in an x row; the y row is the next one
        if q0.size and (q0[-1] + 1 >= rows.size or np.any(rows[q0 + 1] != rows[q0] + 1)):
            return None
        p = rows[q0] // 3
        _rotate_pairs(out, q0, q0 + 1, c[p], s[p])
        start, mid, end = (self.indptr[k:P:3].astype(np.int64) for k in (0, 1, 2))
        ln = mid - start
        if np.any(end - mid != ln):
            return None
        a0 = np.repeat(start - np.cumsum(ln) + ln, ln) + np.arange(int(ln.sum()))  # column 3p's entries
        p = np.repeat(np.arange(n), ln)
        _rotate_pairs(out, a0, a0 + ln[p], c[p], s[p])  # ... and column 3p+1's, row for row
        return out

    def matrix(self, data: np.ndarray) -> sp.csc_matrix:
        """The full symmetric ``H`` from full data (:meth:`linearize`, :meth:`full`)."""
        return sp.csc_matrix((data, self.indices.copy(), self.indptr.copy()), shape=(self.D, self.D))

    def lower_matrix(self, lo_data: np.ndarray) -> sp.csc_matrix:
        """The lower triangle of ``H`` (CSC) from lower data (:meth:`linearize_lower`)."""
        return sp.csc_matrix((lo_data, self.lo_indices, self.lo_indptr), shape=(self.D, self.D))

    def cost(self, x: np.ndarray, params: NlsParams) -> float:
        return problem_cost(self.problem, x, params, self.identity_info)

    def linearize(self, x: np.ndarray, params: NlsParams):
        """Cost, ``H`` data (nnz,) of the full pattern and gradient ``g (D,)`` at ``x``."""
        cost, lo, g = self.linearize_lower(x, params)
        return cost, self.full(lo), g

    def whitened_at(self, x: np.ndarray) -> list[np.ndarray] | None:
        """Every block's whitened residuals ``L r (F, k)`` from the last :meth:`linearize_lower`, when that was at
        this very array ``x`` (an optimiser's final estimate: the summary's χ² counts need no new evaluation),
        else None."""
        last = getattr(self, "_last_whitened", None)
        return last[1] if last is not None and last[0] is x else None

    def _buffer(self, key, shape) -> np.ndarray:
        buf = self._work.get(key)
        if buf is None or buf.shape != shape:
            buf = self._work[key] = np.empty(shape)
        return buf

    def linearize_lower(self, x: np.ndarray, params: NlsParams):
        """Cost, lower-triangle ``H`` data (lo_nnz,) and gradient ``g (D,)`` at ``x``.

        The per-factor products are written into buffers kept across calls (arrays of this size are fresh
        pages from the OS every time otherwise, and the page faults cost more than the arithmetic)."""
        vals_all = self._buffer("vals", (int(self._bounds[-1]),))
        g = np.zeros(self.D)
        total = 0.0
        whitened = []
        body = params.pose_chart == "body" and self.problem.se2_poses > 0
        for i, b in enumerate(self.problem.blocks):
            fused = body and b.evaluate_body is not None  # Jacobians in the body chart already
            r, J = b.evaluate_body(x) if fused else b.evaluate(x)
            F, k, n = J.shape
            JwT = _whitened_jacobian(x, b, J, self.pose_offsets[i] if body and not fused else [],
                                     self._buffer(("jw", i), (k, n, F)), self.identity_info[i])
            rw = r if self.identity_info[i] else whiten(b.sqrt_info, r)  # (F, k)
            whitened.append(rw)
            rho, w = kernel_cost(rw, b.robust, params)
            total += float(np.sum(rho))
            JtT = JwT if w is None else JwT * w
            ia, ib = self.pairs[i]
            vals = vals_all[self._bounds[i] : self._bounds[i + 1]].reshape(ia.size, F)
            if F <= SMALL_BLOCK:  # few factors: a handful of batched calls beat per-pair vector operations
                # the pairs a ≤ b of all n² products, gathered straight into the work buffer
                np.take(np.einsum("kaf,kbf->abf", JtT, JwT).reshape(n * n, F), self._pair_flat[i], axis=0, out=vals)
                g += np.bincount(self._cols_t[i], weights=np.einsum("kaf,fk->af", JtT, rw).ravel(), minlength=self.D)
            else:
                for p, (a, c) in enumerate(zip(ia, ib)):  # H_ab = Σ_k w J̃_ka J̃_kb, vectorised over factors
                    np.multiply(JtT[0, a], JwT[0, c], out=vals[p])
                    for kk in range(1, k):
                        vals[p] += JtT[kk, a] * JwT[kk, c]
                for a in range(n):  # g_a = Σ_k w J̃_ka r̃_k
                    ga = JtT[0, a] * rw[:, 0]
                    for kk in range(1, k):
                        ga += JtT[kk, a] * rw[:, kk]
                    g += np.bincount(self.cols[i][:, a], weights=ga, minlength=self.D)
            if self.twice[i] is not None:
                vals[self.twice[i]] *= 2.0
        data = np.bincount(self._scatter_all, weights=vals_all, minlength=self.lo_nnz)
        self._last_whitened = (x, whitened)
        self.hold_fixed(data, g)
        return total, data, g

    def hold_fixed(self, data: np.ndarray, g: np.ndarray) -> None:
        """Held-fixed columns, in place: identity rows and columns of ``H`` (lower data) and a zero gradient."""
        if self.fixed.size:
            data[self.lo_fixed_mask] = 0.0
            data[self.lo_fixed_diag] = 1.0
            g[self.fixed] = 0.0


def _whitened_jacobian(x: np.ndarray, b, J: np.ndarray, offsets: list[int], out: np.ndarray,
                       identity: bool = False) -> np.ndarray:
    """``L J`` of a block laid out ``(k, n, F)`` (factors last, contiguous) in the work buffer ``out``, each
    pose's columns at the ``offsets`` then rotated into the body chart: ``∂/∂ξ = ∂/∂x · blkdiag(R(θ), 1)``
    (``L`` acts on rows, ``R`` on columns: ``(L J) R = L (J R)``); ``identity``: ``L = I`` (no product)."""
    F, k, n = J.shape
    L = np.asarray(b.sqrt_info, float)
    if identity:
        out[:] = J.transpose(1, 2, 0)
    elif F <= SMALL_BLOCK:  # one batched product (faster than the equivalent einsum), then factors last
        out[:] = np.matmul(L, J).transpose(1, 2, 0)
    for i in range(k if F > SMALL_BLOCK and not identity else 0):
        for a in range(n):
            row = out[i, a]
            if L.ndim == 2:
                np.multiply(J[:, 0, a], L[i, 0], out=row)
                for j in range(1, k):
                    row += J[:, j, a] * L[i, j]
            else:
                np.multiply(J[:, 0, a], L[:, i, 0], out=row)
                for j in range(1, k):
                    row += J[:, j, a] * L[:, i, j]
    for o in offsets:
        th = x[b.cols[:, o] + 2]
        c, s = np.cos(th), np.sin(th)
        j0, j1 = out[:, o].copy(), out[:, o + 1]
        out[:, o] = j0 * c + j1 * s  # [J_x, J_y] R(θ), R = [[c, −s], [s, c]]
        out[:, o + 1] = j0 * -s + j1 * c
    return out


@functools.lru_cache(maxsize=16)
def _local_pairs(n: int) -> tuple[np.ndarray, np.ndarray]:
    """``np.triu_indices(n)`` (local column pairs ``a ≤ b`` of a factor with ``n`` columns), made once per ``n``
    (read-only: shared by every assembler)."""
    ia, ib = np.triu_indices(n)
    ia.flags.writeable = ib.flags.writeable = False
    return ia, ib


def problem_cost(problem: NlsProblem, x: np.ndarray, params: NlsParams, identity_info: list[bool] | None = None) -> float:
    """``Σ ρ(‖L r‖)`` over every factor at ``x`` (``½ ‖L r‖²`` where no kernel applies), block by block, without a
    pattern: ``identity_info[i]`` says that block ``i`` has ``L = I`` (its whitening is skipped), found here when
    None."""
    if identity_info is None:
        identity_info = [_is_identity(b.sqrt_info) for b in problem.blocks]
    total = 0.0
    for b, identity in zip(problem.blocks, identity_info):
        r = b.residuals(x)
        total += float(np.sum(kernel_cost(r if identity else whiten(b.sqrt_info, r), b.robust, params)[0]))
    return total


def _is_identity(L) -> bool:
    L = np.asarray(L)
    return L.ndim == 2 and L.shape[0] == L.shape[1] and bool(np.array_equal(L, np.eye(L.shape[0])))


def _rotate_pairs(d: np.ndarray, i0: np.ndarray, i1: np.ndarray, c: np.ndarray, s: np.ndarray) -> None:
    """``[d_i0, d_i1] ← [c d_i0 − s d_i1, s d_i0 + c d_i1]`` in place."""
    h0, h1 = d[i0], d[i1]
    d[i0] = c * h0 - s * h1
    d[i1] = s * h0 + c * h1


def _repeated_pairs(c: np.ndarray, ia: np.ndarray, ib: np.ndarray) -> np.ndarray | None:
    """Mask ``(P, F)`` of the off-diagonal local pairs ``a < b`` with ``c_a = c_b`` (None when there are none)."""
    off = np.flatnonzero(ia != ib)
    same = c[:, ia[off]] == c[:, ib[off]]  # (F, off-diagonal pairs), one comparison for all of them
    if not same.any():
        return None
    mask = np.zeros((ia.size, c.shape[0]), bool)
    mask[off] = same.T
    return mask


def _positions_in(like: Assembler, key: np.ndarray) -> np.ndarray | None:
    """Positions of the lower-triangle keys ``col·D + row`` in ``like``'s pattern (its keys are sorted:
    CSC order), or None when one is not there."""
    if not hasattr(like, "_lo_keys"):
        col = np.repeat(np.arange(like.D, dtype=np.int64), np.diff(like.lo_indptr))
        like._lo_keys = col * like.D + like.lo_indices
    pos = np.minimum(np.searchsorted(like._lo_keys, key), max(like.lo_nnz - 1, 0))
    if not np.array_equal(like._lo_keys[pos], key):
        return None
    return pos.astype(np.int32 if like.lo_nnz < np.iinfo(np.int32).max else np.int64)


def _positions_by_blocks(like: Assembler, cols: list[np.ndarray]) -> np.ndarray | None:
    """The scatter positions (as :func:`_positions_in`, blocks' pairs then the diagonal) when every block of
    ``cols`` stacks consecutive blocks of ``like`` with the same columns (the certificate's one block of all
    edges = the LM problem's odometry and loop-closure blocks): ``like``'s positions, pair by pair, without a
    search; None otherwise."""
    out, k = [], 0
    for c in cols:
        F, n = c.shape
        parts, row = [], 0
        while row < F and k < len(like.cols):
            lc = like.cols[k]
            if lc.shape[1] == n and row + lc.shape[0] <= F and np.array_equal(lc, c[row:row + lc.shape[0]]):
                parts.append(like.lo_scatter[k].reshape(-1, lc.shape[0]))
                row += lc.shape[0]
            k += 1
        if row != F:
            return None
        out.append(np.concatenate(parts, axis=1).ravel() if parts else np.zeros(0, np.int32))
    out.append(like.lo_diag_pos.astype(out[0].dtype if out else np.int32))
    return np.concatenate(out)


def _pose_groups(c: np.ndarray, k: int) -> np.ndarray | None:
    """The poses ``(F, g)`` of a block whose columns are ``g ≤ 2`` whole pose groups ``k·p … k·p + k − 1``, else None."""
    F, n = c.shape
    if n % k or n // k > 2:
        return None
    grp = c.reshape(F, n // k, k)
    first = grp[:, :, :1]
    if np.any(first % k) or not np.array_equal(grp - first, np.broadcast_to(np.arange(k), grp.shape)):
        return None
    return grp[:, :, 0] // k


def _pose_block_pattern(cols: list[np.ndarray], pairs: list, D: int):
    """``(lo_indices, lo_indptr, positions)`` as :class:`Assembler` computes them by sorting every local pair's key,
    derived instead from the pose-level pattern when every block's factors act on one or two whole poses of
    ``k = 3`` (or 2) consecutive columns and every pose is touched (a pose graph, the chordal systems): one sort of
    the pose pairs (E keys instead of 21 E), and each column ``kQ + b`` holding the diagonal block's rows
    ``kQ + b … kQ + k − 1`` and then ``k`` rows of every pose ``P > Q`` coupled to ``Q``, in order. None otherwise."""
    for k in (3, 2):
        groups = [_pose_groups(c, k) for c in cols] if D % k == 0 else [None]
        if cols and all(g is not None for g in groups):
            break
    else:
        return None
    N = D // k
    touched = np.zeros(N, bool)
    for g in groups:
        touched[g.ravel()] = True
    if not touched.all():  # an untouched pose has only its diagonal entries in the sorted pattern
        return None
    two = [g for g in groups if g.shape[1] == 2]
    keys = [np.minimum(g[:, 0], g[:, 1]) * N + np.maximum(g[:, 0], g[:, 1]) for g in two]
    ukey, pinv = _unique_inverse(np.concatenate(keys + [np.arange(N, dtype=np.int64) * (N + 1)]))
    Q, P = ukey // N, ukey % N
    pptr = _indptr(Q, N).astype(np.int64)
    rank = np.arange(ukey.size) - pptr[Q]  # 0 on the diagonal, the first row of its column
    m = np.diff(pptr)
    indptr = np.zeros(D + 1, np.int64)
    np.cumsum(((k - np.arange(k))[None, :] + k * (m[:, None] - 1)).ravel(), out=indptr[1:])
    start = indptr[:-1].reshape(N, k)
    lo_indices = np.empty(int(indptr[-1]), np.int32)
    off = rank > 0
    Qo, Po, ro = Q[off], P[off], rank[off]
    for b in range(k):
        base = start[Qo, b] + (k - b) + k * (ro - 1)
        for a in range(k):
            if a >= b:
                lo_indices[start[:, b] + (a - b)] = k * np.arange(N) + a
            lo_indices[base + a] = k * Po + a
    idt = np.int32 if indptr[-1] < np.iinfo(np.int32).max else np.int64
    out, o = [], 0
    for g, (ia, ib) in zip(groups, pairs):
        F = g.shape[0]
        pos = np.empty((ia.size, F), idt)
        ra, rb, one = ia % k, ib % k, ia // k == ib // k
        s_ = np.flatnonzero(one)  # pairs in one pose's block: column offset ra ≤ row offset rb
        pos[s_] = (start[g[:, ia[s_] // k], ra[s_]] + (rb[s_] - ra[s_])).T
        if g.shape[1] == 2:
            e = pinv[o:o + F]
            o += F
            c_, re, Qe = np.flatnonzero(~one), rank[e], Q[e]
            colbase = start[Qe] + (k - np.arange(k)) + k * (re - 1)[:, None]  # (F, k): rows of pose P in column b
            ca, cb = ra[c_], rb[c_]
            p_ = np.where((g[:, 0] > g[:, 1])[:, None], colbase[:, cb] + ca, colbase[:, ca] + cb)
            same = np.flatnonzero(re == 0)  # a factor on one pose twice: the pair lies in its diagonal block
            if same.size:
                p_[same] = start[Qe[same]][:, np.minimum(ca, cb)] + np.abs(ca - cb)
            pos[c_] = p_.T
        out.append(pos.ravel())
    out.append(start.ravel().astype(idt))
    return lo_indices, indptr.astype(np.int32), np.concatenate(out)


def _unique_inverse(key: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``np.unique(key, return_inverse=True)`` with less memory: one argsort, the sorted keys reusing the
    input's place, int32 inverse indices when the unique count fits."""
    perm = np.argsort(key)
    key = key[perm]
    new = np.empty(key.size, bool)
    if key.size:
        new[0] = True
        np.not_equal(key[1:], key[:-1], out=new[1:])
    ukey = key[new]
    del key
    idx = np.int32 if ukey.size < np.iinfo(np.int32).max else np.int64
    pos = np.cumsum(new, dtype=idx)
    pos -= 1
    del new
    inv = np.empty(perm.size, idx)
    inv[perm] = pos
    return ukey, inv


def _indptr(sorted_cols: np.ndarray, D: int) -> np.ndarray:
    return np.concatenate([[0], np.cumsum(np.bincount(sorted_cols, minlength=D))]).astype(np.int32)


class ChainSolver:
    """Solve ``H h = b`` for ``H = [[A, B], [Bᵀ, C]]`` with ``A`` block tridiagonal (``n_chain`` blocks of
    size ``k``) and a small dense border ``C`` (``m × m``), by a block Cholesky factorisation::

        A = UᵀU                          banded Cholesky (LAPACK pbtrf), half-bandwidth 2k − 1
        [V, y] = U⁻ᵀ [B, b_A]            banded triangular solve (tbtrs)
        S = C − VᵀV                      Schur complement (dense, m × m), Cholesky
        S h_C = b_C − Vᵀ y ,  h_A = U⁻¹ (y − V h_C)

    The scatter from the CSC data of ``H`` into the banded storage of ``A``, dense ``B`` and dense ``C`` is
    computed once; ``ok`` is False when the sparsity pattern is not chain + border.
    """

    def __init__(self, asm: Assembler, n_chain: int, k: int) -> None:
        D = asm.D
        n = n_chain * k
        self.n, self.m, self.u = n, D - n, 2 * k - 1
        rows = asm.indices.astype(np.int64)
        cols = np.repeat(np.arange(D, dtype=np.int64), np.diff(asm.indptr))
        in_a = (rows < n) & (cols < n)
        self.ok = bool(np.all(np.abs(rows[in_a] // k - cols[in_a] // k) <= 1))
        if not self.ok:
            return
        up = in_a & (rows <= cols)
        self.sel_ab = np.flatnonzero(up)
        self.pos_ab = (self.u + rows[up] - cols[up]) * n + cols[up]  # flat index into ab (u+1, n)
        in_b = (rows < n) & (cols >= n)
        self.sel_b = np.flatnonzero(in_b)
        self.pos_b = rows[in_b] * (self.m + 1) + (cols[in_b] - n)  # into [B | b_A] (n, m+1)
        in_c = (rows >= n) & (cols >= n)
        self.sel_c = np.flatnonzero(in_c)
        self.pos_c = (rows[in_c] - n) * self.m + (cols[in_c] - n)

    def solve(self, data: np.ndarray, rhs: np.ndarray) -> np.ndarray | None:
        import scipy.linalg as sla
        from scipy.linalg import lapack

        n, m, u = self.n, self.m, self.u
        ab = np.zeros((u + 1) * n)
        ab[self.pos_ab] = data[self.sel_ab]
        try:
            cb = sla.cholesky_banded(ab.reshape(u + 1, n), lower=False, check_finite=False)
        except np.linalg.LinAlgError:
            return None
        if m == 0:
            return sla.cho_solve_banded((cb, False), rhs, check_finite=False)
        R = np.zeros(n * (m + 1))
        R[self.pos_b] = data[self.sel_b]
        R = R.reshape(n, m + 1)
        R[:, m] = rhs[:n]
        Vy, info = lapack.dtbtrs(cb, R, uplo="U", trans="T")
        if info != 0:
            return None
        V, y = Vy[:, :m], Vy[:, m]
        C = np.zeros(m * m)
        C[self.pos_c] = data[self.sel_c]
        S = C.reshape(m, m) - V.T @ V
        try:
            hc = sla.cho_solve(
                sla.cho_factor(0.5 * (S + S.T), check_finite=False), rhs[n:] - V.T @ y, check_finite=False
            )
        except np.linalg.LinAlgError:
            return None
        ha, info = lapack.dtbtrs(cb, (y - V @ hc)[:, None], uplo="U", trans="N")
        if info != 0:
            return None
        h = np.concatenate([ha[:, 0], hc])
        return h if np.all(np.isfinite(h)) else None


def factorize_symmetric(H: sp.csc_matrix, ordering: str = "MMD_AT_PLUS_A"):
    """Sparse LU of a symmetric positive (semi-)definite matrix, Cholesky-like: symmetric minimum-degree
    ordering (or ``ordering="NATURAL"`` for a matrix permuted already) and no pivoting off the diagonal."""
    import scipy.sparse.linalg as spla  # imported when used: SuperLU is only the fallback with CHOLMOD

    return spla.splu(
        H,
        permc_spec=ordering,
        diag_pivot_thresh=0.0,
        options={"SymmetricMode": True},
    )


def cholmod_spd_factor(H: sp.csc_matrix):
    """CHOLMOD's Cholesky factor of a sparse symmetric ``H`` (callable: ``F(b) = H⁻¹b``), or None when ``H`` is
    not positive definite (a pivot ≤ 0)."""
    from slamcli.solvers.nls import cholmod

    return cholmod.spd_factor(H)


def solve_spd(H: sp.spmatrix, rhs: np.ndarray) -> np.ndarray:
    """``H⁻¹ rhs`` for a sparse symmetric positive definite ``H``: CHOLMOD's Cholesky (AMD ordering)
    when it imports, else :func:`factorize_symmetric` (SuperLU, minimum degree).

    Raises
    ------
    numpy.linalg.LinAlgError   ``H`` is not numerically positive definite / singular.
    """
    H = sp.csc_matrix(H)
    if cholmod_available():
        F = cholmod_spd_factor(H)
        if F is None:
            raise np.linalg.LinAlgError("matrix is not positive definite (CHOLMOD: a pivot ≤ 0)")
        return F(rhs)
    try:
        return factorize_symmetric(H).solve(rhs)
    except RuntimeError as exc:  # SuperLU: "Factor is exactly singular"
        raise np.linalg.LinAlgError(f"matrix is singular ({exc})") from None


# ----------------------------------------------------------------------------------------------------------
# linear solvers: structure analysed once per problem, numeric factorisation refilled in place
# ----------------------------------------------------------------------------------------------------------
def cholmod_available() -> bool:
    """Whether CHOLMOD (CVXOPT's wheel, a dependency) imports."""
    from slamcli.solvers.nls import cholmod

    return cholmod.available()


class _CholmodFactor:
    """Sparse ``P H Pᵀ = L Lᵀ`` by CHOLMOD (:class:`~slamcli.solvers.nls.cholmod.CholmodFactor`): the
    fill-reducing ordering ``P`` and the symbolic factorisation are computed once from the fixed lower pattern of
    ``H``; :meth:`factorize_lower` refills the numeric values in place and returns False when ``H`` is not
    positive definite. ``mode="auto"`` lets CHOLMOD choose by the flops per entry of ``L``: the supernodal
    ``LLᵀ`` (dense BLAS-3 blocks with the OpenBLAS CVXOPT ships) for large fronts, else the simplicial ``LDLᵀ``
    with a positive-pivot test."""

    name = "cholmod"

    def __init__(self, asm: Assembler, mode: str = "auto", factor=None) -> None:
        """``factor``: a :class:`~slamcli.solvers.nls.cholmod.CholmodFactor` already analysed for ``asm``'s lower
        pattern (:class:`Workspace`), reused instead of a new ordering and symbolic factorisation."""
        from slamcli.solvers.nls.cholmod import CholmodFactor

        self.asm = asm
        self.F = factor if factor is not None else CholmodFactor(asm.lower_matrix(np.ones(asm.lo_nnz)), mode=mode)

    def factorize(self, data: np.ndarray) -> bool:
        """Factorise ``H`` given by data of the full pattern (:meth:`Assembler.linearize`)."""
        return self.factorize_lower(self.asm.lower(data))

    def factorize_lower(self, lo_data: np.ndarray) -> bool:
        """Factorise ``H`` given by its lower-triangle data (:meth:`Assembler.linearize_lower`)."""
        return self.F.refactor(lo_data)

    def solve(self, rhs: np.ndarray) -> np.ndarray | None:
        h = self.F.solve(rhs)
        return h if np.all(np.isfinite(h)) else None


class SuperLUFactor:
    """SciPy's SuperLU used as a Cholesky-like elimination (symmetric mode, pivots on the diagonal).

    The minimum-degree ordering of ``H + Hᵀ`` is computed by SuperLU once, at the first factorisation;
    every later factorisation permutes the new values with a precomputed index map (no new ordering) and
    factors ``P H Pᵀ`` in its natural order."""

    name = "superlu"

    def __init__(self, asm: Assembler) -> None:
        self.asm = asm
        self.perm: np.ndarray | None = None
        self.lu = None
        self.permuted = False  # whether self.lu factors P H Pᵀ (True) or H with SuperLU's own ordering

    def _analyse(self, lu) -> None:
        perm = np.argsort(lu.perm_c)  # perm[k] = column of H eliminated k-th
        # index map: P H Pᵀ data = data[src]
        tag = self.asm.matrix(np.arange(1, self.asm.nnz + 1, dtype=float))
        Hp = tag[perm][:, perm].tocsc()
        Hp.sort_indices()
        self.src = Hp.data.astype(np.int64) - 1
        self.p_indices, self.p_indptr = Hp.indices, Hp.indptr
        self.perm = perm

    def factorize(self, data: np.ndarray) -> bool:
        self.lu = None
        try:
            if self.perm is None:
                self.lu, self.permuted = factorize_symmetric(self.asm.matrix(data)), False
                self._analyse(self.lu)
            else:
                D = self.asm.D
                Hp = sp.csc_matrix((data[self.src], self.p_indices, self.p_indptr), shape=(D, D))
                self.lu = factorize_symmetric(Hp, ordering="NATURAL")
                self.permuted = True
        except RuntimeError:  # exactly singular
            return False
        return True

    def solve(self, rhs: np.ndarray) -> np.ndarray | None:
        if self.lu is None:
            return None
        if self.permuted:
            h = np.empty_like(rhs)
            h[self.perm] = self.lu.solve(rhs[self.perm])
        else:
            h = self.lu.solve(rhs)
        return h if np.all(np.isfinite(h)) else None


class _ChainFactor:
    """:class:`ChainSolver` (banded Cholesky of the pose chain + dense Schur complement on the border)."""

    name = "chain"

    def __init__(self, asm: Assembler, n_chain: int, k: int) -> None:
        self.cs = ChainSolver(asm, n_chain, k)
        self.ok = self.cs.ok
        self.data = None

    def factorize(self, data: np.ndarray) -> bool:
        self.data = data
        return True

    def solve(self, rhs: np.ndarray) -> np.ndarray | None:
        return self.cs.solve(self.data, rhs)


def factorize_lower(lin, asm: Assembler, lo_data: np.ndarray) -> bool:
    """Factorise ``H`` given by lower-triangle data with any solver of :func:`make_linear_solver` (CHOLMOD
    reads the lower data directly, the others get the full pattern)."""
    lower = getattr(lin, "factorize_lower", None)
    return bool(lower(lo_data)) if lower is not None else bool(lin.factorize(asm.full(lo_data)))


FACTOR_NAMES = {
    "cholmod": "CHOLMOD's sparse Cholesky",
    "chain": "banded Cholesky of the pose chain",
    "superlu": "SuperLU",
}


@dataclass
class Workspace:
    """The assembler and linear solver of the last :func:`~slamcli.solvers.nls.solve` given this workspace, for
    the next solve of a problem on the same ``D`` variables (e.g. the same energy under a few changed
    matchings): when every entry of the new ``H`` lies in the last pattern, its scatter positions are looked up
    in that pattern (no sort) and a CHOLMOD solver keeps its fill-reducing ordering and symbolic factorisation
    (only numeric refactorisations). Otherwise both are built anew and kept for the next solve."""

    asm: Assembler | None = None
    lin: object | None = None
    #: solves set up by this workspace, and linear solvers it built (each a new ordering / analysis)
    solves: int = 0
    analyses: int = 0

    def setup(self, problem: NlsProblem, params: NlsParams):
        """``(assembler, linear solver)`` for ``problem``, reusing this workspace's where the pattern allows."""
        like = self.asm if self.asm is not None and self.asm.D == problem.n_vars else None
        asm = Assembler(problem, like=like)
        same = like is not None and asm.lo_indices is like.lo_indices
        self.solves += 1
        if same and isinstance(self.lin, _CholmodFactor) and params.linear_solver in ("auto", "cholmod"):
            lin = _CholmodFactor(asm, factor=self.lin.F)
        else:
            lin = make_linear_solver(asm, params)
            self.analyses += 1
        self.asm, self.lin = asm, lin
        return asm, lin


def make_linear_solver(asm: Assembler, params: NlsParams):
    """The linear solver chosen by ``params.linear_solver`` for the structure of ``asm`` (see NlsParams)."""
    kind = params.linear_solver
    if kind == "auto":
        kind = "cholmod" if cholmod_available() else "superlu"
    if kind == "chain":
        ch = asm.problem.chain
        if ch is not None and asm.D - ch[0] * ch[1] <= params.max_border:
            f = _ChainFactor(asm, ch[0], ch[1])
            if f.ok:
                return f
        kind = "superlu"  # no chain + small border layout
    if kind == "cholmod":
        if not cholmod_available():
            raise ImportError("linear_solver=cholmod needs CVXOPT's CHOLMOD (pip install cvxopt)")
        return _CholmodFactor(asm)
    return SuperLUFactor(asm)
