"""CuikSLAM with unknown correspondence (paper 004): interval constraint propagation over many kinematic
graphs.

Variables are boxes for every pose ``(x, y, θ)``, every odometry leg ``(d, α)`` and landmark ``(x, y)``; pose 0
is the known start. Poses are
added one at a time: the odometry edge t−1 → t is added to every live hypothesis and propagated; then each
observation of pose t branches every hypothesis over the landmarks of the reported type plus "a new landmark"
(§5), each branch is propagated to a fixpoint (§4, :func:`~slamcli.solvers.cuik.propagate.propagate`) and
discarded when a box becomes empty; hypotheses equal up to relabelling are merged; at most
``max_hypotheses`` stay alive (status ``truncated`` when the cap removed some — then the surviving set is no
longer guaranteed to contain the true correspondence).

The data must carry guaranteed bounds (``SlamInputs.noise_bounds``, written by the simulator's bounded-noise
option): the solver reads the bounds, never the truth. Everything is sound under those bounds: if the errors
really lie within them, the true poses and landmarks are inside the boxes of the true correspondence, which
is never discarded (unless the cap bites).

Output: every surviving hypothesis with its association and lower/upper boxes (``SolverResult.hypotheses``);
the point estimate (``poses_xyt``, ``landmarks_xy``, ``assoc``) is the box midpoint of the first hypothesis
in the ``rank`` order (default: fewest landmarks, then largest box volume).

Pruning beyond the paper's empty boxes (each sound under a declaration the data carry):

* the closest-landmark sensor (``NoiseBounds.closest_only``, paper 004 §6 "it does notice the closest
  landmark"): from a pose that reported a landmark at ``r``, no other landmark of any type lies in
  ``[r_min, r)``; from a pose that reported nothing, none lies in ``[r_min, r_max]`` (``OutsideBand``);
* a declared landmark separation (``NoiseBounds.min_separation``, a map prior, not stated by the paper):
  distinct labels are at least that far apart, in the world frame (``Separated``) and, for labels seen from
  consecutive poses, in the frame of the first pose (``SeparatedLocal``) where the boxes do not wrap.

Without the separation prior nothing sound can discard a hypothesis that splits one landmark into several
labels: twin landmarks at one spot produce exactly the same readings (ties allowed by the sensor model).
"""

from __future__ import annotations

import dataclasses
import time
from dataclasses import dataclass
from typing import ClassVar, Literal

import numpy as np

from slamcli.models.angles import wrap_angle
from slamcli.solvers.base import BaseSolver, ProgressFn
from slamcli.types import BoxHypotheses, SlamInputs, SolverResult, Status


@dataclass(frozen=True)
class CuikParams:
    """Parameters of ``cuik``.

    Attributes
    ----------
    narrow_theta : bool        True = the full operator set: the polar relations also narrow headings and
                               the legs (d, α), and a landmark seen from two consecutive poses adds a
                               local-frame cycle operator on that leg (``SharedLandmarkLeg``); False = paper
                               004's set (§6: "no narrowing of θ's were used").
    tol : float                width-change tolerance of the fixpoint: an operator's output re-queues its
                               neighbours only when a bound moved by more than this (m or rad).
    max_hypotheses : int       cap on live kinematic graphs; the first ones in the ``rank`` order are kept.
    association : "types" | "reported"
                               ``types``: unknown correspondence, branch over landmarks of the reported type
                               (paper 004 §5); ``reported``: use sensor-reported ids where present (unique
                               correspondence, Table 1; e.g. ``solve --oracle-association``).
    new_landmarks : bool       offer "a new landmark" as a branch (paper 004: the number is not known).
    shave_slices : int         0 = off; else a final 3B-consistency pass refuting outer 1/slices of every
                               variable (sound; slower).
    shave_rounds : int         passes of the 3B shaving over all variables.
    bisect_leaves : int        0 = off; else a final bisection pass over the pose headings with at most
                               this many leaves per hypothesis, replaced by the hull of the surviving leaves
                               (sound; runs after the 3B pass).
    negative_information : bool
                               when the data declare a closest-landmark sensor (``NoiseBounds.closest_only``):
                               add its negative information, one :class:`OutsideBand` operator per
                               (observation or silent pose, other landmark) — no landmark of any type is in
                               the visible band closer than the reported one (paper 004 §6: the robot
                               "does notice the closest landmark"). Sound; False = the paper's graphs only.
    separation : bool          when the data declare ``NoiseBounds.min_separation > 0`` (a map prior, not a
                               sensor fact): every pair of landmark labels is at least that far apart.
    hull_leaves : int          0 = off; else a final branch-and-bound pass (runs after 3B and bisection) that
                               moves each end of every ``hull_targets`` variable to the extreme over a cover
                               by propagated leaves, bisecting at most this many leaves per end (sound; the
                               boxes approach the hull of the feasible set, paper 004's "sharp" boxes).
    hull_targets : "landmarks" | "all"
                               the variables whose ends the hull pass tightens (landmark coordinates, or
                               every pose and landmark coordinate).
    hull_split : "legs" | "poses" | "all"
                               what the hull pass bisects: the odometry legs (d, α) — the independent
                               errors — or pose positions and headings, or both with landmarks.
    rank : str                 order used by the cap and for the output (a heuristic, not a guarantee):
                               ``parsimony_volume`` = fewest landmarks, then the LARGEST box log-volume (under
                               uniform errors an association's likelihood is proportional to the volume of
                               its feasible set; a wrong re-association survives only in a sliver where two
                               boxes overlap, so its contracted box is small); ``parsimony_area`` = fewest
                               landmarks, then the smallest total landmark box area; ``parsimony_width`` =
                               fewest landmarks, then the smallest sum of all widths. Measured on
                               cuik-corridors with a cap of 16 (bench_cuik): the smallest-first orders
                               keep wrong re-associations and drop the truth.
    recovery_slack : float     subtracted from the closest-landmark band (ties within 1 nm) and added to the
                               odometry bounds: ``(d̃, α̃)`` are recovered from the chained
                               ``odometry_xyt`` with rounding error ~1e-14 (m, rad).
    """

    narrow_theta: bool = True
    tol: float = 1e-6
    max_hypotheses: int = 256
    association: Literal["types", "reported"] = "types"
    new_landmarks: bool = True
    shave_slices: int = 0
    shave_rounds: int = 2
    bisect_leaves: int = 0
    recovery_slack: float = 1e-9
    negative_information: bool = True
    separation: bool = True
    hull_leaves: int = 0
    hull_targets: Literal["landmarks", "all"] = "landmarks"
    hull_split: Literal["legs", "poses", "all"] = "poses"
    rank: Literal["parsimony_area", "parsimony_width", "parsimony_volume"] = "parsimony_volume"

    def __post_init__(self) -> None:
        if not self.tol > 0:
            raise ValueError("tol must be > 0")
        if self.max_hypotheses < 1:
            raise ValueError("max_hypotheses must be >= 1")
        if self.hull_leaves < 0:
            raise ValueError("hull_leaves must be >= 0")
        if self.shave_slices < 0 or self.shave_rounds < 1:
            raise ValueError("shave_slices must be >= 0 and shave_rounds >= 1")
        if self.recovery_slack < 0:
            raise ValueError("recovery_slack must be >= 0")


class CuikSlam(BaseSolver):
    """Set-membership SLAM with unknown correspondence (paper 004), on codac intervals."""

    name = "cuik"
    Params = CuikParams
    #: the solver needs guaranteed error bounds (``inputs.noise_bounds``); on other data it returns FAILED, so
    #: cross-solver comparisons on Gaussian data leave it out (it has its own reproduce section, paper 004)
    needs_noise_bounds: ClassVar[bool] = True

    def solve(self, inputs: SlamInputs, *, init=None, rng: np.random.Generator,
              progress: ProgressFn | None = None) -> SolverResult:
        try:
            from slamcli.solvers.cuik.contractors import interval_rounding
        except ImportError:
            raise ValueError("cuik needs the optional interval extra: pip install 'slamcli[interval]' "
                             "(codac)") from None
        # codac's interval library computes outward-rounded bounds only in round-upward mode; the mode is set
        # for this solve and the caller's (round-to-nearest) restored afterwards
        with interval_rounding():
            return self._solve(inputs, progress)

    def _solve(self, inputs: SlamInputs, progress: ProgressFn | None) -> SolverResult:
        from slamcli.solvers.cuik.contractors import (
            Interval,
            OdometryTurnMove,
            OutsideBand,
            RangeBearing,
            Separated,
            SeparatedLocal,
            SharedLandmarkLeg,
            unbounded,
        )
        from slamcli.solvers.cuik.hypotheses import Hypothesis, merge_relabelled
        from slamcli.solvers.cuik.propagate import Counter, bisect_hull, propagate, shave

        t_start = time.perf_counter()
        p = self.params
        nb = inputs.noise_bounds
        n_poses = inputs.n_poses
        obs = inputs.observations
        why = ("the dataset declares no guaranteed error bounds (inputs/noise_bounds); simulate with "
               "bounded.enabled=true (e.g. scenario cuik-room)" if nb is None else
               f"odometry model {nb.odometry_model!r} not supported (turn_move only)"
               if nb.odometry_model != "turn_move" else None)
        if why is not None:  # no bounds, no guaranteed boxes: a documented failure, not a guess
            return self.make_result(status=Status.FAILED, poses_xyt=np.full((n_poses, 3), np.nan),
                                    landmarks_xy=np.zeros((0, 2)), assoc=np.full(len(obs), -1, np.int64),
                                    t_start=t_start, message=f"cuik: {why}")
        types = (np.asarray(obs.landmark_type, np.int64) if obs.landmark_type is not None
                 else np.zeros(len(obs), np.int64))
        h_d, h_a = (float(x) + p.recovery_slack for x in nb.odometry_half_width)
        h_r, h_b = float(nb.range_half_width), float(nb.bearing_half_width)

        odo = np.asarray(inputs.odometry_xyt, float)
        legs = np.column_stack([np.hypot(*(odo[1:, :2] - odo[:-1, :2]).T), wrap_angle(odo[1:, 2] - odo[:-1, 2])])

        # variables: poses (x, y, θ) at 3t.., legs (d, α) at 3(T+1) + 2t.., landmarks (x, y) from `base` on
        n_legs = n_poses - 1
        base = 3 * n_poses + 2 * n_legs
        box0 = [unbounded() for _ in range(base)]
        for k in range(3):
            box0[k] = Interval(float(inputs.x0[k]))
        # negative information of the closest-landmark sensor (one reading per pose at most, or the declaration
        # is contradicted by the data and not used)
        per_pose = np.diff(np.asarray(obs.offsets))
        neg = bool(p.negative_information and nb.closest_only and (per_pose <= 1).all())
        r_min, r_max = float(nb.min_range), float(inputs.max_range)
        if neg and not np.isfinite(r_max):
            r_max = float("inf")
        # lower end of each true range: R.lb of the outward-rounded reading interval [r̃ ± h_r] ∩ [0, ∞), less
        # recovery_slack (the simulator treats landmarks within 1 nm of the closest as tied)
        r_lo = [max(0.0, ((Interval(float(r)) + Interval(-h_r, h_r)) & Interval(0.0, float("inf"))).lb()
                    - p.recovery_slack) for r in np.asarray(obs.range_m, float)]
        silent: list[int] = []  # poses that reported no landmark
        sep = float(nb.min_separation) if p.separation else 0.0
        rank = {"parsimony_area": lambda h: (h.n_landmarks, h.landmark_area()),
                "parsimony_width": lambda h: (h.n_landmarks, h.total_width()),
                "parsimony_volume": lambda h: (h.n_landmarks, -h.log_volume(3))}[p.rank]
        hyps = [Hypothesis(box=box0)]
        counter = Counter()
        live_per_step: list[int] = []
        branches_per_step: list[int] = []
        merged_total = 0
        capped_steps: list[int] = []
        dropped = 0
        refuted: tuple[int, int] | None = None

        def pose_vars(t: int) -> tuple[int, int, int]:
            return (3 * t, 3 * t + 1, 3 * t + 2)

        def leg_vars(t: int) -> tuple[int, int]:
            return (3 * n_poses + 2 * t, 3 * n_poses + 2 * t + 1)

        def lm_vars(j: int) -> tuple[int, int]:
            return (base + 2 * j, base + 2 * j + 1)

        def consistent(hyps: list[Hypothesis], add_edges) -> list[Hypothesis]:
            """The hypotheses whose boxes stay non-empty after ``add_edges(h)`` (edge indices) is propagated."""
            return [h for h in hyps if propagate(h.box, h.edges, h.adj, add_edges(h), narrow_theta=p.narrow_theta,
                                                 tol=p.tol, counter=counter)]

        for t in range(n_poses):
            if t > 0:
                edge = OdometryTurnMove(pose_vars(t - 1), pose_vars(t), float(legs[t - 1, 0]),
                                        float(legs[t - 1, 1]), h_d, h_a, leg=leg_vars(t - 1))

                def add_leg(h: Hypothesis, edge=edge, leg=leg_vars(t - 1)) -> list[int]:
                    h.box[leg[0]] = Interval(edge.D)
                    h.box[leg[1]] = Interval(edge.A)
                    return [h.add_edge(edge)]

                hyps = consistent(hyps, add_leg)
                if not hyps:
                    refuted = (t, -1)
                    break
            if neg and per_pose[t] == 0:
                # a silent pose: no landmark of any type within [r_min, r_max] of pose t
                silent.append(t)
                hyps = consistent(hyps, lambda h, t=t: [h.add_edge(OutsideBand(pose_vars(t), lm_vars(m), r_min, r_max))
                                                        for m in range(h.n_landmarks)])
                if not hyps:
                    refuted = (t, -1)
                    break
            n_branch = 0
            for i in range(int(obs.offsets[t]), int(obs.offsets[t + 1])):
                r, b, ty = float(obs.range_m[i]), float(obs.bearing_rad[i]), int(types[i])
                rid = int(obs.reported_id[i])
                children = []
                for h in hyps:
                    options: list[int]
                    if p.association == "reported" and rid >= 0:
                        options = [h.reported[rid]] if rid in h.reported else [-1]
                    else:
                        options = [j for j, tj in enumerate(h.landmark_type) if tj == ty]
                        if p.new_landmarks or not options:
                            options.append(-1)
                    for n_opt, j in enumerate(options):
                        g = h if n_opt == len(options) - 1 else h.copy()
                        is_new = j < 0
                        if is_new:
                            j = g.n_landmarks
                            g.box += [unbounded(), unbounded()]
                            g.landmark_type.append(ty)
                            if p.association == "reported" and rid >= 0:
                                g.reported[rid] = j
                        lv = lm_vars(j)
                        start = [g.add_edge(RangeBearing(pose_vars(t), lv, r, b, h_r, h_b))]
                        if neg:
                            # closest-landmark sensor: every other landmark is outside [r_min, r) of pose t ...
                            start += [g.add_edge(OutsideBand(pose_vars(t), lm_vars(m), r_min, r_lo[i]))
                                      for m in range(g.n_landmarks) if m != j]
                            if is_new:  # ... and a new landmark was never closer than what earlier poses saw
                                start += [g.add_edge(OutsideBand(pose_vars(int(obs.step[k])), lv, r_min, r_lo[k]))
                                          for k in range(i)]
                                start += [g.add_edge(OutsideBand(pose_vars(s), lv, r_min, r_max)) for s in silent]
                        if sep > 0 and t > 0:  # a different label seen from pose t−1: separated, in its frame
                            start += [g.add_edge(SeparatedLocal(
                                leg_vars(t - 1), (float(obs.range_m[k]), float(obs.bearing_rad[k])), (r, b), h_r,
                                h_b, sep)) for k in range(int(obs.offsets[t - 1]), int(obs.offsets[t]))
                                if g.assoc[k] != j]
                        if is_new and sep > 0:
                            start += [g.add_edge(Separated(lm_vars(m), lv, sep)) for m in range(g.n_landmarks)
                                      if m != j]
                        if p.narrow_theta and t > 0:  # the same landmark seen from pose t−1: a local cycle
                            for k in range(int(obs.offsets[t - 1]), int(obs.offsets[t])):
                                if g.assoc[k] == j:
                                    start.append(g.add_edge(SharedLandmarkLeg(
                                        leg_vars(t - 1), (float(obs.range_m[k]), float(obs.bearing_rad[k])),
                                        (r, b), h_r, h_b)))
                        n_branch += 1
                        if propagate(g.box, g.edges, g.adj, start, narrow_theta=p.narrow_theta, tol=p.tol,
                                     counter=counter):
                            g.assoc.append(j)
                            children.append(g)
                hyps, m = merge_relabelled(children)
                merged_total += m
                if not hyps:
                    refuted = (t, i)
                    break
                if len(hyps) > p.max_hypotheses:
                    hyps.sort(key=rank)
                    dropped += len(hyps) - p.max_hypotheses
                    hyps = hyps[: p.max_hypotheses]
                    capped_steps.append(t)
            if refuted is not None:
                break
            live_per_step.append(len(hyps))
            branches_per_step.append(n_branch)
            if progress is not None:
                progress(t + 1, n_poses)

        extra = {
            "contractions": counter.contractions,
            "propagations": counter.propagations,
            "live_hypotheses_per_step": live_per_step,
            "branches_per_step": branches_per_step,
            "merged_relabelled": merged_total,
            "hypotheses_dropped_by_cap": dropped,
            "cap_hit_at_steps": capped_steps,
            "operator_set": "full" if p.narrow_theta else "paper",
            "negative_information": neg,
            "min_separation": sep,
        }
        if refuted is not None:
            t, i = refuted
            where = f"pose {t}" + (f", observation row {i}" if i >= 0 else " (odometry edge)")
            extra.update(refuted_at_pose=t, refuted_at_observation=i)
            nan = np.full((n_poses, 3), np.nan)
            return self.make_result(
                status=Status.FAILED, poses_xyt=nan, landmarks_xy=np.zeros((0, 2)),
                assoc=np.full(len(obs), -1, np.int64), t_start=t_start, extra=extra,
                message=f"every hypothesis became empty at {where}: the data contradict the declared bounds")

        if p.shave_slices > 0 or p.bisect_leaves > 0 or p.hull_leaves > 0:
            kept = []
            for h in hyps:
                variables = [v for v, x in enumerate(h.box) if x.diam() > 10 * p.tol]
                ok = p.shave_slices == 0 or shave(h.box, h.edges, h.adj, variables, narrow_theta=p.narrow_theta,
                                                  tol=p.tol, slices=p.shave_slices, rounds=p.shave_rounds,
                                                  counter=counter)
                if ok and p.bisect_leaves > 0:
                    ok = bisect_hull(h.box, h.edges, h.adj, [3 * t + 2 for t in range(n_poses)],
                                     narrow_theta=p.narrow_theta, tol=p.tol, max_leaves=p.bisect_leaves,
                                     counter=counter)
                if ok and p.hull_leaves > 0:
                    ok = _hull(h, p, n_poses, base, counter)
                if ok:
                    kept.append(h)
            hyps = kept
            extra["contractions"] = counter.contractions
            extra["propagations"] = counter.propagations
            if not hyps:
                return self.make_result(
                    status=Status.FAILED, poses_xyt=np.full((n_poses, 3), np.nan), landmarks_xy=np.zeros((0, 2)),
                    assoc=np.full(len(obs), -1, np.int64), t_start=t_start, extra=extra,
                    message="the 3B / bisection pass refuted every hypothesis: the data contradict the declared bounds")

        hyps.sort(key=rank)
        boxes = _to_arrays(hyps, n_poses, len(obs), base)
        best_lo, best_hi = boxes.pose_lo[0], boxes.pose_hi[0]
        poses = 0.5 * (best_lo + best_hi)
        poses[:, 2] = wrap_angle(poses[:, 2])
        L0 = int(boxes.n_landmarks[0])
        lms = 0.5 * (boxes.landmark_lo[0, :L0] + boxes.landmark_hi[0, :L0])
        truncated = bool(capped_steps)
        extra.update(n_hypotheses=len(hyps), n_landmarks_best=L0)
        message = (f"{len(hyps)} kinematic graph(s) survive; the hypothesis cap ({p.max_hypotheses}) removed "
                   f"{dropped} at steps {capped_steps[:5]}{'...' if len(capped_steps) > 5 else ''} — the "
                   "surviving set may miss the true correspondence" if truncated
                   else f"{len(hyps)} kinematic graph(s) survive; boxes are guaranteed under the declared bounds")
        res = self.make_result(status=Status.TRUNCATED if truncated else Status.COMPLETED, poses_xyt=poses,
                               landmarks_xy=lms, assoc=boxes.assoc[0], t_start=t_start, message=message,
                               extra=extra)
        return dataclasses.replace(res, hypotheses=boxes)


def _hull(h, p: CuikParams, n_poses: int, base: int, counter) -> bool:
    """The final branch-and-bound pass (``hull_leaves``) on one hypothesis; False when it is refuted."""
    from slamcli.solvers.cuik.propagate import hull_pass

    poses = [v for t in range(1, n_poses) for v in (3 * t, 3 * t + 1, 3 * t + 2)]
    legs = list(range(3 * n_poses, base))
    lms = list(range(base, len(h.box)))
    targets = lms if p.hull_targets == "landmarks" else poses + lms
    split = {"legs": legs, "poses": poses, "all": poses + legs + lms}[p.hull_split]
    # widths compared in metres: an angle times HULL_LEVER (a heading or turn error moves a point that far)
    scales = [HULL_LEVER if (v < 3 * n_poses and v % 3 == 2) or (3 * n_poses <= v < base and (v - 3 * n_poses) % 2)
              else 1.0 for v in split]
    return hull_pass(h.box, h.edges, h.adj, targets, split, scales, narrow_theta=p.narrow_theta, tol=p.tol,
                     max_leaves=p.hull_leaves, min_width=HULL_MIN_WIDTH, counter=counter)


#: lever arm (m) that turns an angle width into a length for the hull pass's choice of split variable
HULL_LEVER = 10.0
#: the hull pass stops splitting a leaf once every scaled split variable is narrower than this (m)
HULL_MIN_WIDTH = 1e-3


def _to_arrays(hyps, n_poses: int, n_obs: int, base: int) -> BoxHypotheses:
    """Pack hypotheses into :class:`BoxHypotheses` arrays (NaN / -1 padding for missing landmarks); landmark
    variables start at ``base``."""
    H = len(hyps)
    Lmax = max((h.n_landmarks for h in hyps), default=0)
    pose_lo = np.zeros((H, n_poses, 3))
    pose_hi = np.zeros((H, n_poses, 3))
    lm_lo = np.full((H, Lmax, 2), np.nan)
    lm_hi = np.full((H, Lmax, 2), np.nan)
    lm_type = np.full((H, Lmax), -1, np.int64)
    assoc = np.full((H, n_obs), -1, np.int64)
    for k, h in enumerate(hyps):
        lo = np.array([x.lb() for x in h.box])
        hi = np.array([x.ub() for x in h.box])
        pose_lo[k] = lo[: 3 * n_poses].reshape(n_poses, 3)
        pose_hi[k] = hi[: 3 * n_poses].reshape(n_poses, 3)
        L = h.n_landmarks
        lm_lo[k, :L] = lo[base:].reshape(L, 2)
        lm_hi[k, :L] = hi[base:].reshape(L, 2)
        lm_type[k, :L] = h.landmark_type
        assoc[k, : len(h.assoc)] = h.assoc
    return BoxHypotheses(assoc=assoc, pose_lo=pose_lo, pose_hi=pose_hi, landmark_lo=lm_lo, landmark_hi=lm_hi,
                         n_landmarks=np.array([h.n_landmarks for h in hyps], np.int64), landmark_type=lm_type)
