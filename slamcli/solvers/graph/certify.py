"""Global-optimality certificate of a planar pose-graph estimate (SE-Sync's Lagrangian dual).

SE-Sync (Rosen et al., IJRR 2019) poses planar pose-graph optimisation with isotropic noise as::

    F(t, R) = Σ_e κ_e ‖R_j − R_i R̃_e‖²_F + τ_e ‖t_j − t_i − R_i t̃_e‖²        R_i ∈ SO(2), t_i ∈ ℝ²

with ``κ_e = Λ_e[θ, θ]`` and ``τ_e = 2 / tr((Λ_e[xy, xy])⁻¹)`` from an edge's information ``Λ_e``. ``F`` is not
GTSAM's cost, so the LM estimate is first refined to a stationary point of ``F`` (:func:`refine_sesync`).

With ``X = [t_1 … t_n | R_1 … R_n]`` and ``F = tr(X M Xᵀ)`` for the sparse connection Laplacian ``M``, the
multipliers of ``R_iᵀR_i = I`` are ``Λ_i = Sym((M Xᵀ)_{R_i} R_i)`` and::

    S = M − blkdiag(0_t, Λ_1, …, Λ_n)  ⪰ 0   ⟹   X is a global minimiser of F        (weak duality)

``S`` always has the gauge null space, so the test is a sparse Cholesky of ``S + η I``,
``η = ETA_REL · max diag(S)`` (:data:`ETA_REL`), i.e. ``λ_min(S) ≥ −η``. ``λ_min`` is reported by inverse
iteration (certified), else Lanczos (``eigsh``), else bisection on Sylvester's inertia to
:data:`INERTIA_REL_TOL`. Non-finite poses or weights give "not certified" with that reason.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import NamedTuple

import numpy as np
import scipy.sparse as sp

from slamcli.models.angles import wrap_angle
from slamcli.solvers import nls

#: η of the certificate relative to the largest diagonal entry of S (the scale of the problem's weights)
ETA_REL = 1e-9
#: Gauss-Newton refinement on F: stop at a relative cost decrease below this, or after REFINE_MAX_ITERS
REFINE_REL_TOL = 1e-13
REFINE_MAX_ITERS = 60
#: once a step lowers F by less than this (relative), the next steps reuse the last factorisation (simplified
#: Newton; a fresh one only when such a step fails): the final, converging steps then cost a solve each
FROZEN_REL = 1e-6
#: ... and stop on a simplified-Newton step of at most this size (relative to max |x|, 1 at least)
FROZEN_STEP_TOL = 1e-12
#: a Newton step of the refinement is taken when F rises by at most this (relative): F's rounding
NEWTON_SLACK = 1e-14
#: dense eigenvalues below this size of S; Lanczos restarts of the uncertified λ_min
DENSE_EIG_MAX = 600
LANCZOS_MAX_ITERS = 2000
#: inverse iteration for the certified λ_min: step budget and the change of the Rayleigh quotient (relative to
#: max |S_ij|) at which it stops
INVERSE_ITERATIONS = 50
INVERSE_ITERATION_TOL = 1e-14
#: bisection of λ_min on the inertia of S − σI (when the eigen-solvers fail): stop at a bracket this wide
#: relative to max(|λ_min|, η), or after INERTIA_MAX_FACTORS factorisations
INERTIA_REL_TOL = 1e-4
INERTIA_MAX_FACTORS = 80


@dataclass(frozen=True)
class Certificate:
    """Outcome of :func:`certify_pose_graph`.

    Attributes
    ----------
    certified : bool            ``S + ηI`` is positive definite: the refined estimate minimises F globally.
    lambda_min : float          smallest eigenvalue of ``S`` (inverse iteration or Lanczos, :func:`_lambda_min`;
                                 NaN when it did not converge).
    eta : float                 the tolerance η of the test.
    sesync_cost : float         ``F`` at the refined estimate.
    dual_bound : float          ``tr(Λ)``, a lower bound on the global minimum of F when certified.
    suboptimality_bound : float ``F − tr(Λ)`` when certified (the estimate is within it of the optimum of F;
                                 exact up to the slack η‖X*‖²_F), else NaN (no bound).
    poses_xyt : ndarray (n, 3)  the refined stationary point of F.
    reason : str                why it is not certified (``""`` when certified).
    lambda_method : str         how ``lambda_min`` was found: dense, inverse iteration, Lanczos, inertia
                                 bisection (then ``lambda_bracket`` holds it), or none.
    lambda_bracket : tuple      ``(lo, hi)`` with ``lo < λ_min ≤ hi`` from the inertia bisection, else ().
    """

    certified: bool
    lambda_min: float
    eta: float
    sesync_cost: float
    dual_bound: float
    suboptimality_bound: float
    poses_xyt: np.ndarray
    reason: str = ""
    lambda_method: str = ""
    lambda_bracket: tuple = ()

    def as_extra(self) -> dict:
        """The result's ``extra["certificate"]`` entry (JSON-able)."""
        out = {
            "certified": bool(self.certified),
            "lambda_min": float(self.lambda_min),
            "eta": float(self.eta),
            "sesync_cost": float(self.sesync_cost),
            "dual_bound": float(self.dual_bound),
            "suboptimality_bound": float(self.suboptimality_bound),
            "lambda_min_method": self.lambda_method,
        }
        if self.lambda_bracket:
            out["lambda_min_bracket"] = [float(v) for v in self.lambda_bracket]
        if not self.certified:
            out["reason"] = self.reason
        return out

    def verdict(self) -> str:
        """The phrase a solver's message carries: ``certified global optimum (…)`` or ``not certified: <reason>``."""
        if self.certified:
            return (f"certified global optimum (SE-Sync dual: λ_min(S) = {self.lambda_min:.3g} ≥ −η, "
                    f"bound {self.suboptimality_bound:.3g} on the SE-Sync objective)")
        return f"not certified: {self.reason}"


def isotropic_weights(info: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """SE-Sync's ``κ (E,)`` and ``τ (E,)`` from edge information matrices ``info (E, 3, 3)`` over ``[x, y, θ]``."""
    info = np.asarray(info, float).reshape(-1, 3, 3)
    kappa = info[:, 2, 2].copy()
    a, b, c, d = info[:, 0, 0], info[:, 0, 1], info[:, 1, 0], info[:, 1, 1]
    # tr(A⁻¹) = tr(A) / det(A) for a 2×2 A; no translation information (A = 0) is τ = 0, the limit
    trace = a + d
    tau = np.divide(2.0 * (a * d - b * c), trace, out=np.zeros_like(trace), where=trace != 0)
    return kappa, tau


def sesync_cost(poses_xyt, ij, xyt, kappa, tau) -> float:
    """``F(t, R)`` of the module docstring at ``poses_xyt (n, 3)`` for edges ``ij (E, 2)``, ``xyt (E, 3)``
    (:meth:`_Edges.cost`)."""
    return _Edges(ij, xyt, kappa, tau).cost(np.asarray(poses_xyt, float))


class _Terms(NamedTuple):
    """The edges' pose-dependent terms at one point, each ``(E,)`` (``r (E, 4)``): computed once by
    :meth:`_Edges.terms` and shared by the residuals, Jacobians, gradient, Gauss-Newton matrix and θ curvature
    there. ``R(θ_i) t̃ = [q, p]`` and ``dR/dθ(θ_i) t̃ = [−p, q]``."""

    cj: np.ndarray  # cos θ_j
    sj: np.ndarray  # sin θ_j
    ca: np.ndarray  # cos(θ_i + Δθ)
    sa: np.ndarray  # sin(θ_i + Δθ)
    p: np.ndarray  # sin θ_i t̃_x + cos θ_i t̃_y
    q: np.ndarray  # cos θ_i t̃_x − sin θ_i t̃_y
    r: np.ndarray  # the residuals (E, 4) of :class:`_Edges`


class _Edges:
    """The edges' constant terms for ``ij (E, 2)``, ``xyt (E, 3)``, ``κ (E,)``, ``τ (E,)``, and ``F``'s residuals,
    Jacobians, gradient, Gauss-Newton matrix and θ curvature from them and the :class:`_Terms` at a point.

    Residuals per edge ``[rot_x, rot_y, tr_x, tr_y]``:

    rotation:    ``√(2κ) (u_j − R(Δθ) u_i)``, ``u = [cos θ, sin θ]``   (``‖R_j − R_i R̃‖²_F = 2 ‖·‖²``)
    translation: ``√τ (t_j − t_i − R(θ_i) t̃)``

    The sines and cosines are the poses' (``n`` of each), those of ``θ_i + Δθ`` by the addition theorem with
    the measurements' ``cos Δθ``, ``sin Δθ`` computed once: two transcendental calls per evaluation instead
    of six per edge."""

    def __init__(self, ij, xyt, kappa, tau) -> None:
        self.i, self.j = ij[:, 0], ij[:, 1]
        self.kappa = kappa  # (E,), for the data matrix of :func:`_certificate_matrix`
        self.sk, self.st = np.sqrt(2.0 * kappa), np.sqrt(tau)
        self.cd, self.sd = np.cos(xyt[:, 2]), np.sin(xyt[:, 2])
        self.tx, self.ty = xyt[:, 0].copy(), xyt[:, 1].copy()
        #: state columns ``(E, 6)`` of ``[x_i, y_i, θ_i, x_j, y_j, θ_j]`` (the block of :func:`_sesync_problem`), and
        #: the same column-major (the six gradient weights of :meth:`cost_gradient`, each over all edges)
        self.cols = np.concatenate([3 * self.i[:, None] + np.arange(3), 3 * self.j[:, None] + np.arange(3)], axis=1)
        self._grad_cols = self.cols.T.ravel()
        self._gn_of = None  # the assembler :meth:`gauss_newton`'s constant part was scattered for

    def terms(self, poses) -> _Terms:
        """The :class:`_Terms` at ``poses (n, 3)``."""
        cp, sp_ = np.cos(poses[:, 2]), np.sin(poses[:, 2])
        c, s = cp[self.i], sp_[self.i]
        cj, sj = cp[self.j], sp_[self.j]
        ca, sa = c * self.cd - s * self.sd, s * self.cd + c * self.sd
        p, q = s * self.tx + c * self.ty, c * self.tx - s * self.ty
        pi, pj = poses[self.i], poses[self.j]
        r = np.empty((self.i.size, 4))
        r[:, 0] = self.sk * (cj - ca)
        r[:, 1] = self.sk * (sj - sa)
        r[:, 2] = self.st * (pj[:, 0] - pi[:, 0] - q)
        r[:, 3] = self.st * (pj[:, 1] - pi[:, 1] - p)
        return _Terms(cj, sj, ca, sa, p, q, r)

    def residuals(self, poses) -> np.ndarray:
        """``r (E, 4)`` at ``poses (n, 3)``."""
        return self.terms(poses).r

    def cost(self, poses) -> float:
        """``F = ‖r‖²`` at ``poses (n, 3)``."""
        r = self.residuals(poses).ravel()
        return float(r @ r)

    def evaluate(self, poses) -> tuple[np.ndarray, np.ndarray]:
        """``(r (E, 4), J (E, 4, 6))``, ``J`` over ``[x_i, y_i, θ_i, x_j, y_j, θ_j]``."""
        t = self.terms(poses)
        sk, st = self.sk, self.st
        J = np.zeros((self.i.size, 4, 6))
        J[:, 0, 5], J[:, 1, 5] = -sk * t.sj, sk * t.cj
        J[:, 0, 2], J[:, 1, 2] = sk * t.sa, -sk * t.ca
        for k in (0, 1):
            J[:, 2 + k, 3 + k] = st
            J[:, 2 + k, k] = -st
        J[:, 2, 2] = st * t.p  # −√τ dR/dθ t̃
        J[:, 3, 2] = -st * t.q
        return t.r, J

    def cost_gradient(self, poses, t: _Terms | None = None) -> tuple[float, np.ndarray]:
        """``(½F, ∇(½F) (3n,))`` at ``poses (n, 3)`` from the residuals and the closed-form rows of
        :meth:`evaluate`'s Jacobian (``Jᵀr`` per edge without building ``J``; one scatter for all six columns).
        ``t``: the :meth:`terms` at ``poses`` when the caller has them."""
        t = self.terms(poses) if t is None else t
        r = t.r
        E = self.i.size
        w = np.empty((6, E))
        np.multiply(self.st, r[:, 2], out=w[3])
        np.multiply(self.st, r[:, 3], out=w[4])
        np.negative(w[3], out=w[0])
        np.negative(w[4], out=w[1])
        w[2] = self.sk * (t.sa * r[:, 0] - t.ca * r[:, 1]) + self.st * (r[:, 2] * t.p - r[:, 3] * t.q)
        w[5] = self.sk * (t.cj * r[:, 1] - t.sj * r[:, 0])
        g = np.bincount(self._grad_cols, weights=w.ravel(), minlength=3 * poses.shape[0])
        return self.half_cost(r), g

    @staticmethod
    def half_cost(r: np.ndarray) -> float:
        """``½F = ½‖r‖²`` from the residuals, summed as :meth:`nls.Assembler.cost` sums it."""
        return float(np.sum(0.5 * np.einsum("fk,fk->f", r, r)))

    #: local pairs (a ≤ b, numbered as ``np.triu_indices(6)``) of ``JᵀJ`` over ``[x_i, y_i, θ_i, x_j, y_j, θ_j]``
    #: that depend on the poses — every one involves ``θ_i``; the others are constants of ``κ``, ``τ``
    VARYING_PAIRS = (2, 7, 11, 12, 13, 14)  # (x_i,θ_i) (y_i,θ_i) (θ_i,θ_i) (θ_i,x_j) (θ_i,y_j) (θ_i,θ_j)

    def gauss_newton(self, poses, asm: nls.Assembler,
                     t: _Terms | None = None) -> tuple[float, np.ndarray, np.ndarray] | None:
        """``(½F, JᵀJ lower data on asm's pattern, ∇(½F))`` at ``poses``, pose 0 held, in closed form: with
        :class:`_Terms`' ``p``, ``q`` (``J[tr, θ_i] = √τ [p, −q]``) the pose-dependent entries are
        ``(x_i,θ_i) = −τp``, ``(y_i,θ_i) = τq``, ``(θ_i,θ_i) = 2κ + τ(p² + q²)``, ``(θ_i,x_j) = τp``,
        ``(θ_i,y_j) = −τq``, ``(θ_i,θ_j) = −2κ cos(θ_j − θ_i − Δθ)``; the others (``±τ``, ``2κ``, 0) are
        scattered once per assembler. What :meth:`nls.Assembler.linearize_lower` returns for
        :func:`_sesync_problem`, without the ``(E, 4, 6)`` Jacobian and its 21 products per edge; None when
        ``asm`` is not that problem's single-block layout (an edge on one pose), for the generic path. ``t``:
        the :meth:`terms` at ``poses`` when the caller has them."""
        E = self.i.size
        if len(asm.lo_scatter) != 1 or asm.twice[0] is not None or asm.lo_scatter[0].size != 21 * E:
            return None
        if self._gn_of is not asm:
            pos = asm.lo_scatter[0].reshape(21, E)
            tau, k2 = self.st * self.st, self.sk * self.sk  # τ, 2κ
            const = {0: tau, 3: -tau, 6: tau, 9: -tau, 15: tau, 18: tau, 20: k2}
            keys = list(const)
            self._gn_const = np.bincount(pos[keys].ravel(), weights=np.concatenate([const[k] for k in keys]),
                                         minlength=asm.lo_nnz)
            self._gn_pos = pos[list(self.VARYING_PAIRS)].ravel()
            self._gn_of = asm
        t = self.terms(poses) if t is None else t
        cost, g = self.cost_gradient(poses, t)
        tau = self.st * self.st
        tp, tq = tau * t.p, tau * t.q
        w = np.empty((6, E))
        np.negative(tp, out=w[0])
        w[1] = tq
        w[2] = self.sk * self.sk + (tp * t.p + tq * t.q)
        w[3] = tp
        np.negative(tq, out=w[4])
        w[5] = -(self.sk * self.sk) * (t.cj * t.ca + t.sj * t.sa)
        data = self._gn_const + np.bincount(self._gn_pos, weights=w.ravel(), minlength=asm.lo_nnz)
        asm.hold_fixed(data, g)
        return cost, data, g

    def theta_curvature(self, poses, t: _Terms | None = None) -> np.ndarray:
        """``Σ_e r_e ∂²r_e/∂θ²`` per pose ``(n,)``: what ``½F``'s exact Hessian adds to ``JᵀJ``. Every residual
        depends on a pose's θ alone through its rotation, so the second-order term lies on the θ diagonal:
        ``∂²r_rot/∂θ_j² = −√(2κ) u_j``, ``∂²r_rot/∂θ_i² = √(2κ) u(θ_i + Δθ)``, ``∂²r_tr/∂θ_i² = √τ R(θ_i) t̃``."""
        t = self.terms(poses) if t is None else t
        r = t.r
        on_j = -self.sk * (r[:, 0] * t.cj + r[:, 1] * t.sj)
        on_i = self.sk * (r[:, 0] * t.ca + r[:, 1] * t.sa) + self.st * (r[:, 2] * t.q + r[:, 3] * t.p)
        n = poses.shape[0]
        return np.bincount(self.j, weights=on_j, minlength=n) + np.bincount(self.i, weights=on_i, minlength=n)


def refine_sesync(poses_xyt, ij, xyt, kappa, tau) -> np.ndarray:
    """A stationary point of ``F`` near ``poses_xyt (n, 3)``: Newton steps (exact Hessian,
    :meth:`_Edges.theta_curvature`; quadratic convergence where F's residuals are large and Gauss-Newton's is only
    linear) when they lower F, else Gauss-Newton with step halving; pose 0 held (F is invariant under a
    global SE(2) motion, so the held pose is stationary too).

    ``F = ‖r‖²`` (:class:`_Edges`) is posed as an :class:`nls.NlsProblem` (one block of 4 residuals per
    edge over ``[x_i, y_i, θ_i, x_j, y_j, θ_j]``), so every iteration reuses the engine's assembly pattern and
    the linear solver's ordering and symbolic analysis, computed once."""
    return _refine(poses_xyt, _Edges(ij, xyt, kappa, tau))[0]


def _refine(poses_xyt, edges: _Edges, workspace=None):
    """:func:`refine_sesync`'s point ``(n, 3)`` for the :class:`_Edges` ``edges``, with its assembler and linear
    solver (whose sparsity pattern and symbolic analysis the certificate matrix reuses,
    :func:`_certificate_matrix`). ``workspace``: an earlier optimisation's ``(Assembler, linear solver)`` on the
    same graph (``NlsResult.workspace``), whose pattern and CHOLMOD analysis are reused when they hold F's."""
    x = np.array(poses_xyt, float, copy=True)
    n = x.shape[0]
    problem = _sesync_problem(n, edges)
    params = nls.NlsParams(pose_chart="world")
    asm, lin = _workspace(problem, params, workspace)
    flat = x.reshape(-1)
    theta_diag = asm.lo_diag_pos[3 * np.arange(1, n) + 2]  # pose 0 is held (identity rows)
    terms = edges.terms(x)  # always the edges' terms at flat: every evaluation there shares them
    cost, lo, g = _linearize(edges, asm, flat, params, terms)
    near = False  # the last step lowered F by < FROZEN_REL: the previous factorisation is good enough
    stale = False  # lo is not H at flat (after simplified-Newton steps, which need the gradient only)
    for _ in range(REFINE_MAX_ITERS):
        if near:  # simplified Newton with the last factorisation: no new one for the converging last steps
            xn, cn, gn, tn = _frozen_step(edges, lin, flat, g, cost, NEWTON_SLACK)
            if xn is not None:
                # its convergence is linear: stop on a step below F's rounding that also moved x by ≤ FROZEN_STEP_TOL
                step = float(np.max(np.abs(xn - flat), initial=0.0))
                done = cost - cn <= REFINE_REL_TOL * cost and step <= FROZEN_STEP_TOL * max(1.0, float(np.max(np.abs(flat))))
                flat = xn
                if done:
                    break
                cost, g, terms, stale = cn, gn, tn, True
                continue
        if stale:
            cost, lo, g = _linearize(edges, asm, flat, params, terms)
            stale = False
        newton = lo.copy()
        newton[theta_diag] += edges.theta_curvature(flat.reshape(n, 3), terms)[1:]
        # Newton (quadratic convergence); near the optimum its decrease is below F's rounding, so a Newton
        # step may raise F by that much (NEWTON_SLACK): it still shrinks the gradient, which the dual gap needs
        xn, cn, tn = _try_step(edges, asm, lin, flat, newton, g, cost, halving=False, slack=NEWTON_SLACK)
        if xn is None:  # H not positive definite there, or no decrease: Gauss-Newton with step halving
            xn, cn, tn = _try_step(edges, asm, lin, flat, lo, g, cost, halving=True)
        if xn is None:
            break
        done = cost - cn <= REFINE_REL_TOL * cost
        near = cost - cn <= FROZEN_REL * cost
        flat, terms = xn, tn
        if done:
            break
        if near:  # the next step reuses this factorisation: it needs the gradient only, not H
            cost, g = _cost_gradient(edges, flat, terms)
            stale = True
        else:
            cost, lo, g = _linearize(edges, asm, flat, params, terms)
    x = flat.reshape(n, 3).copy()
    x[:, 2] = wrap_angle(x[:, 2])
    return x, asm, lin


def _linearize(edges: _Edges, asm: nls.Assembler, flat: np.ndarray, params: nls.NlsParams, terms: _Terms):
    """``(½F, JᵀJ lower data, ∇(½F))`` at ``flat``, whose :meth:`_Edges.terms` are ``terms``: closed form
    (:meth:`_Edges.gauss_newton`), else the engine's."""
    out = edges.gauss_newton(flat.reshape(-1, 3), asm, terms)
    return out if out is not None else asm.linearize_lower(flat, params)


def _workspace(problem: nls.NlsProblem, params: nls.NlsParams, workspace):
    """``(Assembler, linear solver)`` for the refinement: ``workspace``'s pattern and CHOLMOD analysis when
    they hold ``problem``'s ``H``, else new ones."""
    like, lin = workspace if workspace is not None else (None, None)
    asm = nls.Assembler(problem, like=like)
    if lin is None or getattr(lin, "name", "") != "cholmod" or asm.lo_indices is not like.lo_indices:
        lin = nls.make_linear_solver(asm, params)
    return asm, lin


def _cost_gradient(edges: _Edges, flat: np.ndarray, terms: _Terms) -> tuple[float, np.ndarray]:
    """``(½F, ∇(½F) = Σ_e J_eᵀ r_e)`` at ``flat``, whose :meth:`_Edges.terms` are ``terms``
    (:meth:`_Edges.cost_gradient`: the cost and gradient :meth:`nls.Assembler.linearize_lower` returns for
    :func:`_sesync_problem`, without assembling ``H``), pose 0 held."""
    cost, g = edges.cost_gradient(flat.reshape(-1, 3), terms)
    g[:3] = 0.0
    return cost, g


def _frozen_step(edges, lin, flat, g, cost, slack: float):
    """``(x, cost, gradient, terms)`` after ``−H⁻¹g`` with the factorisation ``lin`` holds (an earlier
    iterate's ``H``) when it does not raise the cost by more than ``slack·cost``, else four Nones; ``terms``:
    the edges' :meth:`_Edges.terms` at ``x``."""
    h = lin.solve(-g)
    if h is None:
        return None, None, None, None
    xn = flat + h
    tn = edges.terms(xn.reshape(-1, 3))
    cn, gn = _cost_gradient(edges, xn, tn)
    return (xn, cn, gn, tn) if cn <= cost + slack * abs(cost) else (None, None, None, None)


def _try_step(edges: _Edges, asm, lin, flat, lo, g, cost, halving: bool, slack: float = 0.0):
    """``(x, cost, terms)`` after the step ``−H⁻¹g`` for the matrix of lower data ``lo`` (halved until the cost
    does not rise by more than ``slack·cost``, when ``halving``), with the edges' :meth:`_Edges.terms` at ``x``
    (the next linearisation's), or ``(None, None, None)``."""
    if not nls.factorize_lower(lin, asm, lo):
        return None, None, None
    h = lin.solve(-g)
    if h is None:
        return None, None, None
    alpha = 1.0
    while alpha > 1e-4:
        xn = flat + alpha * h
        terms = edges.terms(xn.reshape(-1, 3))
        cn = _Edges.half_cost(terms.r)
        if cn <= cost + slack * abs(cost):
            return xn, cn, terms
        if not halving:
            break
        alpha *= 0.5
    return None, None, None


def _sesync_problem(n: int, edges: _Edges) -> nls.NlsProblem:
    """``½F`` as a least-squares problem over ``[x, y, θ]`` of ``n`` poses, pose 0 fixed (residuals and
    Jacobians of :class:`_Edges`, per edge)."""
    block = nls.FactorBlock("sesync", edges.cols, lambda v: edges.evaluate(v.reshape(-1, 3)), np.eye(4),
                            residual=lambda v: edges.residuals(v.reshape(-1, 3)))
    return nls.NlsProblem(3 * n, [block], fixed_cols=np.arange(3, dtype=np.int64),
                          retract=lambda v, h: v + h)


def certify_pose_graph(poses_xyt, ij, xyt, info, workspace=None) -> Certificate:
    """Refine ``poses_xyt (n, 3)`` to a stationary point of F and test the dual certificate (module docstring).

    Parameters
    ----------
    poses_xyt : (n, 3) estimate (e.g. LM's on GTSAM's objective);  ij : (E, 2) edges ``x_i⁻¹ ⊕ x_j``;
    xyt : (E, 3) measurements;  info : (E, 3, 3) information over ``[x, y, θ]``;
    workspace : the LM's ``NlsResult.workspace`` on this graph (optional; its pattern and analysis reused).
    """
    ij = np.asarray(ij, np.int64).reshape(-1, 2)
    xyt = np.asarray(xyt, float).reshape(-1, 3)
    kappa, tau = isotropic_weights(info)
    n = int(np.asarray(poses_xyt).shape[0])
    nan = float("nan")
    bad = np.flatnonzero(~(np.isfinite(kappa) & np.isfinite(tau) & (kappa >= 0) & (tau >= 0)))
    if bad.size:
        return Certificate(False, nan, nan, nan, nan, nan, np.array(poses_xyt, float), lambda_method="none",
                           reason=f"edge {int(bad[0])} ({int(ij[bad[0], 0])} → {int(ij[bad[0], 1])}) has no finite "
                                  f"non-negative SE-Sync weights (κ = {kappa[bad[0]]:.3g}, τ = {tau[bad[0]]:.3g})")
    if not np.all(np.isfinite(poses_xyt)):
        return Certificate(False, nan, nan, nan, nan, nan, np.array(poses_xyt, float), lambda_method="none",
                           reason="the estimate has non-finite poses")
    edges = _Edges(ij, xyt, kappa, tau)
    x, asm, lin = _refine(poses_xyt, edges, workspace)
    F = edges.cost(x)
    if not (np.isfinite(F) and np.all(np.isfinite(x))):
        return Certificate(False, nan, nan, F, nan, nan, x, lambda_method="none",
                           reason="the refinement to a stationary point of the SE-Sync objective did not stay finite")
    S_lo, dual = _certificate_matrix(asm, x, edges)
    S = _LowerSymmetric(asm.lower_matrix(S_lo))  # pose-interleaved order [t_i, R_i e₁, R_i e₂] of the refinement
    eta = ETA_REL * float(np.max(np.abs(S_lo[asm.lo_diag_pos]))) if n else 0.0
    shifted = S_lo.copy()
    shifted[asm.lo_diag_pos] += eta
    if lin.name == "cholmod":  # the refinement's symbolic analysis: a numeric Cholesky, which fails at a pivot ≤ 0
        certified = nls.factorize_lower(lin, asm, shifted)
        solve = _finite_solve(lin) if certified else None
    else:
        certified, solve = _is_positive_definite(asm.matrix(asm.full(shifted)))
    lam_min, method = _lambda_min(S, eta, certified, solve)
    bracket: tuple = ()
    if not np.isfinite(lam_min):  # the eigen-solvers failed: the inertia of S − σI brackets λ_min all the same
        bracket = _lambda_min_by_inertia(S.tocsc(), eta, certified)
        lam_min, method = 0.5 * (bracket[0] + bracket[1]), "inertia bisection"
    gap = max(F - dual, 0.0) if certified else nan
    reason = "" if certified else (
        f"S + ηI is not positive definite (λ_min(S) = {lam_min:.3g} < −η = {-eta:.3g}, {method}): the refined "
        "estimate is a stationary point of the SE-Sync objective that its dual does not prove globally optimal")
    return Certificate(bool(certified), lam_min, eta, F, dual, gap, x, reason, method, bracket)


def _certificate_matrix(asm: nls.Assembler, x, edges: _Edges) -> tuple[np.ndarray, float]:
    """``(S, tr Λ)``: the lower data of ``S = M − blkdiag(0, Λ_i)`` (module docstring) on the refinement's
    pattern ``asm`` — its columns ``3i, 3i+1, 3i+2`` are ``t_i, R_i e₁, R_i e₂`` (a permutation of
    the module docstring's ``[t_1 … t_n | R_1 … R_n]``), so ``M`` scatters like the refinement's ``H`` (edge ``e`` adds
    ``v vᵀ`` over ``[t_i, R_i, t_j, R_j]`` for its three columns ``v`` of ``A_e``, ``a_e``) — and the
    multipliers ``Λ``, at ``x (n, 3)`` for the refinement's ``edges`` (their measurements' cos/sin, √τ and t̃)."""
    n = x.shape[0]
    c, s = edges.cd, edges.sd
    sk, st = np.sqrt(edges.kappa), edges.st
    V = np.zeros((3, 6, c.size))  # (k, n, E): the assembler's layout, edges last
    V[0, 1], V[0, 2], V[0, 4] = -sk * c, -sk * s, sk  # A_e e₁ = e_{R_j e₁} − E_{R_i} R̃ e₁
    V[1, 1], V[1, 2], V[1, 5] = sk * s, -sk * c, sk  # A_e e₂
    V[2, 0], V[2, 1], V[2, 2], V[2, 3] = -st, -st * edges.tx, -st * edges.ty, st  # a_e
    ia, ib = asm.pairs[0]
    vals = np.einsum("kae,kbe->abe", V, V)[ia, ib]
    if asm.twice[0] is not None:
        vals[asm.twice[0]] *= 2.0
    M_lo = np.bincount(asm.lo_scatter[0], weights=vals.ravel(), minlength=asm.lo_nnz)
    ct, st_ = np.cos(x[:, 2]), np.sin(x[:, 2])
    Xt = np.empty((n, 3, 2))  # rows of Xᵀ: t_i, then the columns of R_i = [[c, −s], [s, c]]
    Xt[:, 0], Xt[:, 1], Xt[:, 2] = x[:, :2], np.column_stack([ct, st_]), np.column_stack([-st_, ct])
    G = (_LowerSymmetric(asm.lower_matrix(M_lo)) @ Xt.reshape(3 * n, 2)).reshape(n, 3, 2)[:, 1:]  # (M Xᵀ)_{R_i}
    # Λ_i = sym(G_i R_iᵀ) (R_i's columns are rows 1, 2 of Xt_i): its three entries, without n 2×2 matmuls
    g00, g01, g10, g11 = G[:, 0, 0], G[:, 0, 1], G[:, 1, 0], G[:, 1, 1]
    r00, r01, r10, r11 = Xt[:, 1, 0], Xt[:, 1, 1], Xt[:, 2, 0], Xt[:, 2, 1]
    lam00, lam11 = g00 * r00 + g01 * r01, g10 * r10 + g11 * r11
    lam10 = 0.5 * ((g10 * r00 + g11 * r01) + (g00 * r10 + g01 * r11))
    d1, d2 = asm.lo_diag_pos[3 * np.arange(n) + 1], asm.lo_diag_pos[3 * np.arange(n) + 2]
    # (R_i e₂, R_i e₁): next after the diagonal in column 3i+1 — in the pattern for every pose with an edge
    # (a dense 3×3 block); a pose without edges has G_i = 0, so Λ_i = 0 and nothing to subtract
    below = d1 + 1
    has = asm.lo_indices[below] == 3 * np.arange(n) + 2
    S_lo = M_lo
    S_lo[d1] -= lam00
    S_lo[below[has]] -= lam10[has]
    S_lo[d2] -= lam11
    return S_lo, float(np.sum(lam00 + lam11))


class _LowerSymmetric:
    """A sparse symmetric matrix held by its lower triangle (CSC, the assembler's lower data): products
    ``A v = L v + Lᵀ v − diag(A) v`` without the full symmetric pattern; :meth:`tocsc` builds that when a
    routine needs the matrix itself."""

    def __init__(self, lower: sp.csc_matrix) -> None:
        self.lower, self.diag, self.shape = lower, lower.diagonal(), lower.shape
        self.upper = lower.T  # CSR on the same arrays, made once for every product

    def __matmul__(self, v: np.ndarray) -> np.ndarray:
        d = self.diag if np.ndim(v) == 1 else self.diag[:, None]
        return self.lower @ v + self.upper @ v - d * v

    def tocsc(self) -> sp.csc_matrix:
        return (self.lower + self.lower.T - sp.diags(self.diag)).tocsc()

    def toarray(self) -> np.ndarray:
        return self.tocsc().toarray()

    def abs_max(self) -> float:
        return float(np.max(np.abs(self.lower.data), initial=0.0))


def _finite_solve(lin):
    """``b ↦ A⁻¹b`` by the linear solver ``lin``'s factorisation (NaNs when it is not finite)."""
    def solve(b):
        h = lin.solve(b)
        return np.full_like(b, np.nan) if h is None else h
    return solve


def _is_positive_definite(A: sp.csc_matrix):
    """``(ok, solve)``: whether the sparse symmetric ``A`` has a Cholesky factorisation (CHOLMOD, else an
    LDLᵀ-type SuperLU elimination with every pivot > 0), and ``solve(b) = A⁻¹b`` by that factorisation."""
    if not nls.cholmod_available():
        try:
            lu = nls.factorize_symmetric(A)
        except RuntimeError:
            return False, None
        return bool(np.array_equal(lu.perm_r, lu.perm_c) and np.all(lu.U.diagonal() > 0)), lu.solve
    factor = nls.cholmod_spd_factor(A)
    return factor is not None, factor


def _lambda_min(S: sp.csc_matrix | _LowerSymmetric, eta: float, certified: bool, solve=None) -> tuple[float, str]:
    """``(λ_min(S), method)``; ``(NaN, "")`` when the iterations do not converge.

    Certified (every eigenvalue ≥ −η): inverse iteration with the factorisation of ``S + ηI`` that the test
    made (``solve``), whose dominant eigenvalue ``1/(λ_min + η)`` is the smallest one's, then the Rayleigh
    quotient; without it (or when that does not converge), shift-invert Lanczos at ``σ = −2η``. Otherwise the smallest-algebraic Lanczos
    run, with a bounded budget (the value then only says how negative)."""
    n = S.shape[0]
    if n <= DENSE_EIG_MAX:
        try:
            return float(np.linalg.eigvalsh(S.toarray())[0]), "dense"
        except np.linalg.LinAlgError:
            return float("nan"), ""
    v0 = np.ones(n) / np.sqrt(n)
    if certified and solve is not None:
        lam = _inverse_iteration(S, solve, v0)
        if np.isfinite(lam):
            return lam, "inverse iteration"
    import scipy.sparse.linalg as spla  # the inverse iteration is slow when λ₁ is not isolated

    S = S.tocsc()
    try:
        if certified:
            vals = spla.eigsh(S, k=1, sigma=-2.0 * eta, which="LM", v0=v0, return_eigenvectors=False)
        else:
            vals = spla.eigsh(S, k=1, which="SA", tol=1e-4, maxiter=LANCZOS_MAX_ITERS, v0=v0,
                              return_eigenvectors=False)
    except (spla.ArpackNoConvergence, RuntimeError):
        return float("nan"), ""
    return float(vals[0]), "Lanczos"


def _lambda_min_by_inertia(S: sp.csc_matrix, eta: float, certified: bool) -> tuple[float, float]:
    """``(lo, hi)`` with ``lo ≤ λ_min(S) ≤ hi`` by bisection on Sylvester's inertia: ``S − σI`` has a Cholesky
    factor iff ``σ < λ_min``. The certificate's test is the first probe (``S + ηI`` positive definite or not);
    the other end is found by doubling the step from it, within the Gershgorin interval of ``S``; then the
    bracket is halved to :data:`INERTIA_REL_TOL` (at most :data:`INERTIA_MAX_FACTORS` factorisations)."""
    eye = sp.identity(S.shape[0], format="csc")
    radius = np.asarray(abs(S).sum(axis=1)).ravel() - np.abs(S.diagonal())
    g_lo, g_hi = float(np.min(S.diagonal() - radius)), float(np.max(S.diagonal() + radius))

    def below(sigma: float) -> bool:  # σ < λ_min
        return _is_positive_definite((S - sigma * eye).tocsc())[0]

    step, factors = max(2.0 * eta, np.finfo(float).tiny), 0
    if certified:  # λ_min ≥ −η: step up from it until S − σI is not positive definite (at most g_hi)
        lo, hi = -eta, -eta + step
        while hi < g_hi and factors < INERTIA_MAX_FACTORS:
            factors += 1
            if not below(hi):
                break
            lo, step = hi, 2.0 * step
            hi = -eta + step
        else:
            hi = g_hi
    else:  # λ_min < −η: step down from it until S − σI is positive definite (at least g_lo)
        lo, hi = -eta - step, -eta
        while lo > g_lo and factors < INERTIA_MAX_FACTORS:
            factors += 1
            if below(lo):
                break
            hi, step = lo, 2.0 * step
            lo = -eta - step
        else:
            lo = g_lo
    while hi - lo > INERTIA_REL_TOL * max(abs(lo), abs(hi), eta) and factors < INERTIA_MAX_FACTORS:
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if below(mid) else (lo, mid)
        factors += 1
    return lo, hi


def _inverse_iteration(S: sp.csc_matrix | _LowerSymmetric, solve, v: np.ndarray) -> float:
    """Rayleigh quotient of ``S`` at the limit of ``v ← (S + ηI)⁻¹ v / ‖·‖``: converges at the rate
    ``(λ₁ + η) / (λ₂ + η)`` (``λ₁`` the smallest eigenvalue, ``λ₂`` the next distinct one; at a certified
    optimum ``λ₁ ≈ 0`` on the gauge null space and ``λ₂ ≫ η``, so a few steps). NaN without convergence."""
    lam = np.inf
    scale = max(S.abs_max() if isinstance(S, _LowerSymmetric) else float(abs(S).max()), np.finfo(float).tiny)
    for _ in range(INVERSE_ITERATIONS):
        w = np.asarray(solve(v), float).ravel()
        norm = float(np.linalg.norm(w))
        if not np.isfinite(norm) or norm == 0.0:
            return float("nan")
        v = w / norm
        new = float(v @ (S @ v))
        if abs(new - lam) <= INVERSE_ITERATION_TOL * scale:
            return new
        lam = new
    return float("nan")
