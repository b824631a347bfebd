"""Parameters of ``--method graph`` (:class:`GraphParams`) and the robust-kernel choice.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING, Literal

from slamcli.params import param

if TYPE_CHECKING:  # numpy-free at import: ``slamcli solvers graph`` reads these parameters
    from slamcli.solvers import nls


@dataclass(frozen=True)
class GraphParams:
    """Parameters of :class:`GraphSlam`.

    Each field's documentation is its ``metadata["doc"]`` (``slamcli solvers NAME`` shows it).
    """

    model: Literal["gtsam", "paper"] = param("gtsam", "Factor definitions (module docstring). Default "
                                                      '`"gtsam"`.')
    method: Literal["lm", "gn", "dogleg"] = param("lm", "Levenberg-Marquardt (default, GTSAM's damping "
                                                        "schedule), Gauss-Newton, or Powell's dogleg.")
    linear_solver: Literal["auto", "cholmod", "superlu", "chain"] = param("auto",
        "Sparse linear solver of the optimiser (:class:`slamcli.solvers.nls.NlsParams`): `auto` = CHOLMOD "
        "when it imports (CVXOPT, a dependency), else SciPy's SuperLU; ordering computed once per "
        "problem.")
    pose_chart: Literal["body", "world"] = param("body", "How the optimiser steps a pose: GTSAM's Pose2 "
                                                         "retraction `x ⊕ Exp(ξ)` (default; follows "
                                                         "GTSAM's path, hence its local minimum on "
                                                         "non-convex real data) or additive world "
                                                         "coordinates.")
    max_iterations: int = param(100, "Linear-solve budget (default 100).")
    rel_cost_tol: float = param(1e-12, "Stop when an accepted step lowers the cost by less than this "
                                       "fraction (default 1e-12).")
    pred_cost_tol: float = param(1e-10, "LM on a plain pose graph (the certificate's case, "
                                        ":meth:`GraphSlam._is_pose_graph`): stop before a step whose "
                                        "predicted decrease (the Gauss-Newton decrement) is below this "
                                        "fraction of the cost (default 1e-10; 0 = off, "
                                        ":class:`slamcli.solvers.nls.NlsParams`). On the six public pose "
                                        "graphs this saves one to three linearisations per solve and "
                                        "leaves the cost within 1e-10 (relative) of the fully polished "
                                        "one (`benchmarks/bench_posegraph_defaults.py`).")
    step_tol: float = param(1e-12, "Stop when `‖h‖ ≤ step_tol (‖x‖ + step_tol)` (default 1e-12).")
    robust: Literal["auto", "none", "huber", "cauchy", "geman_mcclure"] = param("auto",
        "Kernel on the observation, GPS and loop-closure factors (GTSAM's m-estimators, "
        ":func:`slamcli.solvers.nls.robust_kernel`). Default `auto`: `cauchy` when the association is ids "
        "reported by a real sensor (MRCLAM), else `none` (:func:`resolve_robust`); the kernel used is "
        '`extra["robust"]`.')
    huber_k: float = param(1.345, "Huber threshold on the whitened residual norm (default 1.345, 95 % "
                                  "efficiency under Gaussian noise).")
    cauchy_k: float = param(2.3849, "Cauchy scale (default 2.3849, 95 % efficiency).")
    geman_mcclure_c: float = param(1.0, "Geman-McClure scale (default 1.0, as in GTSAM's examples).")
    edge_info: bool = param(True, "Use the dataset's per-edge information matrices (`inputs.constraints`: "
                                  "lossless graph imports) for the odometry and observation factors when "
                                  "present, instead of the NoiseSpec σ's (default True).")
    init: Literal["auto", "odometry", "chordal", "spanning_tree", "robust", "incremental"] = param("auto",
        'Initial poses when `init_from = "odometry"`. `auto` (default, :func:`resolve_init`): `chordal` '
        'for a pose graph with loop closures, else `odometry`; `extra["init"]` says which. Otherwise: the '
        "chained odometry, the chordal relaxation of the rotations + linear translations over all "
        "pose-pose edges, or composition along a breadth-first spanning tree "
        "(:mod:`slamcli.solvers.graph.init`) — these two only differ from the odometry chain when the "
        "dataset has between-factors (loop closures) — or `robust`: the poses of a Cauchy-kernel solve of "
        "the same graph started from the odometry chain (:func:`robust_initial_poses`; `model=gtsam` "
        "only). A few wrong correspondences in a long chain (GTSAM's victoria_park.txt has 10 of 3640) "
        "drag a Gaussian solve started from the drifted chain into a stall far from its optimum (cost "
        "4.98e5, λ at its bound), while the same Gaussian graph started from the robust estimate "
        "converges in 8 iterations to 3164 (`benchmarks/bench_graph_real.py`). `incremental`: poses of an "
        "incremental pass for unknown correspondences (:func:`incremental_initial_poses`): every "
        "`incremental_window` seconds the sightings so far are associated by gated nearest neighbour on "
        "the current estimate and the graph is re-optimised (Cauchy kernel), so each new sighting is "
        "compared with the map from poses that drifted only since the last window, not since the start. "
        "Measured on the first 300 s of Victoria Park (aligned GPS ATE): default 21.3 m; "
        "`init=incremental robust=cauchy` 1.38 m with 3 s windows (≈ 15× the default's CPU time), 10.9 m "
        "with 10 s windows; ACFR car park, full run: default 1.79 m (11 of 15 beacons matched), "
        "incremental + cauchy 0.083 m (15 of 15). Cost: one full-chain solve per window (opt-in for that "
        "reason).")
    incremental_window: float = param(3.0, "Window of `init=incremental`, s (default 3).")
    outlier_counts: bool = param(True, "Report χ² outlier counts per factor type at the estimate "
                                       '(`extra["chi2_outliers"]`; default True).')
    association: Literal["auto", "init", "reported", "nn"] = param("auto",
        "Correspondence source: `init` = labels of the `--init` result; `reported` = sensor identities; "
        "`nn` = gated nearest neighbour on the initial poses; `auto` = init if given, else reported if "
        "any row has one, else nn.")
    gate_prob: float = param(0.999, "χ² gate probability of the nearest-neighbour front end (default 0.999).")
    nn_extra_std: float = param(0.0, "Extra landmark-space σ (m) added to every inverse observation in "
                                     "the front end (default 0.0).")
    nn_drift: bool = param(True, "Inflate the front end's landmark covariances by the dead-reckoning "
                                 "drift since their last sighting (odometry σ of the NoiseSpec), so "
                                 "revisits after a loop gate correctly (default True).")
    nn_segment_dist: float = param(0.5, "Returns of one pose that are adjacent in bearing (≤ 0.1 rad) and "
                                        "closer than this (m) are one detection, e.g. the several laser "
                                        "hits on one post (default 0.5; 0 = every row separately).")
    min_obs: int = param(1, "Landmarks with fewer associated observations are dropped (default 1 = keep "
                            "all).")
    merge_rounds: int = param(3, "With `nn` association: after each optimisation, merge landmark pairs "
                                 "that pass the correspondence test of :func:`merge_candidates` (same χ² "
                                 "gate) and re-optimise, at most this many times (default 3; 0 = off). "
                                 "Closes loops the incremental front end missed because of dead-reckoning "
                                 "drift.")
    merge_dist: float = param(1.0, "Never co-observed labels closer than this (m) are merged too (paper "
                                   "000's ϑ; default 1.0).")
    prior_std: tuple[float, float, float] = param((1e-4, 1e-4, 1e-4),
        "σ of the prior on x_0 at the known start pose (gauge), `gtsam` model (default 1e-4 m, m, rad).")
    use_odometry: bool = param(True, "Odometry between-factors (default True).")
    use_controls: bool = param(False, "Motion between-factors from the commanded controls (default False).")
    motion_lateral_std: float = param(0.01, "σ of the lateral component of a motion factor (DDMR has "
                                            "none; default 0.01 m).")
    use_gps: bool = param(True, "Position factors for GPS fixes when the dataset has them (default True).")
    group_returns: bool = param(True, "`gtsam` model: one bearing-range factor per (pose, landmark) pair "
                                      "at the mean range and circular-mean bearing of its rows "
                                      "(:func:`group_returns`; a laser's several hits on one post). Point "
                                      "sensors have one row per pair, so this changes nothing for them "
                                      "(default True).")
    estimate_range_bias: bool = param(False, "`gtsam` model: add one unknown range offset `b` to the "
                                             "state, `r̂ = ‖m − p‖ − b` (default False). A laser measures "
                                             "the surface of a post, on average ≈ π/4 · radius nearer "
                                             "than its centre; estimating `b` recovers the centres. "
                                             'Reported as `extra["range_bias"]`.')
    surface: bool = param(False, "Beyond the paper: the surface-aware model with the landmark radius ρ "
                                 "the dataset declares (`observations.diameter_m`, "
                                 ":mod:`slamcli.solvers.surface`): every range lengthened by π/4 · ρ, the "
                                 "mean distance from a post's surface hit to its centre (default False; "
                                 "refused when none is declared).")
    paper_R: tuple[tuple[float, ...], ...] | None = param(None,
        "Weight matrices of the `paper` model (3×3, 3×3, 2×2). `None` → R = 0, S = ½ diag(σ_odo)⁻², Q = ½ "
        "σ_r⁻² I (so that E equals the Gaussian negative log-likelihood of the odometry).")
    paper_S: tuple[tuple[float, ...], ...] | None = param(None,
        "Weight matrices of the `paper` model (3×3, 3×3, 2×2). `None` → R = 0, S = ½ diag(σ_odo)⁻², Q = ½ "
        "σ_r⁻² I (so that E equals the Gaussian negative log-likelihood of the odometry).")
    paper_Q: tuple[tuple[float, ...], ...] | None = param(None,
        "Weight matrices of the `paper` model (3×3, 3×3, 2×2). `None` → R = 0, S = ½ diag(σ_odo)⁻², Q = ½ "
        "σ_r⁻² I (so that E equals the Gaussian negative log-likelihood of the odometry).")
    init_from: Literal["odometry", "init"] = param("odometry",
        "Initial poses: chained odometry increments from x_0 (default) or the `--init` result's poses.")
    covariance: bool = param(True, "Compute Laplace marginal covariances (default True).")
    certify: bool = param(True, "Pose graphs (no landmarks, `model=gtsam`, no kernel, single robot): test "
                                "global optimality with the SE-Sync Lagrangian-dual certificate "
                                "(:mod:`slamcli.solvers.graph.certify`) and report it in "
                                '`extra["certificate"]` (default True).')
    restart: Literal["auto", "off"] = param("auto", "`auto` (default): a pose-graph solve from the "
                                                    "odometry (or spanning-tree) start that is not "
                                                    "certified is solved again from the chordal "
                                                    "relaxation, and the lower cost is kept; a "
                                                    "landmark-graph solve that stalls (iteration cap "
                                                    "reached with a relative decrease below "
                                                    "`STALL_REL_DECREASE` over its last `STALL_WINDOW` "
                                                    "iterations) is solved again from `init=robust`. A "
                                                    "restart runs only when it can help: its start has a "
                                                    "lower cost than the estimate, or a ridge of the cost "
                                                    "lies between them (another basin, `BASIN_PROBES`); "
                                                    "otherwise the solve stops there. Each is said in "
                                                    '`extra["restart"]` (`skipped`: why not) and the '
                                                    "message.")

    def __post_init__(self) -> None:
        import numpy as np  # constructing parameters means solving: numpy is loaded then anyway

        if self.max_iterations < 1:
            raise ValueError("max_iterations must be ≥ 1")
        if not self.pred_cost_tol >= 0.0:
            raise ValueError("pred_cost_tol must be ≥ 0")
        if self.huber_k <= 0 or self.cauchy_k <= 0 or self.geman_mcclure_c <= 0:
            raise ValueError("huber_k, cauchy_k and geman_mcclure_c must be > 0")
        if len(self.prior_std) != 3 or min(self.prior_std) <= 0:
            raise ValueError("prior_std must be three positive numbers")
        if self.merge_rounds < 0:
            raise ValueError("merge_rounds must be ≥ 0")
        if self.min_obs < 1:
            raise ValueError("min_obs must be ≥ 1")
        if not self.incremental_window > 0:
            raise ValueError("incremental_window must be > 0 s")
        if self.init_from == "odometry" and self.init in ("robust", "incremental") and self.model != "gtsam":
            raise ValueError(f"init={self.init} needs model=gtsam")
        if self.init == "incremental" and self.init_from == "odometry" and self.association in ("reported", "init"):
            raise ValueError("init=incremental builds a nearest-neighbour association (unknown correspondences); "
                             "use association=nn, or another init with reported ids / --init labels")
        for name, k in (("paper_R", 3), ("paper_S", 3), ("paper_Q", 2)):
            w = getattr(self, name)
            if w is not None and np.shape(w) != (k, k):
                raise ValueError(f"{name} must be {k}x{k}, got shape {np.shape(w)}")

    def nls_params(self, robust: str, kernel_k: float, rel_cost_tol: float | None = None,
                   pose_graph: bool = False) -> nls.NlsParams:
        """The optimiser's parameters: this method, linear solver, chart and budget with kernel ``robust`` of
        scale ``kernel_k`` (and ``rel_cost_tol`` if given); ``pred_cost_tol`` for a ``pose_graph`` only."""
        from slamcli.solvers import nls

        return nls.NlsParams(
            method=self.method,
            linear_solver=self.linear_solver,
            pose_chart=self.pose_chart,
            max_iterations=self.max_iterations,
            rel_cost_tol=self.rel_cost_tol if rel_cost_tol is None else rel_cost_tol,
            pred_cost_tol=self.pred_cost_tol if pose_graph else 0.0,
            frozen_step_rel=POSE_GRAPH_FROZEN_STEP_REL if pose_graph else 0.0,
            step_tol=self.step_tol,
            robust=robust,
            huber_k=kernel_k,
        )

    def kernel_scale(self, kernel: str) -> float:
        """The scale parameter of ``kernel`` (``huber_k``, ``cauchy_k`` or ``geman_mcclure_c``)."""
        return {"cauchy": self.cauchy_k, "geman_mcclure": self.geman_mcclure_c}.get(kernel, self.huber_k)


#: LM on a plain pose graph: simplified-Newton steps (NlsParams.frozen_step_rel) once an accepted step lowered the
#: cost by at most this fraction
POSE_GRAPH_FROZEN_STEP_REL = 1e-3

#: a landmark-graph LM run "stalls" when it reaches max_iterations and its cost fell by less than this
#: fraction over its last STALL_WINDOW iterations (GraphParams.restart)
STALL_REL_DECREASE = 1e-3
STALL_WINDOW = 10
#: a restart is skipped when its start costs more than the estimate and lies in the same basin: the cost, at
#: BASIN_PROBES evenly spaced points of the straight path from the estimate to the start, never falls by more
#: than BASIN_REL_TOL of the estimate's cost from one point to the next (no ridge between them)
BASIN_PROBES = 16
BASIN_REL_TOL = 1e-9


def resolve_robust(robust: str, association: str, id_source: str = "unknown") -> str:
    """The kernel ``robust = "auto"`` stands for: ``cauchy`` when the correspondences are identities reported
    by a real sensor (``association = "reported"`` and ``inputs.reported_id_source = "sensor"``: a misread id
    is a gross outlier no Gaussian factor absorbs — MRCLAM's barcodes), else ``none`` (simulated ids, which
    are correct by construction, graph files, gated nearest neighbour, ``--init`` labels). The measurement
    behind the choice: ``benchmarks/bench_robust_study.py`` (MRCLAM Dataset 7, five robots: mean unaligned
    ATE 0.435 m with none, 0.312 m with cauchy, 0.703 m with huber)."""
    if robust != "auto":
        return robust
    return "cauchy" if association == "reported" and id_source == "sensor" else "none"


def uses_gps(params: GraphParams, inputs) -> bool:
    """Whether the graph gets GPS factors: ``use_gps`` and the dataset has fixes."""
    import numpy as np

    return bool(params.use_gps and np.asarray(getattr(inputs, "gps_step", ())).size > 0)


def resolve_init(params: GraphParams, inputs) -> str:
    """The start ``init = "auto"`` stands for (any other value is returned as it is): ``chordal`` when the
    graph is a pose graph with loop closures — between-factors, no landmark observations, one robot, no GPS
    fix, ``model=gtsam`` without control factors — else ``odometry`` (landmark graphs keep the odometry start
    and their stall restart from ``init=robust``, GraphParams.restart).

    Why (``benchmarks/bench_graph_gtsam.py``): from the odometry chain LM stalls on MIT at cost
    385.12 (GTSAM's LM too) and only the certificate's chordal restart reaches the certified 20.60, i.e. two
    solves; from the chordal start one solve reaches it (10 LM iterations), and on intel, CSAIL, manhattan,
    City10000 and KITTI 00 the chordal start reaches the same certified optimum in as many or fewer LM
    iterations (5 / 5 / 4 / 5 / 5 vs 6 / 5 / 6 / 8 / 5 from the odometry chain)."""
    if params.init != "auto":
        return params.init
    c = inputs.constraints
    has_loops = c is not None and int(c.n_between) > 0
    pose_graph = (params.model == "gtsam" and not params.use_controls and inputs.robots is None
                  and not uses_gps(params, inputs) and len(inputs.observations) == 0)
    return "chordal" if has_loops and pose_graph else "odometry"


Params = GraphParams
