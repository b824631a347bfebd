"""The paper-000 (ICM-SLAM) Gibbs energy as a least-squares problem, and its optimum with the
correspondences fixed (:func:`optimize_paper_energy`, ICM's reference energy).
"""

from __future__ import annotations

from typing import Literal

import numpy as np

from slamcli.models import potentials
from slamcli.solvers import nls
from slamcli.solvers.graph.build import GraphProblem, pack_state
from slamcli.solvers.graph.factors import sqrt_of_weight
from slamcli.types import SlamInputs


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
    LR, LS, LQ = sqrt_of_weight(R, "R"), sqrt_of_weight(S, "S"), sqrt_of_weight(Q, "Q")
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
