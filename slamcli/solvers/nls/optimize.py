"""Gauss-Newton, Levenberg-Marquardt (GTSAM's schedule) and Powell's dogleg over an :class:`NlsProblem`
(see :mod:`slamcli.solvers.nls` for the equations).
"""

from __future__ import annotations

import dataclasses
import time
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from slamcli.solvers.nls.kernels import whiten
from slamcli.solvers.nls.linear import (
    FACTOR_NAMES,
    Assembler,
    SuperLUFactor,
    Workspace,
    factorize_lower,
    make_linear_solver,
    problem_cost,
)
from slamcli.solvers.nls.problem import NlsParams, NlsProblem, NlsResult, retract
from slamcli.types import Status


# ----------------------------------------------------------------------------------------------------------
# optimiser
# ----------------------------------------------------------------------------------------------------------
def evaluate_cost(problem: NlsProblem, x: np.ndarray, params: NlsParams | None = None) -> float:
    """``½ Σ ρ(‖L r‖)`` at ``x`` (:func:`~slamcli.solvers.nls.linear.problem_cost`: no pattern is built)."""
    return problem_cost(problem, np.asarray(x, float), params or NlsParams())


def residual_vector(problem: NlsProblem, x: np.ndarray) -> np.ndarray:
    """Stacked whitened residuals ``(Σ F k,)`` at ``x`` (``cost = ½‖·‖²`` without robust kernel)."""
    return np.concatenate([whiten(b.sqrt_info, b.residuals(x)).ravel() for b in problem.blocks])


def jacobian_matrix(problem: NlsProblem, x: np.ndarray) -> sp.csr_matrix:
    """Whitened sparse Jacobian ``(Σ F k, D)`` at ``x``."""
    return whitened_system(problem, x)[0]


def whitened_system(problem: NlsProblem, x: np.ndarray) -> tuple[sp.csr_matrix, np.ndarray]:
    """:func:`jacobian_matrix` and :func:`residual_vector` at ``x`` from one evaluation of every block: the
    whitened sparse Jacobian ``(Σ F k, D)`` and the stacked whitened residuals ``(Σ F k,)`` that come with it
    (``evaluate``'s; a block's residual-only ``residual`` gives the same values)."""
    rows, cols, vals, res = [], [], [], []
    off = 0
    for b in problem.blocks:
        r, J = b.evaluate(x)
        F, k = r.shape
        n = b.cols.shape[1]
        Jw = np.matmul(b.sqrt_info, J)
        rows.append((off + np.arange(F * k).reshape(F, k, 1) + np.zeros((1, 1, n), np.int64)).ravel())
        cols.append(np.broadcast_to(np.asarray(b.cols)[:, None, :], (F, k, n)).ravel())
        vals.append(Jw.ravel())
        res.append(whiten(b.sqrt_info, r).ravel())
        off += F * k
    J = sp.csr_matrix(
        (np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))), shape=(off, problem.n_vars)
    )
    return J, np.concatenate(res)


def solve(
    problem: NlsProblem,
    x0: np.ndarray,
    params: NlsParams | None = None,
    callback: Callable[[int, np.ndarray, float], None] | None = None,
    workspace: Workspace | None = None,
) -> NlsResult:
    """Minimise the problem's cost from ``x0 (D,)``.

    ``callback(k, x, cost)`` is called with the start (k = 0) and after every accepted step (k = iteration).
    ``workspace``: the pattern and linear-solver analysis of an earlier solve to reuse (:class:`Workspace`).
    """
    params = params or NlsParams()
    asm, lin = (workspace.setup(problem, params) if workspace is not None
                else (Assembler(problem), None))
    x = np.array(x0, dtype=float, copy=True)
    if x.shape != (problem.n_vars,):
        raise ValueError(f"x0 has shape {x.shape}, expected ({problem.n_vars},)")
    stats: dict = {"fallbacks": 0, "damped_gn": 0, "solves": 0, "marquardt_trials": 0}
    lin = lin if lin is not None else make_linear_solver(asm, params)
    backup: list = []  # SuperLU, created on the first breakdown of the primary factorisation

    def lin_solve(data: np.ndarray, rhs: np.ndarray) -> np.ndarray | None:
        """``H(data) h = rhs`` for lower-triangle data; None if no factorisation gives a finite solution."""
        stats["solves"] += 1
        h = lin.solve(rhs) if factorize_lower(lin, asm, data) else None
        stats["primary_ok"] = h is not None  # lin holds a good factorisation of the last system
        if h is None and lin.name != "superlu":
            stats["fallbacks"] += 1
            if not backup:
                backup.append(SuperLUFactor(asm))
            h = backup[0].solve(rhs) if backup[0].factorize(asm.full(data)) else None
        return h

    cost, data, g = asm.linearize_lower(x, params)  # H's lower triangle: the optimiser's working data
    if not np.isfinite(cost):
        return NlsResult(
            x,
            cost,
            Status.FAILED,
            "non-finite initial cost",
            0,
            np.array([cost]),
            np.zeros(1),
            lambda: asm.matrix(asm.full(data)),
        )
    costs, times = [cost], [0.0]
    if callback is not None:
        callback(0, x, cost)
    st = _Damping(lam=params.lambda_init, nu=2.0, delta=params.delta_init)
    status = Status.MAX_ITERATIONS
    message = f"stopped after {params.max_iterations} iterations (max_iterations)"
    it = 0
    decrease = np.inf  # of the last accepted step
    t_last = time.perf_counter()

    def small(h: np.ndarray) -> bool:
        return bool(np.linalg.norm(h) <= params.step_tol * (np.linalg.norm(x) + params.step_tol))

    while it < params.max_iterations:
        if cost <= params.abs_cost_tol:
            status, message = Status.CONVERGED, "cost below abs_cost_tol"
            break
        diag = data[asm.lo_diag_pos]
        Dvec = np.clip(diag, 1e-6, 1e32) if params.damping == "marquardt" else np.ones(asm.D)
        stop = None  # (status, message) that ends the optimisation inside this iteration
        h_held = _held_factor_step(lin, stats, params, st, g, cost, decrease) if params.method == "lm" else None
        if _converged_by_last_factor(params, h_held, g, cost, decrease):
            status, message = Status.CONVERGED, "predicted cost decrease below pred_cost_tol (last factorisation)"
            break
        frozen = _frozen_lm_step(problem, asm, params, st, h_held, x, g, cost, decrease)
        if frozen is not None:
            x_new, new_cost = frozen
        elif params.method == "lm":
            stop, x_new, new_cost = _lm_iteration(problem, asm, params, lin_solve, x, cost, data, g, Dvec, st, stats,
                                                  small)
        elif params.method == "dogleg":
            stop, x_new, new_cost, st.delta = _dogleg_iteration(
                problem, asm, params, lin_solve, x, cost, data, g, st.delta, small
            )
        else:
            stop, x_new, new_cost = _gn_iteration(problem, asm, params, lin_solve, x, cost, data, g, Dvec, stats,
                                                  small)
        if stop is not None:
            status, message = stop
            break
        it += 1
        decrease = cost - new_cost
        x = x_new
        # LM linearised its accepted trial already (_Damping.eager); the other methods evaluated its cost only
        cost, data, g = st.trial_lin if st.trial_lin is not None else asm.linearize_lower(x, params)
        st.trial_lin = None
        now = time.perf_counter()
        costs.append(cost)
        times.append(now - t_last)
        t_last = now
        if callback is not None:
            callback(it, x, cost)
        if decrease <= params.rel_cost_tol * max(cost + decrease, 0.0):
            status, message = Status.CONVERGED, "relative cost decrease below rel_cost_tol"
            break
    notes = _notes(stats, lin.name)
    return NlsResult(
        x=x,
        cost=cost,
        status=status,
        message=message,
        iterations=it,
        cost_trace=np.asarray(costs),
        time_trace=np.asarray(times),
        information_fn=_information_fn(problem, asm, params, x, data),
        linear_solves=int(stats["solves"]),
        notes=tuple(notes),
        linear_solver=lin.name,
        workspace=(asm, lin),
        information_lower=data,
        information_chart="body" if params.pose_chart == "body" and problem.se2_poses > 0 else "world",
    )


def _information_fn(problem, asm, params, x, data):
    """``NlsResult.information_fn``: ``H`` at ``x`` (lower data ``data``) in world coordinates, for the marginals
    — rotated out of the body chart, or relinearised in the world chart when the rotation does not apply."""
    def information() -> sp.csc_matrix:
        full = asm.full(data)
        if params.pose_chart == "body" and problem.se2_poses > 0:
            world = asm.body_to_world(full, x)
            full = world if world is not None else asm.linearize(x, dataclasses.replace(params, pose_chart="world"))[1]
        return asm.matrix(full)
    return information


#: LM's predicted-decrease stop without a new factorisation (:func:`_converged_by_last_factor`): only after an
#: accepted step that lowered the cost by at most this fraction (the asymptotic regime, where H hardly changes
#: between iterates), and with this margin on ``pred_cost_tol``
LAST_FACTOR_REGIME = 1e-6
LAST_FACTOR_MARGIN = 0.5


def _held_factor_step(lin, stats, params, st, g, cost, decrease) -> np.ndarray | None:
    """``h = −H_old⁻¹ g``: the Gauss-Newton step at the new iterate with the factorisation of the previous
    iterate's (damped) ``H`` that ``lin`` still holds — one solve shared by :func:`_converged_by_last_factor`
    and :func:`_frozen_lm_step`; None when neither may use it (the primary factorisation failed last time, λ
    grew, or the last decrease is above both their regimes) or the solve fails."""
    regime = max(LAST_FACTOR_REGIME if params.pred_cost_tol > 0.0 else 0.0, params.frozen_step_rel)
    if not (regime > 0.0 and stats.get("primary_ok") and st.lam <= params.lambda_init
            and 0.0 <= decrease <= regime * cost):
        return None
    return lin.solve(-g)


def _converged_by_last_factor(params, h_held, g, cost, decrease) -> bool:
    """Whether the Gauss-Newton decrement ``½ gᵀH⁻¹g`` at the new iterate, from the held factorisation's step
    ``h_held`` (:func:`_held_factor_step`), is below ``LAST_FACTOR_MARGIN · pred_cost_tol · cost`` — the test of
    ``NlsParams.pred_cost_tol`` for one solve instead of a factorisation. Used only once the last step lowered
    the cost by at most ``LAST_FACTOR_REGIME`` (relative), so ``H`` moved by a relative amount of that order and
    the two decrements agree far inside the margin; otherwise the exact test runs in :func:`_lm_iteration`."""
    if h_held is None or not (params.pred_cost_tol > 0.0 and decrease <= LAST_FACTOR_REGIME * cost):
        return False
    return 0.0 <= -0.5 * float(g @ h_held) <= LAST_FACTOR_MARGIN * params.pred_cost_tol * cost


#: a simplified-Newton LM step (NlsParams.frozen_step_rel) is kept when it achieves at least this fraction of its
#: model decrease (near the optimum the ratio is 1 − O(rate); a poor ratio says H has moved: factorise anew)
FROZEN_MIN_FIDELITY = 0.5


def _frozen_lm_step(problem, asm, params, st, h, x, g, cost, decrease):
    """``(x_new, new_cost)`` of NlsParams.frozen_step_rel's simplified-Newton step ``h = −H_old⁻¹ g``
    (:func:`_held_factor_step`), when the last step lowered the cost by at most ``frozen_step_rel · cost`` and
    the trial is kept (its linearisation left in ``st.trial_lin``, as an eager LM trial's); else None."""
    if h is None or not (params.frozen_step_rel > 0.0 and decrease <= params.frozen_step_rel * cost):
        return None
    model = -0.5 * float(g @ h)  # the decrease of the model with H_old
    if not model > 0.0:
        return None
    x_new = retract(problem, params, x, h)
    trial = asm.linearize_lower(x_new, params)
    if not (np.isfinite(trial[0]) and cost - trial[0] >= FROZEN_MIN_FIDELITY * model):
        return None
    st.trial_lin = trial
    return x_new, trial[0]


@dataclass
class _Damping:
    """LM's damping λ and Nielsen's growth factor ν; dogleg's trust radius Δ (carried across iterations)."""

    lam: float
    nu: float
    delta: float
    #: LM: linearise a trial point at once (its cost comes with it) while the last trial was accepted — near
    #: the optimum nearly every trial is, and the accepted point's linearisation is the next iteration's, so its
    #: residuals are evaluated once instead of twice; after a rejection trials get a cost evaluation only
    eager: bool = True
    trial_lin: tuple | None = None  # (cost, H lower data, g) at the accepted trial, when eager


def _solve_damped(lin_solve, asm, data: np.ndarray, damping: np.ndarray, g: np.ndarray) -> np.ndarray | None:
    """``(H + diag(damping)) h = −g`` for ``H``'s lower data; the damped copy lives only for the solve (it is not
    held while the trial point is linearised)."""
    damped = data.copy()
    damped[asm.lo_diag_pos] += damping
    return lin_solve(damped, -g)


def _lm_iteration(problem, asm, params, lin_solve, x, cost, data, g, Dvec, st: _Damping, stats, small):
    """One LM iteration: raise λ until a trial step is accepted (GTSAM's inner loop). Returns ``(stop,
    x_new, new_cost)`` with ``stop`` None or the ``(status, message)`` that ends the optimisation."""
    diag = data[asm.lo_diag_pos]
    stop = x_new = new_cost = None
    while True:
        h = _solve_damped(lin_solve, asm, data, st.lam * Dvec, g)
        if h is None and params.damping == "levenberg":
            # λI cannot regularise an H that is numerically indefinite because of entries many orders
            # above the rest (a landmark on top of a pose): this trial uses Marquardt's D = diag(H)
            Dvec = np.clip(diag, 1e-6, 1e32)
            h = _solve_damped(lin_solve, asm, data, st.lam * Dvec, g)
            stats["marquardt_trials"] += 1
        ok = False
        if h is not None:
            if small(h):
                stop = (Status.CONVERGED, "step norm below step_tol")
                break
            # predicted decrease of the undamped model: −gᵀh − ½hᵀHh = ½hᵀ(λDh − g)
            pred = 0.5 * float(h @ (st.lam * Dvec * h - g))
            if 0.0 <= pred <= params.pred_cost_tol * cost and st.lam <= params.lambda_init:
                stop = (Status.CONVERGED, "predicted cost decrease below pred_cost_tol")
                break
            if pred >= 0.0:
                x_new = retract(problem, params, x, h)
                trial = asm.linearize_lower(x_new, params) if st.eager else None
                new_cost = trial[0] if trial is not None else asm.cost(x_new, params)
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
        st.eager = ok
        if ok:
            st.trial_lin = trial
            if params.lambda_update == "fixed":
                st.lam /= params.lambda_factor
            else:
                st.lam *= max(1.0 / 3.0, 1.0 - (2.0 * rho - 1.0) ** 3)
                st.nu = 2.0
            st.lam = max(st.lam, params.lambda_min)
            break
        if params.lambda_update == "fixed":
            st.lam *= params.lambda_factor
        else:
            st.lam *= st.nu
            st.nu *= 2.0
        if st.lam >= params.lambda_max:  # GTSAM: give up once the raised λ reaches lambdaUpperBound
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
    return stop, x_new, new_cost


def _gn_iteration(problem, asm, params, lin_solve, x, cost, data, g, Dvec, stats, small):
    """One Gauss-Newton step with its safeguards (damped when H is not numerically positive definite,
    halved when the cost rises). Returns ``(stop, x_new, new_cost)`` as :func:`_lm_iteration`."""
    diag = data[asm.lo_diag_pos]
    stop = x_new = new_cost = None
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
            h = _solve_damped(lin_solve, asm, data, lam_gn * Dvec, g)
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
    return stop, x_new, new_cost


def _notes(stats: dict, lin_name: str) -> list[str]:
    """The numerical fallbacks an optimisation needed, one sentence each (``NlsResult.notes``)."""
    notes = []
    if stats["fallbacks"]:
        notes.append(
            f"{FACTOR_NAMES[lin_name]} failed {stats['fallbacks']}× (H not numerically positive definite); "
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
    return notes


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
    H = asm.matrix(asm.full(data))
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
