"""The joint optimum of ICM's energy for fixed matchings (``polish="nls"``, beyond the paper), and how far an
estimate is from it.

Gauss-Seidel sweeps move a pose only as far as its neighbours let it, so on a long chain they creep towards the
optimum of H(x, m, c) for the current matchings c and stop, by any energy rule, short of it. The polish
minimises that same energy over all poses x_1..x_T and map points m at once, with c fixed, by the project's
least-squares engine (:func:`slamcli.solvers.nls.solve`, Levenberg-Marquardt). Its problem (:func:`nls_problem`)
is the energy of :mod:`slamcli.solvers.icm.energy` written as factor blocks — motion (R), odometry (S),
observations (Q), GPS (K) — each whitened by ``√(2W)`` so that the engine's cost ``½ Σ ‖L r‖²`` equals H. With ``observation=range_bearing``
the observation block is the range-bearing residual ``h(x_t, m) − z`` whitened by ``√2 diag(σ_r, σ_b)⁻¹`` under
the engine's Cauchy kernel of width ``√2 k`` (IRLS, as graph applies its kernel): its ``½ k'² log(1 + s'²/k'²)``
is :func:`~slamcli.solvers.icm.energy.range_bearing_energy`'s ``k² log(1 + s²/k²)``, so the cost is again H.

:func:`optimality` measures an estimate against the optimum without moving it: the gradient ∇H over
x_1..x_T and m, and the Gauss-Newton step δ = −(JᵀJ)⁻¹Jᵀr to the optimum of the local quadratic model with the
energy decrease it predicts, ‖r‖² − ‖r + Jδ‖² — the distance to the joint optimum in metres / radians and in
energy, up to the model's curvature.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from slamcli.models import potentials, se2
from slamcli.models.angles import wrap_angle
from slamcli.solvers import nls
from slamcli.solvers.icm import energy as en
from slamcli.types import Status

#: the polish stops after an LM step that lowers H by less than this fraction: three orders below the 1e-6
#: relative gap asked of the result
POLISH_REL_COST_TOL = 1e-9
#: LM iterations per chunk of a polish; after each chunk its displacement Δ is extrapolated (:func:`polish`)
POLISH_CHUNK = 2
#: the multiples β tried in ``x + β Δ`` beyond a chunk's end; the lowest energy is kept (β = 0: the chunk's end)
EXTRAPOLATION_FACTORS = (1.0, 2.0, 4.0, 8.0, 16.0, 32.0)


@dataclass(frozen=True)
class Optimality:
    """How far an estimate is from the joint optimum of H for its matchings.

    gradient_norm : float   ‖∇H‖₂ over x_1..x_T and m (energy per m / rad).
    step_max : float        largest component of the Gauss-Newton step to the optimum (m or rad); NaN when the
                            normal equations could not be solved.
    gap : float             the energy decrease that step predicts (≥ 0; NaN as above).
    """

    gradient_norm: float
    step_max: float
    gap: float

    def holds(self, energy: float, step_tol: float, rtol: float) -> bool:
        """Whether the estimate counts as the optimum: step ≤ ``step_tol`` and gap ≤ ``rtol`` · energy."""
        return bool(self.step_max <= step_tol and self.gap <= rtol * max(abs(energy), 1e-300))


def optimality(prob: en.Problem, W: en.Weights, poses, landmarks, labels) -> Optimality:
    """:class:`Optimality` of ``poses (T+1, 3)``, ``landmarks (L, 2)`` under ``labels (N,)``. With
    ``W.range_bearing`` the gradient is exact and the step and gap are those of the IRLS model (the Cauchy
    weights taken at the estimate, as graph's Gauss-Newton linearises its kernel)."""
    if W.range_bearing:
        r, J = _irls_system(prob, W, poses, landmarks, labels)
    else:
        r, J = en.joint_residuals(prob, W, poses, landmarks, labels)
    if J.shape[1] == 0:
        return Optimality(0.0, 0.0, 0.0)
    g = 2.0 * (J.T @ r)
    try:
        delta = en.solve_normal_sparse(J, r)
    except (np.linalg.LinAlgError, RuntimeError, ValueError, MemoryError):
        return Optimality(float(np.linalg.norm(g)), float("nan"), float("nan"))
    if not np.all(np.isfinite(delta)):
        return Optimality(float(np.linalg.norm(g)), float("nan"), float("nan"))
    model = r + J @ delta
    return Optimality(float(np.linalg.norm(g)), float(np.abs(delta).max(initial=0.0)),
                      max(float(r @ r - model @ model), 0.0))


def _irls_system(prob: en.Problem, W: en.Weights, poses, landmarks, labels):
    """``(r (M,), J (M, D') csr)`` of :func:`nls_problem` at the estimate in :func:`en.joint_residuals`'
    convention (``2 Jᵀr = ∇H``; the columns held fixed dropped): the engine's whitened rows scaled by
    ``√(w/2)``, w the Cauchy kernel's IRLS weight of each robust factor (1 elsewhere)."""
    problem = nls_problem(prob, W, landmarks.shape[0], labels)
    x = np.concatenate([poses.ravel(), landmarks.ravel()])
    J, r = nls.whitened_system(problem, x)
    scale = np.full(r.size, np.sqrt(0.5))
    off = 0
    for b in problem.blocks:
        F, k = b.n_factors, b.sqrt_info.shape[-1]
        if b.robust:
            rw = r[off:off + F * k].reshape(F, k)
            _, w = nls.robust_kernel(np.einsum("fk,fk->f", rw, rw), "cauchy", _kernel_width(W))
            scale[off:off + F * k] *= np.repeat(np.sqrt(w), k)
        off += F * k
    keep = np.setdiff1d(np.arange(problem.n_vars), problem.fixed_cols)
    return scale * r, (sp.diags(scale) @ J).tocsc()[:, keep].tocsr()


def _kernel_width(W: en.Weights) -> float:
    """The engine's Cauchy width on the ``√2``-whitened range-bearing residuals: ``√2 k`` (then its
    ``½ k'² log(1 + s'²/k'²)`` is :func:`en.range_bearing_energy`'s ``k² log(1 + s²/k²)``)."""
    return float(np.sqrt(2.0) * W.cauchy_k)


@dataclass(frozen=True)
class PolishOutcome:
    """What :func:`polish` did: LM iterations, the engine's status, energies before / after, and the largest
    move of a position or map point (m) and of a heading (rad) — the distance from the start to the optimum."""

    iterations: int
    status: str
    energy_before: float
    energy_after: float
    moved_m: float
    moved_rad: float

    def as_extra(self) -> dict:
        return {"iterations": self.iterations, "status": self.status, "energy_before": self.energy_before,
                "energy_after": self.energy_after, "distance_to_optimum_m": self.moved_m,
                "distance_to_optimum_rad": self.moved_rad}


def polish(prob: en.Problem, W: en.Weights, poses, landmarks, labels, *, max_iters: int,
           extrapolate: bool = False, workspace: nls.Workspace | None = None):
    """Minimise H over x_1..x_T and m with ``labels`` fixed, from ``poses (T+1, 3)``, ``landmarks (L, 2)``, in
    at most ``max_iters`` LM iterations. ``workspace``: the engine's pattern and factor analysis kept across
    the polishes of one solve.

    ``extrapolate``: Levenberg-Marquardt runs in chunks of :data:`POLISH_CHUNK` iterations. Where it converges
    linearly (a weakly held mode such as a slow rotation of the whole map about x_0, which Gauss-Newton moves a
    few per cent of the way per iteration) consecutive steps point the same way, so each chunk's displacement
    ``Δ = x_end − x_start`` is extrapolated: the lowest of ``H(x_end + β Δ)``, β ∈ {0} ∪
    :data:`EXTRAPOLATION_FACTORS`, starts the next chunk (headings wrapped at the end). Every accepted point
    lowers H. Without it: one LM run of ``max_iters``.

    Returns ``(poses, landmarks, PolishOutcome)``; the input is returned unchanged when the engine does not
    lower the energy (its accepted steps always do).
    """
    E0 = en.energy(prob, W, poses, landmarks, labels)
    problem = nls_problem(prob, W, landmarks.shape[0], labels)
    x, its, status = np.concatenate([poses.ravel(), landmarks.ravel()]), 0, Status.MAX_ITERATIONS
    chunk = POLISH_CHUNK if extrapolate else max_iters
    while its < max_iters and status != Status.CONVERGED:
        params = _nls_params(W, min(chunk, max_iters - its))
        res = nls.solve(problem, x, params, workspace=workspace)
        its, status = its + res.iterations, res.status
        x = _extrapolate(problem, params, x, res.x, res.cost) if extrapolate and res.iterations else res.x
        if not (extrapolate and res.iterations):
            break
    P = 3 * (prob.T + 1)
    new_poses = x[:P].reshape(-1, 3).copy()
    if extrapolate:
        new_poses[:, 2] = wrap_angle(new_poses[:, 2])
    new_lm = x[P:].reshape(-1, 2).copy()
    E1 = en.energy(prob, W, new_poses, new_lm, labels)
    status = "converged" if status == Status.CONVERGED else str(status.value)
    if not E1 <= E0:
        return poses, landmarks, PolishOutcome(its, f"{status} (not applied)", E0, E0, 0.0, 0.0)
    moved_m = max(float(np.abs(new_poses[:, :2] - poses[:, :2]).max(initial=0.0)),
                  float(np.abs(new_lm - landmarks).max(initial=0.0)))
    moved_rad = float(np.abs(wrap_angle(new_poses[:, 2] - poses[:, 2])).max(initial=0.0))
    return new_poses, new_lm, PolishOutcome(its, status, E0, E1, moved_m, moved_rad)


def _extrapolate(problem: nls.NlsProblem, params: nls.NlsParams, x_start, x_end, cost_end: float):
    """The lowest-cost point of ``x_end + β (x_end − x_start)``, β ∈ {0} ∪ :data:`EXTRAPOLATION_FACTORS`
    (the engine's cost of ``problem`` under ``params``' kernel, = H; the factors are tried in order until the
    cost stops falling)."""
    step = x_end - x_start
    best, best_cost = x_end, cost_end
    for beta in EXTRAPOLATION_FACTORS:
        trial = x_end + beta * step
        if params.robust == "none":
            r = nls.residual_vector(problem, trial)
            c = 0.5 * float(r @ r)
        else:
            c = nls.evaluate_cost(problem, trial, params)
        if not c < best_cost:
            break
        best, best_cost = trial, c
    return best


def _nls_params(W: en.Weights, max_iters: int) -> nls.NlsParams:
    """The engine's LM settings; with ``W.range_bearing`` the Cauchy kernel on the observation block."""
    if W.range_bearing:
        return nls.NlsParams(method="lm", max_iterations=max_iters, rel_cost_tol=POLISH_REL_COST_TOL,
                             robust="cauchy", huber_k=_kernel_width(W))
    return nls.NlsParams(method="lm", max_iterations=max_iters, rel_cost_tol=POLISH_REL_COST_TOL)


def prime_workspace(prob: en.Problem, W: en.Weights, L: int, candidate_labels, workspace: nls.Workspace) -> None:
    """Analyse, once, the pattern of H under every candidate matching ``candidate_labels (N,)`` (e.g. the
    sensor ids behind a null-matching gate) in ``workspace``: a polish whose matchings are any subset of them
    then reuses that pattern and CHOLMOD analysis, however the gate moves sightings in and out."""
    workspace.setup(nls_problem(prob, W, L, candidate_labels), _nls_params(W, 1))


def nls_problem(prob: en.Problem, W: en.Weights, L: int, labels) -> nls.NlsProblem:
    """H(x, m, c) for fixed ``labels (N,)`` as an :class:`~slamcli.solvers.nls.NlsProblem` over the state
    ``[x_0 … x_T (3(T+1)), m (2L)]``; x_0 and the map points no observation is matched to are held fixed."""
    P = 3 * (prob.T + 1)
    pc = np.arange(P, dtype=np.int64).reshape(-1, 3)
    lc = P + np.arange(2 * L, dtype=np.int64).reshape(-1, 2)
    pair = np.concatenate([pc[:-1], pc[1:]], axis=1)

    def poses_of(x):
        return x[:P].reshape(-1, 3)

    def ev_motion(x):
        p = poses_of(x)
        return (en.wrap_angle_last(prob.motion_prediction(p[:-1]) - p[1:]),
                np.concatenate(en.motion_jacobians(prob, p), axis=2))

    def ev_odometry(x):
        p = poses_of(x)
        return (en.wrap_angle_last(se2.between(p[:-1], p[1:]) - prob.odo_inc),
                np.concatenate(potentials.odometry_residual_jacobians(p[:-1], p[1:]), axis=2))

    ok = np.asarray(labels) >= 0
    st, lab, z = prob.step[ok], np.asarray(labels)[ok], prob.z[ok]

    def ev_obs(x):
        p = poses_of(x)[st]
        r = potentials.observation_residual(p, z, x[P:].reshape(-1, 2)[lab])
        return r, np.concatenate(potentials.observation_residual_jacobians(p, z), axis=2)

    def ev_range_bearing(x):
        p, m = poses_of(x)[st], x[P:].reshape(-1, 2)[lab]
        r = potentials.range_bearing_residual(p, z, m)
        return r, np.concatenate(potentials.range_bearing_residual_jacobians(p, m), axis=2)

    g = prob.gps_step
    J_gps = np.zeros((g.size, 2, 3))
    J_gps[:, 0, 0] = J_gps[:, 1, 1] = 1.0

    def ev_gps(x):
        return poses_of(x)[g, :2] - prob.gps_xy, J_gps

    blocks = []
    if W.use_motion and prob.T > 0:
        blocks.append(nls.FactorBlock("motion", pair, ev_motion, np.diag(np.sqrt(2.0 * np.array(W.R)))))
    if W.use_odometry and prob.T > 0:
        blocks.append(nls.FactorBlock("odometry", pair, ev_odometry, np.diag(np.sqrt(2.0 * np.array(W.S)))))
    obs_cols = np.concatenate([pc[st], lc[lab]], axis=1)
    if lab.size and W.range_bearing:  # robust: the engine's Cauchy of width √2 k (_nls_params)
        blocks.append(nls.FactorBlock("observation", obs_cols, ev_range_bearing,
                                      np.diag(np.sqrt(2.0) / np.array(W.obs_sigma)), robust=True))
    elif lab.size and any(W.Q):
        blocks.append(nls.FactorBlock("observation", obs_cols, ev_obs, np.diag(np.sqrt(2.0 * np.array(W.Q)))))
    if W.K and g.size:
        blocks.append(nls.FactorBlock("gps", pc[g], ev_gps, np.sqrt(2.0 * W.K) * np.eye(2)))
    seen = np.zeros(L, bool)
    seen[lab] = W.range_bearing or any(W.Q)
    fixed = np.concatenate([pc[0], lc[~seen].ravel()])
    return nls.NlsProblem(n_vars=P + 2 * L, blocks=blocks, angle_cols=pc[:, 2].copy(), fixed_cols=fixed,
                          chain=(prob.T + 1, 3))
