"""The ``gtsam``-model factor graph of a dataset (:func:`build_gtsam_problem`) and its Laplace marginals.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from slamcli.errors import SolverError
from slamcli.models import motion
from slamcli.solvers import nls
from slamcli.solvers.graph.factors import (
    bearing_range_error,
    bearing_range_jacobian,
    bearing_range_residual,
    between_error,
    between_error_body,
    between_residual,
    group_returns,
    landmark_offset_error,
    prior_error,
    prior_residual,
    robot_range_bearing_error,
    sqrt_info_batch,
    sqrt_info_from_cov,
)
from slamcli.solvers.graph.params import GraphParams
from slamcli.types import SlamInputs


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
    P = 3 * n_poses
    lay = _Layout(
        pc=np.arange(P, dtype=np.int64).reshape(-1, 3),
        lc=P + np.arange(2 * L, dtype=np.int64).reshape(-1, 2),
        P=P,
        L=L,
        bias_col=P + 2 * L if params.estimate_range_bias else None,
    )
    cons = inputs.constraints if params.edge_info else None
    blocks = _pose_blocks(inputs, params, lay, cons)
    obs_blocks, n_rows = _observation_blocks(inputs, np.asarray(assoc, np.int64), params, lay, cons)
    blocks += obs_blocks + _team_and_gps_blocks(inputs, params, lay)
    n_vars = P + 2 * L + (lay.bias_col is not None)
    if lay.bias_col is not None and not n_rows:
        raise SolverError("graph: estimate_range_bias needs associated observations")
    problem = nls.NlsProblem(
        n_vars=n_vars, blocks=blocks, angle_cols=lay.pc[:, 2].copy(), chain=(n_poses, 3), se2_poses=n_poses
    )
    x0 = pack_state(init_poses, init_landmarks)
    if lay.bias_col is not None:
        x0 = np.concatenate([x0, [0.0]])
    return GraphProblem(problem, x0, n_poses, L, lay.bias_col)


@dataclass(frozen=True)
class _Layout:
    """State layout of :func:`build_gtsam_problem`: pose columns ``pc (T+1, 3)``, landmark columns
    ``lc (L, 2)``, ``P = 3 (T+1)``, the range-bias column (or None)."""

    pc: np.ndarray
    lc: np.ndarray
    P: int
    L: int
    bias_col: int | None

    def poses_of(self, x):
        return x[: self.P].reshape(-1, 3)

    def lms_of(self, x):
        return x[self.P : self.P + 2 * self.L].reshape(-1, 2)


def _pose_blocks(inputs: SlamInputs, params: GraphParams, lay: _Layout, cons) -> list:
    """Prior(s), odometry, loop closures and (optional) motion factors."""
    pc, poses_of = lay.pc, lay.poses_of
    n_poses = inputs.n_poses
    blocks: list[nls.FactorBlock] = []
    team = inputs.robots
    # one prior per robot (its known start pose); a single robot: x_0. The odometry chain stays in one robot.
    first = np.zeros(1, np.int64) if team is None else team.first_pose[:-1]
    chain = np.arange(n_poses - 1, dtype=np.int64) if team is None else team.chain_pairs
    prior = np.asarray(inputs.x0, float)[None, :] if team is None else np.asarray(team.x0_xyt, float)

    def ev_prior(x):
        e, J = prior_error(poses_of(x)[first], prior)
        return e, J

    def res_prior(x):
        return prior_residual(poses_of(x)[first], prior)

    prior_b = np.broadcast_to(prior, (first.size, 3))
    zero = np.zeros((first.size, 3))

    def ev_prior_body(x):  # the prior is the between error of (prior, x) with an identity measurement
        e, J = between_error_body(prior_b, poses_of(x)[first], zero)
        return e, J[..., 3:]

    blocks.append(
        nls.FactorBlock("prior", pc[first], ev_prior, sqrt_info_from_cov(np.diag(np.square(params.prior_std))),
                        residual=res_prior, evaluate_body=ev_prior_body)
    )

    def between_block(name, i, j, meas, sqrt_info, robust=False):
        """Between factors of poses ``i (F,)`` → ``j (F,)`` with measurements ``meas (F, 3)``."""
        cs = (np.cos(meas[:, 2]), np.sin(meas[:, 2]))  # the measurements' rotations, constants of the block

        def ev(x):
            p = poses_of(x)
            e, Ji, Jj = between_error(p[i], p[j], meas, cs)
            return e, np.concatenate([Ji, Jj], axis=2)

        def ev_body(x):
            p = poses_of(x)
            return between_error_body(p[i], p[j], meas, cs)

        def res(x):
            p = poses_of(x)
            return between_residual(p[i], p[j], meas, cs)

        return nls.FactorBlock(name, np.concatenate([pc[i], pc[j]], axis=1), ev, sqrt_info, robust=robust,
                               residual=res, evaluate_body=ev_body)

    if n_poses > 1 and params.use_odometry:
        d = motion.odometry_increments(inputs.odometry_xyt)
        if cons is not None and cons.odometry_info is not None:
            odo_L = sqrt_info_batch(cons.odometry_info)[chain]
        else:
            odo_L = sqrt_info_from_cov(np.diag(np.square(inputs.noise.odometry_std)))
        blocks.append(between_block("odometry", chain, chain + 1, d[chain], odo_L))
    if inputs.constraints is not None and inputs.constraints.n_between:
        # pose-pose constraints between any two poses (loop closures): always with their own information
        bc = inputs.constraints
        bij = np.asarray(bc.between_ij, np.int64).reshape(-1, 2)
        bmeas = np.asarray(bc.between_xyt, float).reshape(-1, 3)
        blocks.append(between_block("loop_closure", bij[:, 0], bij[:, 1], bmeas, sqrt_info_batch(bc.between_info),
                                    robust=True))
    if n_poses > 1 and params.use_controls:
        u = np.asarray(inputs.controls, float)
        dt = inputs.dt
        d = np.stack([u[:, 0] * dt, np.zeros(len(u)), u[:, 1] * dt], -1)
        sv, sw = inputs.noise.motion_std
        cov = np.diag([(sv * dt) ** 2, params.motion_lateral_std**2, (sw * dt) ** 2])
        blocks.append(between_block("motion", chain, chain + 1, d[chain], sqrt_info_from_cov(cov)))
    return blocks


def _observation_blocks(inputs: SlamInputs, assoc: np.ndarray, params: GraphParams, lay: _Layout, cons):
    """Landmark sightings labelled by ``assoc``: per-row information (lossless imports) or the NoiseSpec
    bearing-range model; returns ``(blocks, number of associated rows)``."""
    pc, lc, poses_of, lms_of, bias_col, L = lay.pc, lay.lc, lay.poses_of, lay.lms_of, lay.bias_col, lay.L
    blocks: list[nls.FactorBlock] = []
    obs = inputs.observations
    rows = np.flatnonzero(assoc >= 0)
    obs_info = cons.observation_info if cons is not None else None
    if rows.size and obs_info is not None:
        # lossless: one factor per row with the row's own information, in the file's model
        steps = np.asarray(obs.step, np.int64)[rows]
        labels = assoc[rows]
        z = obs.z[rows]
        L_rows = sqrt_info_batch(np.asarray(obs_info, float)[rows])
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
            e, J = bearing_range_jacobian(poses_of(x)[steps], lms_of(x)[labels], z)
            if bias_col is None:
                return e, J
            e[:, 0] -= x[bias_col]  # r̂ = ‖m − p‖ − b
            Jb = np.zeros((e.shape[0], 2, 1))
            Jb[:, 0, 0] = -1.0
            return e, np.concatenate([J, Jb], axis=2)

        def res_obs(x):
            e = bearing_range_residual(poses_of(x)[steps], lms_of(x)[labels], z)
            if bias_col is not None:
                e[:, 0] -= x[bias_col]
            return e

        cols = np.concatenate([pc[steps], lc[labels]], axis=1)
        if bias_col is not None:
            cols = np.concatenate([cols, np.full((cols.shape[0], 1), bias_col, np.int64)], axis=1)
        blocks.append(
            nls.FactorBlock(
                "bearing_range", cols, ev_obs, sqrt_info_from_cov(inputs.noise.obs_cov), robust=True,
                residual=res_obs,
            )
        )
    return blocks, int(rows.size)


def _team_and_gps_blocks(inputs: SlamInputs, params: GraphParams, lay: _Layout) -> list:
    """Inter-robot range-bearing factors (multi-robot datasets) and GPS position factors."""
    pc, poses_of = lay.pc, lay.poses_of
    team = inputs.robots
    blocks: list[nls.FactorBlock] = []
    if team is not None and len(team.range_m):
        ri, rj, rz = np.asarray(team.observer_pose), np.asarray(team.observed_pose), team.z

        def ev_robot(x):
            p = poses_of(x)
            e, Ji, Jj = robot_range_bearing_error(p[ri], p[rj], rz)
            return e, np.concatenate([Ji, Jj], axis=2)

        blocks.append(nls.FactorBlock("robot_range_bearing", np.concatenate([pc[ri], pc[rj]], axis=1), ev_robot,
                                      sqrt_info_from_cov(inputs.noise.obs_cov), robust=True))

    if params.use_gps and np.asarray(inputs.gps_step).size:
        gsteps = np.asarray(inputs.gps_step, np.int64)
        gxy = np.asarray(inputs.gps_xy, float)

        def ev_gps(x):
            e = poses_of(x)[gsteps, :2] - gxy
            J = np.zeros((gsteps.size, 2, 3))
            J[:, 0, 0] = J[:, 1, 1] = 1.0
            return e, J

        blocks.append(nls.FactorBlock("gps", pc[gsteps], ev_gps, np.eye(2) / inputs.gps_std, robust=True))
    return blocks


def laplace_marginals(gp: GraphProblem, information) -> tuple[np.ndarray, np.ndarray]:
    """World-frame marginal covariances ``pose_cov (T+1, 3, 3)`` and ``landmark_cov (L, 2, 2)`` at the optimum.

    The blocks of ``H⁻¹`` for the pose and landmark columns of ``gp``, by the one marginals path
    :func:`slamcli.solvers.nls.marginals.block_marginals` (selected inverse with CHOLMOD; else the chain +
    border elimination when every pose-pose factor links consecutive poses or is unary; else the sparse
    column solve), whose policy on an ``H`` that is not numerically positive definite is to refuse.
    ``information`` may be the LM's ``NlsResult`` itself: then its lower triangle at the estimate is factored
    directly and the pose blocks rotated out of the body chart (:func:`slamcli.solvers.nls.result_marginals`),
    the full ``H`` is not built.

    Raises
    ------
    numpy.linalg.LinAlgError
        ``H`` is not numerically positive definite: no factorisation gives valid marginals. The message
        names the pose or landmark where the factorisation broke down.
    """
    sets, kw = (gp.pose_cols(), gp.landmark_cols()), dict(names=("pose", "landmark"), chain=gp.n_poses,
                                                         locate=lambda c: located(gp, c))
    if isinstance(information, nls.NlsResult):
        pose_cov, lm_cov = nls.result_marginals(information, sets, **kw)
    else:
        pose_cov, lm_cov = nls.block_marginals(information, sets, **kw)
    return pose_cov, lm_cov


def located(gp: GraphProblem, column: int) -> str:
    """The variable (``pose t`` / ``landmark j`` / ``range bias``) that owns state column ``column``."""
    P = 3 * gp.n_poses
    if column < P:
        return f"pose {column // 3}"
    if column < P + 2 * gp.n_landmarks:
        return f"landmark {(column - P) // 2}"
    return "range bias"


def landmark_joint_covariance(gp: GraphProblem, information) -> np.ndarray:
    """Joint marginal covariance ``(2L, 2L)`` of all landmarks (Laplace, chain + border elimination).

    Falls back to the block-diagonal of the marginals (cross-covariances 0,
    :func:`slamcli.solvers.nls.marginals.block_marginals`) when the pose block is not block tridiagonal.

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
    (blocks,) = nls.block_marginals(information, (gp.landmark_cols(),), names=("landmark",))
    out = np.zeros((2 * L, 2 * L))
    for j in range(L):
        out[2 * j : 2 * j + 2, 2 * j : 2 * j + 2] = blocks[j]
    return out
