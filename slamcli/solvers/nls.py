"""A small sparse nonlinear least-squares engine (Gauss-Newton / Levenberg-Marquardt) for factor graphs.

The problem is a set of :class:`FactorBlock` s. A block holds ``F`` factors of one type; each factor has a
residual of size ``k`` and touches ``n`` columns of the flat state vector ``x (D,)``. A block evaluates all
of its factors at once (vectorised: ``r (F, k)``, ``J (F, k, n)``), and is whitened by a square-root
information ``L`` with ``LᵀL = Λ`` (``Λ = Σ⁻¹`` for a Gaussian noise model)::

    cost(x) = Σ_blocks Σ_f ρ(‖L r_f(x)‖)          ρ(s) = ½ s²  (or Huber, see below)

which is exactly GTSAM's ``NonlinearFactorGraph.error`` for Gaussian (and robust) noise models.

Normal equations (Gauss-Newton approximation of the Hessian; IRLS weights ``w_f`` for robust kernels)::

    H = Σ_f w_f J̃_fᵀ J̃_f ,   g = Σ_f w_f J̃_fᵀ r̃_f ,   J̃ = L J,  r̃ = L r
    (H + λ D) h = −g                                      (GN: λ = 0; LM: D = diag(H) or I)

``H`` is assembled as a ``scipy.sparse.csc_matrix`` whose structure (the COO → CSC scatter map) is computed
once per problem; every iteration is one vectorised evaluation per block and a ``np.bincount`` scatter — no
Python loop over factors. Linear systems (:func:`make_linear_solver`): CHOLMOD's supernodal Cholesky
(``scikit-sparse``, extra ``cholmod``) with its fill-reducing ordering and symbolic analysis done once per
problem and the numeric factorisation refilled in place; or SciPy's SuperLU in symmetric mode with the
minimum-degree ordering of the first factorisation reused; or the chain solver (:class:`_ChainSolver`,
banded Cholesky + dense border Schur complement). ``H`` is positive semi-definite in exact arithmetic, but
not always numerically: a landmark that sits (almost) on a pose has a bearing Jacobian ``∝ 1/r`` and puts
entries of 1e24 next to entries of 1e4 into ``H`` (seen on MRCLAM robot 5 with its misread barcodes), and
Cholesky then meets a non-positive pivot: the system then goes to SuperLU, LM damps that trial with
``D = diag(H)``, and Gauss-Newton falls back to a damped step whenever the undamped system cannot be
solved or its solution is not a descent direction (each noted in ``NlsResult.notes``).

Iterations are counted as GTSAM counts them: one iteration linearises once and ends with one accepted step;
the LM steps rejected on the way (λ raised, system solved again) belong to the same iteration. So
``iterations == len(cost_trace) − 1`` and ``NlsParams.max_iterations`` bounds the accepted steps.

LM follows GTSAM's ``LevenbergMarquardtOptimizer`` (defaults of GTSAM 4.3): ``D = I``, ``λ₀ = 1e-5``;
gain ratio (GTSAM's "model fidelity") ``ϱ = (F(x) − F(x ⊞ h)) / (L(0) − L(h))`` with
``L(0) − L(h) = −gᵀh − ½hᵀHh = ½ hᵀ(λ D h − g)``; a trial is accepted iff ``ϱ > 1e-3``; then ``λ ← λ/10``,
else ``λ ← 10 λ``; when λ would exceed 1e5 the optimiser gives up as converged. Marquardt's
``D = diag(H)`` and Nielsen's schedule (Madsen, Nielsen & Tingleff, *Methods for non-linear least squares
problems*, 2004, §3.2: ``λ ← λ · max(1/3, 1 − (2ϱ − 1)³)``, ``λ ← λν, ν ← 2ν``; Ceres's strategy) are
options. They were the former default and stalled on long real chains (Victoria Park, issue 10): the
diagonal of a pose block is the chain's own stiffness there, so ``λ·diag(H)`` pins every pose and the soft
modes that bend the whole chain stay out of reach unless λ ≪ 1e-6. Powell's dogleg (``method="dogleg"``)
is GTSAM's ``DoglegOptimizer`` (:func:`_dogleg_iteration`). With ``NlsProblem.se2_poses`` the SE(2) poses
are stepped in GTSAM's Pose2 chart, ``x ⊕ Exp(ξ)`` (``NlsParams.pose_chart``).

Huber kernel (IRLS, per factor, on the whitened norm ``s = ‖r̃_f‖``, as GTSAM's ``mEstimator.Huber``)::

    ρ(s) = ½ s²           if s ≤ k          w(s) = 1
           k s − ½ k²     otherwise                k / s

Cauchy and Geman-McClure (GTSAM's ``mEstimator.Cauchy`` / ``GemanMcClure``) are in :func:`robust_kernel`.

Marginal covariances (Laplace approximation at the optimum, see ``EVALUATION-METHOD.md`` §A2) are blocks of
``H⁻¹``: for a pose chain + landmark border by :func:`marginals_chain_border` (banded Cholesky, Schur
complement, column batches — never a dense poses × landmarks block), otherwise by solving ``H X = E`` only
for the unit columns ``E`` of the requested variables, in batches, with one sparse factorisation
(:func:`marginal_covariances`) — never a dense inverse.
"""

from __future__ import annotations

import dataclasses
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Literal

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from slamcli.models import se2
from slamcli.models.angles import wrap_angle
from slamcli.types import Status

EvaluateFn = Callable[[np.ndarray], tuple[np.ndarray, np.ndarray]]


# ----------------------------------------------------------------------------------------------------------
# problem description
# ----------------------------------------------------------------------------------------------------------
@dataclass
class FactorBlock:
    """``F`` factors of one type.

    Attributes
    ----------
    name : str
        Label used in cost breakdowns (``"odometry"``, ``"bearing_range"``, ...).
    cols : ndarray (F, n) int64
        State-vector column of each Jacobian column of each factor.
    evaluate : callable ``x (D,) -> (r (F, k), J (F, k, n))``
        Unwhitened residuals and their Jacobians w.r.t. the ``n`` columns in ``cols``.
    sqrt_info : ndarray (k, k) or (F, k, k)
        Whitening ``L`` with ``LᵀL = Λ`` (information of the residual).
    robust : bool
        Whether the problem's robust kernel (if any) applies to this block (observations: yes; priors and
        odometry: usually no).
    """

    name: str
    cols: np.ndarray
    evaluate: EvaluateFn
    sqrt_info: np.ndarray
    robust: bool = False

    @property
    def n_factors(self) -> int:
        return int(self.cols.shape[0])


@dataclass
class NlsProblem:
    """A factor graph over a flat state vector ``x (D,)``.

    Attributes
    ----------
    n_vars : int
        ``D``, the state dimension.
    blocks : list[FactorBlock]
    angle_cols : ndarray (A,) int64
        Columns holding headings; they are wrapped to ``[-pi, pi)`` after every update.
    fixed_cols : ndarray (C,) int64
        Columns held constant (their rows/columns of ``H`` become identity, their gradient zero, so every
        step leaves them unchanged). Their "marginal covariance" is meaningless (identity).
    chain : (n_chain, k) or None
        Declares that the first ``n_chain·k`` columns are a chain of ``k``-blocks whose block of ``H`` is
        block tridiagonal (a pose chain); linear systems are then solved by banded Cholesky of the chain and
        a dense Schur complement on the remaining (border) columns (:class:`_ChainSolver`) when the border
        has at most ``NlsParams.max_border`` columns; otherwise SuperLU.
    retract : callable ``(x (D,), h (D,)) -> x (D,)`` or None
        Manifold update; default ``x + h`` followed by wrapping ``angle_cols``.
    se2_poses : int
        The first ``3·se2_poses`` columns are SE(2) poses ``[x, y, θ]`` (world coordinates). With
        ``NlsParams.pose_chart = "body"`` the optimiser then steps in GTSAM's Pose2 chart (see
        :func:`solve`); 0 = every column is Euclidean (``retract``/``angle_cols`` apply).
    """

    n_vars: int
    blocks: list[FactorBlock]
    angle_cols: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))
    fixed_cols: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))
    chain: tuple[int, int] | None = None
    retract: Callable[[np.ndarray, np.ndarray], np.ndarray] | None = None
    se2_poses: int = 0

    def apply_step(self, x: np.ndarray, h: np.ndarray) -> np.ndarray:
        if self.retract is not None:
            return self.retract(x, h)
        out = x + h
        if self.angle_cols.size:
            out[self.angle_cols] = wrap_angle(out[self.angle_cols])
        return out


@dataclass(frozen=True)
class NlsParams:
    """Optimiser settings (defaults = GTSAM 4.3's ``LevenbergMarquardtParams`` / ``DoglegParams``).

    Attributes
    ----------
    method : "lm" | "gn" | "dogleg"
        Levenberg-Marquardt (default), Gauss-Newton (with step halving when the cost rises, and a damped
        step when the undamped normal equations cannot be solved or give no descent direction), or Powell's
        dogleg trust region (GTSAM's ``DoglegOptimizer``, Ceres's ``DOGLEG``).
    max_iterations : int
        Budget of iterations = accepted steps (an LM iteration may solve several damped systems, as in
        GTSAM's ``LevenbergMarquardtOptimizer``; a dogleg iteration may shrink its region several times).
    rel_cost_tol : float
        Converged when an accepted step lowers the cost by less than ``rel_cost_tol · cost``.
    abs_cost_tol : float
        Converged when the cost is below this value.
    step_tol : float
        Converged when ``‖h‖ ≤ step_tol · (‖x‖ + step_tol)``.
    lambda_init : float
        Initial damping λ₀ (absolute, GTSAM's ``lambdaInitial`` = 1e-5).
    lambda_factor : float
        λ is multiplied by this after a rejected trial and divided by it after an accepted step
        (``lambda_update = "fixed"``; GTSAM's ``lambdaFactor`` = 10, ``useFixedLambdaFactor`` = true).
    lambda_update : "fixed" | "nielsen"
        λ schedule: GTSAM's fixed factor, or Nielsen's ``λ ← λ·max(1/3, 1 − (2ϱ − 1)³)`` on success and
        ``λ ← λν, ν ← 2ν`` on failure (Madsen, Nielsen & Tingleff 2004, §3.2; Ceres's LM strategy).
    lambda_min, lambda_max : float
        Bounds of λ (GTSAM's ``lambdaLowerBound`` = 0 and ``lambdaUpperBound`` = 1e5). When a rejected trial
        raises λ to ``lambda_max`` or above, LM stops as converged (no decrease possible) without trying that
        λ, as GTSAM's ``tryLambda`` does.
    min_model_fidelity : float
        A trial step is accepted when the gain ratio ``ϱ = actual / predicted decrease`` exceeds this
        (GTSAM's ``minModelFidelity`` = 1e-3).
    damping : "levenberg" | "marquardt"
        ``D = I`` (default, GTSAM's ``diagonalDamping = false``) or ``D = diag(H)`` clamped to
        ``[1e-6, 1e32]`` (GTSAM's ``diagonalDamping = true`` with its min/max diagonal). Marquardt scaling
        is what stalled LM on long real chains (Victoria Park): see the module docstring.
    delta_init : float
        Initial trust-region radius of the dogleg (GTSAM's ``deltaInitial`` = 1).
    linear_solver : "auto" | "cholmod" | "superlu" | "chain"
        Sparse Cholesky of CHOLMOD (``scikit-sparse``; symbolic analysis with its fill-reducing ordering
        once per problem, numeric factorisation in place every solve); SciPy's SuperLU in symmetric mode
        with a minimum-degree ordering computed once; or the banded chain + dense border Schur solver.
        ``auto`` = CHOLMOD when installed, else SuperLU. A factorisation that breaks down (pivot ≤ 0 of a
        numerically indefinite ``H``) falls back to SuperLU for that system (noted in the result).
    pose_chart : "body" | "world"
        For the SE(2) pose columns of ``NlsProblem.se2_poses``: ``body`` (default) steps as GTSAM's Pose2
        does, ``x ← x ⊕ Exp(ξ)`` with ``ξ`` in the body frame and the Jacobian columns of a pose rotated
        into it (``∂/∂ξ = ∂/∂x · blkdiag(R(θ), 1)``), so that damping, trust region and the finite steps
        follow GTSAM's path (on non-convex real problems another path can end in another local minimum);
        ``world`` adds ``h`` to the world coordinates and wraps θ.
    robust : "none" | "huber" | "cauchy" | "geman_mcclure"
        Kernel applied to blocks with ``robust=True`` (:func:`robust_kernel`).
    huber_k : float
        Width ``k`` of the kernel on the whitened residual norm (Huber threshold, Cauchy scale, Geman-McClure c).
    max_border : int
        Largest border (non-chain) dimension for the chain/Schur linear solver (see ``NlsProblem.chain``).
    """

    method: Literal["lm", "gn", "dogleg"] = "lm"
    max_iterations: int = 100
    rel_cost_tol: float = 1e-12
    abs_cost_tol: float = 1e-20
    step_tol: float = 1e-12
    lambda_init: float = 1e-5
    lambda_factor: float = 10.0
    lambda_update: Literal["fixed", "nielsen"] = "fixed"
    lambda_min: float = 0.0
    lambda_max: float = 1e5
    min_model_fidelity: float = 1e-3
    damping: Literal["levenberg", "marquardt"] = "levenberg"
    delta_init: float = 1.0
    linear_solver: Literal["auto", "cholmod", "superlu", "chain"] = "auto"
    pose_chart: Literal["body", "world"] = "body"
    robust: Literal["none", "huber", "cauchy", "geman_mcclure"] = "none"
    huber_k: float = 1.345
    max_border: int = 1500

    def __post_init__(self) -> None:
        if self.method not in ("lm", "gn", "dogleg"):
            raise ValueError(f"method must be lm, gn or dogleg, got {self.method!r}")
        if self.linear_solver not in ("auto", "cholmod", "superlu", "chain"):
            raise ValueError(
                f"linear_solver must be auto, cholmod, superlu or chain, got {self.linear_solver!r}"
            )
        if not self.lambda_factor > 1.0:
            raise ValueError("lambda_factor must be > 1")
        if not 0.0 <= self.lambda_min <= self.lambda_init <= self.lambda_max:
            raise ValueError("need 0 ≤ lambda_min ≤ lambda_init ≤ lambda_max")
        if not self.delta_init > 0.0:
            raise ValueError("delta_init must be > 0")
        if self.pose_chart not in ("body", "world"):
            raise ValueError(f"pose_chart must be body or world, got {self.pose_chart!r}")


@dataclass(frozen=True)
class NlsResult:
    """Outcome of :func:`solve`.

    Attributes
    ----------
    x : ndarray (D,)             the estimate.
    cost : float                 final cost (½ Σ ρ).
    status : Status              CONVERGED, MAX_ITERATIONS or FAILED.
    message : str
    iterations : int             accepted steps ``K`` (``len(cost_trace) − 1``).
    cost_trace : ndarray (K+1,)  cost at the start and after every accepted step.
    time_trace : ndarray (K+1,)  wall time of each accepted step (0 for the start), s.
    information : csc_matrix (D, D)  ``H = JᵀΛJ`` (IRLS-weighted) at ``x`` in world coordinates (also with
                                 the body pose chart) — for :func:`marginal_covariances`.
    linear_solves : int          linear systems solved (accepted + rejected steps + GN damping retries).
    notes : tuple[str, ...]      numerical fallbacks that were taken (SuperLU instead of CHOLMOD or the
                                 banded Cholesky, damped Gauss-Newton steps); empty when none were needed.
    linear_solver : str          the linear solver used (``cholmod``, ``superlu`` or ``chain``).
    """

    x: np.ndarray
    cost: float
    status: Status
    message: str
    iterations: int
    cost_trace: np.ndarray
    time_trace: np.ndarray
    information: sp.csc_matrix
    linear_solves: int = 0
    notes: tuple[str, ...] = ()
    linear_solver: str = ""


# ----------------------------------------------------------------------------------------------------------
# assembly
# ----------------------------------------------------------------------------------------------------------
class _Assembler:
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
            _pose_offsets(np.asarray(b.cols, np.int64), problem.se2_poses) for b in problem.blocks
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
            total += float(np.sum(_rho(_whiten(b.sqrt_info, r), b.robust, params)[0]))
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
            rw = _whiten(b.sqrt_info, r)  # (F, k)
            Jw = np.matmul(b.sqrt_info, J)  # (F, k, n)
            rho, w = _rho(rw, b.robust, params)
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


def _pose_offsets(cols: np.ndarray, n_poses: int) -> list[int]:
    """Offsets ``o`` of the Jacobian columns ``cols[:, o:o+3]`` that are one SE(2) pose ``[x, y, θ]`` (one of
    the first ``n_poses`` triplets) in every factor of a block. A pose column outside such a triplet is an
    error (the body chart could not be applied to it)."""
    if n_poses <= 0 or cols.size == 0:
        return []
    P = 3 * n_poses
    offs, covered = [], np.zeros(cols.shape, bool)
    for o in range(cols.shape[1] - 2):
        c = cols[:, o]
        if np.all((c < P) & (c % 3 == 0) & (cols[:, o + 1] == c + 1) & (cols[:, o + 2] == c + 2)):
            offs.append(o)
            covered[:, o : o + 3] = True
    if np.any((cols < P) & ~covered):
        raise ValueError("a factor block touches pose columns that are not whole [x, y, θ] triplets")
    return offs


def retract(problem: NlsProblem, params: NlsParams, x: np.ndarray, h: np.ndarray) -> np.ndarray:
    """The update ``x ⊞ h``: GTSAM's Pose2 retraction ``x ⊕ Exp(ξ)`` on the SE(2) poses in the body chart
    (``NlsParams.pose_chart``), :meth:`NlsProblem.apply_step` on everything else."""
    n = problem.se2_poses
    if params.pose_chart != "body" or n <= 0:
        return problem.apply_step(x, h)
    P = 3 * n
    out = problem.apply_step(x, np.concatenate([np.zeros(P), h[P:]]))
    out[:P] = se2.compose(x[:P].reshape(-1, 3), se2.exp(h[:P].reshape(-1, 3))).ravel()
    return out


class _ChainSolver:
    """Solve ``H h = b`` for ``H = [[A, B], [Bᵀ, C]]`` with ``A`` block tridiagonal (``n_chain`` blocks of
    size ``k``) and a small dense border ``C`` (``m × m``), by a block Cholesky factorisation::

        A = UᵀU                          banded Cholesky (LAPACK pbtrf), half-bandwidth 2k − 1
        [V, y] = U⁻ᵀ [B, b_A]            banded triangular solve (tbtrs)
        S = C − VᵀV                      Schur complement (dense, m × m), Cholesky
        S h_C = b_C − Vᵀ y ,  h_A = U⁻¹ (y − V h_C)

    The scatter from the CSC data of ``H`` into the banded storage of ``A``, dense ``B`` and dense ``C`` is
    computed once; ``ok`` is False when the sparsity pattern is not chain + border.
    """

    def __init__(self, asm: _Assembler, n_chain: int, k: int) -> None:
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


def _whiten(L: np.ndarray, r: np.ndarray) -> np.ndarray:
    if L.ndim == 2:
        return r @ L.T
    return np.einsum("fij,fj->fi", L, r)


def _rho(rw: np.ndarray, robust: bool, params: NlsParams):
    """Per-factor cost ``ρ (F,)`` and IRLS weight ``w (F,)`` (None = all ones)."""
    s2 = np.einsum("fk,fk->f", rw, rw)
    if not robust or params.robust == "none":
        return 0.5 * s2, None
    return robust_kernel(s2, params.robust, params.huber_k)


def robust_kernel(s2: np.ndarray, kind: str, k: float) -> tuple[np.ndarray, np.ndarray]:
    """M-estimator cost ``ρ(s)`` and IRLS weight ``w(s) = ρ'(s)/s`` of whitened norms ``s = √s2`` (F,).

    The definitions of GTSAM's ``noiseModel.mEstimator`` (all equal ``½ s²`` to second order at 0)::

        huber           ρ = ½ s²  (s ≤ k),  k s − ½ k²  (s > k)        w = 1,  k / s
        cauchy          ρ = ½ k² log(1 + s²/k²)                         w = k² / (k² + s²)
        geman_mcclure   ρ = ½ k² s² / (k² + s²)                         w = k⁴ / (k² + s²)²
    """
    if kind == "huber":
        s = np.sqrt(s2)
        big = s > k
        rho = np.where(big, k * s - 0.5 * k * k, 0.5 * s2)
        return rho, np.where(big, k / np.where(big, s, 1.0), 1.0)
    k2 = k * k
    if kind == "cauchy":
        return 0.5 * k2 * np.log1p(s2 / k2), k2 / (k2 + s2)
    if kind == "geman_mcclure":
        return 0.5 * k2 * s2 / (k2 + s2), k2 * k2 / (k2 + s2) ** 2
    raise ValueError(f"unknown robust kernel {kind!r}")


def _factorize(H: sp.csc_matrix):
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
        h = _factorize(H).solve(rhs)
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

    def __init__(self, asm: _Assembler) -> None:
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


class _SuperLUFactor:
    """SciPy's SuperLU used as a Cholesky-like elimination (symmetric mode, pivots on the diagonal).

    The minimum-degree ordering of ``H + Hᵀ`` is computed by SuperLU once, at the first factorisation;
    every later factorisation permutes the new values with a precomputed index map (no new ordering) and
    factors ``P H Pᵀ`` in its natural order."""

    name = "superlu"

    def __init__(self, asm: _Assembler) -> None:
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
                self.lu, self.permuted = _factorize(self.asm.matrix(data)), False
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
    """:class:`_ChainSolver` (banded Cholesky of the pose chain + dense Schur complement on the border)."""

    name = "chain"

    def __init__(self, asm: _Assembler, n_chain: int, k: int) -> None:
        self.cs = _ChainSolver(asm, n_chain, k)
        self.ok = self.cs.ok
        self.data = None

    def factorize(self, data: np.ndarray) -> bool:
        self.data = data
        return True

    def solve(self, rhs: np.ndarray) -> np.ndarray | None:
        return self.cs.solve(self.data, rhs)


_FACTOR_NAMES = {
    "cholmod": "CHOLMOD's sparse Cholesky",
    "chain": "banded Cholesky of the pose chain",
    "superlu": "SuperLU",
}


def make_linear_solver(asm: _Assembler, params: NlsParams):
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
    return _SuperLUFactor(asm)


# ----------------------------------------------------------------------------------------------------------
# optimiser
# ----------------------------------------------------------------------------------------------------------
def evaluate_cost(problem: NlsProblem, x: np.ndarray, params: NlsParams | None = None) -> float:
    """``½ Σ ρ(‖L r‖)`` at ``x``."""
    return _Assembler(problem).cost(np.asarray(x, float), params or NlsParams())


def residual_vector(problem: NlsProblem, x: np.ndarray) -> np.ndarray:
    """Stacked whitened residuals ``(Σ F k,)`` at ``x`` (``cost = ½‖·‖²`` without robust kernel)."""
    return np.concatenate([_whiten(b.sqrt_info, b.evaluate(x)[0]).ravel() for b in problem.blocks])


def jacobian_matrix(problem: NlsProblem, x: np.ndarray) -> sp.csr_matrix:
    """Whitened sparse Jacobian ``(Σ F k, D)`` at ``x``."""
    rows, cols, vals = [], [], []
    off = 0
    for b in problem.blocks:
        r, J = b.evaluate(x)
        F, k = r.shape
        n = b.cols.shape[1]
        Jw = np.matmul(b.sqrt_info, J)
        rows.append((off + np.arange(F * k).reshape(F, k, 1) + np.zeros((1, 1, n), np.int64)).ravel())
        cols.append(np.broadcast_to(np.asarray(b.cols)[:, None, :], (F, k, n)).ravel())
        vals.append(Jw.ravel())
        off += F * k
    return sp.csr_matrix(
        (np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))), shape=(off, problem.n_vars)
    )


def solve(
    problem: NlsProblem,
    x0: np.ndarray,
    params: NlsParams | None = None,
    callback: Callable[[int, np.ndarray, float], None] | None = None,
) -> NlsResult:
    """Minimise the problem's cost from ``x0 (D,)``.

    ``callback(k, x, cost)`` is called with the start (k = 0) and after every accepted step (k = iteration).
    """
    params = params or NlsParams()
    asm = _Assembler(problem)
    x = np.array(x0, dtype=float, copy=True)
    if x.shape != (problem.n_vars,):
        raise ValueError(f"x0 has shape {x.shape}, expected ({problem.n_vars},)")
    stats: dict = {"fallbacks": 0, "damped_gn": 0, "solves": 0, "marquardt_trials": 0}
    lin = make_linear_solver(asm, params)
    backup: list = []  # SuperLU, created on the first breakdown of the primary factorisation

    def lin_solve(data: np.ndarray, rhs: np.ndarray) -> np.ndarray | None:
        """``H(data) h = rhs``; None if no factorisation gives a finite solution."""
        stats["solves"] += 1
        h = lin.solve(rhs) if lin.factorize(data) else None
        if h is None and lin.name != "superlu":
            stats["fallbacks"] += 1
            if not backup:
                backup.append(_SuperLUFactor(asm))
            h = backup[0].solve(rhs) if backup[0].factorize(data) else None
        return h

    cost, data, g = asm.linearize(x, params)
    if not np.isfinite(cost):
        return NlsResult(
            x,
            cost,
            Status.FAILED,
            "non-finite initial cost",
            0,
            np.array([cost]),
            np.zeros(1),
            asm.matrix(data),
        )
    costs, times = [cost], [0.0]
    if callback is not None:
        callback(0, x, cost)
    lam = params.lambda_init
    nu = 2.0  # Nielsen's growth factor
    delta = params.delta_init
    status = Status.MAX_ITERATIONS
    message = f"stopped after {params.max_iterations} iterations (max_iterations)"
    it = 0
    t_last = time.perf_counter()

    def small(h: np.ndarray) -> bool:
        return bool(np.linalg.norm(h) <= params.step_tol * (np.linalg.norm(x) + params.step_tol))

    while it < params.max_iterations:
        if cost <= params.abs_cost_tol:
            status, message = Status.CONVERGED, "cost below abs_cost_tol"
            break
        diag = data[asm.diag_pos]
        Dvec = np.clip(diag, 1e-6, 1e32) if params.damping == "marquardt" else np.ones(asm.D)
        stop = None  # (status, message) that ends the optimisation inside this iteration
        if params.method == "lm":
            # one iteration: raise λ until a trial step is accepted (GTSAM's inner loop)
            while True:
                damped = data.copy()
                damped[asm.diag_pos] += lam * Dvec
                h = lin_solve(damped, -g)
                if h is None and params.damping == "levenberg":
                    # λI cannot regularise an H that is numerically indefinite because of entries many orders
                    # above the rest (a landmark on top of a pose): this trial uses Marquardt's D = diag(H)
                    Dvec = np.clip(diag, 1e-6, 1e32)
                    damped = data.copy()
                    damped[asm.diag_pos] += lam * Dvec
                    h = lin_solve(damped, -g)
                    stats["marquardt_trials"] += 1
                ok = False
                if h is not None:
                    if small(h):
                        stop = (Status.CONVERGED, "step norm below step_tol")
                        break
                    # predicted decrease of the undamped model: −gᵀh − ½hᵀHh = ½hᵀ(λDh − g)
                    pred = 0.5 * float(h @ (lam * Dvec * h - g))
                    if pred >= 0.0:
                        x_new = retract(problem, params, x, h)
                        new_cost = asm.cost(x_new, params)
                        change = cost - new_cost
                        if not np.isfinite(new_cost):
                            ok = False
                        elif pred > np.finfo(float).eps * cost:
                            rho = change / pred
                            ok = rho > params.min_model_fidelity
                        else:  # the model predicts (almost) nothing: accept any decrease
                            rho, ok = 1.0, change >= 0.0
                        if not ok and abs(change) < params.rel_cost_tol * cost:
                            stop = (Status.CONVERGED, "trial cost change below rel_cost_tol")
                            break
                if ok:
                    if params.lambda_update == "fixed":
                        lam /= params.lambda_factor
                    else:
                        lam *= max(1.0 / 3.0, 1.0 - (2.0 * rho - 1.0) ** 3)
                        nu = 2.0
                    lam = max(lam, params.lambda_min)
                    break
                if params.lambda_update == "fixed":
                    lam *= params.lambda_factor
                else:
                    lam *= nu
                    nu *= 2.0
                if lam >= params.lambda_max:  # GTSAM: give up once the raised λ reaches lambdaUpperBound
                    if h is None:
                        stop = (
                            Status.FAILED,
                            f"normal equations unsolvable even with damping λ ≥ {params.lambda_max:.3g}",
                        )
                    else:
                        stop = (
                            Status.CONVERGED,
                            f"no cost decrease with damping λ < {params.lambda_max:.3g} (lambda_max reached)",
                        )
                    break
        elif params.method == "dogleg":
            stop, x_new, new_cost, delta = _dogleg_iteration(
                problem, asm, params, lin_solve, x, cost, data, g, delta, small
            )
        else:
            h = lin_solve(data, -g)
            if h is not None and small(h):
                stop = (Status.CONVERGED, "step norm below step_tol")
            elif h is None or not float(g @ h) < 0.0:
                # H numerically not positive definite: damped step (H + λD) h = −g, λ raised ×10 until the
                # system is solvable and h points downhill (for λ → ∞, h → −g/λ, a descent direction)
                stats["damped_gn"] += 1
                scale = max(float(np.max(np.abs(diag))), 1.0)
                lam_gn = params.lambda_init * scale
                h = None
                while lam_gn <= 1e16 * scale:
                    damped = data.copy()
                    damped[asm.diag_pos] += lam_gn * Dvec
                    h = lin_solve(damped, -g)
                    if h is not None and float(g @ h) < 0.0:
                        break
                    h = None
                    lam_gn *= 10.0
                if h is None:
                    stop = (Status.FAILED, "singular normal equations (is every variable constrained?)")
            if stop is None:
                x_new = retract(problem, params, x, h)
                new_cost = asm.cost(x_new, params)
                alpha = 1.0
                while not (new_cost <= cost) and alpha > 1e-3:  # safeguard: halve the GN step
                    alpha *= 0.5
                    x_new = retract(problem, params, x, alpha * h)
                    new_cost = asm.cost(x_new, params)
                if not new_cost <= cost:
                    stop = (Status.CONVERGED, "no decrease along the Gauss-Newton step")
        if stop is not None:
            status, message = stop
            break
        it += 1
        decrease = cost - new_cost
        x = x_new
        cost, data, g = asm.linearize(x, params)
        now = time.perf_counter()
        costs.append(cost)
        times.append(now - t_last)
        t_last = now
        if callback is not None:
            callback(it, x, cost)
        if decrease <= params.rel_cost_tol * max(cost + decrease, 0.0):
            status, message = Status.CONVERGED, "relative cost decrease below rel_cost_tol"
            break
    notes = []
    if stats["fallbacks"]:
        notes.append(
            f"{_FACTOR_NAMES[lin.name]} failed {stats['fallbacks']}× (H not numerically positive definite); "
            "solved with SuperLU instead"
        )
    if stats["marquardt_trials"]:
        notes.append(
            f"{stats['marquardt_trials']} LM trial(s) damped with D = diag(H): the λI-damped system was not "
            "solvable (H not numerically positive definite)"
        )
    if stats["damped_gn"]:
        notes.append(
            f"{stats['damped_gn']} Gauss-Newton step(s) damped: the undamped normal equations were not solvable "
            "or gave no descent direction"
        )
    if params.pose_chart == "body" and problem.se2_poses > 0:  # H for the marginals: world coordinates
        data = asm.linearize(x, dataclasses.replace(params, pose_chart="world"))[1]
    return NlsResult(
        x=x,
        cost=cost,
        status=status,
        message=message,
        iterations=it,
        cost_trace=np.asarray(costs),
        time_trace=np.asarray(times),
        information=asm.matrix(data),
        linear_solves=int(stats["solves"]),
        notes=tuple(notes),
        linear_solver=lin.name,
    )


def _dogleg_iteration(problem, asm, params, lin_solve, x, cost, data, g, delta, small):
    """One Powell dogleg iteration (Nocedal & Wright, *Numerical Optimization*, §4.1; GTSAM's
    ``DoglegOptimizerImpl``): shrink the trust region ``Δ`` until a step lowers the cost.

    Steepest-descent (Cauchy) point ``h_sd = −(gᵀg / gᵀHg) g``, Gauss-Newton point ``h_gn = −H⁻¹g``::

        h = h_gn                          if ‖h_gn‖ ≤ Δ
            Δ h_sd / ‖h_sd‖               if ‖h_sd‖ ≥ Δ
            h_sd + τ (h_gn − h_sd)        else, τ ∈ [0, 1] with ‖h‖ = Δ

    gain ratio ``ϱ = (F(x) − F(x + h)) / (−gᵀh − ½hᵀHh)``; ``ϱ ≥ 0.75``: ``Δ ← max(Δ, 3‖h‖)``;
    ``0.25 ≤ ϱ < 0.75``: Δ kept; ``0 < ϱ < 0.25``: ``Δ ← Δ/2`` (step accepted); ``ϱ ≤ 0``: ``Δ ← Δ/2``
    and the step is tried again. ``H`` is factorised once per iteration (Δ does not change the system).

    Returns ``(stop, x_new, new_cost, delta)`` with ``stop`` None when a step was accepted.
    """
    H = asm.matrix(data)
    h_gn = lin_solve(data, -g)
    if h_gn is not None and not float(g @ h_gn) < 0.0:
        h_gn = None  # H not positive definite along h_gn: no Gauss-Newton point
    if h_gn is not None and small(h_gn):
        return (Status.CONVERGED, "step norm below step_tol"), None, None, delta
    gg = float(g @ g)
    gHg = float(g @ (H @ g))
    h_sd = -(gg / gHg) * g if gHg > 0.0 else -g * (np.inf if gg > 0 else 0.0)
    n_sd = float(np.linalg.norm(h_sd))
    n_gn = float(np.linalg.norm(h_gn)) if h_gn is not None else np.inf
    delta_min = params.step_tol * (np.linalg.norm(x) + params.step_tol)
    while True:
        if n_gn <= delta:
            h = h_gn
        elif n_sd >= delta:
            h = (delta / np.linalg.norm(g)) * -g  # the steepest-descent direction, cut at Δ
        else:
            d = h_gn - h_sd  # solve ‖h_sd + τ d‖² = Δ², τ ∈ [0, 1]
            a, b, c = float(d @ d), float(2.0 * (h_sd @ d)), n_sd**2 - delta**2
            tau = (-b + np.sqrt(max(b * b - 4.0 * a * c, 0.0))) / (2.0 * a)
            h = h_sd + tau * d
        pred = -float(g @ h) - 0.5 * float(h @ (H @ h))
        x_new = retract(problem, params, x, h)
        new_cost = asm.cost(x_new, params)
        rho = (cost - new_cost) / pred if pred > 0.0 else -1.0
        n_h = float(np.linalg.norm(h))
        if not np.isfinite(new_cost):
            rho = -1.0
        if rho >= 0.75:
            delta = max(delta, 3.0 * n_h)
        elif rho < 0.25:
            delta = 0.5 * min(delta, n_h)
        if rho > 0.0 and new_cost <= cost:
            return None, x_new, new_cost, delta
        if abs(cost - new_cost) < params.rel_cost_tol * cost and np.isfinite(new_cost):
            return (Status.CONVERGED, "trial cost change below rel_cost_tol"), None, None, delta
        if delta <= delta_min:
            return (Status.CONVERGED, "trust region collapsed below step_tol"), None, None, delta


# ----------------------------------------------------------------------------------------------------------
# marginals
# ----------------------------------------------------------------------------------------------------------
class NotPositiveDefiniteError(np.linalg.LinAlgError):
    """``H`` is not numerically positive definite; ``column`` is the state column whose pivot was ≤ 0."""

    def __init__(self, message: str, column: int) -> None:
        super().__init__(message)
        self.column = int(column)


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
        lu = _factorize(sp.csc_matrix(information))
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
    lu = _factorize(H) if factor is None else factor
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
    low = np.linalg.eigvalsh(0.5 * (cov + np.swapaxes(cov, 1, 2)))[:, 0]
    bad = int(np.argmin(low))
    if low[bad] <= 0.0:
        raise np.linalg.LinAlgError(f"{what} {bad}: marginal covariance has eigenvalue {low[bad]:.3g} ≤ 0")


def is_block_tridiagonal(information: sp.spmatrix, n_chain: int, k: int) -> bool:
    """Whether the leading ``(n_chain·k)²`` block of ``H`` only couples neighbouring ``k``-blocks."""
    A = sp.coo_matrix(sp.csc_matrix(information)[: n_chain * k, : n_chain * k])
    return bool(np.all(np.abs(A.row // k - A.col // k) <= 1))


def marginals_chain_border(
    information: sp.spmatrix, n_chain: int, k: int, *, poses: bool = True, batch_size: int = 128
) -> tuple[np.ndarray, np.ndarray]:
    """Marginal covariances for a "chain + border" information matrix (pose chain + landmarks).

    ``H = [[A, B], [Bᵀ, C]]`` where ``A`` (``n_chain`` blocks of size ``k``, e.g. SE(2) poses) is block
    tridiagonal — true whenever pose-pose factors only link consecutive poses (odometry, motion) or are
    unary (prior, GPS) — and the border (landmarks, ``m`` columns, ``B`` sparse) is arbitrary. With the
    banded Cholesky ``A = UᵀU`` and the Cholesky ``S = RᵀR`` of the border Schur complement::

        S = C − Bᵀ A⁻¹ B           (m × m, assembled from column batches of A⁻¹ B)      Σ_CC = S⁻¹
        Σ_ii = (A⁻¹)_ii + Z_i Z_iᵀ ,   Z = A⁻¹ B R⁻¹   (so that W Σ_CC Wᵀ = Z Zᵀ for W = A⁻¹ B)

    ``Z`` (like ``W``) is a dense ``n × m`` matrix and is never formed: its columns are computed
    ``batch_size`` at a time (``B R⁻¹[:, batch]`` is sparse × dense, ``R⁻¹`` is upper triangular so only
    its leading rows enter) and only the ``k × k`` diagonal blocks ``Z_i Z_iᵀ`` are accumulated. The
    diagonal blocks of ``A⁻¹`` come from the block-tridiagonal (Rauch-Tung-Striebel-type) recursion —
    forward ``S_0 = D_0, S_i = D_i − E_{i−1}ᵀ S_{i−1}⁻¹ E_{i−1}``; backward ``Σ_n = S_n⁻¹,
    Σ_i = S_i⁻¹ + G_i Σ_{i+1} G_iᵀ, G_i = S_i⁻¹ E_i`` (``D_i``, ``E_i = A_{i,i+1}`` blocks).

    Memory ``O(n · batch_size + m²)`` — no dense ``n × m`` block (issue 17: 100k poses × 1923 landmarks
    would need 8.6 GiB per such block); time ``O(n m (k + nnz(B)/n) + m³)``. ``poses=False`` skips the
    pose marginals (only ``Σ_CC`` is wanted, e.g. for the correspondence test).

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
