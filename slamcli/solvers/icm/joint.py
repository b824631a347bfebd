"""Joint Gauss-Newton refinement of ICM-SLAM (``joint_iters > 1``, beyond the paper).

Gauss-Seidel sweeps move a pose only as far as its two neighbours let it: on a 12,000-pose chain thirty sweeps
move no pose more than a few centimetres, so a loop closure found by the matchings never reaches the middle of
the chain. A joint Gauss-Newton step over all poses and the map (fixed matchings) moves the whole chain at once.
:func:`joint_refine` repeats :func:`slamcli.solvers.icm.energy.joint_gn_step` (its normal equations are
factorised by the project's sparse machinery, :func:`slamcli.solvers.nls.factorize_information`) until

* the largest step is below ``step_tol`` (m for positions and map points, rad for headings), or
* the relative decrease of the energy is below ``rtol``, or
* no step length lowers the energy (the step is rejected), or ``max_iters`` steps ran.

Every accepted step lowers the same energy the sweeps minimise, so ICM's monotone descent is kept.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from slamcli.solvers.icm import energy as en

#: relative energy decrease below which the refinement stops
RTOL = 1e-9


@dataclass(frozen=True)
class JointOutcome:
    """What one refinement did: steps accepted, why it stopped, the largest step of the last iteration."""

    steps: int
    reason: str  # "step" | "energy" | "rejected" | "max_iters" | "error: ..."
    last_step: float
    energy: float


def joint_refine(prob: en.Problem, W: en.Weights, poses, landmarks, labels, *, max_iters: int, step_tol: float):
    """Joint Gauss-Newton steps with fixed matchings until the step or the decrease is negligible.

    Parameters
    ----------
    poses : ndarray (T+1, 3)     landmarks : ndarray (L, 2)     labels : ndarray (N,) int64
    max_iters : int              at most this many steps.
    step_tol : float             stop when ``max |δ|`` over poses and map points falls below it.

    Returns
    -------
    poses (T+1, 3), landmarks (L, 2), :class:`JointOutcome`.
    """
    f = en.energy(prob, W, poses, landmarks, labels)
    last, reason, steps = float("inf"), "max_iters", 0
    for _ in range(max_iters):
        p_new, m_new, f_new, ok, err = en.joint_gn_step(prob, W, poses, landmarks, labels)
        if err:
            reason = f"error: {err}"
            break
        if not ok:
            reason = "rejected"
            break
        dp = p_new - poses
        dp[:, 2] = (dp[:, 2] + np.pi) % (2 * np.pi) - np.pi
        last = float(max(np.abs(dp).max(initial=0.0), np.abs(m_new - landmarks).max(initial=0.0)))
        steps += 1
        why = stop_reason(f, f_new, last, step_tol)
        poses, landmarks, f = p_new, m_new, f_new
        if why:
            reason = why
            break
    return poses, landmarks, JointOutcome(steps, reason, last, f)


def stop_reason(f: float, f_new: float, last_step: float, step_tol: float) -> str | None:
    """Why a refinement stops after an accepted step from energy ``f`` to ``f_new`` whose largest component was
    ``last_step``: ``"step"`` (below ``step_tol``), ``"energy"`` (relative decrease ≤ :data:`RTOL`) or None."""
    if last_step < step_tol:
        return "step"
    return "energy" if f - f_new <= RTOL * max(abs(f), 1e-300) else None
