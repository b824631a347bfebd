"""CuikSLAM with unknown correspondence (paper 004): interval constraint propagation over many kinematic
graphs.

Variables are boxes for every pose ``(x, y, θ)``, odometry leg ``(d, α)`` and landmark ``(x, y)``; pose 0 is
the known start. Poses are added one at a time: the odometry edge is added to every live hypothesis and
propagated; each observation branches every hypothesis over the landmarks of the reported type plus "a new
landmark" (§5); each branch is propagated to a fixpoint (§4, :func:`~slamcli.solvers.cuik.propagate.propagate`)
and discarded when a box empties; hypotheses equal up to relabelling are merged; at most ``max_hypotheses``
stay alive (status ``truncated`` when the cap removed some — then the true correspondence may be lost).

The data must carry guaranteed bounds (``SlamInputs.noise_bounds``); the solver never reads the truth. If
the errors lie within the bounds, the true poses and landmarks are inside the boxes of the true
correspondence, which is never discarded (unless the cap bites).

Output: every surviving hypothesis with its association and boxes (``SolverResult.hypotheses``); the point
estimate is the box midpoint of the first hypothesis in ``rank`` order (default: fewest landmarks, then
largest volume). Pruning beyond empty boxes, each sound under a declaration the data carry: the
closest-landmark sensor (``NoiseBounds.closest_only``: no other landmark nearer than a reported one,
``OutsideBand``) and a declared landmark separation (``NoiseBounds.min_separation``: ``Separated``,
``SeparatedLocal``). Without the separation prior nothing sound can discard a hypothesis that splits one
landmark into twins at one spot.
"""

from __future__ import annotations

import dataclasses
import time
from typing import ClassVar

import numpy as np

from slamcli.models.angles import wrap_angle
from slamcli.solvers.base import BaseSolver, ProgressFn
from slamcli.solvers.cuik.params import CuikParams
from slamcli.types import BoxHypotheses, SlamInputs, SolverResult, Status


class CuikSlam(BaseSolver):
    """Set-membership SLAM with unknown correspondence (paper 004), on codac intervals."""

    name = "cuik"
    Params = CuikParams
    #: the solver needs guaranteed error bounds (``inputs.noise_bounds``); on other data it returns FAILED, so
    #: cross-solver comparisons on Gaussian data leave it out (it has its own reproduce section, paper 004)
    needs_noise_bounds: ClassVar[bool] = True
    #: what to run instead on data without bounds (both refusals say it: ``slamcli solve`` up front, ``solve``
    #: called directly in its FAILED result). Not ``loop`` with ``bounded.enabled=true``: its 12 landmarks of
    #: unknown correspondence over 500 steps branch far too much (benchmarks/results/design_notes.md).
    noise_bounds_hint: ClassVar[str] = ("cuik is set-membership SLAM (paper 004) for bounded-noise worlds: "
                                        "slamcli simulate -s cuik-room -o room.h5, then solve room.h5")

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
        t_start = time.perf_counter()
        nb = inputs.noise_bounds
        why = (f"the dataset declares no guaranteed error bounds (inputs/noise_bounds); {self.noise_bounds_hint}"
               if nb is None else
               f"odometry model {nb.odometry_model!r} not supported (turn_move only)"
               if nb.odometry_model != "turn_move" else None)
        if why is not None:  # no bounds, no guaranteed boxes: a documented failure, not a guess
            return self._failed(inputs, t_start, f"cuik: {why}", None)
        run = _Run(inputs, self.params)
        for t in range(inputs.n_poses):
            if not run.add_pose(t):
                break
            if progress is not None:
                progress(t + 1, inputs.n_poses)
        extra = run.extra()
        if run.refuted is not None:
            t, i = run.refuted
            where = f"pose {t}" + (f", observation row {i}" if i >= 0 else " (odometry edge)")
            extra.update(refuted_at_pose=t, refuted_at_observation=i)
            return self._failed(inputs, t_start, f"every hypothesis became empty at {where}: the data contradict "
                                "the declared bounds", extra)
        if not run.final_pass():
            return self._failed(inputs, t_start, "the 3B / bisection / hull pass refuted every hypothesis: the data "
                                "contradict the declared bounds", run.extra())
        return self._completed(inputs, run, t_start)

    def _failed(self, inputs: SlamInputs, t_start: float, message: str, extra: dict | None) -> SolverResult:
        """The one FAILED result: no estimate, NaN poses, every observation unassociated."""
        return self.make_result(status=Status.FAILED, poses_xyt=np.full((inputs.n_poses, 3), np.nan),
                                landmarks_xy=np.zeros((0, 2)), assoc=np.full(len(inputs.observations), -1, np.int64),
                                t_start=t_start, message=message, extra=extra)

    def _completed(self, inputs: SlamInputs, run: _Run, t_start: float) -> SolverResult:
        """Rank the survivors; the point estimate is the box midpoint of the first one."""
        p = self.params
        hyps = sorted(run.hyps, key=run.rank)
        boxes = _to_arrays(hyps, inputs.n_poses, len(inputs.observations), run.base)
        poses = 0.5 * (boxes.pose_lo[0] + boxes.pose_hi[0])
        poses[:, 2] = wrap_angle(poses[:, 2])
        L0 = int(boxes.n_landmarks[0])
        lms = 0.5 * (boxes.landmark_lo[0, :L0] + boxes.landmark_hi[0, :L0])
        capped = run.capped_steps
        extra = run.extra()
        extra.update(n_hypotheses=len(hyps), n_landmarks_best=L0)
        message = (f"{len(hyps)} kinematic graph(s) survive; the hypothesis cap ({p.max_hypotheses}) removed "
                   f"{run.dropped} at steps {capped[:5]}{'...' if len(capped) > 5 else ''} — the "
                   "surviving set may miss the true correspondence" if capped
                   else f"{len(hyps)} kinematic graph(s) survive; boxes are guaranteed under the declared bounds")
        res = self.make_result(status=Status.TRUNCATED if capped else Status.COMPLETED, poses_xyt=poses,
                               landmarks_xy=lms, assoc=boxes.assoc[0], t_start=t_start, message=message,
                               extra=extra)
        return dataclasses.replace(res, hypotheses=boxes)


class _Run:
    """One solve's state: the live hypotheses, the variable layout and the bookkeeping of :class:`CuikSlam`.

    Variables: poses ``(x, y, θ)`` at ``3t..3t+2``, legs ``(d, α)`` at ``3·n_poses + 2t``, landmarks ``(x, y)``
    from :attr:`base` on. Call :meth:`add_pose` for t = 0, 1, … (False once every hypothesis is refuted, then
    :attr:`refuted` = (pose, observation row or −1)), then :meth:`final_pass`.
    """

    def __init__(self, inputs: SlamInputs, p: CuikParams) -> None:
        from slamcli.solvers.cuik.contractors import Interval, unbounded
        from slamcli.solvers.cuik.hypotheses import Hypothesis
        from slamcli.solvers.cuik.propagate import Counter

        self.p, self.inputs = p, inputs
        nb = inputs.noise_bounds
        obs = self.obs = inputs.observations
        self.n_poses = n = inputs.n_poses
        self.types = (np.asarray(obs.landmark_type, np.int64) if obs.landmark_type is not None
                      else np.zeros(len(obs), np.int64))
        self.h_d, self.h_a = (float(x) + p.recovery_slack for x in nb.odometry_half_width)
        self.h_r, self.h_b = float(nb.range_half_width), float(nb.bearing_half_width)
        odo = np.asarray(inputs.odometry_xyt, float)
        self.legs = np.column_stack([np.hypot(*(odo[1:, :2] - odo[:-1, :2]).T),
                                     wrap_angle(odo[1:, 2] - odo[:-1, 2])])
        self.base = 3 * n + 2 * (n - 1)
        box0 = [unbounded() for _ in range(self.base)]
        for k in range(3):
            box0[k] = Interval(float(inputs.x0[k]))
        # negative information of the closest-landmark sensor (one reading per pose at most, or the declaration
        # is contradicted by the data and not used)
        self.per_pose = np.diff(np.asarray(obs.offsets))
        self.neg = bool(p.negative_information and nb.closest_only and (self.per_pose <= 1).all())
        self.r_min, self.r_max = float(nb.min_range), float(inputs.max_range)
        # lower end of each true range: R.lb of the outward-rounded reading interval [r̃ ± h_r] ∩ [0, ∞), less
        # recovery_slack (the simulator treats landmarks within 1 nm of the closest as tied)
        self.r_lo = [max(0.0, ((Interval(float(r)) + Interval(-self.h_r, self.h_r)) & Interval(0.0, float("inf")))
                         .lb() - p.recovery_slack) for r in np.asarray(obs.range_m, float)]
        self.silent: list[int] = []  # poses that reported no landmark
        self.sep = float(nb.min_separation) if p.separation else 0.0
        self.rank = {"parsimony_area": lambda h: (h.n_landmarks, h.landmark_area()),
                     "parsimony_width": lambda h: (h.n_landmarks, h.total_width()),
                     "parsimony_volume": lambda h: (h.n_landmarks, -h.log_volume(3))}[p.rank]
        self.hyps = [Hypothesis(box=box0)]
        self.counter = Counter()
        self.live_per_step: list[int] = []
        self.branches_per_step: list[int] = []
        self.merged_total = self.dropped = 0
        self.capped_steps: list[int] = []
        self.refuted: tuple[int, int] | None = None

    # -- variable layout ------------------------------------------------------------------------------------
    def pose_vars(self, t: int) -> tuple[int, int, int]:
        return (3 * t, 3 * t + 1, 3 * t + 2)

    def leg_vars(self, t: int) -> tuple[int, int]:
        return (3 * self.n_poses + 2 * t, 3 * self.n_poses + 2 * t + 1)

    def lm_vars(self, j: int) -> tuple[int, int]:
        return (self.base + 2 * j, self.base + 2 * j + 1)

    def _propagate(self, h, start: list[int]) -> bool:
        from slamcli.solvers.cuik.propagate import propagate

        return propagate(h.box, h.edges, h.adj, start, narrow_theta=self.p.narrow_theta, tol=self.p.tol,
                         counter=self.counter)

    def _keep_consistent(self, add_edges) -> bool:
        """Keep the hypotheses whose boxes stay non-empty after ``add_edges(h)`` (edge indices) is propagated."""
        self.hyps = [h for h in self.hyps if self._propagate(h, add_edges(h))]
        return bool(self.hyps)

    # -- one pose -------------------------------------------------------------------------------------------
    def add_pose(self, t: int) -> bool:
        """Odometry edge t−1 → t, the silent-pose band, then every observation of pose t (branching)."""
        from slamcli.solvers.cuik.contractors import Interval, OdometryTurnMove, OutsideBand

        if t > 0:
            leg = self.leg_vars(t - 1)
            edge = OdometryTurnMove(self.pose_vars(t - 1), self.pose_vars(t), float(self.legs[t - 1, 0]),
                                    float(self.legs[t - 1, 1]), self.h_d, self.h_a, leg=leg)

            def add_leg(h) -> list[int]:
                h.box[leg[0]] = Interval(edge.D)
                h.box[leg[1]] = Interval(edge.A)
                return [h.add_edge(edge)]

            if not self._keep_consistent(add_leg):
                self.refuted = (t, -1)
                return False
        if self.neg and self.per_pose[t] == 0:  # a silent pose: no landmark of any type within [r_min, r_max]
            self.silent.append(t)
            band = (self.r_min, self.r_max)
            if not self._keep_consistent(lambda h: [h.add_edge(OutsideBand(self.pose_vars(t), self.lm_vars(m), *band))
                                                    for m in range(h.n_landmarks)]):
                self.refuted = (t, -1)
                return False
        n_branch = 0
        for i in range(int(self.obs.offsets[t]), int(self.obs.offsets[t + 1])):
            n_branch += self._observe(t, i)
            if not self.hyps:
                self.refuted = (t, i)
                return False
        self.live_per_step.append(len(self.hyps))
        self.branches_per_step.append(n_branch)
        return True

    def _options(self, h, i: int) -> list[int]:
        """Labels observation ``i`` may have in ``h`` (−1 = a new landmark)."""
        rid = int(self.obs.reported_id[i])
        if self.p.association == "reported" and rid >= 0:
            return [h.reported[rid]] if rid in h.reported else [-1]
        options = [j for j, tj in enumerate(h.landmark_type) if tj == int(self.types[i])]
        if self.p.new_landmarks or not options:
            options.append(-1)
        return options

    def _observe(self, t: int, i: int) -> int:
        """Branch every hypothesis over the labels of observation ``i`` (pose t), propagate, merge, cap;
        returns the number of branches tried."""
        from slamcli.solvers.cuik.contractors import unbounded
        from slamcli.solvers.cuik.hypotheses import merge_relabelled

        children, n_branch = [], 0
        for h in self.hyps:
            options = self._options(h, i)
            for n_opt, j in enumerate(options):
                g = h if n_opt == len(options) - 1 else h.copy()
                is_new = j < 0
                if is_new:
                    j = g.n_landmarks
                    g.box += [unbounded(), unbounded()]
                    g.landmark_type.append(int(self.types[i]))
                    rid = int(self.obs.reported_id[i])
                    if self.p.association == "reported" and rid >= 0:
                        g.reported[rid] = j
                n_branch += 1
                if self._propagate(g, self._observation_edges(g, t, i, j, is_new)):
                    g.assoc.append(j)
                    children.append(g)
        self.hyps, m = merge_relabelled(children)
        self.merged_total += m
        if len(self.hyps) > self.p.max_hypotheses:
            self.hyps.sort(key=self.rank)
            self.dropped += len(self.hyps) - self.p.max_hypotheses
            self.hyps = self.hyps[: self.p.max_hypotheses]
            self.capped_steps.append(t)
        return n_branch

    def _observation_edges(self, g, t: int, i: int, j: int, is_new: bool) -> list[int]:
        """Add the edges of observation ``i`` (pose t) read as landmark label ``j`` to ``g``; their indices."""
        from slamcli.solvers.cuik.contractors import (
            OutsideBand,
            OutsideBandLocal,
            RangeBearing,
            Separated,
            SeparatedLocal,
            SharedLandmarkLeg,
        )

        obs, p, lv = self.obs, self.p, self.lm_vars(j)
        r, b = float(obs.range_m[i]), float(obs.bearing_rad[i])
        sl = p.recovery_slack
        start = [g.add_edge(_tagged(RangeBearing(self.pose_vars(t), lv, r, b, self.h_r, self.h_b), i))]
        if self.neg:
            # closest-landmark sensor: every other landmark is outside [r_min, r) of pose t ...
            start += [g.add_edge(_tagged(OutsideBand(self.pose_vars(t), self.lm_vars(m), self.r_min, self.r_lo[i]),
                                         i, slack=sl)) for m in range(g.n_landmarks) if m != j]
            if is_new:  # ... and a new landmark was never closer than what earlier poses saw
                start += [g.add_edge(_tagged(OutsideBand(self.pose_vars(int(obs.step[k])), lv, self.r_min,
                                                         self.r_lo[k]), k, slack=sl)) for k in range(i)]
                start += [g.add_edge(OutsideBand(self.pose_vars(s), lv, self.r_min, self.r_max)) for s in self.silent]
        prev = range(int(obs.offsets[t - 1]), int(obs.offsets[t])) if t > 0 else range(0)
        z = {k: (float(obs.range_m[k]), float(obs.bearing_rad[k])) for k in prev}
        if self.sep > 0:  # a different label seen from pose t−1: separated, in its frame
            start += [g.add_edge(SeparatedLocal(self.leg_vars(t - 1), z[k], (r, b), self.h_r, self.h_b, self.sep))
                      for k in prev if g.assoc[k] != j]
        if is_new and self.sep > 0:
            start += [g.add_edge(Separated(self.lm_vars(m), lv, self.sep)) for m in range(g.n_landmarks) if m != j]
        if self.neg and p.narrow_theta and p.local_negative:  # a different label seen from pose t−1: the
            # closest-landmark information between the two poses, in a local frame (leg and readings only)
            start += [g.add_edge(_tagged(OutsideBandLocal(self.leg_vars(t - 1), z[k], self.h_r, self.h_b, self.r_min,
                                                          self.r_lo[i], from_next=False), k, i, slack=sl))
                      for k in prev if g.assoc[k] != j]
            start += [g.add_edge(_tagged(OutsideBandLocal(self.leg_vars(t - 1), (r, b), self.h_r, self.h_b, self.r_min,
                                                          self.r_lo[k], from_next=True), i, k, slack=sl))
                      for k in prev if g.assoc[k] != j]
        if p.narrow_theta:  # the same landmark seen from pose t−1: a local cycle
            start += [g.add_edge(_tagged(SharedLandmarkLeg(self.leg_vars(t - 1), z[k], (r, b), self.h_r, self.h_b), k, i))
                      for k in prev if g.assoc[k] == j]
        return start

    # -- after the last pose --------------------------------------------------------------------------------
    def final_pass(self) -> bool:
        """The optional 3B shaving, heading bisection and hull passes on every survivor; False when they
        refute every hypothesis."""
        from slamcli.solvers.cuik.propagate import bisect_hull, shave

        p, c = self.p, self.counter
        if not (p.shave_slices > 0 or p.bisect_leaves > 0 or p.hull_leaves > 0 or p.lp_rounds > 0):
            return True
        kept = []
        for h in self.hyps:
            variables = [v for v, x in enumerate(h.box) if x.diam() > 10 * p.tol]
            ok = p.shave_slices == 0 or shave(h.box, h.edges, h.adj, variables, narrow_theta=p.narrow_theta,
                                              tol=p.tol, slices=p.shave_slices, rounds=p.shave_rounds, counter=c)
            if ok and p.bisect_leaves > 0:
                ok = bisect_hull(h.box, h.edges, h.adj, [3 * t + 2 for t in range(self.n_poses)],
                                 narrow_theta=p.narrow_theta, tol=p.tol, max_leaves=p.bisect_leaves, counter=c)
            if ok and p.lp_rounds > 0:
                ok = _lp_rounds(h, p, c)
            if ok and p.hull_leaves > 0:
                ok = _hull(h, p, self.n_poses, self.base, c)
            if ok:
                kept.append(h)
        self.hyps = kept
        return bool(kept)

    def extra(self) -> dict:
        return {
            "contractions": self.counter.contractions,
            "propagations": self.counter.propagations,
            "live_hypotheses_per_step": self.live_per_step,
            "branches_per_step": self.branches_per_step,
            "merged_relabelled": self.merged_total,
            "hypotheses_dropped_by_cap": self.dropped,
            "cap_hit_at_steps": self.capped_steps,
            "operator_set": "full" if self.p.narrow_theta else "paper",
            "negative_information": self.neg,
            "min_separation": self.sep,
        }


def _tagged(edge, *readings: int, slack: float = 0.0):
    """``edge`` with the observation rows of its readings recorded (``Contractor.readings``, for the LP)."""
    edge.readings = readings
    edge.band_slack = slack
    return edge


def _lp_rounds(h, p: CuikParams, counter) -> bool:
    """``lp_rounds`` × (the LP contractor on every bounded variable, then propagation); False when refuted."""
    from slamcli.solvers.cuik.linear import lp_contract
    from slamcli.solvers.cuik.propagate import propagate

    every = list(range(len(h.edges)))
    for _ in range(p.lp_rounds):
        variables = [v for v, x in enumerate(h.box) if 10 * p.tol < x.diam() < float("inf")]
        if not lp_contract(h.box, h.edges, variables, narrow_theta=p.narrow_theta):
            return False
        if not propagate(h.box, h.edges, h.adj, every, narrow_theta=p.narrow_theta, tol=p.tol, counter=counter):
            return False
    return True


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
    leaf_bound = None
    if p.hull_lp:
        from slamcli.solvers.cuik.linear import lp_end

        def leaf_bound(leaf: list, target: int, side: int) -> float | None:
            return lp_end(leaf, h.edges, target, side, narrow_theta=p.narrow_theta)

    return hull_pass(h.box, h.edges, h.adj, targets, split, scales, narrow_theta=p.narrow_theta, tol=p.tol,
                     max_leaves=p.hull_leaves, min_width=HULL_MIN_WIDTH, counter=counter,
                     n_candidates=1 if p.hull_lp else 6, leaf_bound=leaf_bound)


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
