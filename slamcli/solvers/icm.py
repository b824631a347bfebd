"""ICM-SLAM: SLAM as a Markov random field solved by iterated conditional modes (paper 000, Algorithm 2).

Nodes: the poses x_1..x_T (x_0 known), the matchings c_0..c_T of every observation to a map label, and the map
m. The Gibbs energy (eq. 5, see :mod:`slamcli.solvers.icm_energy`) is minimised node by node:

1. **On-line initialisation** (Algorithm 2 step 1, eqs. 9-11): at each time t the matchings come from the
   nearest map point to h⁻¹(g(x_{t-1}, u_{t-1}), z_{t,i}) (a new label when none lies within ϑ), then x_t
   minimises the time-t terms — motion t (R), odometry t (S) and the observations of already-mapped labels
   (Q) — by a few Gauss-Newton steps; map points are created when first seen and kept as running means
   (eq. 17). The init ends with the three-step map update of §4 and the ς filter. ``init="kinematic"`` is
   the paper's "very bad initialisation" (Fig. 6): poses from g(x, u) only.
2. **ICM sweeps** (step 2, eqs. 12-15) with the visit scheme c_0, c_1, x_1, …, c_T, x_T, m. Since c_t
   depends only on x_t^{(n-1)} and m^{(n-1)}, visiting every c_t just before x_t is the same as matching all
   observations first (one KD-tree query); x_t then moves to the mode of its 3-D conditional (eq. 14, a few
   Gauss-Newton steps with step halving); the map step is eq. (17) + label fusion within ϑ + the ς filter.

Beyond the paper (separate options, default off):

* ``schedule="parallel"`` — the coding scheme odd poses / even poses: each class is conditionally independent
  given the other, the map and the matchings, so a class is updated at once, vectorised.
* ``accelerate="joint"`` — every ``accelerate_every`` sweeps, one joint Gauss-Newton step over all poses and the
  map with the current matchings, accepted only if it lowers the same energy (backtracking).
* ``range_offset`` — added to every range before h⁻¹: a laser measures a post's surface, not its centre; the
  bias of the paper-exact inverse observation pulls map points towards the robot and drags the poses with them
  (``benchmarks/bench_icm_study.py``).

Energy bookkeeping: observations whose label the ς filter removed are out of the model for good (the paper's
clutter); the map step is the paper's three-step procedure, and with ``monotone=True`` (default) it is kept
only if the energy after the sweep does not exceed the energy before it (otherwise the previous, feasible map
stays) — so the recorded energy never increases from sweep to sweep.
"""

from __future__ import annotations

import dataclasses
import math
import time
from typing import Literal

import numpy as np

from slamcli.models.angles import wrap_angle
from slamcli.models.motion import integrate
from slamcli.models.observation import inverse_range_bearing
from slamcli.solvers import icm_energy as en
from slamcli.solvers import icm_map as mp
from slamcli.solvers.base import BaseSolver, ProgressFn
from slamcli.solvers.frontend import compact_labels
from slamcli.types import IterationTrace, SlamInputs, SolverResult, Status


@dataclasses.dataclass(frozen=True)
class IcmParams:
    """Parameters of ICM-SLAM (defaults: paper 000 §5, Simulation 1).

    Attributes
    ----------
    R, S, Q : tuple of float     diagonal weight matrices of the motion (3), odometry (16) and observation
                                 potentials: one value = scalar × identity, else the full diagonal (3, 3, 2).
                                 A zero matrix drops its potential. Paper §5: R = Q = I, S = 0; §6: S = I.
    fusion_radius : float        ϑ, m: labels whose points are closer than ϑ are fused (§4); also the radius
                                 within which the on-line init matches an existing label.
    min_observations : int       ς: map points seen fewer times are removed (§4; paper: 500 for its laser data
                                 with many returns per landmark per scan — scale it to the data; the simulated
                                 paper-sim1/octagon lasers give 800-3000 returns per landmark, so 500 fits).
                                 Default 1 keeps every map point.
    init : "online" | "kinematic"  Algorithm 2 step 1 as written, or poses from g(x, u) only (Fig. 6).
    correspondences : "nearest" | "reported"  nearest-map-point matchings (eqs. 9-13), or fixed labels from the
                                 sensor-reported ids (known correspondences; no fusion, no filter).
    max_sweeps : int             maximum number of ICM iterations N.
    map_tol : float              stop when the mean map change of an iteration is below this, m.
    energy_rtol : float          stop when an iteration lowers the energy by less than this fraction.
    pose_iters : int             Gauss-Newton steps per pose conditional in a sweep (eq. 14).
    init_pose_iters : int        Gauss-Newton steps of the on-line init (eq. 11).
    schedule : "sequential" | "parallel"  paper visit order, or odd/even coding scheme (beyond the paper).
    accelerate : "none" | "joint"  occasional joint Gauss-Newton step (beyond the paper).
    accelerate_every : int       sweeps between joint steps.
    monotone : bool              keep the previous map when the paper's map step would raise the energy.
    covariance : bool            Laplace marginal covariances at the end (joint Hessian, fixed matchings).
    range_offset : float         beyond the paper (default 0 = paper-exact): added to every measured range before
                                 the inverse observation h⁻¹(x, [r + range_offset, b]), m — the same option as
                                 EKF's. A laser measures the SURFACE of a post of radius ρ: a beam at lateral
                                 offset s from the centre stops √(ρ² − s²) short of it, π/4 · ρ on average over
                                 s uniform in [−ρ, ρ], so ``range_offset = π/4 · ρ`` re-centres the returns of
                                 a post of known radius ρ (use ρ itself for a sensor that returns the nearest
                                 surface point). See ``benchmarks/bench_icm_study.py``.
    trace_poses_every : int      record the poses of iteration 0 (the initialisation), of every k-th iteration
                                 and of the last one in ``result.trace`` (paper Figs 5b-d / 6b / 9b-c draw the
                                 trajectory after iterations 10, 20, 30, …); 0 = no poses in the trace. Memory:
                                 24·(T+1) bytes per recorded iteration (paper-sim2, T = 3250, 100 sweeps, k = 1:
                                 7.8 MB); raise k for very long runs.
    """

    R: tuple[float, ...] = (1.0,)
    S: tuple[float, ...] = (0.0,)
    Q: tuple[float, ...] = (1.0,)
    fusion_radius: float = 1.0
    min_observations: int = 1
    init: Literal["online", "kinematic"] = "online"
    correspondences: Literal["nearest", "reported"] = "nearest"
    max_sweeps: int = 100
    map_tol: float = 1e-4
    energy_rtol: float = 1e-7
    pose_iters: int = 3
    init_pose_iters: int = 5
    schedule: Literal["sequential", "parallel"] = "sequential"
    accelerate: Literal["none", "joint"] = "none"
    accelerate_every: int = 5
    monotone: bool = True
    covariance: bool = False
    range_offset: float = 0.0
    trace_poses_every: int = 1

    def __post_init__(self) -> None:
        en.Weights.from_params(self.R, self.S, self.Q)  # validates lengths and signs
        if not (self.fusion_radius >= 0 and math.isfinite(self.fusion_radius)):
            raise ValueError(f"fusion_radius must be a finite number >= 0, got {self.fusion_radius}")
        if self.min_observations < 0:
            raise ValueError(f"min_observations must be >= 0, got {self.min_observations}")
        for name in ("max_sweeps", "pose_iters", "init_pose_iters", "accelerate_every"):
            if getattr(self, name) < (0 if name == "max_sweeps" else 1):
                raise ValueError(
                    f"{name} must be >= {0 if name == 'max_sweeps' else 1}, got {getattr(self, name)}"
                )
        if self.map_tol < 0 or self.energy_rtol < 0:
            raise ValueError("map_tol and energy_rtol must be >= 0")
        if not (self.range_offset >= 0 and math.isfinite(self.range_offset)):
            raise ValueError(f"range_offset must be a finite number >= 0, got {self.range_offset}")
        if self.trace_poses_every < 0:
            raise ValueError(f"trace_poses_every must be >= 0 (0 = no poses in the trace), got {self.trace_poses_every}")

    @property
    def weights(self) -> en.Weights:
        return en.Weights.from_params(self.R, self.S, self.Q)


def reported_labels(reported_id) -> np.ndarray:
    """Labels 0.. by order of first appearance of each sensor-reported id; ``-1`` stays ``-1``."""
    return compact_labels(reported_id)[0]


def online_init(
    prob: en.Problem,
    W: en.Weights,
    *,
    radius: float,
    kinematic: bool = False,
    iters: int = 5,
    fixed_labels: np.ndarray | None = None,
):
    """Algorithm 2, step 1 (eqs. 9-11), run causally over t = 0..T.

    Parameters
    ----------
    radius : float               ϑ: an observation starts a new label when no map point lies within it.
    kinematic : bool             poses from g(x, u) only (paper Fig. 6), skipping the minimisation (11).
    fixed_labels : ndarray (N,)  known matchings (used instead of the nearest-point rule); labels must be
                                 numbered by first appearance.

    Returns
    -------
    poses_xyt (T+1, 3), labels (N,) int64, landmarks_xy (L, 2) — the running means (17) — and the time spent
    per step, s (T+1,).
    """
    T, N = prob.T, prob.n_obs
    poses = np.empty((T + 1, 3))
    poses[0] = prob.x0
    kin = integrate(prob.x0, prob.controls, prob.dt) if kinematic else None
    labels = np.full(N, -1, np.int64)
    msum = np.zeros((max(N, 1), 2))
    mcnt = np.zeros(max(N, 1))
    L = 0
    Wf = W.flat
    r2 = radius * radius
    off = prob.offsets
    step_s = np.empty(T + 1)
    U = prob.controls.tolist()
    D = prob.odo_inc.tolist()
    for t in range(T + 1):
        t0 = time.perf_counter()
        a, b = int(off[t]), int(off[t + 1])
        if t == 0:
            xh = prob.x0.copy()
        elif kinematic:
            xh = kin[t].copy()
        else:
            px, py, pth = poses[t - 1]
            v0, w0 = U[t - 1]
            xh = np.array(
                [
                    px + prob.dt * v0 * math.cos(pth),
                    py + prob.dt * v0 * math.sin(pth),
                    wrap_angle(pth + prob.dt * w0),
                ]
            )
        n_t = b - a
        match = np.full(n_t, -1, np.int64)
        if n_t:
            if fixed_labels is not None:
                lab = fixed_labels[a:b]
                match = np.where(lab >= 0, lab, 0)
                match = np.where((lab >= 0) & (mcnt[match] > 0), lab, -1)
            elif L:
                pts = inverse_range_bearing(xh, prob.z[a:b])  # eqs. (9)-(10)
                means = msum[:L] / mcnt[:L, None]
                d2 = ((pts[:, None, :] - means[None, :, :]) ** 2).sum(-1)
                j = np.argmin(d2, axis=1)
                match = np.where(d2[np.arange(n_t), j] <= r2, j, -1)
        x = xh
        if t > 0 and not kinematic:
            ok = match >= 0
            st = _stats_one(prob.v_body[a:b][ok], msum[match[ok]] / mcnt[match[ok], None])
            px, py, pth = poses[t - 1]
            g = (xh[0], xh[1], pth + prob.dt * U[t - 1][1])
            d = D[t - 1]
            ctx = (
                px,
                py,
                pth,
                g[0],
                g[1],
                g[2],
                d[0],
                d[1],
                d[2],
                0.0,
                0.0,
                0.0,
                0.0,
                0.0,
                0.0,
                0.0,
                0.0,
                0.0,
            )
            x = np.array(
                en.cond_minimise_scalar(xh[0], xh[1], xh[2], ctx, st, Wf, prob.dt, iters, 1e-10)
            )  # (11)
        poses[t] = x
        if n_t:
            pts = inverse_range_bearing(x, prob.z[a:b])
            ok = match >= 0
            np.add.at(msum, match[ok], pts[ok])
            np.add.at(mcnt, match[ok], 1.0)
            for i in np.flatnonzero(~ok):  # first sight: a new label (or one just created at this step)
                if fixed_labels is not None:
                    lab = int(fixed_labels[a + i])
                    if lab < 0:
                        continue
                    L = max(L, lab + 1)
                else:
                    lab = -1
                    if L:
                        dd = ((msum[:L] / mcnt[:L, None] - pts[i]) ** 2).sum(-1)
                        j = int(np.argmin(dd))
                        if dd[j] <= r2:
                            lab = j
                    if lab < 0:
                        lab = L
                        L += 1
                match[i] = lab
                msum[lab] += pts[i]
                mcnt[lab] += 1.0
            labels[a:b] = match
        step_s[t] = time.perf_counter() - t0
    with np.errstate(invalid="ignore", divide="ignore"):
        landmarks = msum[:L] / mcnt[:L, None]
    return poses, labels, landmarks, step_s


def _stats_one(v, m):
    """The 14 sufficient statistics (see :func:`icm_energy.step_stats`) of one step's matched observations."""
    if v.shape[0] == 0:
        return (0.0,) * 14
    vx, vy, mx, my = v[:, 0], v[:, 1], m[:, 0], m[:, 1]
    return (
        float(v.shape[0]),
        float(vx.sum()),
        float(vy.sum()),
        float(mx.sum()),
        float(my.sum()),
        float(vx @ vx),
        float(vx @ vy),
        float(vy @ vy),
        float(vx @ mx),
        float(vx @ my),
        float(vy @ mx),
        float(vy @ my),
        float(mx @ mx),
        float(my @ my),
    )


class IcmSlam(BaseSolver):
    """ICM-SLAM (paper 000, Algorithm 2) — see the module docstring."""

    name = "icm"
    Params = IcmParams

    def solve(
        self,
        inputs: SlamInputs,
        *,
        init: SolverResult | None = None,
        rng: np.random.Generator,
        progress: ProgressFn | None = None,
    ) -> SolverResult:
        t_start = time.perf_counter()
        p: IcmParams = self.params
        W = p.weights
        prob = en.Problem.from_inputs(inputs, p.range_offset)
        T, N = prob.T, prob.n_obs
        reported = p.correspondences == "reported"
        fixed = reported_labels(inputs.observations.reported_id) if reported else None
        if reported and N and not np.any(fixed >= 0):
            from slamcli.errors import ConfigError

            raise ConfigError("icm: correspondences=reported needs sensor-reported ids, the dataset has none")
        extra: dict = {"schedule": p.schedule, "accelerate": p.accelerate}
        timings: dict = {}  # wall-clock numbers: SolverResult.timings, never extra (determinism)

        # ---- step 1: initialisation ----------------------------------------------------------------------
        t0 = time.perf_counter()
        if init is not None:
            poses, labels, landmarks = self._from_result(prob, init, fixed, W)
            extra["init"] = f"result:{init.solver}"
        else:
            poses, labels, landmarks, step_s = online_init(
                prob,
                W,
                radius=p.fusion_radius,
                kinematic=p.init == "kinematic",
                iters=p.init_pose_iters,
                fixed_labels=fixed,
            )
            extra["init"] = p.init
            timings["init_ms_per_step"] = float(1e3 * step_s.mean()) if step_s.size else 0.0
            timings["init_ms_per_step_max"] = float(1e3 * step_s.max()) if step_s.size else 0.0
            if not reported:  # end of step 1: the three-step map update of §4 (+ ς filter)
                pts = prob.landmark_points(poses)
                labels, landmarks, _ = mp.map_update(pts, labels, p.fusion_radius, p.min_observations)
            else:
                landmarks = self._means_keep(prob, poses, labels, landmarks)
        out_model = labels < 0  # observations outside the model (filtered / unlabelled); stays so
        E = en.energy(prob, W, poses, landmarks, labels)
        objective, changes, times, lms = [E], [0.0], [time.perf_counter() - t0], [landmarks.copy()]
        every = p.trace_poses_every
        pose_iters, pose_snaps = ([0], [poses.copy()]) if every else ([], [])
        timings["init_s"] = times[0]

        # ---- step 2: ICM sweeps ----------------------------------------------------------------------------
        status = Status.MAX_ITERATIONS if p.max_sweeps > 0 else Status.COMPLETED
        rejected = 0
        joint_accepted = 0
        for n in range(1, p.max_sweeps + 1):
            t0 = time.perf_counter()
            E_start = E
            prev_landmarks = landmarks
            # c_0..c_T (eqs. 12-13): nearest map point to h⁻¹(x_t^{(n-1)}, z_{t,i})
            if not reported and landmarks.shape[0]:
                pts = prob.landmark_points(poses)
                act = ~out_model
                labels = labels.copy()
                labels[act] = mp.nearest_labels(pts[act], landmarks, W.Q, labels[act])
            if p.accelerate == "joint" and n % p.accelerate_every == 0:
                poses, landmarks, _, ok = en.joint_gn_step(prob, W, poses, landmarks, labels)
                joint_accepted += int(ok)
            # x_1..x_T (eq. 14)
            stats = en.step_stats(prob, labels, landmarks)
            poses = poses.copy()
            if p.schedule == "parallel":
                en.sweep_poses_parallel(prob, W, poses, stats, p.pose_iters)
            else:
                en.sweep_poses_sequential(prob, W, poses, stats, p.pose_iters)
            # m (eq. 15): three-step map update + ς filter
            pts = prob.landmark_points(poses)
            E_pose = en.chain_energy(prob, W, poses)
            if reported:
                new_landmarks = self._means_keep(prob, poses, labels, landmarks)
                new_labels = labels
            else:
                new_labels, new_landmarks, _ = mp.map_update(pts, labels, p.fusion_radius, p.min_observations)
            E_new = E_pose + en.observation_energy(pts, new_labels, new_landmarks, W.Q)
            accepted = True
            if p.monotone and not reported and E_new > E_start:
                accepted = False
                rejected += 1
                E_new = E_pose + en.observation_energy(pts, labels, landmarks, W.Q)
            else:
                labels, landmarks = new_labels, new_landmarks
                out_model = labels < 0
            E = E_new
            change = mp.map_change(prev_landmarks, landmarks)
            objective.append(E)
            changes.append(change)
            times.append(time.perf_counter() - t0)
            lms.append(landmarks.copy())
            if every and n % every == 0:
                pose_iters.append(n)
                pose_snaps.append(poses.copy())
            if progress is not None:
                progress(n, p.max_sweeps)
            rel = (E_start - E) / max(abs(E_start), 1e-300)
            if accepted and (change < p.map_tol or rel < p.energy_rtol):
                status = Status.CONVERGED
                break
            if not accepted and rel < p.energy_rtol:
                status = Status.CONVERGED
                break

        timings["s_per_sweep"] = float(np.mean(times[1:])) if len(times) > 1 else 0.0
        extra.update(
            sweeps=len(objective) - 1,
            map_steps_rejected=rejected,
            joint_steps_accepted=joint_accepted,
            n_out_of_model=int((labels < 0).sum()),
            **{f"energy_{k}": v for k, v in en.energy_terms(prob, W, poses, landmarks, labels).items()},
        )
        pose_cov = lm_cov = None
        if p.covariance and landmarks.shape[0] + T > 0:
            pose_cov, lm_cov = en.laplace_covariances(prob, W, poses, landmarks, labels)
        K = len(objective)
        if every and pose_iters[-1] != K - 1:  # the last iteration is always recorded
            pose_iters.append(K - 1)
            pose_snaps.append(poses.copy())
        trace = IterationTrace.from_lists(objective, changes, times, lms,
                                          poses_per_iter=pose_snaps if every else None,
                                          pose_iterations=pose_iters if every else None)
        return self.make_result(
            status=status,
            poses_xyt=poses,
            landmarks_xy=landmarks,
            assoc=labels,
            t_start=t_start,
            message=f"{len(objective) - 1} ICM sweeps, energy {objective[0]:.6g} -> {objective[-1]:.6g}",
            pose_cov=pose_cov,
            landmark_cov=lm_cov,
            trace=trace,
            extra=extra,
            timings=timings,
        )

    # -- helpers ---------------------------------------------------------------------------------------------
    @staticmethod
    def _means_keep(prob, poses, labels, landmarks):
        """Eq. (17) for fixed labels; a label without observations keeps its previous point."""
        L = landmarks.shape[0]
        means, cnt = mp.label_means(prob.landmark_points(poses), labels, L)
        return np.where(cnt[:, None] > 0, means, landmarks)

    @staticmethod
    def _from_result(prob, init: SolverResult, fixed, W):
        """Start from another solver's result (post-processing, paper §7)."""
        from slamcli.errors import ConfigError

        poses = np.array(init.poses_xyt, float)
        if poses.shape != (prob.T + 1, 3):
            raise ConfigError(
                f"--init: result has poses of shape {poses.shape}, dataset needs ({prob.T + 1}, 3)"
            )
        poses[0] = prob.x0
        landmarks = np.asarray(init.landmarks_xy, float).reshape(-1, 2)
        if fixed is not None:
            labels = fixed
            L = int(labels.max()) + 1 if labels.size and labels.max() >= 0 else 0
            means, cnt = mp.label_means(prob.landmark_points(poses), labels, L)
            return poses, labels, np.where(cnt[:, None] > 0, means, 0.0)
        assoc = np.asarray(init.assoc, np.int64)
        if assoc.shape == (prob.n_obs,) and np.all(assoc < landmarks.shape[0]) and np.any(assoc >= 0):
            labels = assoc.copy()
        else:  # no usable association: nearest map point (eq. 12-13)
            labels = mp.nearest_labels(prob.landmark_points(poses), landmarks, W.Q)
        return poses, labels, landmarks
