"""Normal equations and their linear solvers: the sparse assembler (structure once, values by scatter)
and CHOLMOD / SuperLU / banded-chain factorisations refilled in place (see :mod:`slamcli.solvers.nls`).
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from slamcli.models import se2
from slamcli.solvers.nls.kernels import kernel_cost, whiten
from slamcli.solvers.nls.problem import NlsParams, NlsProblem, pose_offsets


# ----------------------------------------------------------------------------------------------------------
# assembly
# ----------------------------------------------------------------------------------------------------------
class Assembler:
    """Sparse structure of ``H`` computed once; every call scatters new values with ``np.bincount``."""

    def __init__(self, problem: NlsProblem) -> None:
        D = problem.n_vars
        self.problem = problem
        rows, cols = [], []
        for b in problem.blocks:
            c = np.asarray(b.cols, np.int64)
            n = c.shape[1]
            rows.append(np.broadcast_to(c[:, :, None], (c.shape[0], n, n)).ravel())
            cols.append(np.broadcast_to(c[:, None, :], (c.shape[0], n, n)).ravel())
        diag = np.arange(D, dtype=np.int64)  # every variable has a diagonal slot (damping, empty rows)
        rows.append(diag)
        cols.append(diag)
        r = np.concatenate(rows)
        c = np.concatenate(cols)
        key = c * D + r  # column-major order → CSC
        ukey, inv = np.unique(key, return_inverse=True)
        self.scatter = inv.astype(np.int64)
        self.nnz = ukey.size
        self.indices = (ukey % D).astype(np.int32)
        ucol = ukey // D
        self.indptr = np.concatenate([[0], np.cumsum(np.bincount(ucol, minlength=D))]).astype(np.int32)
        self.diag_pos = self.scatter[-D:]
        self.D = D
        self.cols_flat = [np.asarray(b.cols, np.int64).ravel() for b in problem.blocks]
        self.pose_offsets = [
            pose_offsets(np.asarray(b.cols, np.int64), problem.se2_poses) for b in problem.blocks
        ]
        fixed = np.asarray(problem.fixed_cols, np.int64)
        self.fixed = fixed
        if fixed.size:
            is_fixed = np.zeros(D, bool)
            is_fixed[fixed] = True
            self.fixed_mask = is_fixed[self.indices] | np.repeat(is_fixed, np.diff(self.indptr))
            self.fixed_diag = self.diag_pos[fixed]

    def matrix(self, data: np.ndarray) -> sp.csc_matrix:
        return sp.csc_matrix((data, self.indices.copy(), self.indptr.copy()), shape=(self.D, self.D))

    def cost(self, x: np.ndarray, params: NlsParams) -> float:
        total = 0.0
        for b in self.problem.blocks:
            r, _ = b.evaluate(x)
            total += float(np.sum(kernel_cost(whiten(b.sqrt_info, r), b.robust, params)[0]))
        return total

    def linearize(self, x: np.ndarray, params: NlsParams):
        """Cost, ``H`` data (nnz,) and gradient ``g (D,)`` at ``x``."""
        vals = []
        g = np.zeros(self.D)
        total = 0.0
        body = params.pose_chart == "body" and self.problem.se2_poses > 0
        for b, cflat, offs in zip(self.problem.blocks, self.cols_flat, self.pose_offsets):
            r, J = b.evaluate(x)
            if body and offs:  # ∂/∂ξ = ∂/∂x · blkdiag(R(θ), 1) for each pose of each factor
                J = np.array(J, float, copy=True)
                for o in offs:
                    R = se2.rot2(x[b.cols[:, o] + 2])  # (F, 2, 2)
                    J[:, :, o : o + 2] = np.matmul(J[:, :, o : o + 2], R)
            rw = whiten(b.sqrt_info, r)  # (F, k)
            Jw = np.matmul(b.sqrt_info, J)  # (F, k, n)
            rho, w = kernel_cost(rw, b.robust, params)
            total += float(np.sum(rho))
            Jt = np.swapaxes(Jw, 1, 2)
            if w is not None:
                Jt = Jt * w[:, None, None]
            vals.append(np.matmul(Jt, Jw).ravel())
            g += np.bincount(cflat, weights=np.einsum("fnk,fk->fn", Jt, rw).ravel(), minlength=self.D)
        vals.append(np.zeros(self.D))
        data = np.bincount(self.scatter, weights=np.concatenate(vals), minlength=self.nnz)
        if self.fixed.size:
            data[self.fixed_mask] = 0.0
            data[self.fixed_diag] = 1.0
            g[self.fixed] = 0.0
        return total, data, g


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


def factorize_symmetric(H: sp.csc_matrix):
    """Sparse LU of a symmetric positive (semi-)definite matrix, Cholesky-like: symmetric minimum-degree
    ordering and no pivoting off the diagonal."""
    return spla.splu(
        H,
        permc_spec="MMD_AT_PLUS_A",
        diag_pivot_thresh=0.0,
        options={"SymmetricMode": True},
    )


def _solve(H: sp.csc_matrix, rhs: np.ndarray) -> np.ndarray | None:
    try:
        h = factorize_symmetric(H).solve(rhs)
    except RuntimeError:  # exactly singular
        return None
    if not np.all(np.isfinite(h)):
        return None
    return h


# ----------------------------------------------------------------------------------------------------------
# linear solvers: structure analysed once per problem, numeric factorisation refilled in place
# ----------------------------------------------------------------------------------------------------------
def cholmod_available() -> bool:
    """Whether ``scikit-sparse`` (CHOLMOD) can be imported (the ``cholmod`` extra)."""
    try:
        import sksparse.cholmod  # noqa: F401
    except ImportError:
        return False
    return True


class _CholmodFactor:
    """Sparse Cholesky ``P H Pᵀ = L Lᵀ`` by CHOLMOD: the fill-reducing ordering ``P`` and the symbolic
    factorisation are computed once from the fixed pattern of ``H``; :meth:`factorize` refills the
    numeric values in place (``cholesky_inplace``). A pivot ≤ 0 (``H`` not numerically positive definite)
    makes :meth:`factorize` return False."""

    name = "cholmod"

    def __init__(self, asm: Assembler) -> None:
        from sksparse.cholmod import CholmodNotPositiveDefiniteError, analyze

        self._not_pd = CholmodNotPositiveDefiniteError
        self.H = asm.matrix(np.ones(asm.nnz))
        self.F = analyze(self.H, mode="supernodal")

    def factorize(self, data: np.ndarray) -> bool:
        self.H.data = data
        try:
            self.F.cholesky_inplace(self.H)
        except self._not_pd:
            return False
        return True

    def solve(self, rhs: np.ndarray) -> np.ndarray | None:
        h = self.F(rhs)
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
                self.lu = spla.splu(
                    Hp, permc_spec="NATURAL", diag_pivot_thresh=0.0, options={"SymmetricMode": True}
                )
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


FACTOR_NAMES = {
    "cholmod": "CHOLMOD's sparse Cholesky",
    "chain": "banded Cholesky of the pose chain",
    "superlu": "SuperLU",
}


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
            raise ImportError("linear_solver=cholmod needs scikit-sparse (pip install 'slamcli[cholmod]')")
        return _CholmodFactor(asm)
    return SuperLUFactor(asm)
