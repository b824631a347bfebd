"""Self-calibrating noise of the ``gtsam``-model factor graph: iterated variance-component estimation (VCE) of the
dataset's :class:`~slamcli.types.NoiseSpec` on a fixed association (:func:`calibrate_noise`).

Five groups of whitened residual rows, one per σ of the NoiseSpec the factors use: odometry x (along the
heading), odometry lateral, odometry heading (``odometry_std``, every per-step between factor), range and
bearing (``range_std`` / ``bearing_std``, every bearing-range factor). Other rows (the prior on ``x_0``) are in
no group. Each round builds :func:`~slamcli.solvers.graph.build.build_gtsam_problem` with the round's σ,
solves it by LM from the previous round's optimum and measures the variance factors
(:func:`slamcli.solvers.nls.variance.iterate_variance_components`); the σ of the next round are ``σ·√r``.
The factors are Gaussian (no kernel: VCE estimates Gaussian variances), built from the NoiseSpec only
(``edge_info=False``) and without GPS factors (``use_gps=False``): the estimate uses odometry and sightings.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from slamcli.solvers import nls
from slamcli.solvers.graph.build import GraphProblem, build_gtsam_problem
from slamcli.solvers.graph.params import GraphParams
from slamcli.solvers.nls.variance import IteratedVce, VceRound, iterate_variance_components
from slamcli.types import NoiseSpec, SlamInputs

#: the variance groups, in the order of :func:`noise_sigmas`
NOISE_GROUPS = ("odo_x", "odo_lat", "odo_theta", "range", "bearing")


def noise_sigmas(noise: NoiseSpec) -> np.ndarray:
    """``(5,)`` σ of :data:`NOISE_GROUPS` in ``noise``."""
    return np.array([*np.asarray(noise.odometry_std, float), noise.range_std, noise.bearing_std], float)


def noise_with_sigmas(noise: NoiseSpec, sigma) -> NoiseSpec:
    """``noise`` with the σ of :data:`NOISE_GROUPS` replaced by ``sigma (5,)`` (the control σ stay)."""
    sigma = np.asarray(sigma, float)
    return dataclasses.replace(noise, odometry_std=sigma[:3].copy(), range_std=float(sigma[3]),
                               bearing_std=float(sigma[4]))


def noise_row_groups(problem: nls.NlsProblem) -> np.ndarray:
    """Group (index into :data:`NOISE_GROUPS`, −1 = none) of every row of ``nls.residual_vector(problem)``."""
    out = []
    for b in problem.blocks:
        F, k = b.n_factors, np.shape(b.sqrt_info)[-1]
        if b.name == "odometry":
            out.append(np.tile(np.arange(3), F))
        elif b.name == "bearing_range":
            out.append(np.tile(np.array([3, 4]), F))
        else:
            out.append(np.full(F * k, -1))
    return np.concatenate(out).astype(np.int64)


def vce_graph_params(params: GraphParams | None = None) -> GraphParams:
    """``params`` (default :class:`GraphParams`) as the VCE rounds solve them: no kernel, NoiseSpec σ only,
    no GPS factors."""
    return dataclasses.replace(params or GraphParams(), robust="none", edge_info=False, use_gps=False)


@dataclass(frozen=True)
class NoiseCalibration:
    """Result of :func:`calibrate_noise`: ``vce`` (the rounds), ``noise`` (the NoiseSpec of the last solve),
    ``problem`` / ``result`` (that solve's factor graph and LM result: the batch optimum under ``noise``)."""

    vce: IteratedVce
    noise: NoiseSpec
    problem: GraphProblem
    result: nls.NlsResult

    @property
    def sigma(self) -> np.ndarray:
        return noise_sigmas(self.noise)


def calibrate_noise(
    inputs: SlamInputs,
    assoc: np.ndarray,
    poses: np.ndarray,
    landmarks: np.ndarray,
    params: GraphParams | None = None,
    tol: float = 0.05,
    max_reweights: int = 10,
    on_round: Callable[[VceRound, GraphProblem, nls.NlsResult], None] | None = None,
) -> NoiseCalibration:
    """Iterated VCE of ``inputs.noise`` at the batch optimum of the association ``assoc (N,)`` (compact labels
    ``0..L−1``, −1 = unused), the first round started from ``poses (T+1, 3)`` / ``landmarks (L, 2)``
    (module docstring). ``params``: the graph's optimiser settings (kernel, edge information and GPS are
    overridden, :func:`vce_graph_params`); ``tol`` / ``max_reweights``: the stopping rule of
    :func:`~slamcli.solvers.nls.variance.iterate_variance_components`; ``on_round(round, problem, result)``
    sees every round."""
    gp_params = vce_graph_params(params)
    sigma0 = noise_sigmas(inputs.noise)
    state = {"poses": np.asarray(poses, float), "lms": np.asarray(landmarks, float)}

    def solve_at(scale):
        noise = noise_with_sigmas(inputs.noise, sigma0 * scale)
        gp = build_gtsam_problem(dataclasses.replace(inputs, noise=noise), assoc, state["poses"], state["lms"],
                                 gp_params)
        res = nls.solve(gp.problem, gp.x0, gp_params.nls_params("none", 1.0))
        poses_r, lms_r = gp.unpack(res.x)
        state.update(poses=poses_r, lms=lms_r, noise=noise, gp=gp, res=res)
        J, e = nls.whitened_system(gp.problem, res.x)  # one evaluation of the factors for both
        return J, e, noise_row_groups(gp.problem)

    def seen(rnd):
        if on_round is not None:
            on_round(rnd, state["gp"], state["res"])

    vce = iterate_variance_components(solve_at, len(NOISE_GROUPS), tol, max_reweights, seen)
    return NoiseCalibration(vce=vce, noise=state["noise"], problem=state["gp"], result=state["res"])
