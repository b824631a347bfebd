"""Batch graph SLAM (``--method graph``): all poses ``x_0..x_T`` and landmarks ``m_0..m_{L-1}`` at once.

Factors (``model="gtsam"``, default) are defined exactly as GTSAM's, so the optimum can be checked against
``gtsam.LevenbergMarquardtOptimizer`` (``tests/test_graph_gtsam.py``)::

    prior      e = Log(p⁻¹ ⊕ x_0)                               PriorFactorPose2,     Σ = diag(prior_std²)
    odometry   e = Log(d_t⁻¹ ⊕ (x_{t-1}⁻¹ ⊕ x_t))                BetweenFactorPose2,   Σ = diag(odometry_std²)
               d_t = between(x̃_{t-1}, x̃_t) (paper 000 eq. 16)
    motion     same with d_t = [v dt, 0, ω dt] (DDMR, optional)   Σ = diag((σ_v dt)², σ_lat², (σ_ω dt)²)
    bearing-   e = [‖m − p‖ − r,  wrap(∠(m − p) − θ − b)]        BearingRangeFactor2D, Σ = NoiseSpec.obs_cov
    range                                                          (GTSAM orders it [bearing, range])
    GPS        e = p_t − z_gps (optional)                         Σ = gps_std² I

with ``Log`` the SE(2) logarithm (tangent ``[v_x, v_y, ω]``). The cost is GTSAM's ``graph.error``:
``½ Σ eᵀ Σ⁻¹ e``.

``model="paper"`` minimises the ICM-SLAM Gibbs energy of paper 000, eqs. (3)-(5) with (16), with the
correspondences held fixed and ``x_0`` fixed at the known start pose (§3)::

    E = Σ_t ‖g(x_{t-1}, u_{t-1}) − x_t‖²_R + Σ_t ‖τ(θ_{t-1})(x_t − x_{t-1}) − d_t‖²_S
        + Σ_{t,i} ‖h⁻¹(x_t, z_{t,i}) − m_{c_{t,i}}‖²_Q ,      ‖a‖²_W = aᵀ W a

(residuals from :mod:`slamcli.models.potentials`; a zero weight matrix drops its potential). See
:func:`optimize_paper_energy` — the entry point the ICM solver uses to compare its final energy with the
optimum of the same energy.

The state is optimised in world coordinates ``[x, y, θ]`` (additive update, θ wrapped) with Jacobians in
the same coordinates, so the Laplace marginals (``EVALUATION-METHOD.md`` §A2) are directly world-frame —
GTSAM's body-frame Pose2 marginals equal ``J Σ_b Jᵀ`` with ``J = blkdiag(R(θ), 1)`` of ours. The optimiser
is :mod:`slamcli.solvers.nls` (sparse GN / LM, optional Huber kernel on the observation factors).
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from typing import Literal

import numpy as np

from slamcli.errors import SolverError
from slamcli.models import motion, observation, potentials, se2
from slamcli.models.angles import wrap_angle
from slamcli.solvers import frontend, nls, selinv
from slamcli.solvers.base import BaseSolver, ProgressFn
from slamcli.types import IterationTrace, Observations, SlamInputs, SolverResult, Status


@dataclass(frozen=True)
class GraphParams:
    """Parameters of :class:`GraphSlam`.

    Attributes
    ----------
    model : "gtsam" | "paper"
        Factor definitions (module docstring). Default ``"gtsam"``.
    method : "lm" | "gn" | "dogleg"
        Levenberg-Marquardt (default, GTSAM's damping schedule), Gauss-Newton, or Powell's dogleg.
    linear_solver : "auto" | "cholmod" | "superlu" | "chain"
        Sparse linear solver of the optimiser (:class:`slamcli.solvers.nls.NlsParams`): ``auto`` = CHOLMOD
        (``scikit-sparse``) when installed, else SciPy's SuperLU; ordering computed once per problem.
    pose_chart : "body" | "world"
        How the optimiser steps a pose: GTSAM's Pose2 retraction ``x ⊕ Exp(ξ)`` (default; follows GTSAM's
        path, hence its local minimum on non-convex real data) or additive world coordinates.
    max_iterations : int
        Linear-solve budget (default 100).
    rel_cost_tol : float
        Stop when an accepted step lowers the cost by less than this fraction (default 1e-12).
    step_tol : float
        Stop when ``‖h‖ ≤ step_tol (‖x‖ + step_tol)`` (default 1e-12).
    robust : "auto" | "none" | "huber" | "cauchy" | "geman_mcclure"
        Kernel on the observation, GPS and loop-closure factors (GTSAM's m-estimators,
        :func:`slamcli.solvers.nls.robust_kernel`). Default ``auto``: ``cauchy`` when the association is ids
        reported by a real sensor (MRCLAM), else ``none`` (:func:`resolve_robust`); the kernel used is
        ``extra["robust"]``.
    huber_k : float
        Huber threshold on the whitened residual norm (default 1.345, 95 % efficiency under Gaussian noise).
    cauchy_k : float
        Cauchy scale (default 2.3849, 95 % efficiency).
    geman_mcclure_c : float
        Geman-McClure scale (default 1.0, as in GTSAM's examples).
    edge_info : bool
        Use the dataset's per-edge information matrices (``inputs.constraints``: lossless graph imports)
        for the odometry and observation factors when present, instead of the NoiseSpec σ's (default True).
    init : "odometry" | "chordal" | "spanning_tree" | "robust"
        Initial poses when ``init_from = "odometry"``: the chained odometry (default), the chordal
        relaxation of the rotations + linear translations over all pose-pose edges, or composition along a
        breadth-first spanning tree (:mod:`slamcli.solvers.pose_init`) — these two only differ from the
        odometry chain when the dataset has between-factors (loop closures) — or ``robust``: the poses of
        a Cauchy-kernel solve of the same graph started from the odometry chain (:func:`robust_initial_poses`;
        ``model=gtsam`` only). A few wrong correspondences in a long chain (GTSAM's victoria_park.txt has
        10 of 3640) drag a Gaussian solve started from the drifted chain into a stall far from its optimum
        (cost 4.98e5, λ at its bound), while the same Gaussian graph started from the robust estimate
        converges in 8 iterations to 3164 (``benchmarks/bench_graph_real.py``). ``incremental``: poses of an
        incremental pass for unknown correspondences (:func:`incremental_initial_poses`): every
        ``incremental_window`` seconds the sightings so far are associated by gated nearest neighbour on the
        current estimate and the graph is re-optimised (Cauchy kernel), so each new sighting is compared
        with the map from poses that drifted only since the last window, not since the start. Measured on
        the first 300 s of Victoria Park (aligned GPS ATE): default 21.3 m; ``init=incremental
        robust=cauchy`` 1.38 m with 3 s windows (≈ 15× the default's CPU time), 10.9 m with 10 s windows;
        ACFR car park, full run: default 1.79 m (11 of 15 beacons matched), incremental + cauchy 0.083 m
        (15 of 15). Cost: one full-chain solve per window (opt-in for that reason).
    incremental_window : float
        Window of ``init=incremental``, s (default 3).
    outlier_counts : bool
        Report χ² outlier counts per factor type at the estimate (``extra["chi2_outliers"]``; default True).
    association : "auto" | "init" | "reported" | "nn"
        Correspondence source: ``init`` = labels of the ``--init`` result; ``reported`` = sensor identities;
        ``nn`` = gated nearest neighbour on the initial poses; ``auto`` = init if given, else reported if
        any row has one, else nn.
    gate_prob : float
        χ² gate probability of the nearest-neighbour front end (default 0.999).
    nn_extra_std : float
        Extra landmark-space σ (m) added to every inverse observation in the front end (default 0.0).
    nn_drift : bool
        Inflate the front end's landmark covariances by the dead-reckoning drift since their last sighting
        (odometry σ of the NoiseSpec), so revisits after a loop gate correctly (default True).
    nn_segment_dist : float
        Returns of one pose that are adjacent in bearing (≤ 0.1 rad) and closer than this (m) are one detection,
        e.g. the several laser hits on one post (default 0.5; 0 = every row separately).
    min_obs : int
        Landmarks with fewer associated observations are dropped (default 1 = keep all).
    merge_rounds : int
        With ``nn`` association: after each optimisation, merge landmark pairs that pass the correspondence
        test of :func:`merge_candidates` (same χ² gate) and re-optimise, at most this many times (default 3;
        0 = off). Closes loops the incremental front end missed because of dead-reckoning drift.
    merge_dist : float
        Never co-observed labels closer than this (m) are merged too (paper 000's ϑ; default 1.0).
    prior_std : tuple[float, float, float]
        σ of the prior on x_0 at the known start pose (gauge), ``gtsam`` model (default 1e-4 m, m, rad).
    use_odometry : bool
        Odometry between-factors (default True).
    use_controls : bool
        Motion between-factors from the commanded controls (default False).
    motion_lateral_std : float
        σ of the lateral component of a motion factor (DDMR has none; default 0.01 m).
    use_gps : bool
        Position factors for GPS fixes when the dataset has them (default True).
    group_returns : bool
        ``gtsam`` model: one bearing-range factor per (pose, landmark) pair at the mean range and
        circular-mean bearing of its rows (:func:`group_returns`; a laser's several hits on one post).
        Point sensors have one row per pair, so this changes nothing for them (default True).
    estimate_range_bias : bool
        ``gtsam`` model: add one unknown range offset ``b`` to the state, ``r̂ = ‖m − p‖ − b`` (default
        False). A laser measures the surface of a post, on average ≈ π/4 · radius nearer than its centre;
        estimating ``b`` recovers the centres. Reported as ``extra["range_bias"]``.
    surface : bool
        Beyond the paper: the surface-aware model with the landmark radius ρ the dataset declares
        (``observations.diameter_m``, :mod:`slamcli.solvers.surface`): every range lengthened by π/4 · ρ, the
        mean distance from a post's surface hit to its centre (default False; refused when none is declared).
    paper_R, paper_S, paper_Q : tuple of rows or None
        Weight matrices of the ``paper`` model (3×3, 3×3, 2×2). ``None`` → R = 0, S = ½ diag(σ_odo)⁻²,
        Q = ½ σ_r⁻² I (so that E equals the Gaussian negative log-likelihood of the odometry).
    init_from : "odometry" | "init"
        Initial poses: chained odometry increments from x_0 (default) or the ``--init`` result's poses.
    covariance : bool
        Compute Laplace marginal covariances (default True).
    """

    model: Literal["gtsam", "paper"] = "gtsam"
    method: Literal["lm", "gn", "dogleg"] = "lm"
    linear_solver: Literal["auto", "cholmod", "superlu", "chain"] = "auto"
    pose_chart: Literal["body", "world"] = "body"
    max_iterations: int = 100
    rel_cost_tol: float = 1e-12
    step_tol: float = 1e-12
    robust: Literal["auto", "none", "huber", "cauchy", "geman_mcclure"] = "auto"
    huber_k: float = 1.345
    cauchy_k: float = 2.3849
    geman_mcclure_c: float = 1.0
    edge_info: bool = True
    init: Literal["odometry", "chordal", "spanning_tree", "robust", "incremental"] = "odometry"
    incremental_window: float = 3.0
    outlier_counts: bool = True
    association: Literal["auto", "init", "reported", "nn"] = "auto"
    gate_prob: float = 0.999
    nn_extra_std: float = 0.0
    nn_drift: bool = True
    nn_segment_dist: float = 0.5
    min_obs: int = 1
    merge_rounds: int = 3
    merge_dist: float = 1.0
    prior_std: tuple[float, float, float] = (1e-4, 1e-4, 1e-4)
    use_odometry: bool = True
    use_controls: bool = False
    motion_lateral_std: float = 0.01
    use_gps: bool = True
    group_returns: bool = True
    estimate_range_bias: bool = False
    surface: bool = False
    paper_R: tuple[tuple[float, ...], ...] | None = None
    paper_S: tuple[tuple[float, ...], ...] | None = None
    paper_Q: tuple[tuple[float, ...], ...] | None = None
    init_from: Literal["odometry", "init"] = "odometry"
    covariance: bool = True

    def __post_init__(self) -> None:
        if self.max_iterations < 1:
            raise ValueError("max_iterations must be ≥ 1")
        if self.huber_k <= 0 or self.cauchy_k <= 0 or self.geman_mcclure_c <= 0:
            raise ValueError("huber_k, cauchy_k and geman_mcclure_c must be > 0")
        if len(self.prior_std) != 3 or min(self.prior_std) <= 0:
            raise ValueError("prior_std must be three positive numbers")
        if self.merge_rounds < 0:
            raise ValueError("merge_rounds must be ≥ 0")
        if self.min_obs < 1:
            raise ValueError("min_obs must be ≥ 1")
        if not self.incremental_window > 0:
            raise ValueError("incremental_window must be > 0 s")


# ----------------------------------------------------------------------------------------------------------
# GTSAM-exact factor errors and Jacobians (world coordinates [x, y, θ]), vectorised over factors
# ----------------------------------------------------------------------------------------------------------
def log_jacobian(p: np.ndarray) -> np.ndarray:
    """Jacobian ``(..., 3, 3)`` of :func:`slamcli.models.se2.log` w.r.t. the pose coordinates ``[x, y, θ]``.

    ``Log(x, y, θ) = [α x + (θ/2) y, −(θ/2) x + α y, θ]`` with ``α = (θ/2) cot(θ/2)``, hence
    ``∂/∂(x, y, θ) = [[α, θ/2, α' x + y/2], [−θ/2, α, −x/2 + α' y], [0, 0, 1]]``,
    ``α' = ½ cot(θ/2) − (θ/4) / sin²(θ/2)`` (series ``1 − θ²/12``, ``−θ/6 − θ³/180`` near 0).
    """
    p = np.asarray(p, float)
    w = wrap_angle(p[..., 2])
    small = np.abs(w) < 1e-4
    ws = np.where(small, 1.0, w)
    half = 0.5 * ws
    cot = np.cos(half) / np.sin(half)
    alpha = np.where(small, 1.0 - w**2 / 12.0, half * cot)
    dalpha = np.where(small, -w / 6.0 - w**3 / 180.0, 0.5 * cot - 0.25 * ws / np.sin(half) ** 2)
    x, y = p[..., 0], p[..., 1]
    J = np.zeros(p.shape[:-1] + (3, 3))
    J[..., 0, 0] = alpha
    J[..., 0, 1] = 0.5 * w
    J[..., 0, 2] = dalpha * x + 0.5 * y
    J[..., 1, 0] = -0.5 * w
    J[..., 1, 1] = alpha
    J[..., 1, 2] = -0.5 * x + dalpha * y
    J[..., 2, 2] = 1.0
    return J


def _compose_left_jacobian(a: np.ndarray) -> np.ndarray:
    """``∂ compose(a, b) / ∂b = blkdiag(R(θ_a), 1)``, ``(..., 3, 3)``."""
    a = np.asarray(a, float)
    J = np.zeros(a.shape[:-1] + (3, 3))
    J[..., :2, :2] = se2.rot2(a[..., 2])
    J[..., 2, 2] = 1.0
    return J


def between_error(x_i, x_j, measured):
    """GTSAM ``BetweenFactorPose2`` error ``e = Log(d⁻¹ ⊕ (x_i⁻¹ ⊕ x_j))`` and its Jacobians.

    Parameters
    ----------
    x_i, x_j, measured : ndarray (F, 3)

    Returns
    -------
    e : ndarray (F, 3);  J_i, J_j : ndarray (F, 3, 3)  (w.r.t. world coordinates of x_i, x_j)
    """
    d_inv = se2.inverse(measured)
    b = se2.between(x_i, x_j)
    p = se2.compose(d_inv, b)
    e = se2.log(p)
    A = log_jacobian(p) @ _compose_left_jacobian(d_inv)
    Ba, Bb = se2.between_jacobians(x_i, x_j)
    return e, A @ Ba, A @ Bb


def prior_error(x, prior):
    """GTSAM ``PriorFactorPose2`` error ``e = Log(p⁻¹ ⊕ x)`` and Jacobian ``(F, 3, 3)``."""
    p_inv = se2.inverse(prior)
    q = se2.compose(p_inv, x)
    return se2.log(q), log_jacobian(q) @ _compose_left_jacobian(p_inv)


def bearing_range_error(x, m, z):
    """Range-bearing error ``e = [r̂ − r, wrap(b̂ − b)]`` (GTSAM's ``BearingRangeFactor2D`` up to row order).

    As in GTSAM (``Rot2::relativeBearing``), a landmark within 1e-5 m of the pose has bearing ``b̂ = 0`` and a
    zero bearing Jacobian: the bearing is undefined there, and a solution that put a landmark on a pose
    (misread ids, a stalled optimisation) must have the cost GTSAM recomputes for it (issue 10, item 4).

    Parameters
    ----------
    x : ndarray (F, 3);  m : ndarray (F, 2);  z : ndarray (F, 2) as ``[range, bearing]``

    Returns
    -------
    e : ndarray (F, 2);  J_x : ndarray (F, 2, 3);  J_m : ndarray (F, 2, 2)
    """
    zh = observation.range_bearing(x, m)
    e = np.stack([zh[:, 0] - z[:, 0], wrap_angle(zh[:, 1] - z[:, 1])], -1)
    J_x, J_m = observation.range_bearing_jacobians(x, m)
    near = zh[:, 0] <= 1e-5
    if np.any(near):  # GTSAM's Rot2::relativeBearing: within 1e-5 m the bearing is 0, its Jacobian zero
        e[near, 1] = wrap_angle(-z[near, 1])
        J_x[near, 1] = 0.0
        J_m[near, 1] = 0.0
    return e, J_x, J_m


def landmark_offset_error(x, m, z_xy):
    """g2o ``EDGE_SE2_XY`` error ``e = R(θ)ᵀ (m − p) − z`` (landmark in the body frame) and its Jacobians.

    Parameters
    ----------
    x : ndarray (F, 3);  m : ndarray (F, 2);  z_xy : ndarray (F, 2) measured offset in the body frame

    Returns
    -------
    e : ndarray (F, 2);  J_x : ndarray (F, 2, 3);  J_m : ndarray (F, 2, 2)
        ``∂e/∂p = −R(θ)ᵀ``, ``∂e/∂θ = [[−s, c], [−c, −s]] (m − p)``, ``∂e/∂m = R(θ)ᵀ``.
    """
    c, s = np.cos(x[:, 2]), np.sin(x[:, 2])
    dx, dy = m[:, 0] - x[:, 0], m[:, 1] - x[:, 1]
    e = np.stack([c * dx + s * dy - z_xy[:, 0], -s * dx + c * dy - z_xy[:, 1]], -1)
    Jm = np.empty((x.shape[0], 2, 2))
    Jm[:, 0, 0], Jm[:, 0, 1], Jm[:, 1, 0], Jm[:, 1, 1] = c, s, -s, c
    Jx = np.empty((x.shape[0], 2, 3))
    Jx[:, :, :2] = -Jm
    Jx[:, 0, 2] = -s * dx + c * dy
    Jx[:, 1, 2] = -c * dx - s * dy
    return e, Jx, Jm


def robot_range_bearing_error(x_i, x_j, z):
    """Inter-robot range-bearing error: robot ``i`` at pose ``x_i`` measures robot ``j``'s body origin.

    ``e = [‖p_j − p_i‖ − r,  wrap(atan2(p_j − p_i) − θ_i − b)]`` — :func:`bearing_range_error` with the
    landmark replaced by the position of another pose; the heading of ``x_j`` does not enter, so the last
    column of ``J_j`` is zero. (Multi-robot MRCLAM, issue 14 item 7.)

    Parameters
    ----------
    x_i, x_j : ndarray (F, 3);  z : ndarray (F, 2) as ``[range, bearing]``

    Returns
    -------
    e : ndarray (F, 2);  J_i : ndarray (F, 2, 3);  J_j : ndarray (F, 2, 3)
    """
    x_j = np.asarray(x_j, float)
    e, J_i, J_m = bearing_range_error(np.asarray(x_i, float), x_j[:, :2], z)
    J_j = np.concatenate([J_m, np.zeros((J_m.shape[0], 2, 1))], axis=2)
    return e, J_i, J_j


def _sqrt_info_batch(info: np.ndarray) -> np.ndarray:
    """``L (F, k, k)`` with ``LᵀL = Λ`` for each information matrix of ``info (F, k, k)``."""
    return np.swapaxes(np.linalg.cholesky(np.asarray(info, float)), 1, 2)


# ----------------------------------------------------------------------------------------------------------
# problem construction
# ----------------------------------------------------------------------------------------------------------
def _sqrt_info_from_cov(cov: np.ndarray) -> np.ndarray:
    """``L`` with ``LᵀL = Σ⁻¹``."""
    return np.linalg.cholesky(np.linalg.inv(np.asarray(cov, float))).T


def _sqrt_of_weight(W: np.ndarray, name: str = "weight") -> np.ndarray | None:
    """``L`` with ``LᵀL = 2W`` for a symmetric PSD weight ``W`` (so ``½‖L r‖² = rᵀ W r``); None if W = 0."""
    W = np.asarray(W, float)
    if not np.all(np.isfinite(W)):
        raise SolverError(f"graph: paper {name} has non-finite entries")
    if not np.any(W):
        return None
    if not np.allclose(W, W.T, atol=1e-12 * max(1.0, np.abs(W).max())):
        raise SolverError(f"graph: paper {name} must be symmetric, got {W.tolist()}")
    lam, V = np.linalg.eigh(0.5 * (W + W.T))
    if lam.min() < -1e-12 * max(1.0, lam.max()):
        raise SolverError(f"graph: paper {name} must be positive semi-definite (eigenvalues {lam.tolist()})")
    return np.sqrt(2.0 * np.clip(lam, 0.0, None))[:, None] * V.T


@dataclass(frozen=True)
class GraphProblem:
    """A built factor graph plus the state layout.

    Attributes
    ----------
    problem : nls.NlsProblem
    x0 : ndarray (D,)          initial state: poses ``(T+1)·3``, landmarks ``L·2`` (then the range bias,
                               if estimated, at ``range_bias_col``).
    n_poses : int              T+1
    n_landmarks : int          L
    """

    problem: nls.NlsProblem
    x0: np.ndarray
    n_poses: int
    n_landmarks: int
    range_bias_col: int | None = None

    def unpack(self, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """``(poses_xyt (T+1, 3), landmarks_xy (L, 2))`` views of a state vector."""
        P = 3 * self.n_poses
        return x[:P].reshape(-1, 3), x[P : P + 2 * self.n_landmarks].reshape(-1, 2)

    def pose_cols(self) -> np.ndarray:
        return np.arange(3 * self.n_poses, dtype=np.int64).reshape(-1, 3)

    def landmark_cols(self) -> np.ndarray:
        return 3 * self.n_poses + np.arange(2 * self.n_landmarks, dtype=np.int64).reshape(-1, 2)


def pack_state(poses_xyt: np.ndarray, landmarks_xy: np.ndarray) -> np.ndarray:
    return np.concatenate([np.asarray(poses_xyt, float).ravel(), np.asarray(landmarks_xy, float).ravel()])


def build_gtsam_problem(
    inputs: SlamInputs,
    assoc: np.ndarray,
    init_poses: np.ndarray,
    init_landmarks: np.ndarray,
    params: GraphParams | None = None,
) -> GraphProblem:
    """Factor graph of the ``gtsam`` model (module docstring) with observations labelled by ``assoc``.

    Parameters
    ----------
    inputs : SlamInputs
    assoc : ndarray (N,) int64      landmark row per observation, -1 = unused.
    init_poses : ndarray (T+1, 3)
    init_landmarks : ndarray (L, 2)
    """
    params = params or GraphParams()
    n_poses = inputs.n_poses
    L = int(np.asarray(init_landmarks).reshape(-1, 2).shape[0])
    pc = np.arange(3 * n_poses, dtype=np.int64).reshape(-1, 3)
    lc = 3 * n_poses + np.arange(2 * L, dtype=np.int64).reshape(-1, 2)
    P = 3 * n_poses
    blocks: list[nls.FactorBlock] = []

    def poses_of(x):
        return x[:P].reshape(-1, 3)

    def lms_of(x):
        return x[P : P + 2 * L].reshape(-1, 2)

    bias_col = P + 2 * L if params.estimate_range_bias else None

    team = inputs.robots
    # one prior per robot (its known start pose); a single robot: x_0. The odometry chain stays in one robot.
    first = np.zeros(1, np.int64) if team is None else team.first_pose[:-1]
    chain = np.arange(n_poses - 1, dtype=np.int64) if team is None else team.chain_pairs
    prior = np.asarray(inputs.x0, float)[None, :] if team is None else np.asarray(team.x0_xyt, float)

    def ev_prior(x):
        e, J = prior_error(poses_of(x)[first], prior)
        return e, J

    blocks.append(
        nls.FactorBlock("prior", pc[first], ev_prior, _sqrt_info_from_cov(np.diag(np.square(params.prior_std))))
    )

    def between_block(name, meas, cov, sqrt_info=None):
        meas = meas[chain]
        if sqrt_info is not None and np.ndim(sqrt_info) == 3:
            sqrt_info = sqrt_info[chain]

        def ev(x):
            p = poses_of(x)
            e, Ji, Jj = between_error(p[chain], p[chain + 1], meas)
            return e, np.concatenate([Ji, Jj], axis=2)

        cols = np.concatenate([pc[chain], pc[chain + 1]], axis=1)
        return nls.FactorBlock(name, cols, ev, _sqrt_info_from_cov(cov) if sqrt_info is None else sqrt_info)

    cons = inputs.constraints if params.edge_info else None
    if n_poses > 1 and params.use_odometry:
        d = motion.odometry_increments(inputs.odometry_xyt)
        odo_L = None
        if cons is not None and cons.odometry_info is not None:
            odo_L = _sqrt_info_batch(cons.odometry_info)
        blocks.append(between_block("odometry", d, np.diag(np.square(inputs.noise.odometry_std)), odo_L))
    if inputs.constraints is not None and inputs.constraints.n_between:
        # pose-pose constraints between any two poses (loop closures): always with their own information
        bc = inputs.constraints
        bij = np.asarray(bc.between_ij, np.int64).reshape(-1, 2)
        bmeas = np.asarray(bc.between_xyt, float).reshape(-1, 3)

        def ev_between(x):
            p = poses_of(x)
            e, Ji, Jj = between_error(p[bij[:, 0]], p[bij[:, 1]], bmeas)
            return e, np.concatenate([Ji, Jj], axis=2)

        blocks.append(
            nls.FactorBlock(
                "loop_closure",
                np.concatenate([pc[bij[:, 0]], pc[bij[:, 1]]], axis=1),
                ev_between,
                _sqrt_info_batch(bc.between_info),
                robust=True,
            )
        )
    if n_poses > 1 and params.use_controls:
        u = np.asarray(inputs.controls, float)
        dt = inputs.dt
        d = np.stack([u[:, 0] * dt, np.zeros(len(u)), u[:, 1] * dt], -1)
        sv, sw = inputs.noise.motion_std
        cov = np.diag([(sv * dt) ** 2, params.motion_lateral_std**2, (sw * dt) ** 2])
        blocks.append(between_block("motion", d, cov))

    obs = inputs.observations
    assoc = np.asarray(assoc, np.int64)
    rows = np.flatnonzero(assoc >= 0)
    obs_info = cons.observation_info if cons is not None else None
    if rows.size and obs_info is not None:
        # lossless: one factor per row with the row's own information, in the file's model
        steps = np.asarray(obs.step, np.int64)[rows]
        labels = assoc[rows]
        z = obs.z[rows]
        L_rows = _sqrt_info_batch(np.asarray(obs_info, float)[rows])
        xy_model = cons.observation_model == "xy"
        z_xy = z[:, :1] * np.column_stack([np.cos(z[:, 1]), np.sin(z[:, 1])])
        if bias_col is not None:
            raise SolverError("graph: estimate_range_bias needs edge_info=false on a dataset with per-edge information")

        def ev_obs_info(x):
            if xy_model:
                e, Jx, Jm = landmark_offset_error(poses_of(x)[steps], lms_of(x)[labels], z_xy)
            else:
                e, Jx, Jm = bearing_range_error(poses_of(x)[steps], lms_of(x)[labels], z)
            return e, np.concatenate([Jx, Jm], axis=2)

        blocks.append(
            nls.FactorBlock(
                "landmark_xy" if xy_model else "bearing_range",
                np.concatenate([pc[steps], lc[labels]], axis=1),
                ev_obs_info,
                L_rows,
                robust=True,
            )
        )
    elif rows.size:
        steps = np.asarray(obs.step, np.int64)[rows]
        labels = assoc[rows]
        z = obs.z[rows]
        if params.group_returns:
            steps, labels, z = group_returns(steps, labels, z, L)

        def ev_obs(x):
            e, Jx, Jm = bearing_range_error(poses_of(x)[steps], lms_of(x)[labels], z)
            if bias_col is None:
                return e, np.concatenate([Jx, Jm], axis=2)
            e[:, 0] -= x[bias_col]  # r̂ = ‖m − p‖ − b
            Jb = np.zeros((e.shape[0], 2, 1))
            Jb[:, 0, 0] = -1.0
            return e, np.concatenate([Jx, Jm, Jb], axis=2)

        cols = np.concatenate([pc[steps], lc[labels]], axis=1)
        if bias_col is not None:
            cols = np.concatenate([cols, np.full((cols.shape[0], 1), bias_col, np.int64)], axis=1)
        blocks.append(
            nls.FactorBlock(
                "bearing_range", cols, ev_obs, _sqrt_info_from_cov(inputs.noise.obs_cov), robust=True
            )
        )

    if team is not None and len(team.range_m):
        ri, rj, rz = np.asarray(team.observer_pose), np.asarray(team.observed_pose), team.z

        def ev_robot(x):
            p = poses_of(x)
            e, Ji, Jj = robot_range_bearing_error(p[ri], p[rj], rz)
            return e, np.concatenate([Ji, Jj], axis=2)

        blocks.append(nls.FactorBlock("robot_range_bearing", np.concatenate([pc[ri], pc[rj]], axis=1), ev_robot,
                                      _sqrt_info_from_cov(inputs.noise.obs_cov), robust=True))

    if params.use_gps and np.asarray(inputs.gps_step).size:
        gsteps = np.asarray(inputs.gps_step, np.int64)
        gxy = np.asarray(inputs.gps_xy, float)

        def ev_gps(x):
            e = poses_of(x)[gsteps, :2] - gxy
            J = np.zeros((gsteps.size, 2, 3))
            J[:, 0, 0] = J[:, 1, 1] = 1.0
            return e, J

        blocks.append(nls.FactorBlock("gps", pc[gsteps], ev_gps, np.eye(2) / inputs.gps_std, robust=True))

    n_vars = P + 2 * L + (bias_col is not None)
    if bias_col is not None and not rows.size:
        raise SolverError("graph: estimate_range_bias needs associated observations")
    problem = nls.NlsProblem(
        n_vars=n_vars, blocks=blocks, angle_cols=pc[:, 2].copy(), chain=(n_poses, 3), se2_poses=n_poses
    )
    x0 = pack_state(init_poses, init_landmarks)
    if bias_col is not None:
        x0 = np.concatenate([x0, [0.0]])
    return GraphProblem(problem, x0, n_poses, L, bias_col)


def group_returns(steps: np.ndarray, labels: np.ndarray, z: np.ndarray, n_landmarks: int):
    """One measurement per (pose, landmark) pair: mean range and circular-mean bearing of its rows.

    A laser gives several returns from one post at one pose (surface points spread over the post's width);
    treating each as an independent point measurement of the centre would overweight that pose-landmark pair
    and put the spread into the bearing residuals. Point sensors have one row per pair, so nothing changes.

    Returns
    -------
    steps (G,), labels (G,), z (G, 2) of the groups, ordered by (step, label).
    """
    key = steps * max(n_landmarks, 1) + labels
    ukey, inv = np.unique(key, return_inverse=True)
    if ukey.size == key.size:
        order = np.argsort(key, kind="stable")
        return steps[order], labels[order], z[order]
    cnt = np.bincount(inv).astype(float)
    r = np.bincount(inv, z[:, 0]) / cnt
    b = np.arctan2(np.bincount(inv, np.sin(z[:, 1])), np.bincount(inv, np.cos(z[:, 1])))
    return ukey // max(n_landmarks, 1), ukey % max(n_landmarks, 1), np.stack([r, wrap_angle(b)], -1)


def default_paper_weights(inputs: SlamInputs) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``R = 0, S = ½ diag(σ_odo)⁻², Q = ½ σ_r⁻² I``."""
    R = np.zeros((3, 3))
    S = 0.5 * np.diag(1.0 / np.square(np.asarray(inputs.noise.odometry_std, float)))
    Q = 0.5 / inputs.noise.range_std**2 * np.eye(2)
    return R, S, Q


def build_paper_problem(
    inputs: SlamInputs,
    assoc: np.ndarray,
    R: np.ndarray,
    S: np.ndarray,
    Q: np.ndarray,
    init_poses: np.ndarray,
    init_landmarks: np.ndarray,
) -> GraphProblem:
    """Factor graph whose cost ``½ Σ ‖L r‖²`` equals the Gibbs energy of paper 000 (module docstring).

    ``x_0`` is held fixed at ``init_poses[0]``; landmarks are held fixed when ``Q = 0`` (the energy does not
    depend on them then).
    """
    n_poses = inputs.n_poses
    L = int(np.asarray(init_landmarks).reshape(-1, 2).shape[0])
    P = 3 * n_poses
    pc = np.arange(P, dtype=np.int64).reshape(-1, 3)
    lc = P + np.arange(2 * L, dtype=np.int64).reshape(-1, 2)
    blocks: list[nls.FactorBlock] = []
    LR, LS, LQ = _sqrt_of_weight(R, "R"), _sqrt_of_weight(S, "S"), _sqrt_of_weight(Q, "Q")
    pair_cols = np.concatenate([pc[:-1], pc[1:]], axis=1)

    def poses_of(x):
        return x[:P].reshape(-1, 3)

    if LR is not None and n_poses > 1:
        u = np.asarray(inputs.controls, float)
        dt = inputs.dt

        def ev_motion(x):
            p = poses_of(x)
            r = potentials.motion_residual(p[:-1], u, p[1:], dt)
            Ja, Jb = potentials.motion_residual_jacobians(p[:-1], u, p[1:], dt)
            return r, np.concatenate([Ja, Jb], axis=2)

        blocks.append(nls.FactorBlock("motion", pair_cols, ev_motion, LR))
    if LS is not None and n_poses > 1:
        odo = np.asarray(inputs.odometry_xyt, float)

        def ev_odo(x):
            p = poses_of(x)
            r = potentials.odometry_residual(p[:-1], p[1:], odo[:-1], odo[1:])
            Ja, Jb = potentials.odometry_residual_jacobians(p[:-1], p[1:])
            return r, np.concatenate([Ja, Jb], axis=2)

        blocks.append(nls.FactorBlock("odometry", pair_cols, ev_odo, LS))
    obs = inputs.observations
    assoc = np.asarray(assoc, np.int64)
    rows = np.flatnonzero(assoc >= 0)
    if LQ is not None and rows.size:
        steps = np.asarray(obs.step, np.int64)[rows]
        labels = assoc[rows]
        z = obs.z[rows]

        def ev_obs(x):
            p = poses_of(x)[steps]
            m = x[P:].reshape(-1, 2)[labels]
            r = potentials.observation_residual(p, z, m)
            Jx, Jm = potentials.observation_residual_jacobians(p, z)
            return r, np.concatenate([Jx, Jm], axis=2)

        blocks.append(
            nls.FactorBlock(
                "observation", np.concatenate([pc[steps], lc[labels]], 1), ev_obs, LQ, robust=True
            )
        )
    fixed = [pc[0]]
    if LQ is None:
        fixed.append(lc.ravel())
    problem = nls.NlsProblem(
        n_vars=P + 2 * L,
        blocks=blocks,
        angle_cols=pc[:, 2].copy(),
        fixed_cols=np.concatenate(fixed),
        chain=(n_poses, 3),
    )
    return GraphProblem(problem, pack_state(init_poses, init_landmarks), n_poses, L)


def optimize_paper_energy(
    inputs: SlamInputs,
    assoc: np.ndarray,
    R: np.ndarray,
    S: np.ndarray,
    Q: np.ndarray,
    init_poses: np.ndarray,
    init_landmarks: np.ndarray,
    *,
    method: Literal["lm", "gn"] = "lm",
    max_iterations: int = 200,
) -> tuple[np.ndarray, np.ndarray, float]:
    """Minimum of the paper-000 Gibbs energy for fixed correspondences (the reference for ICM).

    ``E = Σ_t ‖g(x_{t-1},u_{t-1}) − x_t‖²_R + Σ_t ‖τ(θ_{t-1})(x_t − x_{t-1}) − d_t‖²_S
    + Σ_{t,i} ‖h⁻¹(x_t, z_{t,i}) − m_{c_{t,i}}‖²_Q`` with ``‖a‖²_W = aᵀWa`` — no ½ and no map potential;
    evaluated exactly by :mod:`slamcli.models.potentials`. ``x_0 = init_poses[0]`` stays fixed (the known
    start pose); landmarks stay at ``init_landmarks`` if ``Q = 0``.

    Parameters
    ----------
    inputs : SlamInputs
    assoc : ndarray (N,) int64       landmark row of every observation, -1 = unused.
    R : ndarray (3, 3); S : ndarray (3, 3); Q : ndarray (2, 2)   symmetric PSD weights (zero = dropped).
    init_poses : ndarray (T+1, 3);  init_landmarks : ndarray (L, 2)

    Returns
    -------
    poses_xyt : ndarray (T+1, 3);  landmarks_xy : ndarray (L, 2);  energy : float (E at the optimum)
    """
    gp = build_paper_problem(inputs, assoc, R, S, Q, init_poses, init_landmarks)
    res = nls.solve(gp.problem, gp.x0, nls.NlsParams(method=method, max_iterations=max_iterations))
    poses, lms = gp.unpack(res.x)
    return poses.copy(), lms.copy(), float(res.cost)


def paper_energy(inputs, assoc, R, S, Q, poses_xyt, landmarks_xy) -> float:
    """The paper-000 energy (see :func:`optimize_paper_energy`) at given poses and landmarks."""
    gp = build_paper_problem(inputs, assoc, R, S, Q, poses_xyt, landmarks_xy)
    return nls.evaluate_cost(gp.problem, gp.x0)


def laplace_marginals(gp: GraphProblem, information) -> tuple[np.ndarray, np.ndarray]:
    """World-frame marginal covariances ``pose_cov (T+1, 3, 3)`` and ``landmark_cov (L, 2, 2)`` at the optimum.

    With CHOLMOD (the ``cholmod`` extra) the blocks come from the *selected inverse* of ``H``
    (:mod:`slamcli.solvers.selinv`: Takahashi recurrence on the pattern of the sparse Cholesky factor;
    memory ``O(nnz(L))``, time about that of the factorisation); a pivot ≤ 0 there means ``H`` is not
    numerically positive definite. Without CHOLMOD: ``H`` is block tridiagonal over the pose chain (every pose-pose factor links consecutive poses or is
    unary), so :func:`slamcli.solvers.nls.marginals_chain_border` eliminates the chain with a banded
    Cholesky and inverts only the ``2L × 2L`` landmark Schur complement. When that is not possible (other
    structure, or the banded Cholesky meets a pivot ≤ 0 because ``H`` is badly scaled — e.g. a landmark
    estimated on top of a pose, whose bearing Jacobian ``∝ 1/r`` explodes), the general sparse column solve
    :func:`slamcli.solvers.nls.marginal_covariances` is used, on a SuperLU factorisation that must be a
    symmetric elimination with positive pivots. Every block is checked to be finite and positive definite
    (:func:`slamcli.solvers.nls.check_covariance_blocks`).

    Raises
    ------
    numpy.linalg.LinAlgError
        ``H`` is not numerically positive definite: no factorisation gives valid marginals. The message
        names the pose or landmark where the factorisation broke down.
    """
    L = gp.n_landmarks
    if selinv.available():
        pose_cols, lm_cols = gp.pose_cols(), gp.landmark_cols()
        try:
            sel = selinv.SelectedInverse.from_matrix(information, (pose_cols, lm_cols))
            pose_cov, lm_cov = sel.blocks(pose_cols), sel.blocks(lm_cols)
            nls.check_covariance_blocks(pose_cov, "pose")
            nls.check_covariance_blocks(lm_cov, "landmark")
        except np.linalg.LinAlgError as exc:
            raise np.linalg.LinAlgError(_located(gp, exc)) from None
        return pose_cov, lm_cov
    first_error = None
    if nls.is_block_tridiagonal(information, gp.n_poses, 3):
        try:
            pose_cov, border = nls.marginals_chain_border(information, gp.n_poses, 3)
            j = np.arange(L)
            border = border[: 2 * L, : 2 * L]
            lm_cov = border.reshape(L, 2, L, 2)[j, :, j, :] if L else np.zeros((0, 2, 2))
            lm_cov = np.ascontiguousarray(lm_cov)
            nls.check_covariance_blocks(pose_cov, "pose")
            nls.check_covariance_blocks(lm_cov, "landmark")
            return pose_cov, lm_cov
        except np.linalg.LinAlgError as exc:  # try the general sparse factorisation (another ordering)
            first_error = _located(gp, exc)
    try:
        factor = nls.factorize_information(information, require_positive_definite=True)
        pose_cov = nls.marginal_covariances(information, gp.pose_cols(), factor=factor)
        lm_cov = nls.marginal_covariances(information, gp.landmark_cols(), factor=factor)
        nls.check_covariance_blocks(pose_cov, "pose")
        nls.check_covariance_blocks(lm_cov, "landmark")
    except np.linalg.LinAlgError as exc:
        raise np.linalg.LinAlgError(first_error or _located(gp, exc)) from None
    return pose_cov, lm_cov


def _located(gp: GraphProblem, exc: np.linalg.LinAlgError) -> str:
    """The message of ``exc``, prefixed with the variable (``pose t`` / ``landmark j``) it names, if any."""
    c = getattr(exc, "column", None)
    if c is None:
        return str(exc)
    P = 3 * gp.n_poses
    if c < P:
        what = f"pose {c // 3}"
    elif c < P + 2 * gp.n_landmarks:
        what = f"landmark {(c - P) // 2}"
    else:
        what = "range bias"
    return f"{what}: {exc}"


def landmark_joint_covariance(gp: GraphProblem, information) -> np.ndarray:
    """Joint marginal covariance ``(2L, 2L)`` of all landmarks (Laplace, chain + border elimination).

    Falls back to the block-diagonal of the marginals (cross-covariances 0) when the pose block is not
    block tridiagonal.

    Raises
    ------
    numpy.linalg.LinAlgError
        ``H`` is not numerically positive definite (a factorisation fails or gives an invalid block).
    """
    L = gp.n_landmarks
    if nls.is_block_tridiagonal(information, gp.n_poses, 3):
        cov = nls.marginals_chain_border(information, gp.n_poses, 3, poses=False)[1][: 2 * L, : 2 * L]
        j = np.arange(L)
        nls.check_covariance_blocks(cov.reshape(L, 2, L, 2)[j, :, j, :], "landmark")
        return cov
    factor = nls.factorize_information(information, require_positive_definite=True)
    blocks = nls.marginal_covariances(information, gp.landmark_cols(), factor=factor)
    nls.check_covariance_blocks(blocks, "landmark")
    out = np.zeros((2 * L, 2 * L))
    for j in range(L):
        out[2 * j : 2 * j + 2, 2 * j : 2 * j + 2] = blocks[j]
    return out


def merge_candidates(
    gp: GraphProblem,
    information,
    landmarks_xy: np.ndarray,
    obs,
    assoc: np.ndarray,
    gate_prob: float,
    merge_dist: float = 0.0,
) -> np.ndarray:
    """Landmark pairs that pass GraphSLAM's correspondence test (Thrun, Burgard & Fox, *Probabilistic
    Robotics*, §11.5 "correspondence test"; seed 002, graph SLAM with unknown correspondences).

    For labels ``i < j`` never observed at the same pose, the difference ``Δ = m_i − m_j`` has the Laplace
    covariance ``Σ_Δ = Σ_ii + Σ_jj − Σ_ij − Σ_ji`` (joint marginal at the optimum, so drift between the two
    sightings is accounted for); the pair is a candidate if ``Δᵀ Σ_Δ⁻¹ Δ ≤ χ²₂(gate_prob)``. Pairs are taken
    greedily by increasing distance, each label at most once per call. Pairs closer than ``merge_dist`` (m)
    are candidates as well (paper 000's label fusion radius ϑ), again only if never co-observed — two
    distinct landmarks that close are almost always seen together, which protects them.

    Parameters
    ----------
    gp : GraphProblem;  information : sparse (D, D) H at the optimum;  landmarks_xy : ndarray (L, 2) optimum
    obs : Observations;  assoc : ndarray (N,) labels;  gate_prob : float;  merge_dist : float, m

    Returns
    -------
    ndarray (K, 2) int64 of ``(keep, drop)`` label pairs, ``keep < drop``.
    """
    import scipy.sparse as sp

    L = gp.n_landmarks
    none = np.zeros((0, 2), np.int64)
    if L < 2:
        return none
    thr = frontend.gate_threshold(gate_prob)
    ok = assoc >= 0
    M = sp.csr_matrix((np.ones(int(ok.sum())), (np.asarray(obs.step)[ok], assoc[ok])), shape=(gp.n_poses, L))
    co_seen = (M.T @ M).toarray() > 0
    iu, ju = np.triu_indices(L, 1)
    keep = ~co_seen[iu, ju]
    iu, ju = iu[keep], ju[keep]
    if not iu.size:
        return none
    cov = landmark_joint_covariance(gp, information).reshape(L, 2, L, 2)  # cov[i, :, j, :] = Σ_ij
    Sii = cov[iu, :, iu, :]
    Sjj = cov[ju, :, ju, :]
    Sij = cov[iu, :, ju, :]
    Sd = Sii + Sjj - Sij - np.swapaxes(Sij, 1, 2)  # (K, 2, 2)
    d = landmarks_xy[iu] - landmarks_xy[ju]  # (K, 2)
    det = Sd[:, 0, 0] * Sd[:, 1, 1] - Sd[:, 0, 1] * Sd[:, 1, 0]
    with np.errstate(divide="ignore", invalid="ignore"):
        d2 = (
            Sd[:, 1, 1] * d[:, 0] ** 2 - 2 * Sd[:, 0, 1] * d[:, 0] * d[:, 1] + Sd[:, 0, 0] * d[:, 1] ** 2
        ) / det
    close = np.einsum("ki,ki->k", d, d) <= merge_dist**2
    cand = np.flatnonzero(((det > 0) & (d2 <= thr)) | close)
    used: set[int] = set()
    out = []
    for c in cand[np.argsort(d2[cand], kind="stable")]:  # greedy, O(K log K); K is small after gating
        i, j = int(iu[c]), int(ju[c])
        if i in used or j in used:
            continue
        used.update((i, j))
        out.append((i, j))
    return np.asarray(out, np.int64).reshape(-1, 2)


# ----------------------------------------------------------------------------------------------------------
# solver
# ----------------------------------------------------------------------------------------------------------
def odometry_initial_poses(inputs: SlamInputs) -> np.ndarray:
    """Odometry increments chained from the known start pose, ``(T+1, 3)`` (multi-robot: each robot's chain
    from its own start pose)."""
    team = inputs.robots
    if team is not None:
        from slamcli.datasets.team import solo_inputs

        return np.concatenate([odometry_initial_poses(solo_inputs(inputs, r)) for r in range(team.n_robots)])
    d = motion.odometry_increments(inputs.odometry_xyt)
    poses = np.empty((inputs.n_poses, 3))
    poses[0] = inputs.x0
    # compose sequentially (cumulative heading first, then rotate increments: vectorised)
    th = wrap_angle(inputs.x0[2] + np.concatenate([[0.0], np.cumsum(d[:, 2])]))
    c, s = np.cos(th[:-1]), np.sin(th[:-1])
    dx = c * d[:, 0] - s * d[:, 1]
    dy = s * d[:, 0] + c * d[:, 1]
    poses[1:, 0] = inputs.x0[0] + np.cumsum(dx)
    poses[1:, 1] = inputs.x0[1] + np.cumsum(dy)
    poses[:, 2] = th
    return poses


def resolve_robust(robust: str, association: str, id_source: str = "unknown") -> str:
    """The kernel ``robust = "auto"`` stands for: ``cauchy`` when the correspondences are identities reported
    by a real sensor (``association = "reported"`` and ``inputs.reported_id_source = "sensor"``: a misread id
    is a gross outlier no Gaussian factor absorbs — MRCLAM's barcodes), else ``none`` (simulated ids, which
    are correct by construction, graph files, gated nearest neighbour, ``--init`` labels). The measurement
    behind the choice: ``benchmarks/bench_robust_study.py`` (MRCLAM Dataset 7, five robots: mean unaligned
    ATE 0.435 m with none, 0.312 m with cauchy, 0.703 m with huber)."""
    if robust != "auto":
        return robust
    return "cauchy" if association == "reported" and id_source == "sensor" else "none"


def pose_graph_edges(inputs: SlamInputs, use_edge_info: bool = True):
    """All pose-pose edges of a dataset: the odometry chain ``t → t+1`` then the between-factors.

    Returns
    -------
    ij : ndarray (E, 2) int64;  xyt : ndarray (E, 3) measured ``x_i⁻¹ ⊕ x_j``;  info : ndarray (E, 3, 3)
    """
    T = inputs.n_poses - 1
    d = motion.odometry_increments(inputs.odometry_xyt)
    c = inputs.constraints
    if c is not None and c.odometry_info is not None and use_edge_info:
        odo_info = np.asarray(c.odometry_info, float)
    else:
        odo_info = np.broadcast_to(np.diag(1.0 / np.square(np.maximum(inputs.noise.odometry_std, 1e-12))), (T, 3, 3))
    ij = [np.stack([np.arange(T), np.arange(1, T + 1)], axis=1)]
    xyt, info = [d.reshape(-1, 3)], [odo_info]
    if c is not None and c.n_between:
        ij.append(np.asarray(c.between_ij, np.int64).reshape(-1, 2))
        xyt.append(np.asarray(c.between_xyt, float).reshape(-1, 3))
        info.append(np.asarray(c.between_info, float).reshape(-1, 3, 3))
    return np.concatenate(ij).astype(np.int64), np.concatenate(xyt), np.concatenate(info)


def initial_poses(inputs: SlamInputs, method: str = "odometry") -> np.ndarray:
    """Initial poses ``(T+1, 3)``: chained odometry, chordal relaxation or spanning tree (:mod:`pose_init`).

    Raises
    ------
    SolverError  unknown method, or a pose not connected to ``x_0`` (chordal / spanning tree).
    """
    from slamcli.solvers import pose_init

    if method == "odometry":
        return odometry_initial_poses(inputs)
    ij, xyt, info = pose_graph_edges(inputs)
    try:
        if method == "chordal":
            return pose_init.chordal_poses(inputs.n_poses, ij, xyt, info, np.asarray(inputs.x0, float))
        if method == "spanning_tree":
            return pose_init.spanning_tree_poses(inputs.n_poses, ij, xyt, np.asarray(inputs.x0, float))
    except ValueError as exc:
        raise SolverError(f"graph: init={method}: {exc}") from None
    raise SolverError(f"graph: unknown init {method!r} (odometry, chordal or spanning_tree)")


def robust_initial_poses(
    inputs: SlamInputs, assoc: np.ndarray, poses0: np.ndarray, params: GraphParams
) -> tuple[np.ndarray, nls.NlsResult]:
    """Initial poses ``(T+1, 3)`` from a robust solve: the ``gtsam``-model graph of ``assoc`` with GTSAM's
    Cauchy kernel (scale ``params.cauchy_k``) on the observation factors, started at ``poses0`` (landmarks
    at their mean inverse observation) and optimised with ``params``' method, tolerances and budget.

    Why: under the Gaussian model a wrong correspondence costs ``½ s²`` (s = its whitened residual), so a
    handful of them pull a whole drifted chain into a basin far from the optimum; the Cauchy cost
    ``½ k² log(1 + s²/k²)`` grows only logarithmically and its IRLS weight ``1/(1 + s²/k²)`` lets such a
    factor go, so the robust optimum sits where the consistent majority of the factors puts it — a start
    inside the Gaussian optimum's basin. Returns the poses and the robust solve's result (for its status,
    iterations and cost)."""
    lm0 = frontend.landmarks_from_observations(poses0, inputs.observations, assoc, int(assoc.max(initial=-1)) + 1)
    gp = build_gtsam_problem(inputs, assoc, poses0, lm0, params)
    res = nls.solve(
        gp.problem,
        gp.x0,
        nls.NlsParams(
            method=params.method,
            linear_solver=params.linear_solver,
            pose_chart=params.pose_chart,
            max_iterations=params.max_iterations,
            rel_cost_tol=params.rel_cost_tol,
            step_tol=params.step_tol,
            robust="cauchy",
            huber_k=params.cauchy_k,
        ),
    )
    return gp.unpack(res.x)[0].copy(), res


def _nearest_neighbour(poses, obs: Observations, inputs: SlamInputs, p: GraphParams) -> np.ndarray:
    """``graph``'s nearest-neighbour association of ``obs`` from ``poses`` (T+1, 3), with its parameters
    (gate, extra σ, drift-aware gating, segment distance); labels (N,), -1 = unassociated."""
    assoc, _ = frontend.associate_nearest_neighbour(
        poses,
        obs,
        inputs.noise.obs_cov,
        gate_prob=p.gate_prob,
        extra_std=p.nn_extra_std,
        odometry_std=inputs.noise.odometry_std if p.nn_drift else None,
        segment_dist=p.nn_segment_dist,
    )
    return assoc

def incremental_initial_poses(inputs: SlamInputs, poses0: np.ndarray, params: GraphParams) -> np.ndarray:
    """Initial poses ``(T+1, 3)`` for unknown correspondences, built incrementally.

    The batch front end associates every sighting on the dead-reckoned poses, whose drift grows without
    bound (26 m after 300 s of Victoria Park): revisited trees then fall outside their gates or into a
    neighbour's. Here the run is cut into windows of ``params.incremental_window`` s; at the end ``t_k`` of
    each window the sightings of steps ``≤ t_k`` are associated by the gated nearest-neighbour front end
    (:func:`slamcli.solvers.frontend.associate_nearest_neighbour`, same gate and drift model) on the
    current poses, and the ``gtsam``-model graph of those sightings is optimised (LM, Cauchy kernel on the
    sightings, started at the current poses; the poses after ``t_k`` carry only odometry factors, so the
    optimum continues them by dead reckoning from the optimised ``x_{t_k}``). The next window's sightings
    are thus projected from poses that drifted only since ``t_k``. Cost: one association and one warm-started
    optimisation per window.
    """
    obs = inputs.observations
    T = inputs.n_poses - 1
    poses = np.array(poses0, float, copy=True)
    if not len(obs) or T < 1:
        return poses
    win = max(1, int(round(params.incremental_window / max(inputs.dt, 1e-12))))
    nparams = nls.NlsParams(
        method=params.method,
        linear_solver=params.linear_solver,
        pose_chart=params.pose_chart,
        max_iterations=params.max_iterations,
        rel_cost_tol=max(params.rel_cost_tol, 1e-6),  # an initial guess: the final solve polishes
        step_tol=params.step_tol,
        robust="cauchy",
        huber_k=params.cauchy_k,
    )
    ends = list(range(win, T, win)) + [T]
    for t_end in ends:
        n = int(obs.offsets[t_end + 1])
        if n == 0:
            continue
        sub = Observations.from_rows(obs.step[:n], obs.z[:n], inputs.n_poses, sensor=obs.sensor[:n])
        a_sub = _nearest_neighbour(poses, sub, inputs, params)
        assoc = np.full(len(obs), -1, np.int64)
        assoc[:n] = a_sub
        assoc, old_of_new = frontend.compact_labels(assoc, 1)
        if not old_of_new.size:
            continue
        lm0 = frontend.landmarks_from_observations(poses, obs, assoc, old_of_new.size)
        gp = build_gtsam_problem(inputs, assoc, poses, lm0, params)
        res = nls.solve(gp.problem, gp.x0, nparams)
        if res.status != Status.FAILED:
            poses = gp.unpack(res.x)[0].copy()
    return poses


def chi2_outlier_counts(problem: nls.NlsProblem, x: np.ndarray) -> dict:
    """χ² outlier counts per factor block at ``x``.

    A factor with whitened residual ``r̃ = L r`` (``k`` components) is an outlier at level ``p`` when
    ``‖r̃‖² > χ²_k(p)`` — the test a Gaussian factor fails with probability ``1 − p`` at the true state.
    The kernel (if any) is ignored here: the counts say which factors a robust kernel down-weighted.

    Returns
    -------
    dict ``{block name: {"factors": F, "dof": k, "over_95": n, "over_99": n}}`` (blocks of the same name
    merged).
    """
    from scipy.stats import chi2

    out: dict[str, dict] = {}
    for b in problem.blocks:
        r, _ = b.evaluate(x)
        L = np.asarray(b.sqrt_info, float)
        rw = r @ L.T if L.ndim == 2 else np.einsum("fij,fj->fi", L, r)
        s2 = np.einsum("fk,fk->f", rw, rw)
        k = int(r.shape[1])
        t95, t99 = chi2.ppf([0.95, 0.99], k)
        d = out.setdefault(b.name, {"factors": 0, "dof": k, "over_95": 0, "over_99": 0})
        d["factors"] += int(s2.size)
        d["over_95"] += int(np.sum(s2 > t95))
        d["over_99"] += int(np.sum(s2 > t99))
    return out


class GraphSlam(BaseSolver):
    """Batch graph SLAM with sparse GN/LM and Laplace marginals (see module docstring).

    Pipeline: initial poses (chained odometry, or the ``--init`` result's) → correspondences (``init`` /
    ``reported`` / gated nearest neighbour, :mod:`slamcli.solvers.frontend`) → landmarks from the mean
    inverse observation → optimisation → (``nn`` only) merge landmark pairs passing the correspondence test
    and re-optimise, up to ``merge_rounds`` times → marginal covariances at the optimum.

    Result: ``poses_xyt``, ``landmarks_xy``, ``assoc`` (rows of ``landmarks_xy``, in order of first
    sighting), ``pose_cov`` / ``landmark_cov`` (world frame; zero for the fixed ``x_0`` of the paper model),
    ``trace`` (cost — GTSAM's ``½ Σ‖e‖²_Σ`` or the paper energy — and landmarks after every accepted step;
    with merge rounds the rounds are concatenated, each starting with its re-initialised cost),
    ``status`` CONVERGED / MAX_ITERATIONS (of the last round) / FAILED, and ``extra`` with ``association``,
    ``n_landmarks``, ``iterations`` (accepted steps of all rounds), ``final_cost``, ``model`` (and
    ``merged_landmarks``; ``numerical_notes`` when the optimiser needed a numerical fallback;
    ``covariance_error`` when ``H`` at the estimate is not numerically positive definite — the result then
    has no covariances and says so in ``message``).
    """

    name = "graph"
    Params = GraphParams
    #: ackermann: between factors on the odometry increments, which an importer integrates with the car model
    motion_models = ("ddmr", "ackermann")
    #: multi-robot datasets (slamcli.types.RobotTeam): one prior per robot, chains per robot, and the
    #: inter-robot range-bearing factor :func:`robot_range_bearing_error`
    multi_robot = True

    def _associate(self, inputs: SlamInputs, init: SolverResult | None, poses: np.ndarray):
        p = self.params
        obs = inputs.observations
        mode = p.association
        if mode == "auto":
            if init is not None:
                mode = "init"
            elif len(obs) and np.any(np.asarray(obs.reported_id) >= 0):
                mode = "reported"
            else:
                mode = "nn"
        if mode == "init":
            if init is None:
                raise SolverError("graph: association=init needs an --init result")
            assoc, _ = frontend.associations_from_result(init, len(obs))
        elif mode == "reported":
            if not len(obs) or not np.any(np.asarray(obs.reported_id) >= 0):
                raise SolverError("graph: association=reported but the observations carry no reported_id")
            assoc = frontend.associate_reported(obs)
        else:
            assoc = _nearest_neighbour(poses, obs, inputs, p)
        assoc, old_of_new = frontend.compact_labels(assoc, p.min_obs)
        return assoc, old_of_new, mode

    def solve(
        self,
        inputs: SlamInputs,
        *,
        init: SolverResult | None = None,
        rng: np.random.Generator,
        progress: ProgressFn | None = None,
    ) -> SolverResult:
        t_start = time.perf_counter()
        p = self.params
        if p.surface:  # the declared landmark radius (issue 22)
            from slamcli.solvers.surface import mean_offset_inputs

            inputs = mean_offset_inputs(inputs, "graph")
        if inputs.motion_model != "ddmr" and (p.use_controls or p.model == "paper"):
            raise SolverError(f"graph: use_controls / model=paper read the controls as DDMR [v, omega]; with "
                              f"motion_model={inputs.motion_model!r} use the odometry factors (model=gtsam)")
        if inputs.robots is not None and (p.model == "paper" or p.init != "odometry" or p.use_controls):
            raise SolverError("graph: multi-robot data supports model=gtsam with init=odometry and "
                              "use_controls=false only")
        if p.init_from == "init":
            if init is None:
                raise SolverError("graph: init_from=init needs an --init result")
            poses0 = np.asarray(init.poses_xyt, float)
            if poses0.shape != (inputs.n_poses, 3):
                raise SolverError(
                    f"graph: init result has poses {poses0.shape}, dataset needs ({inputs.n_poses}, 3)"
                )
        else:
            poses0 = initial_poses(inputs, "odometry" if p.init in ("robust", "incremental") else p.init)
            if p.init == "incremental":
                if p.model != "gtsam":
                    raise SolverError("graph: init=incremental needs model=gtsam")
                if getattr(inputs, "robots", None) is not None:
                    raise SolverError("graph: init=incremental cuts one robot's run into time windows (single robot only)")
                has_ids = len(inputs.observations) and np.any(np.asarray(inputs.observations.reported_id) >= 0)
                if p.association in ("reported", "init") or (p.association == "auto" and (init is not None or has_ids)):
                    raise SolverError(
                        "graph: init=incremental builds a nearest-neighbour association (unknown correspondences); "
                        "use association=nn, or another init with reported ids / --init labels"
                    )
                poses0 = incremental_initial_poses(inputs, poses0, p)
        assoc, old_of_new, mode = self._associate(inputs, init, poses0)
        L = old_of_new.size
        robust_init = None
        if p.init == "robust" and p.init_from == "odometry":
            if p.model != "gtsam":
                raise SolverError("graph: init=robust needs model=gtsam")
            if L:
                poses0, robust_init = robust_initial_poses(inputs, assoc, poses0, p)
        lm0 = frontend.landmarks_from_observations(poses0, inputs.observations, assoc, L)
        if mode == "init" and init is not None and p.init_from == "init":
            lm0 = np.asarray(init.landmarks_xy, float).reshape(-1, 2)[old_of_new]

        Q = None
        if p.model == "paper":
            R0, S0, Q0 = default_paper_weights(inputs)
            R = R0 if p.paper_R is None else np.asarray(p.paper_R, float)
            S = S0 if p.paper_S is None else np.asarray(p.paper_S, float)
            Q = Q0 if p.paper_Q is None else np.asarray(p.paper_Q, float)
            if R.shape != (3, 3) or S.shape != (3, 3) or Q.shape != (2, 2):
                raise SolverError(
                    f"graph: paper_R and paper_S must be 3x3 and paper_Q 2x2, got {R.shape}, {S.shape}, {Q.shape}"
                )

        def build(assoc, poses_init, lm_init):
            if p.model == "gtsam":
                return build_gtsam_problem(inputs, assoc, poses_init, lm_init, p)
            return build_paper_problem(inputs, assoc, R, S, Q, poses_init, lm_init)

        objective: list[float] = []
        times: list[float] = []
        lm_trace: list[np.ndarray] = []
        change: list[float] = []
        budget = p.max_iterations * (1 + (p.merge_rounds if mode == "nn" else 0))
        done_iters = 0

        def on_iter(k, x, cost):
            lm = gp.unpack(x)[1].copy()
            same = lm_trace and lm_trace[-1].shape == lm.shape and lm.size
            change.append(float(np.mean(np.linalg.norm(lm - lm_trace[-1], axis=1))) if same else 0.0)
            lm_trace.append(lm)
            if progress is not None:
                progress(min(done_iters + k, budget), budget)

        kernel = resolve_robust(p.robust, mode, inputs.reported_id_source)
        nparams = nls.NlsParams(
            method=p.method,
            linear_solver=p.linear_solver,
            pose_chart=p.pose_chart,
            max_iterations=p.max_iterations,
            rel_cost_tol=p.rel_cost_tol,
            step_tol=p.step_tol,
            robust=kernel,
            huber_k={"cauchy": p.cauchy_k, "geman_mcclure": p.geman_mcclure_c}.get(kernel, p.huber_k),
        )
        merged_total = 0
        rounds = p.merge_rounds if mode == "nn" else 0
        x_init_poses, x_init_lms = poses0, lm0
        notes: list[str] = []
        for rnd in range(rounds + 1):
            gp = build(assoc, x_init_poses, x_init_lms)
            res = nls.solve(gp.problem, gp.x0, nparams, callback=on_iter)
            objective.extend(res.cost_trace.tolist())
            times.extend(res.time_trace.tolist())
            done_iters += res.iterations
            notes.extend(f"round {rnd}: {n}" if rounds else n for n in res.notes)
            if rnd == rounds or res.status == Status.FAILED or gp.n_landmarks < 2:
                break
            poses_r, lms_r = gp.unpack(res.x)
            try:
                pairs = merge_candidates(
                    gp, res.information, lms_r, inputs.observations, assoc, p.gate_prob, p.merge_dist
                )
            except np.linalg.LinAlgError as exc:
                notes.append(
                    f"merging stopped after round {rnd}: no landmark covariances for the test ({exc})"
                )
                break
            if not pairs.size:
                break
            lut = np.arange(gp.n_landmarks)
            lut[pairs[:, 1]] = pairs[:, 0]
            new_lms = lms_r.copy()
            new_lms[pairs[:, 0]] = 0.5 * (lms_r[pairs[:, 0]] + lms_r[pairs[:, 1]])
            relabelled = np.where(assoc >= 0, lut[np.maximum(assoc, 0)], -1)
            assoc, old_of_new = frontend.compact_labels(relabelled)
            x_init_poses, x_init_lms = poses_r.copy(), new_lms[old_of_new]
            merged_total += int(pairs.shape[0])
        poses, lms = gp.unpack(res.x)
        L = gp.n_landmarks
        pose_cov = landmark_cov = None
        extra: dict = {
            "association": mode,
            "n_landmarks": int(L),
            "iterations": int(done_iters),
            "final_cost": float(res.cost),
            "model": p.model,
            "robust": kernel,
        }
        if rounds:
            extra["merged_landmarks"] = merged_total
        if gp.range_bias_col is not None:
            extra["range_bias"] = float(res.x[gp.range_bias_col])
        if p.init != "odometry" and p.init_from == "odometry":
            extra["init"] = p.init
        if robust_init is not None:
            extra["robust_init"] = {
                "status": robust_init.status.value,
                "iterations": int(robust_init.iterations),
                "cost": float(robust_init.cost),
            }
        if p.outlier_counts:
            extra["chi2_outliers"] = chi2_outlier_counts(gp.problem, res.x)
        message = res.message
        if rnd:  # the status is that of the last round; the trace holds every round (each with its start)
            message += (
                f" (in optimisation round {rnd + 1}, after landmark merges; {done_iters} iterations in all)"
            )
        team_cov_skipped = p.covariance and inputs.robots is not None and len(inputs.robots.range_m) > 0
        if team_cov_skipped:  # inter-robot factors break the chain + border layout of the fast marginals
            extra["covariance_note"] = ("not computed: the inter-robot factors couple poses of different robots, "
                                        "so the chain + border marginals do not apply and the general sparse "
                                        "column solve takes minutes on a few thousand poses")
        if p.covariance and res.status != Status.FAILED and not team_cov_skipped:
            try:
                pose_cov, landmark_cov = laplace_marginals(gp, res.information)
            except np.linalg.LinAlgError as exc:
                # never report covariances from a factorisation that broke down; the estimate itself stands
                why = f"the information matrix is not numerically positive definite at the estimate ({exc})"
                extra["covariance_error"] = why
                message += f"; no covariances: {why}"
            else:
                if p.model == "paper":
                    pose_cov[0] = 0.0  # x_0 is held fixed
                    if not np.any(Q):
                        landmark_cov = None  # landmarks were held fixed
        if notes:
            extra["numerical_notes"] = notes
        if progress is not None:
            progress(budget, budget)
        trace = IterationTrace.from_lists(objective, change, times, lm_trace)
        return self.make_result(
            status=res.status,
            poses_xyt=poses.copy(),
            landmarks_xy=lms.copy(),
            assoc=assoc,
            t_start=t_start,
            message=message,
            pose_cov=pose_cov,
            landmark_cov=landmark_cov,
            trace=trace,
            extra=extra,
        )
