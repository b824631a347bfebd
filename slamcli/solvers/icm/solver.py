"""ICM-SLAM: SLAM as a Markov random field solved by iterated conditional modes (paper 000, Algorithm 2).

Nodes: the poses x_1..x_T (x_0 known), the matchings c_0..c_T of every observation to a map label, and the map
m. The Gibbs energy (eq. 5, see :mod:`slamcli.solvers.icm.energy`) is minimised node by node:

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

Deliberate deviations from the paper (Algorithm 2 as printed), each an option or a documented choice:

* **new label when nothing lies within ϑ** — eqs. (9)-(10) give the nearest existing label; the paper's own
  text creates labels for objects seen for the first time, and the on-line init does so when no map point
  lies within ϑ.
* **up to 10 fusion passes** — the paper's three-step map procedure makes one regrouping pass; regrouping
  can leave two points closer than ϑ (infeasible under Φ_m), so it is repeated (≤ 10, almost always 1).
* **running-mean map points in the init** — Algorithm 2 step 1 freezes a map point m⁽⁰⁾ at the first sight
  of its landmark; the on-line init here keeps each point as the running mean of every sighting so far (eq. 17
  applied causally), which both matches later sightings against a better point and gives a better initial map
  (the audit of issue 22 measured a mean landmark error of 0.213 m with running means against 0.329 m with the
  frozen first sightings, after step 1 on ``paper-sim1``).
* **per-return matching** — the paper groups the returns of one scan into objects before matching; here every
  return is matched on its own to the nearest map point (one KD-tree query per sweep, eqs. 12-13), so the
  returns of one post may go to different labels until fusion joins them.
* **3 Gauss-Newton steps per pose** (``pose_iters``) — eq. (14) asks for the mode of each pose conditional; a
  sweep takes a fixed number of Gauss-Newton steps with step halving instead of minimising to convergence
  (the next sweep continues from there, so the fixed point is the same; it is reached in more sweeps).
* **eq. (6) where the printed eq. (14) drops a term** — the pose conditional keeps every potential that
  involves x_t (the motion and odometry terms of step t+1 too), as eq. (6) prescribes.
* **ς defaults to 1** (paper: 500) — ς counts laser returns per landmark and must be scaled to the data
  (the paper's 500 fits its laser with many returns per post; a point sensor sees a landmark a few dozen
  times). The paper experiments in ``slamcli/experiments/`` set ς = 500.
* **the monotone guard** (``monotone=True``, default) — the map step always applies eq. (17) (the exact
  conditional mode of m for the current matchings); label fusion and the ς filter are applied only when
  the energy after them, over the same observations, does not exceed the energy at the start of the sweep.
  ``monotone=False`` is the paper's unguarded procedure. ``extra["map_step_parts"]`` records, per sweep,
  which parts ran (``eq17``, ``fusion``, ``filter``, or ``rejected`` when the guard kept the eq.-17 map).
* **stopping rule** — the paper runs a fixed number of iterations (30 / 100); here the run stops early
  (status ``converged``) when one sweep lowers the energy by a non-negative relative amount ≤
  ``energy_rtol``, over the same observations, *and* the estimate is at the optimum of its energy for its
  matchings: with ``polish="none"`` the Gauss-Newton step to that optimum is at most ``opt_step_tol`` and
  the decrease it predicts at most ``opt_rtol`` · H (:func:`slamcli.solvers.icm.polish.optimality`), with
  ``polish="nls"`` the sweep's polish lowered the energy by at most ``energy_rtol``. An energy *increase*
  (possible with ``monotone=False``) never stops the run. ``extra["energy_increases"]`` counts every rise
  of the recorded trace (with ``surface=true`` the offsets refreshed at the start of a sweep change the
  energy itself, so the trace can rise while each sweep lowers the energy of its own offsets);
  ``extra["energy_increases_same_terms"]`` counts the sweeps that raised the energy over the same terms.
* **polish="nls" is the default** (beyond the paper; ``polish="none"`` is Algorithm 2's Gauss-Seidel alone)
  — when a sweep lowers the energy by a relative amount ≤ ``polish_rtol`` (and after the last sweep), all
  poses and the map move at once to the optimum of the energy under the current matchings
  (:mod:`slamcli.solvers.icm.polish`, the project's least-squares engine); the next sweep re-matches from
  there. Gauss-Seidel sweeps stall on a long chain far from that optimum (``loop`` with known
  correspondences: 100 sweeps end 0.03-0.9 % above it, poses up to 0.3 m away); with the polish the same
  runs converge in 6-13 sweeps to within 1e-12 of it. The optimum is not always nearer the truth than a
  stalled sweep (paper-sim1 seed 0: ATE 0.331 m at the optimum, 0.301 m after 100 Gauss-Seidel sweeps;
  the octagon of Fig. 9 with R = Q = S = I, ς = 500, seeds 0-2: mean landmark error 0.18-0.23 m at the
  optimum under the matchings of 100 sweeps, 0.10-0.11 m at those sweeps' stalled estimate, 0.31-0.39 m
  away): that is a property of the energy. ``extra`` records ``polishes`` (per polish: sweep, LM iterations,
  energies, ``distance_to_optimum_m`` / ``_rad``: how far it moved the estimate), and at the end
  ``gradient_norm`` (‖∇H‖₂ over poses and map, fixed matchings), ``newton_step_max`` and ``optimum_gap``.

Observations of map points removed by the ς filter: ``filtered="rematch"`` (the paper's eq. 13) matches them
again to the nearest remaining map point in the next sweep — they stay in the energy; ``filtered="drop"``
(default) takes them out of the model for good (fewer terms: the energy falls without any optimisation, so
energies are compared over the observations in the model at the start of each sweep).

* **filtered="drop" is the default** — a deviation from eq. 13, chosen by measurement on the octagon (Fig. 9,
  R = Q = S = I, ς = 500, 100 sweeps, seeds 0-2; the two columns of the Fig. 9 section of ``slamcli
  reproduce``): re-matching the returns of the removed points (clutter, rarely seen objects) to the nearest
  remaining cone puts the energy after the init at 31,000-93,000 and takes the map from 0.11-0.12 m to
  0.41-0.73 m mean landmark error (ATE 0.7-2.3 m); dropping them leaves the energy at 115-126 and takes the map
  from 0.11-0.12 m to 0.10-0.11 m (ATE 0.16-0.17 m), the map change per sweep falling from 4.9-6.1 mm in sweep
  1 to 0.07-0.11 mm in sweep 100. With ς = 1 (the default) nothing is removed and the two are the same.

Beyond the paper (separate options, default off):

* ``schedule="parallel"`` — the coding scheme odd poses / even poses: each class is conditionally independent
  given the other, the map and the matchings, so a class is updated at once, vectorised.
* ``accelerate="joint"`` — every ``accelerate_every`` sweeps, one joint Gauss-Newton step over all poses and the
  map with the current matchings, accepted only if it lowers the same energy (backtracking).
* ``weights="information"`` — R, S, Q (and K) from the dataset's noise model (inverse covariances,
  :func:`slamcli.solvers.icm.energy.information_weights`) instead of the design matrices given.
* ``range_offset`` — added to every range before h⁻¹: a laser measures a post's surface, not its centre; the
  bias of the paper-exact inverse observation pulls map points towards the robot and drags the poses with them
  (``benchmarks/bench_icm_study.py``).

For long real runs (issue 22; separate options, default off, bundled as ``preset="real"``,
:mod:`slamcli.solvers.icm.presets`):

* ``init="gated"`` — the on-line init gates a sighting with a χ² test on a propagated pose covariance, and the
  pose's gain follows that covariance (:mod:`slamcli.solvers.icm.init_gated`, KD-tree search of the map);
* ``joint_iters`` — with ``accelerate="joint"``, Gauss-Newton steps until the step or the decrease is negligible
  (:mod:`slamcli.solvers.icm.joint`);
* ``merge`` — χ² label merge after each map step, never across labels seen in one scan; ``label_cost`` adds
  λ per landmark to the reported energy (:mod:`slamcli.solvers.icm.merge`);
* ``outlier_sigma`` — with reported ids, a null matching at a constant cost for sightings more than k σ from their
  id's map point (a truncated quadratic; :mod:`slamcli.solvers.icm.gate`).

The GPS potential of §4 (``K``, ``use_gps``) is in the energy whenever the dataset has GPS fixes (the paper
writes it down, then leaves it out of its experiments; ``use_gps=false`` or ``K=0`` drops it).
"""

from __future__ import annotations

import dataclasses
import math
import time
from typing import Literal

import numpy as np

from slamcli.solvers.base import BaseSolver, ProgressFn
from slamcli.solvers.frontend import resolve_motion_input
from slamcli.solvers.icm import energy as en
from slamcli.solvers.icm import gate
from slamcli.solvers.icm import map_step as mp
from slamcli.solvers.icm import surface as surf
from slamcli.solvers.icm.common import online_init, reported_labels, stop_decision
from slamcli.solvers.icm.init_gated import gated_init
from slamcli.solvers.icm.joint import joint_refine
from slamcli.solvers.icm.merge import label_cost_energy, label_covariances, merge_labels
from slamcli.solvers.icm.polish import optimality, polish
from slamcli.solvers.icm.presets import apply_data_rule, apply_preset, explicit_weights, weights_note
from slamcli.solvers.surface import require_radius
from slamcli.types import IterationTrace, SlamInputs, SolverResult, Status


@dataclasses.dataclass(frozen=True)
class IcmParams:
    """Parameters of ICM-SLAM (defaults: paper 000 §5, Simulation 1, except ς and the deviations listed in the
    module docstring).

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
                                 Default 1 keeps every map point (a deviation from the paper's 500, see above).
    filtered : "rematch" | "drop"  observations of removed map points: matched again to the nearest remaining
                                 point in the next sweep (paper eq. 13) or out of the model for good (default,
                                 chosen by measurement, see the module docstring).
    init : "online" | "kinematic" | "gated"  Algorithm 2 step 1 as written, poses from g(x, u) only (Fig. 6),
                                 or (beyond the paper) the on-line init whose gate and gain follow a propagated
                                 pose covariance (:mod:`slamcli.solvers.icm.init_gated`).
    gate_prob : float            init=gated: χ² probability of the association gate (2 dof; 0.99 → 9.21).
    birth_prob : float           init=gated: χ² probability of the birth test — a sighting farther than this
                                 from every label starts a new one (0.9999 → 18.4); in between it stays
                                 unlabelled until the sweeps re-match it.
    correspondences : "nearest" | "reported"  nearest-map-point matchings (eqs. 9-13), or fixed labels from the
                                 sensor-reported ids (known correspondences; no fusion, no filter).
    max_sweeps : int             maximum number of ICM iterations N.
    energy_rtol : float          the one stopping rule: stop (``converged``) when a sweep lowers the energy by a
                                 relative amount in [0, energy_rtol], over the same observations; 0 = never
                                 stop early (the paper's fixed iteration count).
    pose_iters : int             Gauss-Newton steps per pose conditional in a sweep (eq. 14).
    init_pose_iters : int        Gauss-Newton steps of the on-line init (eq. 11).
    schedule : "sequential" | "parallel"  paper visit order, or odd/even coding scheme (beyond the paper).
    accelerate : "none" | "joint"  occasional joint Gauss-Newton step (beyond the paper).
    accelerate_every : int       sweeps between joint steps.
    joint_iters : int            accelerate=joint: Gauss-Newton steps per joint refinement (1 = one step, as
                                 before); more steps stop early on ``joint_step_tol`` or a negligible energy
                                 decrease (:mod:`slamcli.solvers.icm.joint`).
    joint_step_tol : float       stop the joint refinement when its largest step is below this (m / rad).
    merge : bool                 beyond the paper: after each map step, merge labels that pass a χ² test and
                                 were never seen in one scan (:mod:`slamcli.solvers.icm.merge`).
    merge_prob : float           χ² probability of the merge test (2 dof; 0.999 → 13.8).
    preset : "paper" | "real"    named setting (:mod:`slamcli.solvers.icm.presets`): "paper" = these defaults;
                                 "real" = accelerate=joint, accelerate_every=1, joint_iters=20, max_sweeps=5,
                                 merge=true, weights=design, init=gated, gate_prob=0.9999,
                                 birth_prob=0.999999; with sensor-reported ids also correspondences=reported,
                                 init=online, weights=information, outlier_sigma=7, max_sweeps=30,
                                 polish_rtol=1, polish_iters=6, team_range_weights=true,
                                 team_odometry_only=true
                                 (each key still at its paper default takes the preset's value; other explicit
                                 values win).
    outlier_sigma : float        k > 0: an observation with a reported id whose residual exceeds k σ of the noise
                                 model takes the null matching at a constant cost (truncated quadratic,
                                 :mod:`slamcli.solvers.icm.gate`); 0 = the paper's quadratic (default). Only with
                                 correspondences=reported.
    robust : "none" | "cauchy"   multi-robot solves only (a one-robot solve ignores it): the observation and
                                 reading terms under ``graph``'s Cauchy kernel of scale ``cauchy_k`` (whitened
                                 units; ICM keeps the kernel's weights fixed through a sweep and takes them at
                                 the new estimate before the next — the half-quadratic form, still monotone;
                                 the joint steps are IRLS steps). Default "none" (the paper's quadratic).
                                 MRCLAM Dataset 7 team, preset=real: mean ATE 0.152 m against 0.136 m without.
    cauchy_k : float             the Cauchy scale (``graph``'s default 2.3849).
    team_range_weights : bool    multi-robot solves only: each sighting's (and robot reading's) isotropic weight
                                 from its own range, ``q(r) = 2 / (σ_r² + r² σ_b²)``, instead of one q at the
                                 median range (weights=information; with design weights the same factors
                                 ``q(r) / q(r̃)`` of Q); the null cost ``outlier_sigma`` keeps meaning k σ.
    team_odometry_only : bool    multi-robot solves only: drop the motion potential R when the odometry
                                 potential is on (on MRCLAM the odometry is the integral of the controls, so
                                 both count the same motion twice; ``graph`` uses the odometry alone).
    label_cost : float           λ: cost per landmark added to the reported energy (``extra["energy_label_cost"]``,
                                 0 = the paper's Φ_m); with weights=information, merging by the χ² test is
                                 merging when it lowers H + λ·L for λ = χ²₂(merge_prob).
    monotone : bool              apply label fusion and the ς filter only when they do not raise the energy
                                 above the sweep's starting energy (eq. 17 always applies); False = the
                                 paper's unguarded map step.
    weights : "design" | "information"  R, S, Q, K as given (paper) or from the dataset's noise model.
    K : float                    GPS weight k (K = k·I, paper §4); used when the dataset has GPS fixes and
                                 ``use_gps``; needs an isotropic Q (the GPS fix enters the pose conditional
                                 as a pseudo-observation). 0 drops the GPS potential.
    use_gps : bool               include the GPS potential when the dataset has fixes.
    covariance : bool            Laplace marginal covariances at the end (joint Hessian, fixed matchings).
    range_offset : float         beyond the paper (default 0 = paper-exact): added to every measured range before
                                 the inverse observation h⁻¹(x, [r + range_offset, b]), m — the same option as
                                 EKF's. A laser measures the SURFACE of a post of radius ρ: a beam at lateral
                                 offset s from the centre stops √(ρ² − s²) short of it, π/4 · ρ on average over
                                 s uniform in [−ρ, ρ], so ``range_offset = π/4 · ρ`` re-centres the returns of
                                 a post of known radius ρ (use ρ itself for a sensor that returns the nearest
                                 surface point). See ``benchmarks/bench_icm_study.py``.
    surface : bool               beyond the paper (default off = paper-exact): the surface-aware observation model
                                 (:mod:`slamcli.solvers.icm.surface`) with the landmark radius the dataset
                                 declares (``observations.diameter_m``): per-return offsets √(ρ² − s²) from the
                                 current estimate, refreshed every sweep.
    range_bias : "none" | "estimate"  beyond the paper: one more node, a common range bias estimated in every
                                 sweep (its closed-form conditional mode), with or without ``surface``.
    motion_input : "auto" | "controls" | "odometry"  what drives the motion potential and the initialisation: the
                                 controls through g(x, u), or the odometry increments (``x ⊕ d``, the full SE(2)
                                 step, sideways part included); ``auto`` (default) = the dataset's
                                 ``motion_source`` (odometry for graph imports). Recorded as
                                 ``extra["motion_input"]``. Single-robot solves.
    polish : "none" | "nls"      beyond the paper (default "nls"): the joint optimum of the energy under the
                                 current matchings when the sweeps stall (module docstring); "none" =
                                 Gauss-Seidel sweeps only (Algorithm 2). Single-robot solves; the
                                 multi-robot solve (:mod:`slamcli.solvers.icm.team`) ignores it.
    polish_rtol : float          polish after a sweep that lowered the energy by a relative amount ≤ this; ≥ 1 =
                                 after every sweep, and then accelerate=joint takes no joint steps in a one-robot
                                 solve (the polish reaches the optimum those steps approach).
    polish_iters : int           Levenberg-Marquardt iterations per polish at most.
    opt_step_tol : float         polish="none": a run is ``converged`` only when the Gauss-Newton step to the
                                 optimum has no component above this (m / rad) …
    opt_rtol : float             … and the energy decrease it predicts is at most this · H.
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
    init: Literal["online", "kinematic", "gated"] = "online"
    correspondences: Literal["nearest", "reported"] = "nearest"
    max_sweeps: int = 100
    energy_rtol: float = 1e-6
    pose_iters: int = 3
    init_pose_iters: int = 5
    schedule: Literal["sequential", "parallel"] = "sequential"
    accelerate: Literal["none", "joint"] = "none"
    accelerate_every: int = 5
    monotone: bool = True
    filtered: Literal["rematch", "drop"] = "drop"
    weights: Literal["design", "information"] = "design"
    K: float = 1.0
    use_gps: bool = True
    covariance: bool = False
    range_offset: float = 0.0
    trace_poses_every: int = 1
    surface: bool = False
    range_bias: Literal["none", "estimate"] = "none"
    gate_prob: float = 0.99
    birth_prob: float = 0.9999
    joint_iters: int = 1
    joint_step_tol: float = 1e-4
    merge: bool = False
    merge_prob: float = 0.999
    label_cost: float = 0.0
    outlier_sigma: float = 0.0
    robust: Literal["none", "cauchy"] = "none"
    cauchy_k: float = 2.3849
    team_range_weights: bool = False
    team_odometry_only: bool = False
    preset: Literal["paper", "real"] = "paper"
    motion_input: Literal["auto", "controls", "odometry"] = "auto"
    polish: Literal["none", "nls"] = "nls"
    polish_rtol: float = 1e-3
    polish_iters: int = 100
    opt_step_tol: float = 1e-4
    opt_rtol: float = 1e-8

    def __post_init__(self) -> None:
        defaults = {f.name: f.default for f in dataclasses.fields(self)}
        for key, value in apply_preset(self, defaults).items():
            object.__setattr__(self, key, value)
        en.Weights.from_params(self.R, self.S, self.Q, self.K)  # validates lengths and signs
        given = explicit_weights(self, defaults)
        if self.weights == "information" and given:
            raise ValueError(f"{', '.join(given)} given with weights=information, which takes R, S, Q, K from the "
                             "dataset's noise model: drop them or use weights=design")
        if not (self.fusion_radius >= 0 and math.isfinite(self.fusion_radius)):
            raise ValueError(f"fusion_radius must be a finite number >= 0, got {self.fusion_radius}")
        if self.min_observations < 0:
            raise ValueError(f"min_observations must be >= 0, got {self.min_observations}")
        for name in ("max_sweeps", "pose_iters", "init_pose_iters", "accelerate_every", "joint_iters", "polish_iters"):
            if getattr(self, name) < (0 if name == "max_sweeps" else 1):
                raise ValueError(
                    f"{name} must be >= {0 if name == 'max_sweeps' else 1}, got {getattr(self, name)}"
                )
        if not (self.energy_rtol >= 0):
            raise ValueError(f"energy_rtol must be >= 0, got {self.energy_rtol}")
        if not (self.range_offset >= 0 and math.isfinite(self.range_offset)):
            raise ValueError(f"range_offset must be a finite number >= 0, got {self.range_offset}")
        if not (self.outlier_sigma >= 0 and math.isfinite(self.outlier_sigma)):
            raise ValueError(f"outlier_sigma must be a finite number >= 0 (0 = no null matching), "
                             f"got {self.outlier_sigma}")
        if not (self.cauchy_k > 0 and math.isfinite(self.cauchy_k)):
            raise ValueError(f"cauchy_k must be a finite number > 0, got {self.cauchy_k}")
        if not (0.0 < self.merge_prob < 1.0):
            raise ValueError(f"merge_prob must be in (0, 1), got {self.merge_prob}")
        if self.polish not in ("none", "nls"):
            raise ValueError(f"polish must be none or nls, got {self.polish!r}")
        for name in ("joint_step_tol", "label_cost", "polish_rtol", "opt_step_tol", "opt_rtol"):
            v = getattr(self, name)
            if not (v >= 0 and math.isfinite(v)):
                raise ValueError(f"{name} must be a finite number >= 0, got {v}")
        if not (0.0 < self.gate_prob <= self.birth_prob < 1.0):
            raise ValueError(f"need 0 < gate_prob <= birth_prob < 1, got gate_prob={self.gate_prob}, "
                             f"birth_prob={self.birth_prob}")
        if self.trace_poses_every < 0:
            raise ValueError(f"trace_poses_every must be >= 0 (0 = no poses in the trace), got {self.trace_poses_every}")

    @property
    def polish_every_sweep(self) -> bool:
        """Whether every sweep of a one-robot solve ends with the polish (``polish="nls"``, ``polish_rtol ≥ 1``:
        a sweep's relative energy decrease never exceeds 1)."""
        return self.polish == "nls" and self.polish_rtol >= 1.0

    def weights_note(self, inputs: SlamInputs) -> str:
        """The line :func:`slamcli.solvers.icm.presets.weights_note` gives for this dataset (``""`` if none)."""
        return weights_note(self, {f.name: f.default for f in dataclasses.fields(self)}, _has_ids(inputs))

    def for_data(self, inputs: SlamInputs) -> IcmParams:
        """These parameters with the preset's rule for the dataset applied (``preset=real`` on data with
        sensor-reported ids: :data:`slamcli.solvers.icm.presets.WITH_IDS`); ``self`` when nothing changes."""
        defaults = {f.name: f.default for f in dataclasses.fields(self)}
        changes = apply_data_rule(self, defaults, _has_ids(inputs))
        if not changes:
            return self
        out = dataclasses.replace(self)  # a copy; the rule's values are set after __post_init__, which would
        for key, value in changes.items():  # otherwise hand a key back to the preset (init=online is the default)
            object.__setattr__(out, key, value)
        return out

    def design_weights(self) -> en.Weights:
        """R, S, Q, K as given (``weights="design"``)."""
        return en.Weights.from_params(self.R, self.S, self.Q, self.K)

    def weights_for(self, inputs: SlamInputs) -> en.Weights:
        """The weights a solve uses: the design matrices, or the dataset's information matrices."""
        return en.information_weights(inputs) if self.weights == "information" else self.design_weights()


def _has_ids(inputs: SlamInputs) -> bool:
    """Whether any observation row carries a sensor-reported id (the presets' data rule)."""
    rid = inputs.observations.reported_id
    return bool(len(rid)) and bool(np.any(np.asarray(rid) >= 0))


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
    rejected: int = 0
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

    def solve(
        self,
        inputs: SlamInputs,
        *,
        init: SolverResult | None = None,
        rng: np.random.Generator,
        progress: ProgressFn | None = None,
    ) -> SolverResult:
        resolved = self.params.for_data(inputs)
        if resolved is not self.params:  # the preset's rule for this dataset (presets.WITH_IDS)
            return type(self)(resolved).solve(inputs, init=init, rng=rng, progress=progress)
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
        if p.weights_note(inputs):
            extra["preset_note"] = p.weights_note(inputs)
        rematch = p.filtered == "rematch" and not reported
        # null matching behind a gate (outlier_sigma > 0, reported ids only): τ_i per observation, or None
        tau = (gate.null_costs(prob, W, inputs.noise.range_std, inputs.noise.bearing_std, p.outlier_sigma)
               if reported and p.outlier_sigma > 0 else None)
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

        # ---- step 2: ICM sweeps ----------------------------------------------------------------------------
        status = Status.MAX_ITERATIONS if p.max_sweeps > 0 else Status.COMPLETED
        for n in range(1, p.max_sweeps + 1):
            t0 = time.perf_counter()
            if base_z is not None:  # the sweep's surface offsets / range bias, then its starting energy
                prob, bias = surf.refresh(prob, base_z, rho, bias, p.range_bias == "estimate", W, poses,
                                          landmarks, labels)
                E = en.energy(prob, W, poses, landmarks, labels) + null_E(labels)
            E_start = E
            prev_landmarks = landmarks
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
            E_same = E_pose + en.observation_energy(pts, lab_same, landmarks, W.Q) + null_E(lab_same)
            if rematch:
                labels = lab_same
            elif not reported:  # reported ids: the model keeps every observation with an id (null or not)
                in_model = labels >= 0
            E = E_same if rematch else E_pose + en.observation_energy(pts, labels, landmarks, W.Q) + null_E(labels)
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
        poses, landmarks, out = polish(prob, W, poses, landmarks, labels, max_iters=p.polish_iters)
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
            map_step_parts=log.parts_log,
            energy_increases=increases,
            energy_increases_same_terms=log.increases,
            polish=p.polish,
            polishes=log.polishes,
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
