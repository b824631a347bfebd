"""Marginal covariances (Laplace approximation) from a sparse information matrix — the one marginals path
of slamcli: graph SLAM (:func:`slamcli.solvers.graph.build.laplace_marginals`), ICM
(:func:`slamcli.solvers.icm.energy.laplace_covariances`) and the landmark merge test all call
:func:`block_marginals`.

Marginals are blocks of ``Σ = H⁻¹`` (``EVALUATION-METHOD.md`` §A2), never a dense inverse. Three algorithms,
tried in this order by :func:`block_marginals`:

1. the *selected inverse* (:mod:`slamcli.solvers.nls.selinv`, CHOLMOD's factor; Takahashi recurrence on the
   pattern of ``L``), whenever CHOLMOD imports (CVXOPT, a dependency);
2. the chain + border elimination (:func:`marginals_chain_border`) when the leading pose block of ``H`` is
   block tridiagonal;
3. the column solve on a symmetric SuperLU elimination (:func:`factorize_information`,
   :func:`marginal_covariances`).

Policy on an ``H`` that is not numerically positive definite (singular, indefinite, a pivot ≤ 0): **refuse**.
No algorithm regularises ``H`` (no ``ε·I``): a covariance from a regularised singular ``H`` is a number the
data do not determine. :func:`block_marginals` raises ``numpy.linalg.LinAlgError`` (or its subclass
:class:`NotPositiveDefiniteError`, which carries the column) with a message naming the variable, and every
returned block has been checked finite and positive definite (:func:`check_covariance_blocks`); the solvers
then report no covariances and say why in the result's message.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence

import numpy as np
import scipy.sparse as sp

from slamcli.solvers.nls import selinv
from slamcli.solvers.nls.linear import cholmod_available, factorize_symmetric
from slamcli.solvers.nls.selinv import NotPositiveDefiniteError


def factorize_information(information: sp.spmatrix, require_positive_definite: bool = False):
    """Sparse factorisation of ``H`` to share between several :func:`marginal_covariances` calls.

    With ``require_positive_definite``, the factorisation must be a symmetric elimination (row order =
    column order, i.e. SuperLU never left the diagonal) with every pivot ``> 0`` — then it is the
    ``LDLᵀ`` of a numerically positive definite ``H`` and its inverse is a valid covariance. Otherwise
    :class:`NotPositiveDefiniteError` names the column of the most negative pivot (or a plain LinAlgError
    says that a zero pivot forced SuperLU off the diagonal); this costs nothing beyond the factorisation,
    unlike solving for the columns of ``H⁻¹`` and finding invalid blocks afterwards.

    Raises
    ------
    numpy.linalg.LinAlgError   (exactly) singular ``H``;  NotPositiveDefiniteError, see above.
    """
    try:
        lu = factorize_symmetric(sp.csc_matrix(information))
    except RuntimeError as exc:  # SuperLU: "Factor is exactly singular"
        raise np.linalg.LinAlgError(f"information matrix is singular ({exc})") from None
    if require_positive_definite:
        piv = lu.U.diagonal()
        col_at = np.argsort(lu.perm_c)  # col_at[k] = column of H eliminated k-th
        if not np.array_equal(lu.perm_r, lu.perm_c):  # a zero pivot: SuperLU left the diagonal
            raise np.linalg.LinAlgError("the sparse elimination of H met a zero pivot (left the diagonal)")
        bad = np.flatnonzero(~(piv > 0.0))
        if bad.size:
            k = int(bad[np.argmin(piv[bad])])
            raise NotPositiveDefiniteError(
                f"{bad.size} pivot(s) ≤ 0 in the sparse LDLᵀ of H (smallest {piv[k]:.3g})", col_at[k]
            )
    return lu


def marginal_covariances(
    information: sp.spmatrix, index_blocks: np.ndarray, batch_size: int = 512, factor=None
) -> np.ndarray:
    """Marginal covariance blocks ``(H⁻¹)[idx, idx]`` for each row of ``index_blocks (B, k)``.

    One sparse factorisation of ``H``; the unit columns of all requested indices are solved in batches of
    ``batch_size`` and only the ``k × k`` blocks are kept. Cost ``O(B k · nnz(factor))``, memory
    ``O(D · batch_size)``. Pass ``factor`` (from :func:`factorize_information`) to reuse a factorisation.

    Returns
    -------
    ndarray (B, k, k)
    """
    H = sp.csc_matrix(information)
    idx = np.asarray(index_blocks, np.int64)
    B, k = idx.shape
    out = np.empty((B, k, k))
    if B == 0:
        return out
    lu = factorize_symmetric(H) if factor is None else factor
    D = H.shape[0]
    flat = idx.ravel()
    per = max(1, batch_size // k)  # blocks per batch
    for start in range(0, B, per):
        stop = min(B, start + per)
        cols = flat[start * k : stop * k]
        E = np.zeros((D, cols.size))
        E[cols, np.arange(cols.size)] = 1.0
        X = lu.solve(E)  # (D, nb·k): columns of H⁻¹
        nb = stop - start
        rows = idx[start:stop]  # (nb, k)
        Xb = X.T.reshape(nb, k, D)  # Xb[b, j, :] = column idx[b, j] of H⁻¹
        out[start:stop] = np.take_along_axis(Xb, np.broadcast_to(rows[:, None, :], (nb, k, k)), axis=2)
    # symmetrise round-off
    return 0.5 * (out + np.swapaxes(out, 1, 2))


def check_covariance_blocks(cov: np.ndarray, what: str) -> None:
    """Raise ``numpy.linalg.LinAlgError`` unless every block of ``cov (B, k, k)`` is finite and positive
    definite — the property every marginal of a positive definite ``H`` has. A factorisation of an ``H``
    that is not numerically positive definite returns blocks that violate it; they must not be reported.

    ``what`` names the variable kind in the message (``"pose"`` → ``"pose 17: ..."``).
    """
    cov = np.asarray(cov, float)
    if not cov.shape[0]:
        return
    finite = np.all(np.isfinite(cov.reshape(cov.shape[0], -1)), axis=1)
    if not np.all(finite):
        raise np.linalg.LinAlgError(
            f"{what} {int(np.flatnonzero(~finite)[0])}: non-finite marginal covariance"
        )
    sym = 0.5 * (cov + np.swapaxes(cov, 1, 2))
    if _leading_minors_positive(sym):  # the usual case: positive definite, no eigenvalues needed
        return
    low = np.linalg.eigvalsh(sym)[:, 0]
    bad = int(np.argmin(low))
    if low[bad] <= 0.0:
        raise np.linalg.LinAlgError(f"{what} {bad}: marginal covariance has eigenvalue {low[bad]:.3g} ≤ 0")


def _leading_minors_positive(sym: np.ndarray) -> bool:
    """Whether every symmetric block of ``sym (B, k, k)`` is positive definite by Sylvester's criterion (all
    leading principal minors > 0), in closed form for ``k ≤ 3`` (a few elementwise operations, cheaper than a
    batched Cholesky), by a batched Cholesky otherwise. False means "not shown":
    the caller decides with eigenvalues."""
    k = sym.shape[1]
    if k > 3:
        try:
            np.linalg.cholesky(sym)
        except np.linalg.LinAlgError:
            return False
        return True
    a = sym[:, 0, 0]
    if k == 1 or not np.all(a > 0.0):
        return bool(np.all(a > 0.0))
    b, d = sym[:, 1, 0], sym[:, 1, 1]
    m2 = a * d - b * b
    if k == 2 or not np.all(m2 > 0.0):
        return bool(np.all(m2 > 0.0))
    c, e, f = sym[:, 2, 0], sym[:, 2, 1], sym[:, 2, 2]
    m3 = f * m2 - a * e * e + 2.0 * b * c * e - d * c * c
    return bool(np.all(m3 > 0.0))


def is_block_tridiagonal(information: sp.spmatrix, n_chain: int, k: int) -> bool:
    """Whether the leading ``(n_chain·k)²`` block of ``H`` only couples neighbouring ``k``-blocks."""
    A = sp.coo_matrix(sp.csc_matrix(information)[: n_chain * k, : n_chain * k])
    return bool(np.all(np.abs(A.row // k - A.col // k) <= 1))


def marginals_chain_border(
    information: sp.spmatrix, n_chain: int, k: int, *, poses: bool = True, batch_size: int = 128
) -> tuple[np.ndarray, np.ndarray]:
    """Marginal covariances for a "chain + border" information matrix (pose chain + landmarks).

    ``H = [[A, B], [Bᵀ, C]]`` with ``A`` block tridiagonal (``n_chain`` blocks of size ``k``: pose-pose factors
    only between consecutive poses, or unary) and an arbitrary sparse border ``B`` (``m`` columns). With the
    banded Cholesky ``A = UᵀU`` and ``S = RᵀR``::

        S = C − Bᵀ A⁻¹ B           (m × m, from column batches of A⁻¹ B)      Σ_CC = S⁻¹
        Σ_ii = (A⁻¹)_ii + Z_i Z_iᵀ ,   Z = A⁻¹ B R⁻¹

    ``Z`` is never formed: its columns come ``batch_size`` at a time and only the ``k × k`` blocks ``Z_i Z_iᵀ``
    are accumulated; the blocks of ``A⁻¹`` come from the block-tridiagonal (RTS-type) recursion. Memory
    ``O(n · batch_size + m²)`` (no dense ``n × m`` block), time ``O(n m (k + nnz(B)/n) + m³)``. ``poses=False``
    skips the pose marginals (only ``Σ_CC``).

    Returns
    -------
    chain_cov : ndarray (n_chain, k, k)   marginal blocks of the chain variables (empty with ``poses=False``).
    border_cov : ndarray (m, m)           joint marginal covariance of all border variables.

    Raises
    ------
    NotPositiveDefiniteError   the banded Cholesky of ``A`` or the Cholesky of ``S`` met a pivot ≤ 0
                               (``column`` = the column of ``H`` where it happened).
    """
    import scipy.linalg as sla
    from scipy.linalg import lapack

    H = sp.csc_matrix(information)
    n = n_chain * k
    if not is_block_tridiagonal(H, n_chain, k):
        raise ValueError("the chain block of H is not block tridiagonal")
    A = H[:n, :n].tocsr()
    Bs = H[:n, n:].tocsc()
    Cm = H[n:, n:].toarray()
    # banded upper storage of A (half-bandwidth u = 2k − 1)
    u = 2 * k - 1
    Au = sp.triu(A).tocoo()
    ab = np.zeros((u + 1, n))
    ab[u + Au.row - Au.col, Au.col] = Au.data
    cb, info = lapack.dpbtrf(ab, lower=0)
    if info != 0:
        raise NotPositiveDefiniteError(
            f"banded Cholesky of the pose chain: leading minor {info} of H is not positive definite", info - 1
        )

    def a_solve(rhs: np.ndarray) -> np.ndarray:  # A⁻¹ rhs, rhs (n, b)
        return sla.cho_solve_banded((cb, False), rhs, check_finite=False)

    m = Bs.shape[1]
    pose_extra = np.zeros((n_chain if poses else 0, k, k))
    if m:
        BsT = Bs.T.tocsr()
        Sch = Cm
        for j0 in range(0, m, batch_size):
            j1 = min(m, j0 + batch_size)
            Sch[:, j0:j1] -= BsT @ a_solve(Bs[:, j0:j1].toarray())
        Sch = 0.5 * (Sch + Sch.T)
        cS, info = lapack.dpotrf(Sch, lower=0, clean=1)
        if info != 0:
            raise NotPositiveDefiniteError(
                f"Cholesky of the border Schur complement: leading minor {info} is not positive definite",
                n + info - 1,
            )
        Rinv, info = lapack.dtrtri(cS, lower=0)  # S⁻¹ = R⁻¹R⁻ᵀ
        border_cov = Rinv @ Rinv.T
        if poses:
            for j0 in range(0, m, batch_size):
                j1 = min(m, j0 + batch_size)  # R⁻¹ is upper triangular: rows ≥ j1 of its columns j0:j1 are 0
                Z = a_solve(Bs[:, :j1] @ Rinv[:j1, j0:j1]).reshape(n_chain, k, j1 - j0)
                pose_extra += np.einsum("tkb,tlb->tkl", Z, Z, optimize=True)
    else:
        border_cov = np.zeros((0, 0))
    if not poses:
        return np.zeros((0, k, k)), border_cov
    # block-tridiagonal selected inverse of A
    idx = np.arange(n_chain)[:, None] * k + np.arange(k)[None, :]  # (n_chain, k)
    Dblk = _gather_blocks(A, idx, idx)
    Eblk = _gather_blocks(A, idx[:-1], idx[1:])
    Sinv = np.empty((n_chain, k, k))
    S = Dblk[0]
    Sinv[0] = np.linalg.inv(S)
    for i in range(1, n_chain):  # sequential recursion; O(k³) numpy work per block
        S = Dblk[i] - Eblk[i - 1].T @ Sinv[i - 1] @ Eblk[i - 1]
        Sinv[i] = np.linalg.inv(S)
    G = Sinv[:-1] @ Eblk  # (n_chain-1, k, k)
    cov = np.empty((n_chain, k, k))
    cov[-1] = Sinv[-1]
    for i in range(n_chain - 2, -1, -1):
        cov[i] = Sinv[i] + G[i] @ cov[i + 1] @ G[i].T
    cov += pose_extra
    return 0.5 * (cov + np.swapaxes(cov, 1, 2)), border_cov


def _gather_blocks(A: sp.csr_matrix, rows: np.ndarray, cols: np.ndarray) -> np.ndarray:
    """Dense ``(B, k, k)`` blocks ``A[rows[b]][:, cols[b]]`` of a sparse matrix (vectorised lookup)."""
    B, k = rows.shape
    if B == 0:
        return np.zeros((0, k, k))
    r = np.broadcast_to(rows[:, :, None], (B, k, k)).ravel()
    c = np.broadcast_to(cols[:, None, :], (B, k, k)).ravel()
    return np.asarray(A[r, c]).reshape(B, k, k)


def block_marginals(
    information: sp.spmatrix,
    index_blocks: Sequence[np.ndarray],
    *,
    names: Sequence[str] | None = None,
    chain: int = 0,
    locate: Callable[[int], str] | None = None,
    batch_size: int = 512,
    workspace: tuple | None = None,
) -> list[np.ndarray]:
    """Marginal covariance blocks of ``Σ = H⁻¹`` for several sets of variables (module docstring).

    Parameters
    ----------
    information : sparse (D, D)      ``H``, symmetric.
    index_blocks : sequence of int arrays ``(B_s, k_s)``: row ``b`` of set ``s`` lists the columns of one
        variable (e.g. poses ``(T, 3)``, landmarks ``(L, 2)``).
    names : one word per set for messages (``"pose"`` → ``"pose 17: …"``); default ``"variable"``.
    chain : number of leading ``3``-column pose blocks that may form a block-tridiagonal chain (0 = none);
        enables the chain + border elimination when CHOLMOD is missing. Only valid when every set either
        is exactly the chain's blocks (``arange(3·chain).reshape(chain, 3)``) or lies in the border.
    locate : ``column → "pose 17"``-style name of the variable owning a column of ``H`` (for messages).
    batch_size : columns of ``H⁻¹`` per batch of the column solve.
    workspace : the ``NlsResult.workspace`` of the optimisation that produced ``H``: when its linear solver is
        CHOLMOD's factorisation of ``H``'s pattern, the selected inverse reuses its ordering and
        symbolic analysis (:func:`cholmod_analysis`).

    Returns
    -------
    list of ndarray ``(B_s, k_s, k_s)``, one per set, each block finite and positive definite.

    Raises
    ------
    numpy.linalg.LinAlgError  ``H`` is not numerically positive definite (message names the variable).
    """
    sets = [np.asarray(b, np.int64).reshape(len(b), -1) if np.size(b) else np.zeros((0, 1), np.int64)
            for b in index_blocks]
    names = list(names) if names is not None else ["variable"] * len(sets)

    def where(exc: np.linalg.LinAlgError) -> str:
        c = getattr(exc, "column", None)
        return f"{locate(c)}: {exc}" if (locate is not None and c is not None) else str(exc)

    def checked(blocks: list[np.ndarray]) -> list[np.ndarray]:
        for b, nm in zip(blocks, names):
            check_covariance_blocks(b, nm)
        return blocks

    if cholmod_available():
        try:
            return checked(selinv.inverse_blocks(information, sets, cholmod_analysis(workspace, information)))
        except np.linalg.LinAlgError as exc:
            raise np.linalg.LinAlgError(where(exc)) from None
    first_error = None
    if chain and is_block_tridiagonal(information, chain, 3):
        try:
            return checked(_chain_border_blocks(information, sets, chain))
        except np.linalg.LinAlgError as exc:  # the general sparse factorisation (another ordering) may work
            first_error = where(exc)
    try:
        factor = factorize_information(information, require_positive_definite=True)
        return checked([marginal_covariances(information, s, batch_size=batch_size, factor=factor)
                        for s in sets])
    except np.linalg.LinAlgError as exc:
        raise np.linalg.LinAlgError(first_error or where(exc)) from None


def cholmod_analysis(workspace: tuple | None, information: sp.spmatrix):
    """The CHOLMOD factor (symbolic analysis) of an optimisation's workspace ``(Assembler, linear solver)``
    when it was analysed on ``information``'s own pattern — the assembler's full pattern
    or its lower triangle (CHOLMOD reads the lower triangle of either) — else None."""
    H = information
    if not (_cholmod_workspace(workspace) and sp.isspmatrix_csc(H)):
        return None
    asm, lin = workspace
    # the lower pattern is checked first: the full one is built on first use only
    if ((np.array_equal(H.indptr, asm.lo_indptr) and np.array_equal(H.indices, asm.lo_indices))
            or (np.array_equal(H.indptr, asm.indptr) and np.array_equal(H.indices, asm.indices))):
        return lin.F
    return None


def _cholmod_workspace(workspace: tuple | None) -> bool:
    """Whether an optimisation's workspace ``(Assembler, linear solver)`` holds a CHOLMOD factor."""
    if workspace is None:
        return False
    lin = workspace[1]
    return getattr(lin, "name", "") == "cholmod"


def result_marginals(res, index_blocks: Sequence[np.ndarray], **kw) -> list[np.ndarray]:
    """:func:`block_marginals` of an optimisation's ``H`` at its estimate (``res``: an ``NlsResult``), world chart.

    When the run factored ``H`` with CHOLMOD, ``H``'s lower triangle at the estimate
    (``res.information_lower``, the optimiser's own data) goes straight into a numeric refactorisation with
    the run's symbolic analysis — no full symmetric matrix, no rotation of it. In the body pose chart
    (``J_body = J_world M``, ``M = blkdiag(R(θ_p), 1, …, I)`` orthogonal, so ``Σ_world = M Σ_body Mᵀ``) each
    requested pose block ``[x, y, θ]`` is rotated afterwards, ``R_p Σ_body,pp R_pᵀ`` with
    ``R_p = blkdiag(R(θ_p), 1)``; blocks of other variables are the same in both charts. Anything else (another
    linear solver, held-fixed pose columns, a set mixing pose and other columns) takes ``res.information``.
    ``kw``: as :func:`block_marginals` (not ``workspace``)."""
    sets = [np.asarray(b, np.int64).reshape(len(b), -1) if np.size(b) else np.zeros((0, 1), np.int64)
            for b in index_blocks]
    lower = _lower_at_estimate(res, sets)
    if lower is None:
        return block_marginals(res.information, sets, workspace=res.workspace, **kw)
    H, rotate = lower
    out = block_marginals(H, sets, workspace=res.workspace, **kw)
    if rotate is None:
        return out
    th = np.asarray(res.x, float)[2 : 3 * rotate : 3]
    for s, blk in zip(sets, out):
        if s.size and s[0, 0] < 3 * rotate:  # a set of whole pose triplets (checked by _lower_at_estimate)
            # R_p Σ R_pᵀ: the x, y rows, then the x, y columns, each pair turned by R(θ_p) (no batched 3×3
            # matmuls: 1045 blocks ≈ 170 → 85 µs)
            th_s = th[s[:, 0] // 3]
            c, sn = np.cos(th_s)[:, None], np.sin(th_s)[:, None]
            x, y = blk[:, 0], blk[:, 1]
            blk[:, 0], blk[:, 1] = c * x - sn * y, sn * x + c * y
            x, y = blk[:, :, 0], blk[:, :, 1]
            blk[:, :, 0], blk[:, :, 1] = c * x - sn * y, sn * x + c * y
    return out


def _lower_at_estimate(res, sets: list[np.ndarray]):
    """``(lower-triangle H, n_poses to rotate or None)`` for :func:`result_marginals`, or None when its
    conditions fail (then ``res.information`` is used)."""
    ws, lo = getattr(res, "workspace", None), getattr(res, "information_lower", None)
    # only the selected inverse reads a lower triangle, with the run's analysis (H below has its pattern)
    if lo is None or not _cholmod_workspace(ws) or not cholmod_available():
        return None
    asm = ws[0]
    H = asm.lower_matrix(lo)
    n = asm.problem.se2_poses
    if res.information_chart != "body" or n <= 0:
        return H, None
    P = 3 * n
    if np.any(np.asarray(asm.fixed) < P):  # a held-fixed pose column: its identity row is not a rotated one
        return None
    for s in sets:
        if not s.size or s.min() >= P:
            continue
        if s.shape[1] != 3 or np.any(s[:, 0] % 3) or np.any(s != s[:, :1] + np.arange(3)) or s.max() >= P:
            return None
    return H, n


def _chain_border_blocks(information: sp.spmatrix, sets: list[np.ndarray], chain: int) -> list[np.ndarray]:
    """The blocks of :func:`block_marginals` from :func:`marginals_chain_border`: the chain's own blocks
    from its pose marginals, every other set from the dense border covariance."""
    n = 3 * chain
    chain_idx = np.arange(n).reshape(chain, 3)
    wants_chain = any(s.shape == chain_idx.shape and np.array_equal(s, chain_idx) for s in sets)
    pose_cov, border = marginals_chain_border(information, chain, 3, poses=wants_chain)
    out = []
    for s in sets:
        if wants_chain and s.shape == chain_idx.shape and np.array_equal(s, chain_idx):
            out.append(pose_cov)
        elif s.size and s.min() < n:
            raise ValueError("a variable set mixes chain and border columns")
        else:
            b = s - n
            out.append(np.ascontiguousarray(border[b[:, :, None], b[:, None, :]]))
    return out
