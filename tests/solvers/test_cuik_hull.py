"""cuik boxes against the feasible hull: an independent inner bound (SLSQP over the bounded errors, written from
paper 004 without the solver's contractors) that every sound box must contain, Porta's setting, and the
branch-and-bound hull pass.

The inner bound is a set of genuine solutions (constraint violation < 1e-6), so ``box ⊇ [lo, hi]`` is a
soundness check and ``box width / (hi − lo)`` an upper bound on how far the box is from the exact hull.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

pytest.importorskip("slamcli.solvers.cuik.contractors")  # loads codac after h5py (see there)

from slamcli.api.solve import solve_dataset
from slamcli.metrics import sets
from slamcli.reproduce.paper004 import FEASIBLE_TOL, FeasibleSet, inner_hull
from slamcli.sim.simulate import simulate_scenario
from slamcli.solvers.cuik.contractors import Interval, interval_rounding
from slamcli.solvers.cuik.propagate import propagate, tighten_bound
from slamcli.types import Status


def _box(hb, h, coordinate, label_of):
    _kind, j, c = coordinate
    k = label_of[j]
    return float(hb.landmark_lo[h, k, c]), float(hb.landmark_hi[h, k, c])


def test_the_inner_bound_is_made_of_genuine_solutions():
    # the zero-error point of exact readings is the truth: feasible, and its landmark is the true one
    exact = simulate_scenario("cuik-room", 0, {"bounded.exact_readings": True})
    fs = FeasibleSet(exact.inputs, exact.truth.obs_landmark)
    u0 = np.zeros(fs.n)
    assert fs.violation(u0) < 1e-9
    P, L, _ = fs.unpack(u0)
    np.testing.assert_allclose(P[:, :2], exact.truth.poses_xyt[:, :2], atol=1e-9)
    np.testing.assert_allclose(L[2], exact.truth.landmarks_xy[2], atol=1e-9)
    # a point that moves one re-observed reading by its whole bound breaks the cycle it closes
    u = u0.copy()
    u[2 * fs.T + 4] = 1.0  # range error of observation 4 (l3's second sighting)
    assert fs.violation(u) > 1e-3


@pytest.mark.slow
def test_porta_setting_reaches_the_hull_and_stays_below_1m_and_sound_over_200_seeds():
    # paper 004 §1/§6, Porta's setting: every landmark within 40 m reported with its identity. Exact readings:
    # the widest landmark coordinate (l3 x) is within 2 % of the inner bound of the hull
    exact = simulate_scenario("cuik-room-porta", 0, {"bounded.exact_readings": True})
    assert (exact.inputs.observations.reported_id == exact.truth.obs_landmark).all()
    r = solve_dataset(exact.inputs, "cuik", {"association": "reported"})
    hb = r.hypotheses
    label_of = {v: k for k, v in sets.landmark_map(hb.assoc[0], exact.truth.obs_landmark).items()}
    for c, (lo, hi, viol) in inner_hull(exact, [("landmark", 2, 0)], n_starts=1, maxiter=100).items():
        b_lo, b_hi = _box(hb, 0, c, label_of)
        assert viol < FEASIBLE_TOL and b_lo - FEASIBLE_TOL <= lo and hi <= b_hi + FEASIBLE_TOL, c
        assert b_hi - b_lo <= 1.02 * (hi - lo), c
    widths = []
    for seed in range(200):  # issue 26: sound in >= 200 seeded runs
        ds = simulate_scenario("cuik-room-porta", seed)
        r = solve_dataset(ds.inputs, "cuik", {"association": "reported"})
        assert r.status is Status.COMPLETED and len(r.hypotheses) == 1
        m = sets.set_metrics(r.hypotheses, ds.truth.poses_xyt, ds.truth.landmarks_xy, ds.truth.obs_landmark)
        assert m["soundness"] == 1.0, seed
        widths.append(m["true_landmark_width_mean"])
    assert max(widths) < 1.0


def test_paper_leg_length_scenario_has_sqrt60_legs():
    ds = simulate_scenario("cuik-room-paper-legs", 0, {"bounded.exact_readings": True})
    legs = np.hypot(*np.diff(ds.truth.poses_xyt[:, :2], axis=0).T)
    np.testing.assert_allclose(legs, math.sqrt(60.0), rtol=1e-9)
    np.testing.assert_allclose(ds.truth.poses_xyt[0, :2], [15.0, 5.0])


def _arc():
    """Pose (0, 0, θ ∈ [0, π/2]) seeing a landmark at range 10, bearing 0 (exact), and a fixed pose (0, 10, 0)
    that has it at least 9 m away; propagated (call inside :func:`interval_rounding`)."""
    from slamcli.solvers.cuik.contractors import OutsideBand, RangeBearing, unbounded
    from slamcli.solvers.cuik.hypotheses import Hypothesis

    box = [Interval(0.0), Interval(0.0), Interval(0.0, math.pi / 2), unbounded(), unbounded(),
           Interval(0.0), Interval(10.0), Interval(0.0)]
    h = Hypothesis(box=box)
    e = [h.add_edge(RangeBearing((0, 1, 2), (3, 4), 10.0, 0.0, 0.0, 0.0)),
         h.add_edge(OutsideBand((5, 6, 7), (3, 4), 0.0, 9.0))]
    assert propagate(h.box, h.edges, h.adj, e, narrow_theta=True, tol=1e-9)
    return h


def test_tighten_bound_reaches_the_exact_end_on_a_hand_built_arc():
    # a pose at the origin with heading θ ∈ [0, π/2] sees a landmark at range 10, bearing 0 (exact readings):
    # the landmark is on the quarter arc l = 10·(cos θ, sin θ). A second, fixed pose at (0, 10) adds "the
    # landmark is at least 9 m away" (OutsideBand). Closed form: ‖l − (0, 10)‖² = 200 − 200 sin θ ≥ 81, so
    # sin θ ≤ 0.595 and the exact lower end of l_x is 10·cos(asin 0.595) = 8.04 m
    with interval_rounding():
        h = _arc()
        before = h.box[3].lb()
        lo = tighten_bound(h.box, h.edges, h.adj, 3, 0, [2, 4], [10.0, 1.0], narrow_theta=True, tol=1e-9,
                           max_leaves=200, min_width=1e-4)
    exact = 10.0 * math.cos(math.asin((200.0 - 81.0) / 200.0))
    assert before < exact - 0.5  # propagation alone is loose here ...
    assert exact - 0.01 < lo <= exact + 1e-9  # ... the branch and bound reaches the hull and stays sound


def test_hull_pass_moves_every_target_to_the_hull_on_the_hand_built_arc():
    # the same arc and constraint: the feasible θ ∈ [0, asin 0.595], so l_x ∈ [8.04, 10] and l_y ∈ [0, 5.95]
    from slamcli.solvers.cuik.propagate import hull_pass

    with interval_rounding():
        h = _arc()
        assert hull_pass(h.box, h.edges, h.adj, [3, 4], [2, 3, 4], [10.0, 1.0, 1.0], narrow_theta=True,
                         tol=1e-9, max_leaves=200, min_width=1e-4)
        x, y = (h.box[3].lb(), h.box[3].ub()), (h.box[4].lb(), h.box[4].ub())
    s = 119.0 / 200.0
    hull_x, hull_y = (10.0 * math.cos(math.asin(s)), 10.0), (0.0, 10.0 * s)
    for (lo, hi), (e_lo, e_hi) in ((x, hull_x), (y, hull_y)):
        assert lo <= e_lo + 1e-9 and hi >= e_hi - 1e-9  # sound
        assert lo > e_lo - 0.02 and hi < e_hi + 0.02  # at the hull


def test_paper_set_on_the_paper_legs_reproduces_table1_bound_for_bound():
    # with the paper's √60 m legs and its operator set, every printed bound of paper 004's Table 1 (x, y, and
    # θ converted from its clockwise-from-+y convention) is reproduced to the printed precision
    from slamcli.reproduce.paper004 import PAPER_SET, TABLE1, with_true_association
    from slamcli.sim.bounded import heading_from_paper004

    legs = simulate_scenario("cuik-room-paper-legs", 0, {"bounded.exact_readings": True})
    hb = solve_dataset(with_true_association(legs), "cuik", {**PAPER_SET, "association": "reported"}).hypotheses
    for t in range(9):
        x_lo, x_hi, y_lo, y_hi, th_lo, th_hi = TABLE1[f"r{t + 1}"]
        ours = np.r_[hb.pose_lo[0, t, :2], hb.pose_hi[0, t, :2]]
        np.testing.assert_allclose(ours, [x_lo, y_lo, x_hi, y_hi], atol=2e-5, err_msg=f"r{t + 1}")
        th = np.sort(heading_from_paper004([th_lo, th_hi]))
        np.testing.assert_allclose([hb.pose_lo[0, t, 2], hb.pose_hi[0, t, 2]], th, atol=2e-6, err_msg=f"θ r{t + 1}")
    for j in range(4):
        x_lo, x_hi, y_lo, y_hi = TABLE1[f"l{j + 1}"][:4]
        ours = np.r_[hb.landmark_lo[0, j], hb.landmark_hi[0, j]]
        np.testing.assert_allclose(ours, [x_lo, y_lo, x_hi, y_hi], atol=2e-5, err_msg=f"l{j + 1}")


@pytest.mark.slow
def test_unknown_correspondence_true_graph_contains_the_feasible_extremes():
    # noisy seed 2, types only: the true hypothesis' boxes contain both feasible extremes of the widest
    # coordinates (l3 y, l4 x, l4 y), computed under the true association by the independent FeasibleSet
    from slamcli.reproduce.paper004 import box_vs_hull

    ds = simulate_scenario("cuik-room", 2)
    r = solve_dataset(ds.inputs, "cuik", {})
    h = sets.true_hypothesis(r.hypotheses, ds.truth.obs_landmark)
    assert h >= 0
    hull = inner_hull(ds, [("landmark", 2, 1), ("landmark", 3, 0), ("landmark", 3, 1)], n_starts=1, maxiter=100)
    assert all(v < FEASIBLE_TOL for _lo, _hi, v in hull.values())
    for _width, ratio, inside in box_vs_hull(r.hypotheses, h, ds.truth.obs_landmark, hull):
        assert inside and ratio >= 1.0 - 1e-9
