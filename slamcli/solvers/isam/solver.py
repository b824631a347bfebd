"""``--method isam``: the :class:`IsamSlam` driver (incremental smoother → optional final batch LM)."""

from __future__ import annotations

import time

import numpy as np

from slamcli.errors import SolverError
from slamcli.solvers import frontend, nls
from slamcli.solvers.base import BaseSolver, ProgressFn
from slamcli.solvers.graph import (
    NOISE_GROUPS,
    GraphParams,
    build_gtsam_problem,
    calibrate_noise,
    noise_sigmas,
    resolve_robust,
)
from slamcli.solvers.isam.params import IsamParams
from slamcli.solvers.isam.smoother import IncrementalSmoother
from slamcli.types import SlamInputs, SolverResult, Status


def per_step_slope(step_cpu) -> float:
    """Least-squares slope of per-update CPU time against the update index, s per update."""
    y = np.asarray(step_cpu, float)
    if y.size < 2:
        return 0.0
    return float(np.polyfit(np.arange(y.size, dtype=float), y, 1)[0])


class IsamSlam(BaseSolver):
    """Incremental smoothing for on-line SLAM (see :mod:`slamcli.solvers.isam`).

    Result: ``poses_xyt (T+1, 3)`` (the smoother's keyframes, poses between keyframes by odometry from the
    previous one; with ``final_batch`` the batch optimum of the full graph), ``landmarks_xy (L, 2)`` in order of
    first sighting, ``assoc (N,)``; no covariances. ``extra``: ``association``, ``robust``, ``keyframes``,
    ``n_landmarks``, ``batch_steps``, ``deferred_sightings`` (sightings of marginalised landmarks, used from
    the next batch step on), and with ``final_batch`` or ``noise=vce`` ``final_cost`` / ``final_iterations``;
    with ``noise=vce`` also ``noise`` and ``vce_sigma`` / ``vce_factor`` / ``vce_ratio`` (per group of
    :data:`~slamcli.solvers.graph.NOISE_GROUPS`: the σ of the returned optimum, σ / the dataset's σ, the
    variance factor measured there), ``vce_rounds`` (re-weighted solves) and ``vce_converged``.
    ``timings``: ``smoother_cpu_s``, ``max_update_cpu_s``, ``update_cpu_slope_s`` and ``final_batch_cpu_s``
    (with ``noise=vce``: every VCE round's batch solve and estimate).
    """

    name = "isam"
    Params = IsamParams
    motion_models = ("ddmr", "ackermann")

    def solve(
        self,
        inputs: SlamInputs,
        *,
        init: SolverResult | None = None,
        rng: np.random.Generator,
        progress: ProgressFn | None = None,
    ) -> SolverResult:
        """Run the smoother over ``inputs`` (``init`` and ``rng`` unused: the smoother starts from the known
        ``x0`` and draws nothing)."""
        t_start = time.perf_counter()
        p = self.params
        if inputs.robots is not None or (inputs.constraints is not None and inputs.constraints.n_between):
            raise SolverError("isam: multi-robot data and pose-pose constraints are not supported; use graph")
        if inputs.n_poses < 2:
            raise SolverError("isam: needs at least two poses")
        obs = inputs.observations
        has_ids = bool(len(obs) and np.any(np.asarray(obs.reported_id) >= 0))
        mode = p.association if p.association != "auto" else ("reported" if has_ids else "nn")
        if mode == "reported" and not has_ids:
            raise SolverError("isam: association=reported but the observations carry no reported_id")
        kernel = resolve_robust(p.robust, mode, inputs.reported_id_source)
        if p.noise == "vce" and kernel != "none":  # refused before the on-line pass, not after it
            raise SolverError(f"isam: noise=vce estimates Gaussian noise and needs robust=none (this association's "
                              f"kernel is {kernel})")
        gp_params = GraphParams(robust=kernel, cauchy_k=p.cauchy_k, huber_k=p.huber_k)
        k = gp_params.kernel_scale(kernel)
        c0 = time.process_time()
        sm = IncrementalSmoother(inputs, p, mode, kernel, k).run(progress)
        cpu = time.process_time() - c0
        poses, lms, assoc = sm.poses(), sm.landmarks(), sm.assoc
        extra = {"association": mode, "robust": kernel, "keyframes": int(sm.kf_steps.size),
                 "n_landmarks": int(lms.shape[0]), "batch_steps": int(sm.n_batches),
                 "deferred_sightings": int(sm.n_deferred), "reactivated_landmarks": int(sm.n_reactivated)}
        timings = {"smoother_cpu_s": cpu, "max_update_cpu_s": float(max(sm.step_cpu, default=0.0)),
                   "update_cpu_slope_s": per_step_slope(sm.step_cpu)}
        status, message = Status.CONVERGED, f"incremental smoother: {sm.kf_steps.size} updates"
        if lms.shape[0] and (p.final_batch or p.noise == "vce"):
            c1 = time.process_time()
            assoc_c, old_of_new = frontend.compact_labels(assoc)
            if p.noise == "vce":
                res, gp, note = _vce_batch(inputs, assoc_c, poses, lms[old_of_new], gp_params, p, extra)
            else:
                gp = build_gtsam_problem(inputs, assoc_c, poses, lms[old_of_new], gp_params)
                res, note = nls.solve(gp.problem, gp.x0, gp_params.nls_params(kernel, k)), "final batch LM"
            poses, lms = (a.copy() for a in gp.unpack(res.x))
            assoc = assoc_c
            status, message = res.status, f"{message}; {note}: {res.message}"
            extra.update(final_cost=float(res.cost), final_iterations=int(res.iterations))
            timings["final_batch_cpu_s"] = time.process_time() - c1
        elif p.noise == "vce":
            message += "; noise=vce not applied: no landmarks, the odometry alone has no redundancy"
        return self.make_result(status=status, poses_xyt=poses, landmarks_xy=lms, assoc=assoc, t_start=t_start,
                                message=message, extra=extra, timings=timings)


def _vce_batch(inputs, assoc, poses, lms, gp_params, p: IsamParams, extra: dict):
    """``noise=vce``: iterated VCE on the smoother's association (:func:`calibrate_noise`); returns the last
    round's ``(LM result, graph problem, message prefix)`` and writes the estimate into ``extra``."""
    try:
        cal = calibrate_noise(inputs, assoc, poses, lms, gp_params, tol=p.vce_tol, max_reweights=p.vce_max_rounds)
    except ValueError as exc:  # e.g. no redundancy: fewer residual rows than unknowns
        raise SolverError(f"isam: noise=vce: {exc}") from None
    sigma0 = noise_sigmas(inputs.noise)
    n = len(cal.vce.rounds) - 1
    extra.update(noise="vce", vce_rounds=n, vce_converged=cal.vce.converged,
                 vce_sigma=dict(zip(NOISE_GROUPS, cal.sigma.tolist())),
                 vce_factor=dict(zip(NOISE_GROUPS, (cal.sigma / sigma0).tolist())),
                 vce_ratio=dict(zip(NOISE_GROUPS, cal.vce.ratio.tolist())))
    state = "converged" if cal.vce.converged else f"not converged (tolerance {p.vce_tol:g})"
    note = (f"noise σ re-estimated by VCE on the smoother's association ({n} re-weighted batch solves, {state}; "
            "σ × the dataset's: " + ", ".join(f"{g} {f:.2f}" for g, f in zip(NOISE_GROUPS, cal.sigma / sigma0))
            + "); batch LM under those σ")
    return cal.result, cal.problem, note
