"""``--method ekf``: :class:`EkfParams`, importable without numpy (``slamcli solvers ekf`` reads it)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

from slamcli.params import param


@dataclass(frozen=True)
class EkfParams:
    """Parameters of :class:`EkfSlam` (all have defaults).

    Each field's documentation is its ``metadata["doc"]`` (``slamcli solvers NAME`` shows it).
    """

    association: Literal["auto", "known", "ml"] = param("auto",
        "`known`: the landmark of a row is its sensor-reported id (rows with id −1 are discarded); `ml`: "
        "maximum-likelihood association by Mahalanobis distance (paper 002 §14.7, Fig. 14.5); `auto` "
        "(default): `known` when the dataset reports ids, else `ml`. The association used is recorded as "
        '`extra["association"]`.')
    motion_input: Literal["auto", "controls", "odometry"] = param("auto",
        "Drive the prediction by the commanded controls through the DDMR model (noise `motion_std`) or by "
        "the encoder odometry increments (noise `odometry_std`, on the body-frame increment). `auto` "
        "(default): the dataset's `motion_source` (`odometry` for graph imports, whose controls are "
        "derived from the increments and lose their sideways part; `controls` otherwise). The input used "
        'is recorded as `extra["motion_input"]`.')
    gate_prob: float = param(0.99, "χ²(2) probability of the association gate: a row is fused with its "
                                   "best landmark when `d² ≤ chi2.ppf(gate_prob, 2)` (0.99 → 9.21).")
    new_landmark_prob: float = param(0.9999, "χ²(2) probability beyond which the best match is so "
                                             "unlikely that the row starts a new landmark (`d² > "
                                             "chi2.ppf(new_landmark_prob, 2)`; 0.9999 → 18.4; 0.999999 → "
                                             "27.6). In between: ambiguous → discarded (−1). With 0.9999, "
                                             "paper-sim1 seed 0 (laser, defaults otherwise) made 78 "
                                             "landmarks for 63 true; with 0.999999, 67.")
    provisional: bool = param(False, "Keep new landmarks on a provisional list first (paper 002 §14.1); "
                                     "used by `ml` association only, ignored with `known` ids: a return "
                                     "that gates nowhere becomes a landmark only after "
                                     "`provisional_min_hits` sightings. Off by default: on paper-sim1 the "
                                     "duplicates it removed are removed by `group_returns` and "
                                     "`size_gate` (0 spurious of 63, seeds 0-4), while on the car park "
                                     "(15 of 15 beacons either way) it raises the GPS ATE from 0.455 m to "
                                     "0.736 m.")
    provisional_min_hits: int = param(3, "Consistent sightings (gated) needed before a provisional "
                                         "landmark enters the state.")
    provisional_window: int = param(10, "Sensor frames (steps that carry observation rows) after its "
                                        "first sighting within which a candidate must be confirmed; "
                                        "otherwise dropped. Counted in frames, not steps: the car park "
                                        "scans every 9th step, so a window of 10 steps saw at most 2 "
                                        "sightings and confirmed 2 of 15 beacons (15 with frames).")
    exclusive_per_step: bool = param(False, "ml only: one landmark explains at most one row per (step, "
                                            "sensor). Off by default: a laser gives several returns on "
                                            "adjacent beams from one post, which must all go to the same "
                                            "landmark.")
    obs_std_scale: float = param(1.0, "Stabilising noise: factor on σ_r and σ_b used by the filter (paper "
                                      "001 §III uses ≈10).")
    motion_std_scale: float = param(1.0, "Stabilising noise: factor on the process noise standard "
                                         "deviations.")
    stabilising_pose_std: tuple[float, float, float] = param((0.0, 0.0, 0.0),
        "Extra additive pose noise [σ_x m, σ_y m, σ_θ rad] per step (world frame), 0 = off.")
    init_pose_std: tuple[float, float, float] = param((0.0, 0.0, 0.0),
        "Prior standard deviation of the start pose `x0` (0 = known exactly, fixes the gauge).")
    use_gps: bool = param(True, "Fuse the dataset's GPS position fixes (if any) with a linear update `H = "
                                "[I₂ 0]`, σ = `gps_std`.")
    group_returns: bool = param(True, "Merge the returns of one landmark at one step into one measurement "
                                      "(mean range, circular-mean bearing) before the update — for a "
                                      "laser's several hits on one post. Point sensors: no effect. On by "
                                      "default: paper-sim1 seed 0 (ml, `size_gate`): 99.7 % of the rows "
                                      "associated with it, 89.5 % without, at half the CPU.")
    group_dist: float = param(0.5, "ml + group_returns: returns whose landmark-space points are closer "
                                   "than this (m, single linkage) are one detection.")
    range_offset: float = param(0.0, "Added to every measured range (m). A laser measures a post's "
                                     "surface, on average ≈ π/4 · radius nearer than its centre; "
                                     "`range_offset` ≈ π/4 · radius re-centres those returns.")
    size_gate: bool = param(True, "`ml` with a landmark size declared per row (`observations.diameter_m`, "
                                  "radius ρ; no effect when the dataset declares none, e.g. point sensors "
                                  "and the car park): a detection that matches no state landmark but "
                                  "whose point `h⁻¹(x_r, z)` lies within 2ρ of one (two posts of radius ρ "
                                  "cannot be closer) is discarded instead of starting a landmark. A post "
                                  "cut by the edge of the field of view returns only some of its beams, "
                                  "whose mean bearing misses the centre by several σ_b at 2 m: paper-sim1 "
                                  "seed 0 with `group_returns` made 39 duplicate landmarks so, all first "
                                  "seen at 1.3-2.7 m and |bearing| 81-90°, ending 0.14-0.26 m from their "
                                  "post's first landmark; with the gate, 0.")
    surface: bool = param(False, "Lengthen every range by the mean surface-to-centre distance π/4 · ρ of "
                                 "the declared radius (:mod:`slamcli.solvers.surface`; refused when the "
                                 "dataset declares none), as graph's `surface`. Off by default: "
                                 "paper-sim1 seed 0's ATE drops from 0.216 m to 0.024 m with it, but "
                                 "Victoria Park's first 300 s (one detection per trunk) rises from 1.428 "
                                 "m to 1.449 m GPS ATE.")

    def __post_init__(self) -> None:
        if not 0.0 < self.gate_prob < 1.0:
            raise ValueError(f"gate_prob must be in (0, 1), got {self.gate_prob}")
        if not self.gate_prob <= self.new_landmark_prob < 1.0:
            raise ValueError(
                f"new_landmark_prob must be in [gate_prob, 1), got {self.new_landmark_prob} (gate_prob={self.gate_prob})"
            )
        if self.provisional_min_hits < 1 or self.provisional_window < 1:
            raise ValueError("provisional_min_hits and provisional_window must be ≥ 1")
        if self.obs_std_scale <= 0 or self.motion_std_scale <= 0:
            raise ValueError("obs_std_scale and motion_std_scale must be > 0")
        if min(self.stabilising_pose_std) < 0 or min(self.init_pose_std) < 0:
            raise ValueError("stabilising_pose_std and init_pose_std must be ≥ 0")


Params = EkfParams
