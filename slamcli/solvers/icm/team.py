"""Multi-robot ICM-SLAM: the same Gibbs energy, one more potential, robot by robot.

For a :class:`slamcli.types.RobotTeam` the energy is the sum of every robot's own chain (motion R, odometry S),
the landmark observations of all robots against ONE shared map (Q), and one potential per inter-robot reading
of robot j by robot i at step t::

    H = Σ_r H_chain(x^r) + Σ_{t,i} ‖h⁻¹(x_t, z_{t,i}) − m_{c_{t,i}}‖²_Q + Σ_k ‖h⁻¹(x^i_t, z_k) − p(x^j_t)‖²_Q

(the reading term is the observation potential of paper 000 with the observed robot's position in place of a
map point). ICM visits the nodes as for one robot: the poses of robot 1 (x_1..x_T, its x_0 is known), then
robot 2, …, then the map (eq. 17 over the observations of all robots). A pose's conditional now also contains
the reading terms that involve it, both kinds being terms of the observation form ``p + R(θ)v − m`` that the
sufficient statistics (:func:`slamcli.solvers.icm.energy.step_stats`) already describe:

* robot r observed robot j:  ``v = r[cos b, sin b]``, ``m = p(x^j_t)`` (the other robot's current position);
* robot r was observed by i: ``v = 0``, ``m = h⁻¹(x^i_t, z)`` (``‖m − p‖²_Q = ‖p + 0 − m‖²_Q``).

Each pose update minimises its conditional and eq. (17) is the exact conditional mode of the map, so the
energy never rises from one sweep to the next. Correspondences are the sensor-reported ids (MRCLAM's
barcodes); the nearest-point correspondence step of one robot would need the per-robot initial maps merged
first, which is not implemented (refused in one line).
"""

from __future__ import annotations

import dataclasses
import time
from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from slamcli.errors import ConfigError
from slamcli.models.observation import inverse_range_bearing
from slamcli.models.potentials import observation_residual_jacobians
from slamcli.solvers.frontend import compact_labels
from slamcli.solvers.icm import energy as en
from slamcli.solvers.icm import gate
from slamcli.solvers.icm import map_step as mp
from slamcli.solvers.icm.common import online_init, reported_labels, stop_decision
from slamcli.solvers.nls import robust_kernel
from slamcli.types import IterationTrace, SlamInputs, SolverResult, Status, solo_inputs


def _add_stats(out: np.ndarray, step: np.ndarray, v: np.ndarray, m: np.ndarray, w=None) -> None:
    """Add rows ``e = p + R(θ)v − m`` at local pose ``step`` to the statistics ``out (14, K)`` (same rows as
    :func:`slamcli.solvers.icm.energy.step_stats`), each scaled by its weight ``w`` when given."""
    if not step.size:
        return
    K = out.shape[1]
    vx, vy, mx, my = v[:, 0], v[:, 1], m[:, 0], m[:, 1]
    cols = [np.ones_like(vx), vx, vy, mx, my, vx * vx, vx * vy, vy * vy, vx * mx, vx * my, vy * mx, vy * my,
            mx * mx, my * my]
    for k, c in enumerate(cols):
        out[k] += np.bincount(step, weights=c if w is None else c * w, minlength=K)[:K]


def kernel_cost(s2: np.ndarray, k: float | None) -> tuple[np.ndarray, np.ndarray]:
    """Per-term energy and IRLS weight of squared weighted residuals ``s2 = ‖e‖²_Q``: ``(s2, 1)`` without a
    kernel (``k`` None), else ``graph``'s Cauchy kernel of scale ``k`` in ICM's units (H = ‖r‖², twice
    ``graph``'s ½‖r‖² cost): ``(k² log(1 + s2/k²), k² / (k² + s2))``. Minimising ``Σ w_i s2_i`` with the weights
    held, then taking the weights at the new residuals, never raises ``Σ cost`` (the half-quadratic form of
    the kernel), so ICM's sweeps stay monotone."""
    if k is None:
        return s2, np.ones_like(s2)
    rho, w = robust_kernel(s2, "cauchy", k)
    return 2.0 * rho, w


@dataclass(frozen=True)
class TermWeights:
    """How the observation and reading terms enter a team energy beyond ``‖e‖²_Q``: the Cauchy scale ``k``
    (None = quadratic) and per-term factors ``obs (N,)``, ``rd (K,)`` of Q (None = 1; ``team_range_weights``:
    ``q(r_i) / q(r̃)``, :func:`range_scales`). A term costs ``kernel_cost(f_i ‖e_i‖²_Q, k)``."""

    k: float | None = None
    obs: np.ndarray | None = None
    rd: np.ndarray | None = None

    @property
    def plain(self) -> bool:
        return self.k is None and self.obs is None and self.rd is None

    def obs_s2(self, team_prob, poses, landmarks, labels, Q) -> np.ndarray:
        """``f_i ‖h⁻¹(x_t, z_i) − m_{c_i}‖²_Q (N,)`` of every observation (0 where ``labels < 0``)."""
        ok = labels >= 0
        d = team_prob.landmark_points(poses)[ok] - landmarks[labels[ok]]
        out = np.zeros(len(labels))
        out[ok] = Q[0] * d[:, 0] ** 2 + Q[1] * d[:, 1] ** 2
        return out if self.obs is None else out * self.obs

    def rd_s2(self, inputs, poses, Q) -> np.ndarray:
        """``f_k ‖h⁻¹(x_i, z_k) − p(x_j)‖²_Q (K,)`` of every inter-robot reading."""
        d = reading_points(inputs, poses) - poses[np.asarray(inputs.robots.observed_pose), :2]
        out = Q[0] * d[:, 0] ** 2 + Q[1] * d[:, 1] ** 2
        return out if self.rd is None else out * self.rd

    def weights(self, s2: np.ndarray, which: str) -> np.ndarray:
        """Weight of each term's ``‖e‖²_Q`` in the quadratic ICM minimises next (factor × IRLS weight)."""
        f = self.obs if which == "obs" else self.rd
        w = kernel_cost(s2, self.k)[1]
        return w if f is None else w * f


def range_scales(r: np.ndarray, r_med: float, range_std: float, bearing_std: float) -> np.ndarray:
    """``q(r) / q(r̃)`` with ``q(r) = 2 / (σ_r² + r² σ_b²)``: the isotropic information of a sighting at range r
    relative to the median range's, which :func:`slamcli.solvers.icm.energy.information_weights` uses for all."""
    def var(x):
        return float(range_std) ** 2 + (np.asarray(x, float) * float(bearing_std)) ** 2

    return var(r_med) / var(r)


def reading_stats(inputs: SlamInputs, poses_xyt: np.ndarray, robot: int, active=None, w=None) -> np.ndarray:
    """Sufficient statistics ``(14, T_r+1)`` of the inter-robot reading terms that involve robot ``robot``'s
    poses, the other robots' poses held at ``poses_xyt`` (stacked); ``w (K,)``: per-reading weights."""
    team = inputs.robots
    fp = team.first_pose
    a, b = int(fp[robot]), int(fp[robot + 1])
    out = np.zeros((14, b - a))
    oi, oj, z = np.asarray(team.observer_pose), np.asarray(team.observed_pose), team.z
    act = np.ones(len(oi), bool) if active is None else active
    mine = (oi >= a) & (oi < b) & act
    v = np.stack([z[mine, 0] * np.cos(z[mine, 1]), z[mine, 0] * np.sin(z[mine, 1])], -1)
    _add_stats(out, oi[mine] - a, v, poses_xyt[oj[mine], :2], None if w is None else w[mine])
    seen = (oj >= a) & (oj < b) & act
    y = inverse_range_bearing(poses_xyt[oi[seen]], z[seen]).reshape(-1, 2)
    _add_stats(out, oj[seen] - a, np.zeros_like(y), y, None if w is None else w[seen])
    return out


def reading_points(inputs: SlamInputs, poses_xyt: np.ndarray) -> np.ndarray:
    """``h⁻¹(x_i, z_k) (K, 2)`` of every inter-robot reading."""
    team = inputs.robots
    return inverse_range_bearing(poses_xyt[team.observer_pose], team.z).reshape(-1, 2)


def reading_energy(inputs: SlamInputs, W: en.Weights, poses_xyt: np.ndarray, active=None) -> float:
    """``Σ_k ‖h⁻¹(x_i, z_k) − p(x_j)‖²_Q`` over the inter-robot readings (those in ``active``, default all)."""
    team = inputs.robots
    if team is None or not len(team.range_m):
        return 0.0
    pts = reading_points(inputs, poses_xyt)
    lab = np.arange(len(pts)) if active is None else np.where(active, np.arange(len(pts)), -1)
    return en.observation_energy(pts, lab, poses_xyt[team.observed_pose, :2], W.Q)


def team_energy_terms(inputs, W, probs, team_prob, poses, landmarks, labels, active=None,
                      tw: TermWeights | None = None) -> dict[str, float]:
    """``chain`` (motion + odometry of every robot), ``observation`` (shared map), ``robot_readings``, ``total``;
    with ``tw`` the observation and reading terms as :class:`TermWeights` says."""
    fp = inputs.robots.first_pose
    chain = sum(en.chain_energy(pr, W, poses[fp[r]:fp[r + 1]]) for r, pr in enumerate(probs))
    if tw is None or tw.plain:
        obs = en.observation_energy(team_prob.landmark_points(poses), labels, landmarks, W.Q)
        rd = reading_energy(inputs, W, poses, active)
    else:
        obs = float(kernel_cost(tw.obs_s2(team_prob, poses, landmarks, labels, W.Q)[labels >= 0], tw.k)[0].sum())
        act = np.ones(len(inputs.robots.range_m), bool) if active is None else active
        rd = float(kernel_cost(tw.rd_s2(inputs, poses, W.Q)[act], tw.k)[0].sum()) if act.any() else 0.0
    return {"chain": float(chain), "observation": float(obs), "robot_readings": float(rd),
            "total": float(chain + obs + rd)}


def _pose_columns(fp: np.ndarray) -> np.ndarray:
    """Column of the first coordinate of every stacked pose ``(P,)`` in the team's joint vector
    ``[robot 1: x_1..x_T, robot 2: x_1..x_T, …, m]``; ``-1`` for each robot's fixed x_0."""
    cols = np.full(int(fp[-1]), -1, np.int64)
    off = 0
    for r in range(len(fp) - 1):
        a, b = int(fp[r]), int(fp[r + 1])
        cols[a + 1:b] = off + 3 * np.arange(b - a - 1)
        off += 3 * (b - a - 1)
    return cols


def team_joint_residuals(inputs, W, probs, poses, landmarks, labels, active=None, tw=None, team_prob=None):
    """Whitened residuals ``r`` (``‖r‖²`` = the team energy) and their sparse Jacobian over
    ``[every robot's x_1..x_T (3 Σ T_r), m (2L)]``: each robot's chain and landmark terms
    (:func:`slamcli.solvers.icm.energy.joint_residuals`, its columns moved to the robot's block) and the
    inter-robot readings ``h⁻¹(x^i_t, z) − p(x^j_t)``. With ``tw`` (and ``team_prob``) the observation and
    reading rows carry the weights ``√w`` of :meth:`TermWeights.weights` at ``poses`` (IRLS with a kernel)."""
    team, obs = inputs.robots, inputs.observations
    fp = team.first_pose
    pcol = _pose_columns(fp)
    n_pose = 3 * int(sum(pr.T for pr in probs))
    L = landmarks.shape[0]
    rs, Js = [], []
    use = tw is not None and not tw.plain
    w_obs = tw.weights(tw.obs_s2(team_prob, poses, landmarks, labels, W.Q), "obs") if use else None
    for r, pr in enumerate(probs):
        a, b = int(fp[r]), int(fp[r + 1])
        rows = slice(int(obs.offsets[a]), int(obs.offsets[b]))
        lab = labels[rows]
        rr, Jr = en.joint_residuals(pr, W, poses[a:b], landmarks, lab, obs_w=None if w_obs is None else w_obs[rows])
        Jr = Jr.tocoo()
        own = Jr.col < 3 * pr.T
        col = np.where(own, Jr.col + (pcol[a + 1] if b - a > 1 else 0), Jr.col - 3 * pr.T + n_pose)
        rs.append(rr)
        Js.append(sp.csr_matrix((Jr.data, (Jr.row, col)), shape=(Jr.shape[0], n_pose + 2 * L)))
    act = np.ones(len(team.range_m), bool) if active is None else active
    K = int(act.sum())
    if K:
        oi, oj, z = np.asarray(team.observer_pose)[act], np.asarray(team.observed_pose)[act], team.z[act]
        e = inverse_range_bearing(poses[oi], z).reshape(-1, 2) - poses[oj, :2]
        Jx, _ = observation_residual_jacobians(poses[oi], z)
        sw = np.broadcast_to(np.sqrt(np.asarray(W.Q, float)), (K, 2))
        if use:
            sw = sw * np.sqrt(tw.weights(tw.rd_s2(inputs, poses, W.Q), "rd")[act])[:, None]
        rows = np.arange(2 * K).reshape(K, 2)
        ri, ci, vi = [], [], []
        for pose, Jb, d in ((oi, Jx, 3), (oj, np.broadcast_to(-np.eye(2), (K, 2, 2)), 2)):
            ok = pcol[pose] >= 0
            c = pcol[pose][ok, None] + np.arange(d)[None, :]
            ri.append(np.repeat(rows[ok][:, :, None], d, 2).ravel())
            ci.append(np.repeat(c[:, None, :], 2, 1).ravel())
            vi.append((Jb[ok] * sw[ok][:, :, None]).ravel())
        rs.append((e * sw).ravel())
        Js.append(sp.csr_matrix((np.concatenate(vi), (np.concatenate(ri), np.concatenate(ci))),
                                shape=(2 * K, n_pose + 2 * L)))
    return np.concatenate(rs), sp.vstack(Js).tocsr()


def team_joint_refine(inputs, W, probs, team_prob, poses, landmarks, labels, *, max_iters: int, step_tol: float,
                      max_halvings: int = 12, active=None, tw=None):
    """Joint Gauss-Newton steps over every robot's poses and the shared map with fixed matchings (the team's
    ``accelerate=joint``; the same stopping rules as :func:`slamcli.solvers.icm.joint.joint_refine`), each step
    accepted only if it lowers the team energy (with ``tw``: IRLS steps of :class:`TermWeights`' energy).
    Returns ``(poses, landmarks, steps, reason)``."""
    from slamcli.solvers.icm.joint import stop_reason

    fp = inputs.robots.first_pose
    pcol = _pose_columns(fp)
    moving = pcol >= 0
    L = landmarks.shape[0]

    def total(p, m):
        return team_energy_terms(inputs, W, probs, team_prob, p, m, labels, active, tw)["total"]

    f, steps, reason = total(poses, landmarks), 0, "max_iters"
    for _ in range(max_iters):
        r, J = team_joint_residuals(inputs, W, probs, poses, landmarks, labels, active, tw, team_prob)
        try:
            delta = en.solve_normal_sparse(J, r)
        except (np.linalg.LinAlgError, RuntimeError, ValueError, MemoryError) as exc:
            reason = f"error: {type(exc).__name__}"
            break
        if not np.all(np.isfinite(delta)):
            reason = "error: non-finite step"
            break
        dp = delta[:-2 * L or None].reshape(-1, 3) if L else delta.reshape(-1, 3)
        dm = delta[len(delta) - 2 * L:].reshape(L, 2)
        alpha, accepted = 1.0, False
        for _ in range(max_halvings):
            p_new, m_new = poses.copy(), landmarks + alpha * dm
            p_new[moving] += alpha * dp[(pcol[moving] // 3)]
            p_new[:, 2] = (p_new[:, 2] + np.pi) % (2 * np.pi) - np.pi
            f_new = total(p_new, m_new)
            if f_new < f:
                accepted = True
                break
            alpha *= 0.5
        if not accepted:
            reason = "rejected"
            break
        steps += 1
        why = stop_reason(f, f_new, alpha * float(np.abs(delta).max(initial=0.0)), step_tol)
        poses, landmarks, f = p_new, m_new, f_new
        if why:
            reason = why
            break
    return poses, landmarks, steps, reason


def _refuse_unsupported(p, inputs: SlamInputs, init) -> None:
    """One-line :class:`ConfigError` naming every setting a team solve needs and does not have."""
    unsupported = [
        (p.correspondences != "reported", "correspondences=reported"),
        (init is not None, "no --init"),
        (p.schedule != "sequential", "schedule=sequential"),
        (p.covariance, "covariance=false"),
        (len(inputs.gps_step) > 0, "no GPS fixes"),
    ]
    needs = [what for bad, what in unsupported if bad]
    if needs:
        raise ConfigError(f"icm: multi-robot data needs {', '.join(needs)}")


def _gated_c_step(inputs, team_prob, W, poses, fixed, landmarks, tau, tau_rd, tw: TermWeights):
    """The c-step with the null value (:mod:`slamcli.solvers.icm.gate`): the landmark labels and the mask of the
    inter-robot readings kept (a term's cost ``kernel_cost(f ‖e‖²_Q, k) ≤ τ``, :class:`TermWeights`)."""
    if tw.plain:
        labels = gate.gate_labels(team_prob.landmark_points(poses), fixed, landmarks, W.Q, tau)
        d = reading_points(inputs, poses) - poses[np.asarray(inputs.robots.observed_pose), :2]
        return labels, W.Q[0] * d[:, 0] ** 2 + W.Q[1] * d[:, 1] ** 2 <= tau_rd
    c_obs = kernel_cost(tw.obs_s2(team_prob, poses, landmarks, fixed, W.Q), tw.k)[0]
    labels = np.where((fixed >= 0) & (c_obs <= tau), fixed, -1)
    return labels, kernel_cost(tw.rd_s2(inputs, poses, W.Q), tw.k)[0] <= tau_rd


def _term_weights(p, inputs: SlamInputs, team_prob) -> TermWeights:
    """The :class:`TermWeights` of ``p.robust``/``cauchy_k`` and ``p.team_range_weights``."""
    k = p.cauchy_k if p.robust == "cauchy" else None
    if not p.team_range_weights:
        return TermWeights(k)
    nz, r = inputs.noise, np.asarray(team_prob.z[:, 0], float)
    if not (nz.range_std > 0):
        raise ConfigError(f"icm: team_range_weights needs noise.range_std > 0, got {nz.range_std}")
    r_med = float(np.median(r)) if r.size else 0.0
    rd = np.asarray(inputs.robots.z, float).reshape(-1, 2)[:, 0]
    return TermWeights(k, range_scales(r, r_med, nz.range_std, nz.bearing_std),
                       range_scales(rd, r_med, nz.range_std, nz.bearing_std))


def _team_model(p, inputs: SlamInputs, team_prob, W):
    """``(W, tw, τ, τ_rd)``: the weights (without R under ``team_odometry_only``), the :class:`TermWeights`, and
    the null costs of the observations and of the inter-robot readings (τ from their own ranges; None without
    ``outlier_sigma``)."""
    tau = tau_rd = None
    if p.outlier_sigma > 0:
        nz = inputs.noise
        tau = gate.null_costs(team_prob, W, nz.range_std, nz.bearing_std, p.outlier_sigma)
        tau_rd = gate.null_costs(_reading_problem(inputs), W, nz.range_std, nz.bearing_std, p.outlier_sigma)
    tw = _term_weights(p, inputs, team_prob)
    if tau is not None and tw.obs is not None:  # the null cost of a term k σ out: τ in the term's own units
        tau, tau_rd = tau * tw.obs, tau_rd * tw.rd
    if p.team_odometry_only and W.use_odometry:  # the controls' potential counts the odometry's motion again
        W = dataclasses.replace(W, R=(0.0, 0.0, 0.0))
    return W, tw, tau, tau_rd


def _reading_problem(inputs):
    """A stand-in with the readings' ``z`` (what :func:`slamcli.solvers.icm.gate.null_costs` reads)."""
    from types import SimpleNamespace

    return SimpleNamespace(z=np.asarray(inputs.robots.z, float).reshape(-1, 2))


def solve_team(solver, inputs: SlamInputs, *, init: SolverResult | None, progress=None) -> SolverResult:
    """ICM on a multi-robot dataset (module docstring); ``solver`` is the :class:`IcmSlam` instance."""
    t_start = time.perf_counter()
    p = solver.params
    _refuse_unsupported(p, inputs, init)
    try:
        W = p.weights_for(inputs)
    except ValueError as exc:
        raise ConfigError(f"icm: {exc}") from None
    team = inputs.robots
    fp = team.first_pose
    R = team.n_robots
    solos = [solo_inputs(inputs, r) for r in range(R)]
    probs = [en.Problem.from_inputs(s, p.range_offset, use_gps=False) for s in solos]
    team_prob = en.Problem.from_inputs(inputs, p.range_offset, use_gps=False)
    labels = reported_labels(inputs.observations.reported_id)
    if len(labels) and not np.any(labels >= 0):
        raise ConfigError("icm: correspondences=reported needs sensor-reported ids, the dataset has none")
    L = int(labels.max()) + 1 if labels.size and labels.max() >= 0 else 0
    obs = inputs.observations
    fixed = labels  # the ids; with outlier_sigma > 0 each sweep's c-step may null some (solvers/icm/gate.py)
    W, tw, tau, tau_rd = _team_model(p, inputs, team_prob, W)
    active = None  # the inter-robot readings kept by the gate; None = all

    def null_E(lab) -> float:
        if tau is None:
            return 0.0
        return gate.null_energy(lab, fixed, tau) + (0.0 if active is None else float(tau_rd[~active].sum()))

    # ---- step 1: each robot's on-line initialisation (its own data only), then the shared map ---------------
    t0 = time.perf_counter()
    poses = np.empty((inputs.n_poses, 3))
    for r in range(R):
        a, b = int(fp[r]), int(fp[r + 1])
        rows = slice(int(obs.offsets[a]), int(obs.offsets[b]))
        local = compact_labels(labels[rows])[0]
        poses[a:b] = online_init(probs[r], W, radius=p.fusion_radius, kinematic=p.init == "kinematic",
                                 iters=p.init_pose_iters, fixed_labels=local)[0]
    landmarks, _ = mp.label_means(team_prob.landmark_points(poses), labels, L)
    terms = team_energy_terms(inputs, W, probs, team_prob, poses, landmarks, labels, tw=tw)
    E = terms["total"]
    objective, changes, times, lms = [E], [0.0], [time.perf_counter() - t0], [landmarks.copy()]
    every = p.trace_poses_every
    pose_iters, pose_snaps = ([0], [poses.copy()]) if every else ([], [])

    # ---- step 2: sweeps: robot 1's poses, robot 2's, …, then the map ---------------------------------------
    status = Status.MAX_ITERATIONS if p.max_sweeps > 0 else Status.COMPLETED
    increases, joint_log = 0, []
    for n in range(1, p.max_sweeps + 1):
        t0 = time.perf_counter()
        E_start, prev = E, landmarks
        if tau is not None and landmarks.shape[0]:  # c-step with the null value
            labels, active = _gated_c_step(inputs, team_prob, W, poses, fixed, landmarks, tau, tau_rd, tw)
        if p.accelerate == "joint" and n % p.accelerate_every == 0:  # joint Gauss-Newton over the whole team
            poses, landmarks, n_steps, why = team_joint_refine(inputs, W, probs, team_prob, poses, landmarks, labels,
                                                         max_iters=p.joint_iters, step_tol=p.joint_step_tol, active=active,
                                                         tw=tw)
            joint_log.append(f"{n_steps}:{why}")
        # the kernel's weights at the current estimate, held through the sweep (half-quadratic, kernel_cost)
        w_obs = None if tw.plain else tw.weights(tw.obs_s2(team_prob, poses, landmarks, labels, W.Q), "obs")
        w_rd = None if tw.plain else tw.weights(tw.rd_s2(inputs, poses, W.Q), "rd")
        stats_all = en.step_stats(team_prob, labels, landmarks, obs_w=w_obs)  # (14, P): landmark terms
        poses = poses.copy()
        for r in range(R):
            a, b = int(fp[r]), int(fp[r + 1])
            st = stats_all[:, a:b] + reading_stats(inputs, poses, r, active, w_rd)  # the others at their poses
            pr = poses[a:b].copy()
            en.sweep_poses_sequential(probs[r], W, pr, st, p.pose_iters)
            poses[a:b] = pr
        means, cnt = mp.label_means(team_prob.landmark_points(poses), labels, L, w_obs)
        landmarks = np.where(cnt[:, None] > 0, means, landmarks)  # eq. (17)
        E = team_energy_terms(inputs, W, probs, team_prob, poses, landmarks, labels, active, tw)["total"] + null_E(labels)
        objective.append(E)
        changes.append(mp.map_change(prev, landmarks))
        times.append(time.perf_counter() - t0)
        lms.append(landmarks.copy())
        if every and n % every == 0:
            pose_iters.append(n)
            pose_snaps.append(poses.copy())
        if progress is not None:
            progress(n, p.max_sweeps)
        decision = stop_decision(E_start, E, p.energy_rtol)
        if decision == "increase":
            increases += 1
        elif decision == "converged":
            status = Status.CONVERGED
            break
    K = len(objective)
    if every and pose_iters[-1] != K - 1:
        pose_iters.append(K - 1)
        pose_snaps.append(poses.copy())
    terms = team_energy_terms(inputs, W, probs, team_prob, poses, landmarks, labels, active, tw)
    extra = {
        "weights": p.weights,
        "weights_used": {"R": list(W.R), "S": list(W.S), "Q": list(W.Q), "K": W.K},
        "init": p.init,
        "multi_robot": {"robots": [int(x) for x in team.robot_number], "readings": int(len(team.range_m))},
        "sweeps": K - 1,
        "energy_increases": increases,
        "accelerate": p.accelerate,
        "joint_refinements": joint_log,
        "outlier_gate": p.outlier_sigma if tau is not None else "off",
        "robust": "none" if tw.k is None else f"cauchy (k = {tw.k:g})",
        "team_range_weights": tw.obs is not None,
        "motion_potential": W.use_motion,
        "outliers_nulled": int(((fixed >= 0) & (labels < 0)).sum()),
        "energy_null": null_E(labels),
        "readings_nulled": 0 if active is None else int((~active).sum()),
        **{f"energy_{k}": v for k, v in terms.items()},
    }
    trace = IterationTrace.from_lists(objective, changes, times, lms,
                                      poses_per_iter=pose_snaps if every else None,
                                      pose_iterations=pose_iters if every else None)
    return solver.make_result(
        status=status, poses_xyt=poses, landmarks_xy=landmarks, assoc=labels, t_start=t_start,
        message=f"{K - 1} multi-robot ICM sweeps ({R} robots), energy {objective[0]:.6g} -> {objective[-1]:.6g}"
        + (f"; energy rose in {increases} sweep(s)" if increases else ""),
        trace=trace, extra=extra, timings={"init_s": times[0],
                                           "s_per_sweep": float(np.mean(times[1:])) if K > 1 else 0.0},
    )
