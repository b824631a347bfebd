"""ICM-SLAM: SLAM as a Markov random field solved by iterated conditional modes (paper 000, Algorithm 2).

Nodes: the poses x_1..x_T (x_0 known), the matchings c_0..c_T of every observation to a map label, and the map
m. The Gibbs energy (eq. 5, :mod:`slamcli.solvers.icm.energy`; weights R motion, S odometry, Q observations,
K GPS) is minimised node by node:

1. **On-line initialisation** (step 1, eqs. 9-11): each x_t from motion, odometry and the observations of
   already-mapped labels; new labels when nothing lies within ϑ; map points as running means (eq. 17), then
   the map update of §4 and the ς filter. ``init="kinematic"``: poses from g(x, u) only (Fig. 6).
2. **ICM sweeps** (step 2, eqs. 12-15), visit order c_0, c_1, x_1, …, c_T, x_T, m: all matchings in one
   KD-tree query, each pose to the mode of its conditional (eq. (6), a few Gauss-Newton steps with halving),
   then the map step (eq. 17 + label fusion within ϑ + the ς filter).

Deliberate deviations from Algorithm 2 as printed (reasons and measurements: benchmarks/results/design_notes.md):
new label when nothing lies within ϑ; up to 10 fusion passes; running-mean map points in the init;
per-return matching; ``pose_iters`` Gauss-Newton steps per pose; ς defaults to 1 (paper 500); the
``monotone`` guard on fusion and filtering; a stopping rule (``energy_rtol`` and an optimality test);
``polish="nls"`` (all poses and the map to the optimum under the current matchings, :mod:`.polish`);
``filtered="drop"`` (observations of filtered points leave the model; ``"rematch"`` is eq. 13).
Further options, default off: ``schedule="parallel"`` (odd/even pose classes), ``accelerate="joint"``,
``weights="information"``, ``range_offset``, and for long real runs (``preset="real"``) ``init="gated"``
(:mod:`.init_gated`), ``joint_iters`` (:mod:`.joint`), ``merge`` / ``label_cost`` (:mod:`.merge`) and
``outlier_sigma`` (:mod:`.gate`). The GPS potential of §4 is used whenever the dataset has fixes.
``observation="range_bearing"``: H's observation term is graph's Cauchy bearing-range factor; it is recorded,
stop-tested and polished, and a sweep's Cartesian pose / map steps are a proposal kept only when they lower it.
"""

from __future__ import annotations

import dataclasses
import math
import time

import numpy as np

from slamcli.solvers import nls
from slamcli.solvers.base import BaseSolver, ProgressFn
from slamcli.solvers.frontend import resolve_motion_input
from slamcli.solvers.icm import energy as en
from slamcli.solvers.icm import gate, presets
from slamcli.solvers.icm import map_step as mp
from slamcli.solvers.icm import surface as surf
from slamcli.solvers.icm.common import online_init, reported_labels, stop_decision
from slamcli.solvers.icm.init_gated import gated_init
from slamcli.solvers.icm.joint import joint_refine
from slamcli.solvers.icm.merge import label_cost_energy, label_covariances, merge_labels
from slamcli.solvers.icm.params import IcmParams
from slamcli.solvers.icm.polish import optimality, polish, prime_workspace
from slamcli.solvers.surface import require_radius
from slamcli.types import IterationTrace, SlamInputs, SolverResult, Status


def _fill_nearest(prob, poses, labels, landmarks, W, in_model, pts=None) -> np.ndarray:
    """``labels`` with every in-model observation labelled ``-1`` matched to its nearest map point (eq. 13), i.e.
    the matchings the next sweep's c-step starts from for observations whose map point the ς filter removed."""
    need = in_model & (labels < 0)
    if not need.any() or landmarks.shape[0] == 0:
        return labels
    pts = prob.landmark_points(poses) if pts is None else pts
    out = labels.copy()
    out[need] = mp.nearest_labels(pts[need], landmarks, W.Q)
    return out


def _not_converged_note(objective, rtol: float) -> str:
    """Why a run that hit ``max_sweeps`` is not ``converged``: the last sweep's relative energy decrease
    against the stopping rule's ``energy_rtol``, and the two ways on (ICM's Gauss-Seidel sweeps move a long
    chain slowly; joint Gauss-Newton steps reach the same optimum in a few sweeps)."""
    if len(objective) < 2:
        return ""
    drop = (objective[-2] - objective[-1]) / max(abs(objective[-2]), 1e-300)
    return (f"; not converged: the last sweep lowered the energy by {drop:.2g} (relative; energy_rtol "
            f"{rtol:g}) — raise -p max_sweeps or add -p accelerate=joint")


@dataclasses.dataclass
class _SweepLog:
    """What :meth:`IcmSlam.solve` records per iteration (the :class:`~slamcli.types.IterationTrace` lists, the
    poses of every ``every``-th iteration) and the sweep counters reported in ``extra``."""

    objective: list
    changes: list
    times: list
    lms: list
    every: int
    pose_iters: list = dataclasses.field(default_factory=list)
    pose_snaps: list = dataclasses.field(default_factory=list)
    parts_log: list = dataclasses.field(default_factory=list)
    joint_errors: list = dataclasses.field(default_factory=list)
    joint_log: list = dataclasses.field(default_factory=list)
    polishes: list = dataclasses.field(default_factory=list)
    #: the polishes' least-squares pattern and CHOLMOD analysis, reused while the matchings keep the pattern
    workspace: nls.Workspace = dataclasses.field(default_factory=nls.Workspace)
    rejected: int = 0
    #: observation=range_bearing: sweeps whose pose and map steps were not kept (they raised H)
    proposals_rejected: int = 0
    increases: int = 0
    unconfirmed: int = 0
    joint_accepted: int = 0
    merges: int = 0

    def record(self, n, E, change, seconds, landmarks, poses) -> None:
        """Sweep ``n``'s energy, map change, wall-clock time and map points (and poses every ``every`` sweeps)."""
        self.objective.append(E)
        self.changes.append(change)
        self.times.append(seconds)
        self.lms.append(landmarks.copy())
        if self.every and n % self.every == 0:
            self.pose_iters.append(n)
            self.pose_snaps.append(poses.copy())


class IcmSlam(BaseSolver):
    """ICM-SLAM (paper 000, Algorithm 2) — see the module docstring."""

    name = "icm"
    Params = IcmParams
    #: ackermann: every motion term is the car model of the tracked point (energy.Problem); the sensor offset is
    #: handled by api.solve's sensor-frame change, so the observation potentials stay offset-free
    motion_models = ("ddmr", "ackermann")
    #: multi-robot datasets: one more potential per inter-robot reading (slamcli.solvers.icm.team)
    multi_robot = True
    #: one line from resolving the parameters with the dataset (:meth:`IcmParams.resolve_note`), set by the api
    config_note = ""

    def solve(
        self,
        inputs: SlamInputs,
        *,
        init: SolverResult | None = None,
        rng: np.random.Generator,
        progress: ProgressFn | None = None,
    ) -> SolverResult:
        if inputs.robots is not None:
            return self._solve_team(inputs, init, progress)
        t_start = time.perf_counter()
        p: IcmParams = self.params
        from slamcli.errors import ConfigError

        W, prob, rho, base_z, bias = self._problem(inputs)
        N = prob.n_obs
        reported = p.correspondences == "reported"
        fixed = reported_labels(inputs.observations.reported_id) if reported else None
        if reported and N and not np.any(fixed >= 0):
            raise ConfigError("icm: correspondences=reported needs sensor-reported ids, the dataset has none")
        extra: dict = {"schedule": p.schedule, "accelerate": p.accelerate, "weights": p.weights,
                       "motion_input": resolve_motion_input(p.motion_input, inputs),
                       "weights_used": {"R": list(W.R), "S": list(W.S), "Q": list(W.Q), "K": W.K},
                       "gps_fixes_used": int(prob.gps_step.size), "filtered": p.filtered}
        if self.config_note:
            extra["preset_note"] = self.config_note
        rematch = p.filtered == "rematch" and not reported
        # null matching behind a gate (outlier_sigma > 0, reported ids only; not under observation=range_bearing,
        # whose Cauchy kernel takes its place): τ_i per observation, or None
        tau = (gate.null_costs(prob, W, inputs.noise.range_std, inputs.noise.bearing_std, p.outlier_sigma)
               if reported and p.outlier_sigma > 0 and not W.range_bearing else None)
        extra["outlier_gate"] = p.outlier_sigma if tau is not None else "off"

        def null_E(lab) -> float:
            return 0.0 if tau is None else gate.null_energy(lab, fixed, tau)
        timings: dict = {}  # wall-clock numbers: SolverResult.timings, never extra (determinism)

        # ---- step 1: initialisation ----------------------------------------------------------------------
        t0 = time.perf_counter()
        poses, labels, landmarks = self._initialise(prob, inputs, init, fixed, W, extra, timings)
        # observations in the model: all of them (eq. 13 re-matches the filtered ones), or — filtered="drop" —
        # those with a label after the initialisation (reported: those with a sensor id)
        in_model = np.ones(N, bool) if rematch else labels >= 0
        if rematch:
            labels = _fill_nearest(prob, poses, labels, landmarks, W, in_model)
        E = en.energy(prob, W, poses, landmarks, labels)
        log = _SweepLog([E], [0.0], [time.perf_counter() - t0], [landmarks.copy()], p.trace_poses_every)
        if log.every:
            log.pose_iters, log.pose_snaps = [0], [poses.copy()]
        timings["init_s"] = log.times[0]
        if tau is not None and p.polish == "nls":  # the gate moves sightings in and out of the polish's pattern
            prime_workspace(prob, W, landmarks.shape[0], fixed, log.workspace)

        # ---- step 2: ICM sweeps ----------------------------------------------------------------------------
        status = Status.MAX_ITERATIONS if p.max_sweeps > 0 else Status.COMPLETED
        for n in range(1, p.max_sweeps + 1):
            t0 = time.perf_counter()
            if base_z is not None:  # the sweep's surface offsets / range bias, then its starting energy
                prob, bias = surf.refresh(prob, base_z, rho, bias, p.range_bias == "estimate", W, poses,
                                          landmarks, labels)
                E = en.energy(prob, W, poses, landmarks, labels) + null_E(labels)
            E_start = E
            prev_poses, prev_landmarks = poses, landmarks
            # c_0..c_T (eqs. 12-13): nearest map point to h⁻¹(x_t^{(n-1)}, z_{t,i}), every observation in the model
            if not reported and landmarks.shape[0]:
                pts = prob.landmark_points(poses)
                labels = labels.copy()
                labels[in_model] = mp.nearest_labels(pts[in_model], landmarks, W.Q, labels[in_model])
            elif tau is not None and landmarks.shape[0]:  # c-step with the null value (solvers/icm/gate.py)
                labels = gate.gate_labels(prob.landmark_points(poses), fixed, landmarks, W.Q, tau)
            if p.accelerate == "joint" and n % p.accelerate_every == 0 and not p.polish_every_sweep:
                poses, landmarks = self._joint_step(prob, W, poses, landmarks, labels, n, log)
            # x_1..x_T (eq. 14)
            poses = self._pose_sweep(prob, W, poses, labels, landmarks)
            # m (eq. 15)
            pts = prob.landmark_points(poses)
            E_pose = en.chain_energy(prob, W, poses) + en.gps_energy(prob, W, poses)
            labels, landmarks = self._map_sweep(prob, inputs, W, poses, pts, labels, landmarks, in_model,
                                                E_pose, E_start, log)
            # the energy over the observations in the model at the start of this sweep (the stopping rule's
            # comparison), then the model of the next sweep
            lab_same = labels if reported else _fill_nearest(prob, poses, labels, landmarks, W, in_model, pts)
            E_same = E_pose + en.observation_term(prob, W, poses, pts, lab_same, landmarks) + null_E(lab_same)
            if rematch:
                labels = lab_same
            elif not reported:  # reported ids: the model keeps every observation with an id (null or not)
                in_model = labels >= 0
            E = E_same if rematch else E_pose + en.observation_term(prob, W, poses, pts, labels, landmarks) + null_E(
                labels)
            if W.range_bearing and E_same > E_start:  # the quadratic conditionals' proposal raised H: not taken
                poses, landmarks, E_same, E = prev_poses, prev_landmarks, E_start, E_start
                log.proposals_rejected += 1
            decision = stop_decision(E_start, E_same, p.energy_rtol)
            poses, landmarks, E, decision = self._polish_or_confirm(prob, W, poses, landmarks, labels, E, E_start,
                                                                    E_same, decision, n, log, null_E)
            log.record(n, E, mp.map_change(prev_landmarks, landmarks), time.perf_counter() - t0, landmarks, poses)
            if progress is not None:
                progress(n, p.max_sweeps)
            if decision == "converged":
                status = Status.CONVERGED
                break
        if tau is not None:
            extra.update(outliers_nulled=int(((fixed >= 0) & (labels < 0)).sum()), energy_null=null_E(labels))
        return self._finish(prob, W, status, poses, landmarks, labels, bias, log, extra, timings, t_start)

    # -- the steps of solve ----------------------------------------------------------------------------------
    def _solve_team(self, inputs, init, progress):
        """Multi-robot datasets: :func:`slamcli.solvers.icm.team.solve_team` (no surface / range bias there)."""
        from slamcli.solvers.icm.team import solve_team

        if self.params.surface or self.params.range_bias != "none":
            from slamcli.errors import ConfigError

            raise ConfigError("icm: surface / range_bias are not implemented for multi-robot datasets")

        return solve_team(self, inputs, init=init, progress=progress)

    def _problem(self, inputs):
        """``(W, prob, ρ, the unshifted z, bias)``: the weights, the energy's :class:`~.energy.Problem` (with the
        initial surface offsets when ``surface`` / ``range_bias`` asks for them) and :meth:`_surface_setup`'s
        values. Invalid weights or data: one-line :class:`~slamcli.errors.ConfigError`."""
        from slamcli.errors import ConfigError

        p: IcmParams = self.params
        try:
            W = p.weights_for(inputs)
            prob = en.Problem.from_inputs(inputs, p.range_offset, use_gps=p.use_gps and W.K > 0,
                                          motion_input=resolve_motion_input(p.motion_input, inputs))
            if prob.gps_step.size:
                W.gps_obs_weight()  # the GPS pseudo-observation needs an isotropic Q
        except ValueError as exc:
            raise ConfigError(f"icm: {exc}") from None
        if W.range_bearing:
            self._check_range_bearing()
        rho, base_z, bias = self._surface_setup(inputs, prob)  # surface=true / range_bias=estimate
        if base_z is not None:
            prob = surf.with_range_offsets(prob, base_z, surf.initial_offsets(rho, prob.n_obs))
        return W, prob, rho, base_z, bias

    def _initialise(self, prob, inputs, init, fixed, W, extra, timings):
        """Step 1: ``(poses, labels, landmarks)`` from ``--init``'s result, the gated or the on-line
        initialisation, then (not for a given result) the map update of §4 or eq. (17) for reported labels.
        Records ``extra["init"]`` and the per-step timings."""
        from slamcli.errors import ConfigError

        p: IcmParams = self.params
        reported = fixed is not None
        if init is not None:
            poses, labels, landmarks = self._from_result(prob, init, fixed, W)
            extra["init"] = f"result:{init.solver}"
        elif p.init == "gated":
            try:
                poses, labels, landmarks, step_s, _ = gated_init(
                    prob, inputs, gate_prob=p.gate_prob, birth_prob=p.birth_prob, fixed_labels=fixed)
            except ValueError as exc:
                raise ConfigError(f"icm: {exc}") from None
            extra["init"] = p.init
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
        if init is None:
            timings["init_ms_per_step"] = float(1e3 * step_s.mean()) if step_s.size else 0.0
            timings["init_ms_per_step_max"] = float(1e3 * step_s.max()) if step_s.size else 0.0
            if not reported:  # end of step 1: the three-step map update of §4 (+ ς filter)
                pts = prob.landmark_points(poses)
                labels, landmarks, _ = mp.map_update(pts, labels, p.fusion_radius, p.min_observations)
            else:
                landmarks = self._means_keep(prob, poses, labels, landmarks)
        return poses, labels, landmarks

    def _joint_step(self, prob, W, poses, landmarks, labels, n, log):
        """``accelerate="joint"``: sweep ``n``'s joint Gauss-Newton refinement of poses and map points; the
        outcome goes to ``log``."""
        p: IcmParams = self.params
        poses, landmarks, jo = joint_refine(prob, W, poses, landmarks, labels, max_iters=p.joint_iters,
                                            step_tol=p.joint_step_tol)
        log.joint_accepted += jo.steps
        log.joint_log.append(f"{jo.steps}:{jo.reason}")
        if jo.reason.startswith("error"):
            log.joint_errors.append(f"sweep {n}: {jo.reason[7:]}")
        return poses, landmarks

    def _polish_or_confirm(self, prob, W, poses, landmarks, labels, E, E_start, E_same, decision, n, log, null_E):
        """The end of sweep ``n``. ``polish="nls"``: when the sweep lowered the energy by a relative amount
        ≤ ``polish_rtol`` (or rose), or it is the last sweep, the joint optimum of H for ``labels``
        (:func:`~slamcli.solvers.icm.polish.polish`); the run is ``converged`` only when neither the sweep nor
        the polish lowered the energy by more than ``energy_rtol``. ``polish="none"``: a ``converged`` by the
        energy rule stands only when the estimate passes the optimality test (Gauss-Newton step ≤
        ``opt_step_tol``, predicted gap ≤ ``opt_rtol`` · H); otherwise the sweeps go on. ``E``: the sweep's
        recorded energy. A sweep that raised the energy over the same terms is counted in ``log``. Returns
        ``(poses, landmarks, E, decision)``."""
        p: IcmParams = self.params
        log.increases += decision == "increase"
        if p.polish == "none":
            if decision == "converged" and not optimality(prob, W, poses, landmarks, labels).holds(
                    E, p.opt_step_tol, p.opt_rtol):
                log.unconfirmed += 1
                decision = "continue"
            return poses, landmarks, E, decision
        drop = (E_start - E_same) / max(abs(E_start), 1e-300)
        if drop > p.polish_rtol and n < p.max_sweeps:
            return poses, landmarks, E, decision
        poses, landmarks, out = polish(prob, W, poses, landmarks, labels, max_iters=p.polish_iters,
                                       extrapolate=p.polish_extrapolate, workspace=log.workspace)
        E_new = out.energy_after + null_E(labels)  # H of the returned estimate (polish evaluates it)
        log.polishes.append({"sweep": n, **out.as_extra()})
        tol = p.energy_rtol * max(abs(E_start), 1e-300)  # sweep and polish together moved nothing (a rounding
        settled = abs(E_start - E_same) <= tol and E - E_new <= tol  # rise at the optimum included)
        return poses, landmarks, E_new, "converged" if settled else "continue"

    def _pose_sweep(self, prob, W, poses, labels, landmarks):
        """x_1..x_T (eq. 14): one sweep of the pose conditional modes, on a copy of ``poses``."""
        p: IcmParams = self.params
        stats = en.step_stats(prob, labels, landmarks, W)
        poses = poses.copy()
        if p.schedule == "parallel":
            en.sweep_poses_parallel(prob, W, poses, stats, p.pose_iters)
        else:
            en.sweep_poses_sequential(prob, W, poses, stats, p.pose_iters)
        return poses

    def _map_sweep(self, prob, inputs, W, poses, pts, labels, landmarks, in_model, E_pose, E_start, log):
        """m (eq. 15): eq. (17) always; label fusion within ϑ and the ς filter (guarded when monotone), then the
        optional χ² merge. ``pts``: h⁻¹ of every observation from the new poses; ``E_pose``: the motion + GPS
        energy of the new poses; ``E_start``: the sweep's starting energy. Returns ``(labels, landmarks)``; the
        parts applied and the counters go to ``log``."""
        p: IcmParams = self.params
        if p.correspondences == "reported":
            log.parts_log.append("eq17")
            return labels, self._means_keep(prob, poses, labels, landmarks)
        labels, landmarks = mp.eq17(pts, labels)
        parts = "eq17"
        cand_labels, cand_lm, info = mp.map_update(pts, labels, p.fusion_radius, p.min_observations)
        if info["fused"] or info["removed"]:
            what = "+".join(k for k, f in (("fusion", info["fused"]), ("filter", info["removed"])) if f)
            E_cand = E_pose + en.observation_energy(
                pts, _fill_nearest(prob, poses, cand_labels, cand_lm, W, in_model, pts), cand_lm, W.Q)
            if p.monotone and E_cand > E_start:
                log.rejected += 1
                parts = f"eq17 ({what} rejected)"
            else:
                labels, landmarks = cand_labels, cand_lm
                parts = f"eq17+{what}"
        if p.merge:
            labels, landmarks, k = self._merge(prob, inputs, poses, pts, labels, landmarks, p.merge_prob)
            log.merges += k
            parts += f"+merge({k})" if k else ""
        log.parts_log.append(parts)
        return labels, landmarks

    def _finish(self, prob, W, status, poses, landmarks, labels, bias, log, extra, timings, t_start):
        """The result: ``extra``'s sweep counters and energy terms, the optional Laplace covariances, the
        iteration trace (the last iteration's poses always recorded) and the message."""
        p: IcmParams = self.params
        objective, joint_errors = log.objective, log.joint_errors
        increases = int(np.count_nonzero(np.diff(objective) > 0))  # every rise of the recorded trace
        opt = optimality(prob, W, poses, landmarks, labels)
        timings["s_per_sweep"] = float(np.mean(log.times[1:])) if len(log.times) > 1 else 0.0
        extra.update(
            sweeps=len(objective) - 1,
            map_steps_rejected=log.rejected,
            sweep_proposals_rejected=log.proposals_rejected,
            map_step_parts=log.parts_log,
            energy_increases=increases,
            energy_increases_same_terms=log.increases,
            polish=p.polish,
            polishes=log.polishes,
            polish_factor_analyses=log.workspace.analyses,
            converged_unconfirmed=log.unconfirmed,
            gradient_norm=opt.gradient_norm,
            newton_step_max=None if math.isnan(opt.step_max) else opt.step_max,
            optimum_gap=None if math.isnan(opt.gap) else opt.gap,
            distance_to_optimum_m=log.polishes[-1]["distance_to_optimum_m"] if log.polishes else None,
            joint_steps_accepted=log.joint_accepted,
            joint_refinements=log.joint_log,
            labels_merged=log.merges,
            energy_label_cost=label_cost_energy(landmarks.shape[0], p.label_cost),
            n_out_of_model=int((labels < 0).sum()),
            surface=bool(p.surface), range_bias_m=float(bias),
            **{f"energy_{k}": v for k, v in en.energy_terms(prob, W, poses, landmarks, labels).items()},
        )
        if joint_errors:
            extra["joint_step_errors"] = joint_errors[:10]
        pose_cov = lm_cov = None
        cov_note = ""
        if p.covariance and landmarks.shape[0] + prob.T > 0:
            try:
                pose_cov, lm_cov = en.laplace_covariances(prob, W, poses, landmarks, labels)
            except np.linalg.LinAlgError as exc:  # the one marginals policy: refuse, never regularise H
                why = f"the information matrix is not numerically positive definite at the estimate ({exc})"
                extra["covariance_error"] = why
                cov_note = f"; no covariances: {why}"
        every, K = log.every, len(objective)
        if every and log.pose_iters[-1] != K - 1:  # the last iteration is always recorded
            log.pose_iters.append(K - 1)
            log.pose_snaps.append(poses.copy())
        trace = IterationTrace.from_lists(objective, log.changes, log.times, log.lms,
                                          poses_per_iter=log.pose_snaps if every else None,
                                          pose_iterations=log.pose_iters if every else None)
        return self.make_result(
            status=status,
            poses_xyt=poses,
            landmarks_xy=landmarks,
            assoc=labels,
            t_start=t_start,
            message=f"{len(objective) - 1} ICM sweeps, energy {objective[0]:.6g} -> {objective[-1]:.6g}"
            + (f"; {len(log.polishes)} joint polish(es), final gradient norm {opt.gradient_norm:.2g}"
               if log.polishes else "")
            + (f"; energy rose in {increases} sweep(s)" if increases else "")
            + (_not_converged_note(objective, p.energy_rtol) if status == Status.MAX_ITERATIONS else "")
            + (f"; joint step failed: {joint_errors[0]}" if joint_errors else "")
            + cov_note + (f"; {extra['preset_note']}" if "preset_note" in extra else ""),
            pose_cov=pose_cov,
            landmark_cov=lm_cov,
            trace=trace,
            extra=extra,
            timings=timings,
        )

    # -- helpers ---------------------------------------------------------------------------------------------
    def _check_range_bearing(self) -> None:
        """One-line :class:`~slamcli.errors.ConfigError` when ``observation=range_bearing`` is combined with what
        it does not support (its energy is minimised by the polish, on fixed sensor-reported matchings)."""
        from slamcli.errors import ConfigError

        values = {k: getattr(self.params, k) for k in presets.RANGE_BEARING_NEEDS}
        bad = [f"{k}={str(values[k]).lower()}" for k in presets.range_bearing_conflicts(values)]
        if bad:
            raise ConfigError(f"icm: observation=range_bearing needs correspondences=reported and polish=nls, "
                              f"without covariance, surface or range_bias; got {', '.join(bad)}")

    def _surface_setup(self, inputs, prob):
        """``(ρ (N,) | None, the unshifted z (N, 2) | None, bias 0.0)``; None, None when the paper-exact model
        is used. One-line refusal when ``surface`` is asked for on a dataset that declares no radius."""
        from slamcli.errors import ConfigError

        p: IcmParams = self.params
        if not p.surface and p.range_bias == "none":
            return None, None, 0.0
        rho = surf.declared_radius(inputs) if p.surface else None
        if p.surface and rho is None and p.range_bias == "none":
            try:
                require_radius(inputs, "icm")
            except ConfigError as exc:
                raise ConfigError(f"{exc}; add -p range_bias=estimate to estimate a range offset instead") from None
        return rho, prob.z.copy(), 0.0

    @staticmethod
    def _merge(prob, inputs, poses, pts, labels, landmarks, merge_prob):
        """χ² label merge (:mod:`slamcli.solvers.icm.merge`) and eq. (17) for the merged labels."""
        nz = inputs.noise
        cov, _ = label_covariances(prob.step, prob.z, poses, labels, landmarks.shape[0], float(nz.range_std),
                                   float(nz.bearing_std))
        new, k, _ = merge_labels(landmarks, labels, prob.step, cov, merge_prob=merge_prob)
        if not k:
            return labels, landmarks, 0
        new_labels, new_lm = mp.eq17(pts, new)
        return new_labels, new_lm, k

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
