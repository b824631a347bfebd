"""``--method icm``: :class:`IcmParams`, importable without numpy (``slamcli solvers icm`` reads it)."""

from __future__ import annotations

import dataclasses
import math
from typing import TYPE_CHECKING, Literal

from slamcli.params import param
from slamcli.solvers.icm import presets

if TYPE_CHECKING:
    from slamcli.solvers.icm import energy as en
    from slamcli.types import SlamInputs


@dataclasses.dataclass(frozen=True)
class IcmParams:
    """Parameters of ICM-SLAM (defaults: paper 000 §5, Simulation 1, except ς and the deviations listed in the
    module docstring).

    Each field's documentation is its ``metadata["doc"]`` (``slamcli solvers NAME`` shows it).
    """

    R: tuple[float, ...] = param((1.0,), "diagonal weight matrices of the motion (3), odometry (16) and "
                                         "observation potentials: one value = scalar × identity, else the "
                                         "full diagonal (3, 3, 2). A zero matrix drops its potential. "
                                         "Paper §5: R = Q = I, S = 0; §6: S = I.")
    S: tuple[float, ...] = param((0.0,), "diagonal weight matrices of the motion (3), odometry (16) and "
                                         "observation potentials: one value = scalar × identity, else the "
                                         "full diagonal (3, 3, 2). A zero matrix drops its potential. "
                                         "Paper §5: R = Q = I, S = 0; §6: S = I.")
    Q: tuple[float, ...] = param((1.0,), "diagonal weight matrices of the motion (3), odometry (16) and "
                                         "observation potentials: one value = scalar × identity, else the "
                                         "full diagonal (3, 3, 2). A zero matrix drops its potential. "
                                         "Paper §5: R = Q = I, S = 0; §6: S = I.")
    fusion_radius: float = param(1.0, "ϑ, m: labels whose points are closer than ϑ are fused (§4); also "
                                      "the radius within which the on-line init matches an existing "
                                      "label.")
    min_observations: int = param(1, "ς: map points seen fewer times are removed (§4; paper: 500 for its "
                                     "laser data with many returns per landmark per scan — scale it to "
                                     "the data; the simulated paper-sim1/octagon lasers give 800-3000 "
                                     "returns per landmark, so 500 fits). Default 1 keeps every map point "
                                     "(a deviation from the paper's 500, see above).")
    init: Literal["online", "kinematic", "gated"] = param("online",
        "Algorithm 2 step 1 as written, poses from g(x, u) only (Fig. 6), or (beyond the paper) the "
        "on-line init whose gate and gain follow a propagated pose covariance "
        "(:mod:`slamcli.solvers.icm.init_gated`).")
    correspondences: Literal["nearest", "reported"] = param("nearest",
        "nearest-map-point matchings (eqs. 9-13), or fixed labels from the sensor-reported ids (known "
        "correspondences; no fusion, no filter).")
    max_sweeps: int = param(100, "maximum number of ICM iterations N.")
    energy_rtol: float = param(1e-6, "the one stopping rule: stop (`converged`) when a sweep lowers the "
                                     "energy by a relative amount in [0, energy_rtol], over the same "
                                     "observations; 0 = never stop early (the paper's fixed iteration "
                                     "count).")
    pose_iters: int = param(3, "Gauss-Newton steps per pose conditional in a sweep (eq. 14).")
    init_pose_iters: int = param(5, "Gauss-Newton steps of the on-line init (eq. 11).")
    schedule: Literal["sequential", "parallel"] = param("sequential",
        "paper visit order, or odd/even coding scheme (beyond the paper).")
    accelerate: Literal["none", "joint"] = param("none", "occasional joint Gauss-Newton step (beyond the "
                                                         "paper).")
    accelerate_every: int = param(5, "sweeps between joint steps.")
    monotone: bool = param(True, "apply label fusion and the ς filter only when they do not raise the "
                                 "energy above the sweep's starting energy (eq. 17 always applies); False "
                                 "= the paper's unguarded map step.")
    filtered: Literal["rematch", "drop"] = param("drop", "observations of removed map points: matched "
                                                         "again to the nearest remaining point in the "
                                                         "next sweep (paper eq. 13) or out of the model "
                                                         "for good (default, chosen by measurement, see "
                                                         "the module docstring).")
    weights: Literal["design", "information"] = param("design",
        "R, S, Q, K as given (paper) or from the dataset's noise model.")
    K: float = param(1.0, "GPS weight k (K = k·I, paper §4); used when the dataset has GPS fixes and "
                          "`use_gps`; needs an isotropic Q (the GPS fix enters the pose conditional as a "
                          "pseudo-observation). 0 drops the GPS potential.")
    use_gps: bool = param(True, "include the GPS potential when the dataset has fixes.")
    covariance: bool = param(False, "Laplace marginal covariances at the end (joint Hessian, fixed "
                                    "matchings).")
    range_offset: float = param(0.0, "beyond the paper (default 0 = paper-exact): added to every measured "
                                     "range before the inverse observation h⁻¹(x, [r + range_offset, b]), "
                                     "m — the same option as EKF's. A laser measures the SURFACE of a "
                                     "post of radius ρ: a beam at lateral offset s from the centre stops "
                                     "√(ρ² − s²) short of it, π/4 · ρ on average over s uniform in [−ρ, "
                                     "ρ], so `range_offset = π/4 · ρ` re-centres the returns of a post of "
                                     "known radius ρ (use ρ itself for a sensor that returns the nearest "
                                     "surface point). See `benchmarks/bench_icm_study.py`.")
    trace_poses_every: int = param(1, "record the poses of iteration 0 (the initialisation), of every "
                                      "k-th iteration and of the last one in `result.trace` (paper Figs "
                                      "5b-d / 6b / 9b-c draw the trajectory after iterations 10, 20, 30, "
                                      "…); 0 = no poses in the trace. Memory: 24·(T+1) bytes per recorded "
                                      "iteration (paper-sim2, T = 3250, 100 sweeps, k = 1: 7.8 MB); raise "
                                      "k for very long runs.")
    surface: bool = param(False, "beyond the paper (default off = paper-exact): the surface-aware "
                                 "observation model (:mod:`slamcli.solvers.icm.surface`) with the "
                                 "landmark radius the dataset declares (`observations.diameter_m`): "
                                 "per-return offsets √(ρ² − s²) from the current estimate, refreshed "
                                 "every sweep.")
    range_bias: Literal["none", "estimate"] = param("none", "beyond the paper: one more node, a common "
                                                            "range bias estimated in every sweep (its "
                                                            "closed-form conditional mode), with or "
                                                            "without `surface`.")
    gate_prob: float = param(0.99, "init=gated: χ² probability of the association gate (2 dof; 0.99 → 9.21).")
    birth_prob: float = param(0.9999, "init=gated: χ² probability of the birth test — a sighting farther "
                                      "than this from every label starts a new one (0.9999 → 18.4); in "
                                      "between it stays unlabelled until the sweeps re-match it.")
    joint_iters: int = param(1, "accelerate=joint: Gauss-Newton steps per joint refinement (1 = one step, "
                                "as before); more steps stop early on `joint_step_tol` or a negligible "
                                "energy decrease (:mod:`slamcli.solvers.icm.joint`).")
    joint_step_tol: float = param(1e-4, "stop the joint refinement when its largest step is below this (m "
                                        "/ rad).")
    merge: bool = param(False, "beyond the paper: after each map step, merge labels that pass a χ² test "
                               "and were never seen in one scan (:mod:`slamcli.solvers.icm.merge`).")
    merge_prob: float = param(0.999, "χ² probability of the merge test (2 dof; 0.999 → 13.8).")
    label_cost: float = param(0.0, "λ: cost per landmark added to the reported energy "
                                   '(`extra["energy_label_cost"]`, 0 = the paper\'s Φ_m); with '
                                   "weights=information, merging by the χ² test is merging when it lowers "
                                   "H + λ·L for λ = χ²₂(merge_prob).")
    outlier_sigma: float = param(0.0, "k > 0: an observation with a reported id whose residual exceeds k "
                                      "σ of the noise model takes the null matching at a constant cost "
                                      "(truncated quadratic, :mod:`slamcli.solvers.icm.gate`); 0 = the "
                                      "paper's quadratic (default). Only with correspondences=reported.")
    robust: Literal["none", "cauchy"] = param("none", "multi-robot solves only (a one-robot solve ignores "
                                                      "it): the observation and reading terms under "
                                                      "`graph`'s Cauchy kernel of scale `cauchy_k` "
                                                      "(whitened units; ICM keeps the kernel's weights "
                                                      "fixed through a sweep and takes them at the new "
                                                      "estimate before the next — the half-quadratic "
                                                      "form, still monotone; the joint steps are IRLS "
                                                      'steps). Default "none" (the paper\'s quadratic). '
                                                      "MRCLAM Dataset 7 team, preset=real: mean ATE 0.152 "
                                                      "m against 0.136 m without.")
    cauchy_k: float = param(2.3849, "the Cauchy scale (`graph`'s default 2.3849).")
    observation: Literal["cartesian", "range_bearing"] = param("cartesian",
        "the observation potential of a one-robot solve: the paper's ‖h⁻¹(x_t, z) − m‖²_Q (eq. 5, default), "
        "or (beyond the paper) `graph`'s bearing-range factor under its Cauchy kernel, Σ k² log(1 + s²/k²) "
        "with s² = ((r̂ − r)/σ_r)² + ((b̂ − b)/σ_b)², [r̂, b̂] = h(x_t, m), σ the dataset's noise and k = "
        "`cauchy_k` (:func:`slamcli.solvers.icm.energy.range_bearing_energy`). range_bearing needs "
        "correspondences=reported and polish=nls: the recorded energy, the stopping rule and the polish "
        "(IRLS Levenberg-Marquardt) are on it; each sweep's pose and map steps keep the paper's quadratic "
        "conditionals as a proposal, kept only when it lowers the energy. The kernel replaces the null "
        "matching (`outlier_sigma` is not used) and `covariance`, `surface` and `range_bias` are refused. "
        "Multi-robot solves ignore it (see `robust`).")
    team_range_weights: bool = param(False, "multi-robot solves only: each sighting's (and robot "
                                            "reading's) isotropic weight from its own range, `q(r) = 2 / "
                                            "(σ_r² + r² σ_b²)`, instead of one q at the median range "
                                            "(weights=information; with design weights the same factors "
                                            "`q(r) / q(r̃)` of Q); the null cost `outlier_sigma` keeps "
                                            "meaning k σ.")
    team_odometry_only: bool = param(False, "multi-robot solves only: drop the motion potential R when "
                                            "the odometry potential is on (on MRCLAM the odometry is the "
                                            "integral of the controls, so both count the same motion "
                                            "twice; `graph` uses the odometry alone).")
    odometry_only: bool = param(False, "one-robot solves: drop the motion potential R when the odometry "
                                       "potential is on (`team_odometry_only`'s rule for one robot: where the "
                                       "odometry is the integral of the controls both count the same motion "
                                       "twice; `graph` uses the odometry alone).")
    preset: Literal["paper", "real"] = param("paper", "named setting (:mod:`slamcli.solvers.icm.presets`), "
                                             "built by `IcmParams.real(**given)`: keys given explicitly keep their "
                                             "values; " + "; ".join(f"{name} = {presets.expansion_text(name)}"
                                                                    for name in presets.PRESETS) + ".")
    motion_input: Literal["auto", "controls", "odometry"] = param("auto",
        "what drives the motion potential and the initialisation: the controls through g(x, u), or the "
        "odometry increments (`x ⊕ d`, the full SE(2) step, sideways part included); `auto` (default) = "
        "the dataset's `motion_source` (odometry for graph imports). Recorded as "
        '`extra["motion_input"]`. Single-robot solves.')
    polish: Literal["none", "nls"] = param("nls", 'beyond the paper (default "nls"): the joint optimum of '
                                                  "the energy under the current matchings when the sweeps "
                                                  'stall (module docstring); "none" = Gauss-Seidel sweeps '
                                                  "only (Algorithm 2). Single-robot solves; the "
                                                  "multi-robot solve (:mod:`slamcli.solvers.icm.team`) "
                                                  "ignores it.")
    polish_rtol: float = param(1e-3, "polish after a sweep that lowered the energy by a relative amount ≤ "
                                     "this; ≥ 1 = after every sweep, and then accelerate=joint takes no joint "
                                     "steps in a one-robot solve (the polish reaches the optimum they approach).")
    polish_iters: int = param(100, "Levenberg-Marquardt iterations per polish at most.")
    polish_extrapolate: bool = param(False, "the polish runs LM in chunks of two iterations and extrapolates "
                                            "each chunk's displacement Δ to the lowest energy of x + βΔ, β = "
                                            "1, 2, 4 … 32 (:func:`slamcli.solvers.icm.polish.polish`): a "
                                            "weakly held mode that LM moves a few per cent per iteration "
                                            "gets there in a few chunks. Default off (one LM run). "
                                            "Single-robot solves.")
    opt_step_tol: float = param(1e-4, 'polish="none": a run is `converged` only when the Gauss-Newton '
                                      "step to the optimum has no component above this (m / rad) …")
    opt_rtol: float = param(1e-8, "… and the energy decrease it predicts is at most this · H.")

    def __post_init__(self) -> None:
        from slamcli.solvers.icm import energy as en  # constructing parameters means solving: numpy is loaded

        presets.check_name(self.preset)
        en.Weights.from_params(self.R, self.S, self.Q, self.K)  # validates lengths and signs
        given = [k for k in presets.WEIGHT_KEYS if getattr(self, k) != _DEFAULTS[k]]
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
        if self.observation not in ("cartesian", "range_bearing"):
            raise ValueError(f"observation must be cartesian or range_bearing, got {self.observation!r}")
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

    @classmethod
    def paper(cls, **given) -> IcmParams:
        """Algorithm 2 as the paper runs it: the field defaults, ``given`` over them."""
        return cls.resolve({**given, "preset": "paper"})

    @classmethod
    def real(cls, **given) -> IcmParams:
        """The setting for real recordings (:data:`slamcli.solvers.icm.presets.PRESETS`), ``given`` over it."""
        return cls.resolve({**given, "preset": "real"})

    @classmethod
    def resolve(cls, given: dict, inputs: SlamInputs | None = None) -> IcmParams:
        """The parameters for the keys ``given`` explicitly: the preset named by ``given["preset"]`` fills the
        keys left unset, with its sensor-reported-ids rule when ``inputs`` carry ids."""
        name = given.get("preset", "paper")
        return cls(**presets.resolve(name, given, inputs is not None and _has_ids(inputs)))

    def given(self) -> dict:
        """The keys of these parameters away from their preset's values, with ``preset`` (what a caller that
        passes an instance is taken to have given)."""
        base = _DEFAULTS | presets.PRESETS[self.preset]
        return {k: getattr(self, k) for k in _DEFAULTS if getattr(self, k) != base[k]} | {"preset": self.preset}

    @classmethod
    def resolve_note(cls, given: dict, inputs: SlamInputs) -> str:
        """The lines :func:`~slamcli.solvers.icm.presets.weights_note` and
        :func:`~slamcli.solvers.icm.presets.range_bearing_note` give for this dataset, joined by ``"; "``
        (``""`` if none)."""
        name, ids = given.get("preset", "paper"), _has_ids(inputs)
        return "; ".join(n for n in (presets.weights_note(name, given, ids),
                                     presets.range_bearing_note(name, given, ids)) if n)

    def design_weights(self) -> en.Weights:
        """R, S, Q, K as given (``weights="design"``)."""
        from slamcli.solvers.icm import energy as en

        return en.Weights.from_params(self.R, self.S, self.Q, self.K)

    def weights_for(self, inputs: SlamInputs) -> en.Weights:
        """The weights a solve uses: the design matrices, or the dataset's information matrices; in a one-robot
        solve with ``observation=range_bearing`` also that potential's σ and Cauchy scale, and R = 0 with
        ``odometry_only``."""
        from slamcli.solvers.icm import energy as en

        W = en.information_weights(inputs) if self.weights == "information" else self.design_weights()
        solo = getattr(inputs, "robots", None) is None
        if self.odometry_only and solo and W.use_odometry:
            W = dataclasses.replace(W, R=(0.0, 0.0, 0.0))
        if self.observation == "range_bearing" and solo:
            nz = inputs.noise
            sigma = (float(nz.range_std), float(nz.bearing_std))
            if not (min(sigma) > 0 and all(math.isfinite(v) for v in sigma)):
                raise ValueError(f"observation=range_bearing: noise.range_std, noise.bearing_std = {list(sigma)} "
                                 "must be positive")
            W = dataclasses.replace(W, obs_model="range_bearing", obs_sigma=sigma, cauchy_k=float(self.cauchy_k))
        return W


_DEFAULTS = {f.name: f.default for f in dataclasses.fields(IcmParams)}


def _has_ids(inputs: SlamInputs) -> bool:
    """Whether any observation row carries a sensor-reported id (the presets' data rule)."""
    import numpy as np

    rid = inputs.observations.reported_id
    return bool(len(rid)) and bool(np.any(np.asarray(rid) >= 0))


Params = IcmParams
