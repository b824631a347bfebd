"""Problem description of the sparse least-squares engine: factor blocks, the problem, its parameters
and result, and the retraction ``x ⊞ h`` (see :mod:`slamcli.solvers.nls`).
"""

from __future__ import annotations

import functools
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Literal

import numpy as np
import scipy.sparse as sp

from slamcli.models import se2
from slamcli.models.angles import wrap_angle
from slamcli.types import Status


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
    residual : callable ``x (D,) -> r (F, k)`` or None
        The residuals of ``evaluate`` without the Jacobians (the same values), for cost-only evaluations
        (LM's trial steps); None = ``evaluate(x)[0]``.
    evaluate_body : callable ``x (D,) -> (r (F, k), J (F, k, n))`` or None
        ``evaluate`` with the columns of every SE(2) pose already in the body chart
        (``J · blkdiag(R(θ), 1)``, ``NlsParams.pose_chart = "body"``), for blocks that get them cheaper in
        one pass than by the assembler's rotation of ``evaluate``'s; None = ``evaluate`` then that rotation.
    """

    name: str
    cols: np.ndarray
    evaluate: EvaluateFn
    sqrt_info: np.ndarray
    robust: bool = False
    residual: Callable[[np.ndarray], np.ndarray] | None = None
    evaluate_body: EvaluateFn | None = None

    def residuals(self, x: np.ndarray) -> np.ndarray:
        """Unwhitened residuals ``r (F, k)`` at ``x``."""
        return self.evaluate(x)[0] if self.residual is None else self.residual(x)

    @property
    def n_factors(self) -> int:
        return int(self.cols.shape[0])


EvaluateFn = Callable[[np.ndarray], tuple[np.ndarray, np.ndarray]]


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
        a dense Schur complement on the remaining (border) columns (:class:`ChainSolver`) when the border
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

    method : "lm" | "gn" | "dogleg"   LM; Gauss-Newton with step halving; Powell's dogleg trust region.
    max_iterations : int         accepted steps (an LM iteration may solve several damped systems, as GTSAM's).
    rel_cost_tol : float         converged when an accepted step lowers the cost by < ``rel_cost_tol · cost``.
    pred_cost_tol : float        LM, 0 = off: converged when the predicted decrease ``−gᵀh − ½hᵀHh`` is below
                                 ``pred_cost_tol · cost`` while λ ≤ ``lambda_init`` (``optimize.LAST_FACTOR_REGIME``).
    frozen_step_rel : float      LM, 0 = off: after a step lowering the cost by ≤ this fraction, first try the
                                 held factorisation (simplified Newton; kept at ``optimize.FROZEN_MIN_FIDELITY``).
    abs_cost_tol, step_tol : float       converged when cost < abs_cost_tol or ‖h‖ ≤ step_tol · (‖x‖ + step_tol).
    lambda_init, lambda_factor : float   λ₀ (GTSAM 1e-5) and the fixed factor (GTSAM 10).
    lambda_update : "fixed" | "nielsen"  GTSAM's fixed factor, or Nielsen's schedule (Madsen et al. 2004 §3.2).
    lambda_min, lambda_max : float       bounds of λ; a rejected trial reaching ``lambda_max`` stops (GTSAM).
    min_model_fidelity : float   accept a trial when actual / predicted decrease exceeds this (GTSAM 1e-3).
    damping : "levenberg" | "marquardt"  ``D = I`` or ``D = diag(H)`` clamped to [1e-6, 1e32].
    delta_init : float           initial dogleg trust-region radius (GTSAM 1).
    linear_solver : "auto" | "cholmod" | "superlu" | "chain"   CHOLMOD (CVXOPT), SciPy's SuperLU, or the banded
                                 chain + dense border Schur solver; ``auto`` = CHOLMOD when it imports.
    pose_chart : "body" | "world"        SE(2) steps ``x ⊕ Exp(ξ)``, ξ in the body frame (GTSAM's Pose2), or world.
    robust, huber_k : str, float kernel ("none" | "huber" | "cauchy" | "geman_mcclure") on blocks with
                                 ``robust=True``, and its width on the whitened residual norm.
    max_border : int             largest border dimension for the chain/Schur solver.
    """

    method: Literal["lm", "gn", "dogleg"] = "lm"
    max_iterations: int = 100
    rel_cost_tol: float = 1e-12
    pred_cost_tol: float = 0.0
    frozen_step_rel: float = 0.0
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
        if not self.pred_cost_tol >= 0.0:
            raise ValueError("pred_cost_tol must be ≥ 0")
        if not 0.0 <= self.frozen_step_rel < 1.0:
            raise ValueError("frozen_step_rel must be in [0, 1)")
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
    information : csc_matrix (D, D)  ``H = JᵀΛJ`` (IRLS-weighted) at ``x`` in world coordinates, built on first
                                 access (a property over ``information_fn``) — for :func:`marginal_covariances`.
    linear_solves : int          linear systems solved (accepted + rejected steps + GN damping retries).
    notes : tuple[str, ...]      numerical fallbacks taken (SuperLU instead of CHOLMOD or the banded Cholesky,
                                 damped Gauss-Newton steps); empty when none were needed.
    linear_solver : str          ``cholmod``, ``superlu`` or ``chain``.
    workspace : tuple or None    ``(Assembler, linear solver)`` of the run, reusable for a follow-up problem on
                                 the same factor graph (``Assembler(problem, like=...)``).
    information_lower : ndarray (lo_nnz,) or None   lower-triangle data of ``H`` on ``workspace``'s pattern, in
                                 the pose chart ``information_chart`` — what the marginals factor directly.
    information_chart : "body" | "world"   the pose chart of ``information_lower``.
    """

    x: np.ndarray
    cost: float
    status: Status
    message: str
    iterations: int
    cost_trace: np.ndarray
    time_trace: np.ndarray
    information_fn: Callable[[], sp.csc_matrix] = field(repr=False, compare=False)
    linear_solves: int = 0
    notes: tuple[str, ...] = ()
    linear_solver: str = ""
    workspace: tuple | None = field(default=None, repr=False, compare=False)
    information_lower: np.ndarray | None = field(default=None, repr=False, compare=False)
    information_chart: str = "world"

    @functools.cached_property
    def information(self) -> sp.csc_matrix:
        """``H`` at ``x`` in world coordinates (class docstring), computed once on first access."""
        return self.information_fn()


def pose_offsets(cols: np.ndarray, n_poses: int) -> list[int]:
    """Offsets ``o`` of the Jacobian columns ``cols[:, o:o+3]`` that are one SE(2) pose ``[x, y, θ]`` (one of
    the first ``n_poses`` triplets) in every factor of a block. A pose column outside such a triplet is an
    error (the body chart could not be applied to it)."""
    if n_poses <= 0 or cols.size == 0:
        return []
    P = 3 * n_poses
    offs, covered = [], np.zeros(cols.shape, bool)
    first = [int(v) for v in cols[0]]
    for o in range(cols.shape[1] - 2):
        f0 = first[o]  # a triplet in every factor is one in the first: test that before all of them
        if not (f0 < P and f0 % 3 == 0 and first[o + 1] == f0 + 1 and first[o + 2] == f0 + 2):
            continue
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
    poses = se2.compose(x[:P].reshape(-1, 3), se2.exp(h[:P].reshape(-1, 3))).ravel()
    if P == x.size:  # a pose graph: nothing else to step
        return poses
    out = problem.apply_step(x, np.concatenate([np.zeros(P), h[P:]]))
    out[:P] = poses
    return out
