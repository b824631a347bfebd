"""``--method graph``: the :class:`GraphSlam` driver (initial poses → association → optimisation →
merges → marginals).
"""

from __future__ import annotations

import functools
import math
import time
from dataclasses import dataclass, field

import numpy as np

from slamcli.errors import SolverError
from slamcli.models.angles import wrap_angle
from slamcli.solvers import frontend, nls
from slamcli.solvers.base import BaseSolver, ProgressFn
from slamcli.solvers.graph.build import GraphProblem, build_gtsam_problem, laplace_marginals
from slamcli.solvers.graph.certify import certify_pose_graph
from slamcli.solvers.graph.init import (
    incremental_initial_poses,
    initial_poses,
    nearest_neighbour_association,
    pose_graph_edges,
    robust_initial_poses,
)
from slamcli.solvers.graph.merge import merge_candidates
from slamcli.solvers.graph.paper import build_paper_problem, default_paper_weights
from slamcli.solvers.graph.params import (
    BASIN_PROBES,
    BASIN_REL_TOL,
    STALL_REL_DECREASE,
    STALL_WINDOW,
    GraphParams,
    resolve_init,
    resolve_robust,
    uses_gps,
)
from slamcli.types import IterationTrace, SlamInputs, SolverResult, Status


def chi2_cdf(x: float, k: int) -> float:
    """χ² distribution function with ``k ≥ 1`` (integer) degrees of freedom: the regularised lower incomplete
    gamma ``P(k/2, x/2)``, from ``P(1/2, y) = erf(√y)``, ``P(1, y) = 1 − e^{−y}`` and the recurrence
    ``P(a+1, y) = P(a, y) − yᵃ e^{−y} / Γ(a+1)`` (closed forms: no scipy.stats / scipy.special import, a
    start-up cost of every solve)."""
    if x <= 0.0:
        return 0.0
    y = 0.5 * x
    a = 0.5 if k % 2 else 1.0
    P = math.erf(math.sqrt(y)) if k % 2 else -math.expm1(-y)
    while a < 0.5 * k:
        P -= math.exp(a * math.log(y) - y - math.lgamma(a + 1.0))
        a += 1.0
    return min(max(P, 0.0), 1.0)


@functools.lru_cache(maxsize=64)
def chi2_quantile(p: float, k: int) -> float:
    """``x`` with ``chi2_cdf(x, k) = p`` (0 < p < 1) by bisection to ``CHI2_QUANTILE_RTOL`` (the CDF is
    monotone; the bracket doubles until it holds ``p``). Cached: every solve's outlier counts ask for the same
    few ``(p, k)`` (≈ 50 CDF evaluations each)."""
    lo, hi = 0.0, max(1.0, float(k))
    while chi2_cdf(hi, k) < p:
        lo, hi = hi, 2.0 * hi
    while hi - lo > CHI2_QUANTILE_RTOL * hi:
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if chi2_cdf(mid, k) < p else (lo, mid)
    return 0.5 * (lo + hi)


#: relative width of the bisection bracket of chi2_quantile
CHI2_QUANTILE_RTOL = 1e-13


def chi2_outlier_counts(problem: nls.NlsProblem, x: np.ndarray, whitened: list | None = None) -> dict:
    """χ² outlier counts per factor block at ``x`` (``whitened``: the blocks' whitened residuals there when
    known, :meth:`nls.Assembler.whitened_at`).

    A factor with whitened residual ``r̃ = L r`` (``k`` components) is an outlier at level ``p`` when
    ``‖r̃‖² > χ²_k(p)`` — the test a Gaussian factor fails with probability ``1 − p`` at the true state.
    The kernel (if any) is ignored here: the counts say which factors a robust kernel down-weighted.

    Returns
    -------
    dict ``{block name: {"factors": F, "dof": k, "over_95": n, "over_99": n}}`` (blocks of the same name
    merged).
    """
    out: dict[str, dict] = {}
    thresholds: dict[int, tuple[float, float]] = {}
    for i, b in enumerate(problem.blocks):
        if whitened is not None:
            rw = whitened[i]
        else:
            r = b.residuals(x)  # no Jacobians
            L = np.asarray(b.sqrt_info, float)
            rw = r @ L.T if L.ndim == 2 else np.einsum("fij,fj->fi", L, r)
        s2 = np.einsum("fk,fk->f", rw, rw)
        k = int(rw.shape[1])
        if k not in thresholds:
            thresholds[k] = (chi2_quantile(0.95, k), chi2_quantile(0.99, k))
        t95, t99 = thresholds[k]
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
            assoc = nearest_neighbour_association(poses, obs, inputs, p)
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
        """Batch graph SLAM of ``inputs`` (class docstring for the pipeline and the result's fields).

        Parameters
        ----------
        inputs : SlamInputs   ``n_poses = T+1`` poses; odometry ``(T, 3)``; observations ``(N, 2)``.
        init : SolverResult, optional   start / association from another run (``association=init``,
            ``init_from=init``); its ``poses_xyt`` must be ``(T+1, 3)``.
        rng : numpy.random.Generator   unused (graph SLAM draws nothing); part of the solver contract.
        progress : ProgressFn, optional   ``progress(done, total)`` over the linear-solve budget.

        Returns
        -------
        SolverResult   ``poses_xyt (T+1, 3)``, ``landmarks_xy (L, 2)``, ``assoc (N,)``, ``pose_cov
        (T+1, 3, 3)``, ``landmark_cov (L, 2, 2)`` (or None, see ``extra["covariance_error"]``).
        """
        t_start = time.perf_counter()
        p = self.params
        if p.surface:  # the declared landmark radius
            from slamcli.solvers.surface import mean_offset_inputs

            inputs = mean_offset_inputs(inputs, "graph")
        self._check_inputs(inputs, init)
        start = resolve_init(p, inputs)
        poses0 = self._initial_poses(inputs, init, start)
        assoc, old_of_new, mode = self._associate(inputs, init, poses0)
        robust_init = None
        if p.init == "robust" and p.init_from == "odometry" and old_of_new.size:
            poses0, robust_init = robust_initial_poses(inputs, assoc, poses0, p)
        lm0 = frontend.landmarks_from_observations(poses0, inputs.observations, assoc, old_of_new.size)
        if mode == "init" and init is not None and p.init_from == "init":
            lm0 = np.asarray(init.landmarks_xy, float).reshape(-1, 2)[old_of_new]
        kernel = resolve_robust(p.robust, mode, inputs.reported_id_source)
        run = self._optimise(inputs, assoc, poses0, lm0, mode, kernel, progress)
        run, cert, restart = self._certify_or_restart(inputs, run, assoc, poses0, mode, kernel, progress, start)
        extra, message = self._summary(run, mode, kernel, robust_init, start)
        message = self._report_restart(extra, message, cert, restart)
        pose_cov, landmark_cov, message = self._covariances(inputs, run, extra, message)
        if run.notes:
            extra["numerical_notes"] = run.notes
        if progress is not None:
            progress(run.budget, run.budget)
        poses, lms = run.gp.unpack(run.res.x)
        trace = IterationTrace.from_lists(run.objective, run.change, run.times, run.lm_trace)
        return self.make_result(
            status=run.res.status,
            poses_xyt=poses.copy(),
            landmarks_xy=lms.copy(),
            assoc=run.assoc,
            t_start=t_start,
            message=message,
            pose_cov=pose_cov,
            landmark_cov=landmark_cov,
            trace=trace,
            extra=extra,
        )

    # -- steps of solve ----------------------------------------------------------------------------------
    def _check_inputs(self, inputs: SlamInputs, init: SolverResult | None) -> None:
        """Refuse parameter + data combinations (the parameter-only checks are in GraphParams)."""
        p = self.params
        if inputs.motion_model != "ddmr" and (p.use_controls or p.model == "paper"):
            raise SolverError(f"graph: use_controls / model=paper read the controls as DDMR [v, omega]; with "
                              f"motion_model={inputs.motion_model!r} use the odometry factors (model=gtsam)")
        if inputs.robots is not None and (p.model == "paper" or p.init not in ("auto", "odometry") or p.use_controls):
            raise SolverError("graph: multi-robot data supports model=gtsam with init=odometry and "
                              "use_controls=false only")
        if p.init_from == "init" and init is None:
            raise SolverError("graph: init_from=init needs an --init result")
        if p.init == "incremental" and p.init_from == "odometry" and p.association == "auto":
            has_ids = len(inputs.observations) and np.any(np.asarray(inputs.observations.reported_id) >= 0)
            if init is not None or has_ids:
                raise SolverError(
                    "graph: init=incremental builds a nearest-neighbour association (unknown correspondences); "
                    "use association=nn, or another init with reported ids / --init labels"
                )

    def _initial_poses(self, inputs: SlamInputs, init: SolverResult | None, start: str) -> np.ndarray:
        """Start poses ``(T+1, 3)``: the ``--init`` result's, or those of ``start`` (``params.init`` resolved,
        :func:`resolve_init`; robust: odometry first)."""
        p = self.params
        if p.init_from == "init":
            poses0 = np.asarray(init.poses_xyt, float)
            if poses0.shape != (inputs.n_poses, 3):
                raise SolverError(
                    f"graph: init result has poses {poses0.shape}, dataset needs ({inputs.n_poses}, 3)"
                )
            return poses0
        poses0 = initial_poses(inputs, "odometry" if start in ("robust", "incremental") else start)
        if start == "incremental":
            poses0 = incremental_initial_poses(inputs, poses0, p)
        return poses0

    def _paper_weights(self, inputs: SlamInputs):
        """``(R (3,3), S (3,3), Q (2,2))`` of the paper model: the parameters' or the noise model's."""
        p = self.params
        R0, S0, Q0 = default_paper_weights(inputs)
        R = R0 if p.paper_R is None else np.asarray(p.paper_R, float)
        S = S0 if p.paper_S is None else np.asarray(p.paper_S, float)
        Q = Q0 if p.paper_Q is None else np.asarray(p.paper_Q, float)
        return R, S, Q

    def _optimise(self, inputs, assoc, poses0, lm0, mode, kernel, progress) -> _Run:
        """Optimise, then (association ``nn``) merge landmark pairs and re-optimise, up to ``merge_rounds``."""
        p = self.params
        RSQ = self._paper_weights(inputs) if p.model == "paper" else None
        rounds = p.merge_rounds if mode == "nn" else 0
        run = _Run(assoc=assoc, rounds=rounds, budget=p.max_iterations * (1 + rounds), paper_Q=None)
        if RSQ is not None:
            run.paper_Q = RSQ[2]

        def on_iter(k, x, cost):
            lm = run.gp.unpack(x)[1].copy()
            same = run.lm_trace and run.lm_trace[-1].shape == lm.shape and lm.size
            run.change.append(float(np.mean(np.linalg.norm(lm - run.lm_trace[-1], axis=1))) if same else 0.0)
            run.lm_trace.append(lm)
            if progress is not None:
                progress(min(run.done_iters + k, run.budget), run.budget)

        nparams = p.nls_params(kernel, p.kernel_scale(kernel), pose_graph=self._is_pose_graph(inputs, len(lm0), kernel))
        x_init_poses, x_init_lms = poses0, lm0
        for rnd in range(rounds + 1):
            run.rnd = rnd
            if RSQ is None:
                run.gp = build_gtsam_problem(inputs, run.assoc, x_init_poses, x_init_lms, p)
            else:
                run.gp = build_paper_problem(inputs, run.assoc, *RSQ, x_init_poses, x_init_lms)
            res = run.res = nls.solve(run.gp.problem, run.gp.x0, nparams, callback=on_iter)
            run.objective.extend(res.cost_trace.tolist())
            run.times.extend(res.time_trace.tolist())
            run.done_iters += res.iterations
            run.notes.extend(f"round {rnd}: {n}" if rounds else n for n in res.notes)
            if rnd == rounds or res.status == Status.FAILED or run.gp.n_landmarks < 2:
                break
            merged = self._merge_round(inputs, run)
            if merged is None:
                break
            x_init_poses, x_init_lms = merged
        return run

    def _is_pose_graph(self, inputs: SlamInputs, n_landmarks: int, kernel: str) -> bool:
        """Whether the solved graph is a plain pose graph (the SE-Sync certificate applies): ``gtsam`` model,
        no landmarks, no kernel, GPS, controls, range bias or second robot."""
        p = self.params
        return (p.model == "gtsam" and n_landmarks == 0 and kernel == "none" and inputs.robots is None
                and not p.use_controls and not uses_gps(p, inputs) and not p.estimate_range_bias and inputs.n_poses >= 2)

    def _certify_or_restart(self, inputs, run: _Run, assoc, poses0, mode, kernel, progress, start: str):
        """Certify a pose graph's optimum, re-solving from the chordal relaxation when the first start is not
        certified; re-solve a stalled landmark graph from ``init=robust`` (GraphParams.restart). Either restart
        runs only when :meth:`_restart_skip` finds it can help.

        Returns ``(run, certificate or None, restart dict or None)``; the run kept has the lower cost."""
        p = self.params
        auto = p.restart == "auto" and p.init_from == "odometry"
        if self._is_pose_graph(inputs, run.gp.n_landmarks, kernel):
            if not p.certify:
                return run, None, None
            ij, xyt, info = pose_graph_edges(inputs, p.edge_info)
            cert = certify_pose_graph(run.gp.unpack(run.res.x)[0], ij, xyt, info, run.res.workspace)
            if cert.certified or not auto or start == "chordal":
                return run, cert, None
            restart = {"from": "chordal", "first_cost": float(run.res.cost),
                       "first_lambda_min": float(cert.lambda_min), "first_init": start}
            poses_c, lm_c = initial_poses(inputs, "chordal"), np.zeros((0, 2))
            skip = self._restart_skip(inputs, run, assoc, poses_c, lm_c, kernel, restart)
            if skip:
                return run, cert, {**restart, "skipped": skip}
            run2 = self._optimise(inputs, assoc, poses_c, lm_c, mode, kernel, progress)
            cert2 = certify_pose_graph(run2.gp.unpack(run2.res.x)[0], ij, xyt, info, run2.res.workspace)
            restart["restart_cost"] = float(run2.res.cost)
            if run2.res.cost <= run.res.cost:
                return run2, cert2, restart
            return run, cert, {**restart, "kept": "first"}
        if not (auto and p.model == "gtsam" and start == "odometry" and run.gp.n_landmarks and _stalled(run)):
            return run, None, None
        poses_r, robust_res = robust_initial_poses(inputs, assoc, poses0, p)
        lm_r = frontend.landmarks_from_observations(poses_r, inputs.observations, assoc, int(assoc.max(initial=-1)) + 1)
        restart = {"from": "robust", "first_cost": float(run.res.cost), "first_init": start,
                   "robust_cost": float(robust_res.cost)}
        skip = self._restart_skip(inputs, run, assoc, poses_r, lm_r, kernel, restart)
        if skip:
            return run, None, {**restart, "skipped": skip}
        run2 = self._optimise(inputs, assoc, poses_r, lm_r, mode, kernel, progress)
        restart["restart_cost"] = float(run2.res.cost)
        if run2.res.cost <= run.res.cost:
            return run2, None, restart
        return run, None, {**restart, "kept": "first"}

    def _restart_skip(self, inputs, run: _Run, assoc, poses_r, lm_r, kernel, restart: dict) -> str:
        """Why a restart from ``poses_r (T+1, 3)``, ``lm_r (L, 2)`` cannot help ``run``'s estimate, or ``""``.

        It can help when its start has a lower cost (stored as ``restart["start_cost"]``), or when the cost
        falls somewhere on the straight path from the estimate to it (angles the short way round; the cost at
        :data:`BASIN_PROBES` points): a ridge between the two, so LM from there descends into another basin.
        A start that costs more and is reached from the estimate uphill all the way lies in the estimate's
        basin: LM would come back. When the two graphs differ (landmarks merged since), the restart runs."""
        gp_r = build_gtsam_problem(inputs, assoc, poses_r, lm_r, self.params)
        nparams = self.params.nls_params(kernel, self.params.kernel_scale(kernel),
                                         pose_graph=self._is_pose_graph(inputs, len(lm_r), kernel))
        start_cost = nls.evaluate_cost(gp_r.problem, gp_r.x0, nparams)
        restart["start_cost"] = float(start_cost)
        x_est = np.asarray(run.res.x, float)
        if not start_cost >= run.res.cost or gp_r.x0.shape != x_est.shape or run.gp.n_landmarks != gp_r.n_landmarks:
            return ""
        delta = gp_r.x0 - x_est
        ang = gp_r.problem.angle_cols
        delta[ang] = np.asarray(wrap_angle(delta[ang]), float)
        path = [nls.evaluate_cost(gp_r.problem, x_est + t * delta, nparams)
                for t in np.linspace(0.0, 1.0, BASIN_PROBES + 2)]
        if np.any(np.diff(path) < -BASIN_REL_TOL * abs(path[0])):
            return ""
        return (f"its start costs more ({start_cost:.6g}) and lies in the same basin (the cost rises all the way "
                "from the estimate to it), so LM would return here")

    @staticmethod
    def _report_restart(extra: dict, message: str, cert, restart) -> str:
        """Put the certificate and the restart into ``extra`` and the message."""
        if restart is not None:
            extra["restart"] = restart
            why = ("not certified" if restart["from"] == "chordal"
                   else "LM stalled at the iteration cap")
            if restart.get("skipped"):
                message += (f"; {why} from the {restart['first_init']} start (cost {restart['first_cost']:.6g}); "
                            f"stopped without re-solving from init={restart['from']}: {restart['skipped']}")
            else:
                kept = "kept the first run (lower cost)" if restart.get("kept") == "first" else "kept the restart"
                message += (f"; {why} from the {restart['first_init']} start (cost {restart['first_cost']:.6g}), "
                            f"re-solved from init={restart['from']}: {kept}")
        if cert is not None:
            extra["certificate"] = cert.as_extra()
            message += f"; {cert.verdict()}"
        return message

    def _merge_round(self, inputs: SlamInputs, run: _Run):
        """Merge the landmark pairs that pass the correspondence test at ``run``'s optimum; the next round's
        start ``(poses (T+1, 3), landmarks (L', 2))``, or None when nothing merges."""
        p, gp = self.params, run.gp
        poses_r, lms_r = gp.unpack(run.res.x)
        try:
            pairs = merge_candidates(
                gp, run.res.information, lms_r, inputs.observations, run.assoc, p.gate_prob, p.merge_dist
            )
        except np.linalg.LinAlgError as exc:
            run.notes.append(f"merging stopped after round {run.rnd}: no landmark covariances for the test ({exc})")
            return None
        if not pairs.size:
            return None
        lut = np.arange(gp.n_landmarks)
        lut[pairs[:, 1]] = pairs[:, 0]
        new_lms = lms_r.copy()
        new_lms[pairs[:, 0]] = 0.5 * (lms_r[pairs[:, 0]] + lms_r[pairs[:, 1]])
        relabelled = np.where(run.assoc >= 0, lut[np.maximum(run.assoc, 0)], -1)
        run.assoc, old_of_new = frontend.compact_labels(relabelled)
        run.merged_total += int(pairs.shape[0])
        return poses_r.copy(), new_lms[old_of_new]

    def _summary(self, run: _Run, mode: str, kernel: str, robust_init, start: str) -> tuple[dict, str]:
        """The result's ``extra`` dict and message (before covariances)."""
        p, gp, res = self.params, run.gp, run.res
        extra: dict = {
            "association": mode,
            "n_landmarks": int(gp.n_landmarks),
            "iterations": int(run.done_iters),
            "final_cost": float(res.cost),
            "model": p.model,
            "robust": kernel,
        }
        if run.rounds:
            extra["merged_landmarks"] = run.merged_total
        if gp.range_bias_col is not None:
            extra["range_bias"] = float(res.x[gp.range_bias_col])
        if start != "odometry" and p.init_from == "odometry":
            extra["init"] = start
        if robust_init is not None:
            extra["robust_init"] = {
                "status": robust_init.status.value,
                "iterations": int(robust_init.iterations),
                "cost": float(robust_init.cost),
            }
        if p.outlier_counts:
            asm = res.workspace[0] if res.workspace is not None else None
            extra["chi2_outliers"] = chi2_outlier_counts(gp.problem, res.x,
                                                         asm.whitened_at(res.x) if asm is not None else None)
        message = res.message
        if mode == "nn" and "chi2_outliers" in extra:
            message += _association_check(extra)
        if p.init == "auto" and start != "odometry" and p.init_from == "odometry":
            message += f"; started from the {start} relaxation (init=auto: a pose graph with loop closures)"
        if run.rnd:  # the status is that of the last round; the trace holds every round (each with its start)
            message += (
                f" (in optimisation round {run.rnd + 1}, after landmark merges; {run.done_iters} iterations in all)"
            )
        return extra, message

    def _covariances(self, inputs: SlamInputs, run: _Run, extra: dict, message: str):
        """``(pose_cov (T+1, 3, 3), landmark_cov (L, 2, 2), message)`` at the optimum, or None blocks with
        the reason in ``extra`` and the message (the one marginals policy: refuse a singular / indefinite H)."""
        p = self.params
        pose_cov = landmark_cov = None
        team_cov_skipped = p.covariance and inputs.robots is not None and len(inputs.robots.range_m) > 0
        if team_cov_skipped:  # inter-robot factors break the chain + border layout of the fast marginals
            extra["covariance_note"] = ("not computed: the inter-robot factors couple poses of different robots, "
                                        "so the chain + border marginals do not apply and the general sparse "
                                        "column solve takes minutes on a few thousand poses")
        if p.covariance and run.res.status != Status.FAILED and not team_cov_skipped:
            try:
                pose_cov, landmark_cov = laplace_marginals(run.gp, run.res)
            except np.linalg.LinAlgError as exc:
                # never report covariances from a factorisation that broke down; the estimate itself stands
                why = f"the information matrix is not numerically positive definite at the estimate ({exc})"
                extra["covariance_error"] = why
                message += f"; no covariances: {why}"
            else:
                if p.model == "paper":
                    pose_cov[0] = 0.0  # x_0 is held fixed
                    if not np.any(run.paper_Q):
                        landmark_cov = None  # landmarks were held fixed
        return pose_cov, landmark_cov, message


def _stalled(run: _Run) -> bool:
    """LM reached its iteration cap with a relative decrease below STALL_REL_DECREASE over the last
    STALL_WINDOW iterations."""
    obj = run.objective
    if run.res.status != Status.MAX_ITERATIONS or len(obj) <= STALL_WINDOW:
        return False
    return (obj[-STALL_WINDOW - 1] - obj[-1]) <= STALL_REL_DECREASE * abs(obj[-STALL_WINDOW - 1])


#: Our own (nearest-neighbour) association is flagged when more than this fraction of the sightings lie outside
#: the 99 % χ² gate at the estimate — ten times the 1 % a right association and noise model give (chosen by
#: measurement: benchmarks/results/design_notes.md).
ASSOCIATION_SUSPECT_FRAC = 0.10


def _association_check(extra: dict) -> str:
    """With ``association=nn``: put the fraction of sightings beyond the 99 % χ² gate at the estimate into
    ``extra["association_check"]`` and return a warning for the message when it exceeds
    :data:`ASSOCIATION_SUSPECT_FRAC` (else "")."""
    obs = [v for k, v in extra["chi2_outliers"].items() if k in ("bearing_range", "landmark_xy")]
    n = sum(v["factors"] for v in obs)
    if n == 0:
        return ""
    frac = sum(v["over_99"] for v in obs) / n
    suspect = frac > ASSOCIATION_SUSPECT_FRAC
    extra["association_check"] = {"sightings": n, "frac_over_chi2_99": frac, "suspect": suspect}
    if not suspect:
        return ""
    return (f"; association suspect: {100 * frac:.0f} % of the sightings lie beyond the 99 % χ² gate at the "
            f"estimate (≈ 1 % expected) — the nearest-neighbour association was built once from the dead-reckoned "
            f"path; on long recordings use -m isam (associates per step; -p final_batch=true for the batch "
            f"optimum) or -p init=incremental")


@dataclass
class _Run:
    """State of :meth:`GraphSlam._optimise` across its merge rounds (traces concatenated over rounds)."""

    assoc: np.ndarray
    rounds: int
    budget: int
    paper_Q: np.ndarray | None
    gp: GraphProblem | None = None
    res: nls.NlsResult | None = None
    rnd: int = 0
    done_iters: int = 0
    merged_total: int = 0
    objective: list = field(default_factory=list)
    times: list = field(default_factory=list)
    lm_trace: list = field(default_factory=list)
    change: list = field(default_factory=list)
    notes: list = field(default_factory=list)
