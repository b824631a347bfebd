"""``--method fastslam``: :class:`FastSlamParams`, importable without numpy (``slamcli solvers fastslam`` reads it)."""

from __future__ import annotations

import dataclasses
import math
from typing import Literal

from slamcli.params import param


@dataclasses.dataclass(frozen=True)
class FastSlamParams:
    """Parameters of :class:`FastSlam`.

    Each field's documentation is its ``metadata["doc"]`` (``slamcli solvers NAME`` shows it).
    """

    n_particles: int = param(50, "Number of particles P. Default 50: with `group_returns` a default run "
                                 "of paper-sim1 (3251 steps, ≈ 42 laser returns per step) finishes in "
                                 "under a minute (`benchmarks/results/defaults.csv`); 2.0's proposal "
                                 "needs few particles (Montemerlo et al. 2003).")
    version: Literal[1, 2] = param(2, "1 = proposal from the motion model; 2 = proposal improved by the "
                                      "observations (sampled, not its mean).")
    association: Literal["auto", "known", "ml"] = param("auto",
        "`known` uses `observations.reported_id` (rows with id −1 are ignored, assoc −1); `ml` = "
        "per-particle maximum likelihood (eq. 14.30; keeps an `(N_obs, P)` int32 association history); "
        "`auto` (default) = `known` when the dataset reports ids, else `ml`; the association used is "
        'recorded as `extra["association"]`.')
    motion_source: Literal["auto", "controls", "odometry"] = param("auto",
        "Motion model used for the proposal: commanded controls with `noise.motion_std` (DDMR, paper 000 "
        "§4), or the encoder odometry increments (eq. 16) with `noise.odometry_std`. `auto` (default): "
        "the dataset's `motion_source` (odometry for graph imports, whose controls lose the sideways part "
        'of each step); the source used is recorded as `extra["motion_input"]`.')
    motion_noise_scale: float = param(1.0, "Multiplies the motion noise standard deviations (`>1` = "
                                           "stabilising noise; 1 = as specified).")
    resampling: Literal["systematic", "multinomial"] = param("systematic",
        "Resampling scheme (:mod:`slamcli.solvers.resampling`): systematic (one uniform draw, lower "
        "variance) or multinomial (P independent draws).")
    resample_threshold: float = param(0.5, "Resample when `ESS < resample_threshold · P` (0 = never, 1 = "
                                           "every step).")
    output: Literal["mean", "best"] = param("mean", "Reported path: weighted mean per step, or the best "
                                                    "final particle's path.")
    p0: float | None = param(None, "ML association: new-landmark likelihood (a density in measurement "
                                   "space). `None` = the Gaussian density of the sensor noise `Q` at "
                                   "Mahalanobis² = χ²₂(0.9999) = 18.42.")
    remove_unsupported: bool = param(False, "ML association: drop landmarks by negative evidence inside "
                                            "the sensor's range / field of view.")
    fov_rad: float = param(2.0 * math.pi, "Sensor field of view used by the negative-evidence test (full "
                                          "width, rad; 2π = omnidirectional).")
    removal_range_frac: float = param(0.95, "Negative evidence only counts for landmarks predicted within "
                                            "`removal_range_frac · max_range` (misses right at the range "
                                            "edge are expected).")
    group_returns: bool = param(True, "Merge the returns of one landmark at one step into one measurement "
                                      "(mean range, circular-mean bearing; "
                                      ":func:`slamcli.solvers.frontend.group_detections`, as EKF's): "
                                      "`known` by reported id, `ml` by single-linkage clusters of the "
                                      "inverse observations closer than `group_dist` (from the previous "
                                      "estimate). A laser hits a post on several adjacent beams; fused "
                                      "one by one they overweight that pose-landmark pair and cost one "
                                      "particle update each (paper-sim1: ≈ 42 returns per step). Point "
                                      "sensors (one row per landmark and step) are unaffected. On by "
                                      "default.")
    group_dist: float = param(0.5, "`ml` + `group_returns`: cluster distance in metres.")
    size_gate: bool = param(True, "`ml` with a landmark size declared per row (`observations.diameter_m`, "
                                  "radius ρ; no effect when the dataset declares none), per particle: a "
                                  "detection that would start a new landmark in a particle whose map has "
                                  "a landmark within 2ρ of its point `h⁻¹(x^[k], z)` (two posts of radius "
                                  "ρ cannot be closer) is a cut view of that post: its landmark is hidden "
                                  "from the reported map (`size_gate_hide`, default) or dropped at the "
                                  "end of the step (EKF's `size_gate`; "
                                  ":func:`slamcli.solvers.frontend.inside_declared_size`). The particle "
                                  "is weighted as for a new landmark (`p0`): the gate changes the map, "
                                  "not the weights. A post cut by the edge of the field of view returns "
                                  "only some of its beams, whose mean bearing misses the centre: "
                                  "paper-sim1 seed 0 without the gate made 36 extra landmarks so (of 99; "
                                  "63 true), all first seen at 1.35-2.65 m and |bearing| 79-90°, ending "
                                  "0.17-0.26 m from their post's first landmark.")
    size_gate_hide: bool = param(True, "With `size_gate`: keep the gated landmark inside the particle, "
                                       "flagged, and leave it (and its rows) out of the reported map, "
                                       "instead of dropping it. The flagged landmark goes on absorbing "
                                       "the later returns of that cut view, so the filter runs exactly as "
                                       "without the gate. Defaults (size_gate, hidden) on paper-sim1 / "
                                       "paper-sim2 seeds 0-4: spurious landmarks 39.2 → 0.0 and 49.6 → "
                                       "12.2 of 63 (matched 63.0 → 63.0 and 52.4 → 50.8), aligned ATE "
                                       "unchanged (0.180 m, 0.388 m); dropped instead, spurious 0.0 and "
                                       "12.0 but ATE 0.189 m and 0.418 m (worse on every paper-sim1 "
                                       "seed).")

    def __post_init__(self) -> None:
        import numpy as np  # constructing parameters means solving: numpy is loaded then anyway

        from slamcli.solvers.resampling import RESAMPLERS

        if self.n_particles < 1:
            raise ValueError(f"n_particles must be ≥ 1, got {self.n_particles}")
        if self.version not in (1, 2):
            raise ValueError(f"version must be 1 or 2, got {self.version}")
        if self.association not in ("auto", "known", "ml"):
            raise ValueError(f"association must be 'auto', 'known' or 'ml', got {self.association!r}")
        if self.motion_source not in ("auto", "controls", "odometry"):
            raise ValueError(f"motion_source must be 'auto', 'controls' or 'odometry', got {self.motion_source!r}")
        if self.resampling not in RESAMPLERS:
            raise ValueError(f"resampling must be one of {', '.join(RESAMPLERS)}, got {self.resampling!r}")
        if self.output not in ("mean", "best"):
            raise ValueError(f"output must be 'mean' or 'best', got {self.output!r}")
        if not 0.0 <= self.resample_threshold <= 1.0:
            raise ValueError(f"resample_threshold must be in [0, 1], got {self.resample_threshold}")
        if not self.motion_noise_scale > 0.0:
            raise ValueError(f"motion_noise_scale must be > 0, got {self.motion_noise_scale}")
        if self.p0 is not None and not self.p0 > 0.0:
            raise ValueError(f"p0 must be > 0, got {self.p0}")
        if not self.fov_rad > 0.0:
            raise ValueError(f"fov_rad must be > 0, got {self.fov_rad}")
        if not self.group_dist > 0.0:
            raise ValueError(f"group_dist must be > 0, got {self.group_dist}")
        for name in ("size_gate", "size_gate_hide"):
            if not isinstance(getattr(self, name), (bool, np.bool_)):
                raise ValueError(f"{name} must be true or false, got {getattr(self, name)!r}")
        if not 0.0 < self.removal_range_frac <= 1.0:
            raise ValueError(f"removal_range_frac must be in (0, 1], got {self.removal_range_frac}")


Params = FastSlamParams
