"""``--method cuik``: :class:`CuikParams`, importable without numpy (``slamcli solvers cuik`` reads it)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

from slamcli.params import param


@dataclass(frozen=True)
class CuikParams:
    """Parameters of ``cuik``.

    Each field's documentation is its ``metadata["doc"]`` (``slamcli solvers NAME`` shows it).
    """

    narrow_theta: bool = param(True, "True = the full operator set: the polar relations also narrow "
                                     "headings and the legs (d, α), and a landmark seen from two "
                                     "consecutive poses adds a local-frame cycle operator on that leg "
                                     '(`SharedLandmarkLeg`); False = paper 004\'s set (§6: "no narrowing '
                                     'of θ\'s were used").')
    tol: float = param(1e-6, "width-change tolerance of the fixpoint: an operator's output re-queues its "
                             "neighbours only when a bound moved by more than this (m or rad).")
    max_hypotheses: int = param(256, "cap on live kinematic graphs; the first ones in the `rank` order "
                                     "are kept.")
    association: Literal["types", "reported"] = param("types",
        "`types`: unknown correspondence, branch over landmarks of the reported type (paper 004 §5); "
        "`reported`: use sensor-reported ids where present (unique correspondence, Table 1; e.g. `solve "
        "--oracle-association`).")
    new_landmarks: bool = param(True, 'offer "a new landmark" as a branch (paper 004: the number is not '
                                      "known).")
    shave_slices: int = param(0, "0 = off; else a final 3B-consistency pass refuting outer 1/slices of "
                                 "every variable (sound; slower).")
    shave_rounds: int = param(2, "passes of the 3B shaving over all variables.")
    bisect_leaves: int = param(0, "0 = off; else a final bisection pass over the pose headings with at "
                                  "most this many leaves per hypothesis, replaced by the hull of the "
                                  "surviving leaves (sound; runs after the 3B pass).")
    recovery_slack: float = param(1e-9, "subtracted from the closest-landmark band (ties within 1 nm) and "
                                        "added to the odometry bounds: `(d̃, α̃)` are recovered from the "
                                        "chained `odometry_xyt` with rounding error ~1e-14 (m, rad).")
    negative_information: bool = param(True, "when the data declare a closest-landmark sensor "
                                             "(`NoiseBounds.closest_only`): add its negative information, "
                                             "one :class:`OutsideBand` operator per (observation or "
                                             "silent pose, other landmark) — no landmark of any type is "
                                             "in the visible band closer than the reported one (paper 004 "
                                             '§6: the robot "does notice the closest landmark"). Sound; '
                                             "False = the paper's graphs only.")
    local_negative: bool = param(True, "with the negative information and the full set: for landmarks "
                                       "seen from consecutive poses under different labels, the same "
                                       "constraint written in the first pose's frame "
                                       "(:class:`OutsideBandLocal`: only the leg and the readings enter, "
                                       "not the metres-wide world boxes). Sound; it is what pins the "
                                       "room's tie poses.")
    separation: bool = param(True, "when the data declare `NoiseBounds.min_separation > 0` (a map prior, "
                                   "not a sensor fact): every pair of landmark labels is at least that "
                                   "far apart.")
    hull_leaves: int = param(0, "0 = off; else a final branch-and-bound pass (runs after 3B and "
                                "bisection) that moves each end of every `hull_targets` variable to the "
                                "extreme over a cover by propagated leaves, bisecting at most this many "
                                "leaves per end (sound; the boxes approach the hull of the feasible set, "
                                'paper 004\'s "sharp" boxes).')
    hull_targets: Literal["landmarks", "all"] = param("landmarks",
        "the variables whose ends the hull pass tightens (landmark coordinates, or every pose and "
        "landmark coordinate).")
    hull_split: Literal["legs", "poses", "all"] = param("poses",
        "what the hull pass bisects: the odometry legs (d, α) — the independent errors — or pose "
        "positions and headings, or both with landmarks.")
    lp_rounds: int = param(0, "0 = off; else rounds of the LP contractor "
                              "(:mod:`~slamcli.solvers.cuik.linear`: an affine relaxation of the whole "
                              "graph over the box, every bounded variable minimised and maximised with "
                              "HiGHS, each bound made rigorous by interval arithmetic on the dual) in the "
                              "final pass, after 3B and bisection, each followed by propagation (sound; "
                              "catches the coupling through the loop that per-edge operators lose).")
    hull_lp: bool = param(False, "the hull pass bounds every leaf's end by the same LP relaxation and "
                                 "splits the widest scaled variable (no strong branching) — converges to "
                                 "the hull with far fewer leaves.")
    rank: Literal["parsimony_area", "parsimony_width", "parsimony_volume"] = param("parsimony_volume",
        "order used by the cap and for the output (a heuristic, not a guarantee): `parsimony_volume` = "
        "fewest landmarks, then the LARGEST box log-volume (under uniform errors an association's "
        "likelihood is proportional to the volume of its feasible set; a wrong re-association survives "
        "only in a sliver where two boxes overlap, so its contracted box is small); `parsimony_area` = "
        "fewest landmarks, then the smallest total landmark box area; `parsimony_width` = fewest "
        "landmarks, then the smallest sum of all widths. Measured on cuik-corridors with a cap of 16 "
        "(bench_cuik): the smallest-first orders keep wrong re-associations and drop the truth.")

    def __post_init__(self) -> None:
        if not self.tol > 0:
            raise ValueError("tol must be > 0")
        if self.max_hypotheses < 1:
            raise ValueError("max_hypotheses must be >= 1")
        if self.hull_leaves < 0:
            raise ValueError("hull_leaves must be >= 0")
        if self.lp_rounds < 0:
            raise ValueError("lp_rounds must be >= 0")
        if self.shave_slices < 0 or self.shave_rounds < 1:
            raise ValueError("shave_slices must be >= 0 and shave_rounds >= 1")
        if self.recovery_slack < 0:
            raise ValueError("recovery_slack must be >= 0")


Params = CuikParams
