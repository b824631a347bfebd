"""cuik's narrowing operators (paper 004 Def. 4.1): contracting, correct, idempotent — and the propagation.

Correctness is checked with a Monte-Carlo cloud: points that satisfy the edge's constraint with errors inside
the bounds and that lie in the input box must stay inside the contracted box.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

# through the solver's own module: it loads codac only after h5py (the other order crashes natively)
contractors = pytest.importorskip("slamcli.solvers.cuik.contractors")

from slamcli.solvers.cuik.contractors import (  # noqa: E402
    OdometryTurnMove,
    OutsideBand,
    RangeBearing,
    Separated,
    SeparatedLocal,
    SharedLandmarkLeg,
    unbounded,
)
from slamcli.solvers.cuik.propagate import propagate  # noqa: E402

I = contractors.Interval
TOL = 1e-9


@pytest.fixture(autouse=True)
def _interval_mode():
    """codac computes outward-rounded bounds only in round-upward mode (the solver switches per solve)."""
    with contractors.interval_rounding():
        yield


@pytest.mark.slow
def test_rounding_mode_is_upward_inside_and_restored_outside():
    third = I(1) / I(3)
    assert third.lb() < third.ub()  # outward rounding: 1/3 is not a float, so the bounds differ by an ulp
    with contractors.interval_rounding():
        pass
    # the fixture's mode is still active here; a solve restores the caller's mode: check in a fresh context
    import subprocess
    import sys

    code = ("import slamcli.solvers.cuik.contractors as c; assert float('1.2') == 1.2; "
            "import numpy as np; from slamcli.sim.simulate import simulate_scenario; "
            "from slamcli.api.solve import solve_dataset; "
            "r = solve_dataset(simulate_scenario('cuik-room', 0).inputs, 'cuik', {}); "
            "assert float('1.2') == 1.2 and 0.1 + 0.2 == 0.30000000000000004; import h5py; print('ok')")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert out.returncode == 0 and out.stdout.strip() == "ok", out.stderr[-500:]


def as_box(lo_hi):
    return [I(a, b) for a, b in lo_hi]


def bounds(box):
    return np.array([[x.lb(), x.ub()] for x in box])


def inside(points, box, slack=1e-9):
    b = bounds(box)
    return np.all((points >= b[:, 0] - slack) & (points <= b[:, 1] + slack), axis=1)


# -- odometry edge: pose0 (x, y, θ), pose1 (x, y, θ) -------------------------------------------------------
D_MEAS, A_MEAS, H_D, H_A = 7.65, math.radians(45.0), 0.25, math.radians(5.0)


def odometry_cloud(rng, n=20000):
    """Points satisfying the turn-and-move relation with |d − d̃| ≤ h_d, |α − α̃| ≤ h_α."""
    p0 = np.column_stack([rng.uniform(14.5, 15.5, n), rng.uniform(4.5, 5.5, n), rng.uniform(-0.5, -0.3, n)])
    d = D_MEAS + rng.uniform(-H_D, H_D, n)
    a = A_MEAS + rng.uniform(-H_A, H_A, n)
    th1 = p0[:, 2] + a
    p1 = np.column_stack([p0[:, 0] + d * np.cos(th1), p0[:, 1] + d * np.sin(th1), th1])
    return np.hstack([p0, p1])


ODO_BOX = [(14.5, 15.5), (4.5, 5.5), (-0.5, -0.3), (20.0, 23.0), (6.5, 9.5), (-1.0, 1.0)]


# -- observation edge: pose (x, y, θ), landmark (x, y) ---------------------------------------------------
R_MEAS, B_MEAS, H_R, H_B = 5.0, math.radians(-67.5), 0.025, math.radians(0.5)


def observation_cloud(rng, n=20000):
    pose = np.column_stack([rng.uniform(14.9, 15.1, n), rng.uniform(4.9, 5.1, n), rng.uniform(-0.5, -0.2, n)])
    r = R_MEAS + rng.uniform(-H_R, H_R, n)
    b = B_MEAS + rng.uniform(-H_B, H_B, n)
    phi = pose[:, 2] + b
    lm = pose[:, :2] + r[:, None] * np.column_stack([np.cos(phi), np.sin(phi)])
    return np.hstack([pose, lm])


OBS_BOX = [(14.9, 15.1), (4.9, 5.1), (-0.5, -0.2), (15.0, 15.4), (-1.0, 1.0)]


# -- local cycle: poses t, t+1 see one landmark; variables the leg (d, α) --------------------------------
QS = np.array([3.0, -4.0])  # landmark in frame t+1 (truth)
D_TRUE, A_TRUE = 7.65, math.radians(45.0)


def _qt(d, a, qs):
    c, s_ = np.cos(a), np.sin(a)
    return np.column_stack([d * c + c * qs[:, 0] - s_ * qs[:, 1], d * s_ + s_ * qs[:, 0] + c * qs[:, 1]])


QT = _qt(np.array([D_TRUE]), np.array([A_TRUE]), QS[None])[0]
ZT = (float(np.hypot(*QT)), float(np.arctan2(QT[1], QT[0])))
ZS = (float(np.hypot(*QS)), float(np.arctan2(QS[1], QS[0])))


def shared_cloud(rng, n=400000):
    """(d, α) for which some readings within the bounds satisfy the local cycle exactly."""
    d = rng.uniform(D_TRUE - H_D, D_TRUE + H_D, n)
    a = rng.uniform(A_TRUE - H_A, A_TRUE + H_A, n)
    rs = ZS[0] + rng.uniform(-H_R, H_R, n)
    bs = ZS[1] + rng.uniform(-H_B, H_B, n)
    qt = _qt(d, a, np.column_stack([rs * np.cos(bs), rs * np.sin(bs)]))
    ok = (np.abs(np.hypot(qt[:, 0], qt[:, 1]) - ZT[0]) <= H_R) & \
        (np.abs(np.arctan2(qt[:, 1], qt[:, 0]) - ZT[1]) <= H_B)
    return np.column_stack([d, a])[ok]


SHARED_BOX = [(D_TRUE - H_D, D_TRUE + H_D), (A_TRUE - H_A, A_TRUE + H_A)]


def make(kind):
    if kind == "shared":
        return SharedLandmarkLeg((0, 1), ZT, ZS, H_R, H_B), SHARED_BOX, shared_cloud
    if kind == "odometry":
        return OdometryTurnMove((0, 1, 2), (3, 4, 5), D_MEAS, A_MEAS, H_D, H_A), ODO_BOX, odometry_cloud
    return RangeBearing((0, 1, 2), (3, 4), R_MEAS, B_MEAS, H_R, H_B), OBS_BOX, observation_cloud


@pytest.mark.parametrize(("kind", "narrow_theta"), [
    ("odometry", True), ("odometry", False), ("observation", True), ("observation", False),
    ("shared", True),  # the local-cycle operator belongs to the full set only (paper set: identity, below)
], ids=["odometry-full", "odometry-paper", "observation-full", "observation-paper", "shared-full"])
def test_contractor_is_contracting_correct_and_idempotent(kind, narrow_theta):
    ctc, box0, cloud = make(kind)
    box = as_box(box0)
    pts = cloud(np.random.default_rng(11))
    pts = pts[inside(pts, box)]
    assert len(pts) > 200  # the cloud really populates the input box

    changed = ctc.contract(box, narrow_theta, TOL)
    b0, b1 = np.array(box0), bounds(box)
    # contractance: f(X) ⊆ X, and it really narrows something
    assert (b1[:, 0] >= b0[:, 0]).all() and (b1[:, 1] <= b0[:, 1]).all()
    assert changed and ((b1[:, 1] - b1[:, 0]) < 0.8 * (b0[:, 1] - b0[:, 0])).any()
    # correctness: X ∩ ρ ⊆ f(X) — every consistent point of the input box survives
    assert inside(pts, box).all()
    # the cloud's hull is not much smaller than the box: the operator is tight, not just sound (the paper set
    # leaves the heading of an observation edge alone, so that one stays wide on purpose)
    hull_w = pts.max(0) - pts.min(0)
    tight = np.ones(len(box0), bool)
    if kind == "observation" and not narrow_theta:
        tight[2] = False
    assert (hull_w[tight] >= 0.5 * (b1[tight, 1] - b1[tight, 0]) - 1e-6).all()
    # idempotence (up to the tolerance that ends the local fixpoint)
    again = ctc.contract(box, narrow_theta, TOL)
    assert again == []
    np.testing.assert_allclose(bounds(box), b1, atol=10 * TOL)


@pytest.mark.parametrize("kind", ["odometry", "observation"])
def test_paper_operator_set_never_narrows_the_heading_from_positions(kind):
    ctc, box0, _ = make(kind)
    full, paper = as_box(box0), as_box(box0)
    ctc.contract(full, True, TOL)
    ctc.contract(paper, False, TOL)
    theta = 2  # heading of pose 0 (observation) / turn chain (odometry: θ1 = θ0 + α only)
    if kind == "observation":
        assert (paper[theta].lb(), paper[theta].ub()) == box0[theta]
        assert full[theta].diam() < paper[theta].diam()
    else:
        # the turn chain narrows θ1 to θ0 + A in both sets; only the full set narrows it further
        assert paper[5].diam() == pytest.approx(0.2 + 2 * H_A, abs=1e-9)
        assert full[5].diam() <= paper[5].diam() + 1e-12
    # the full set is at least as narrow everywhere
    assert all(f.is_subset(p) for f, p in zip(full, paper))


def test_contractor_detects_an_empty_intersection():
    ctc, _, _ = make("observation")
    box = as_box([(14.9, 15.1), (4.9, 5.1), (-0.5, -0.2), (40.0, 41.0), (40.0, 41.0)])  # landmark 50 m away
    assert ctc.contract(box, True, TOL) is None
    assert all(x.is_empty() for x in box)


def test_propagation_reaches_a_fixpoint_of_every_operator():
    # a 3-pose chain seeing one landmark from both ends (a cycle in the kinematic graph)
    rng = np.random.default_rng(3)
    true = np.array([[0.0, 0.0, 0.0], [5.0, 0.0, 0.0], [5.0, 5.0, math.pi / 2]])
    lm = np.array([8.0, 3.0])
    box = [unbounded() for _ in range(11)]
    for k in range(3):
        box[k] = I(float(true[0, k]))
    edges = []
    for t in range(2):
        d = float(np.hypot(*(true[t + 1, :2] - true[t, :2]))) + rng.uniform(-0.1, 0.1)
        a = float(true[t + 1, 2] - true[t, 2]) + rng.uniform(-0.02, 0.02)
        edges.append(OdometryTurnMove((3 * t, 3 * t + 1, 3 * t + 2), (3 * t + 3, 3 * t + 4, 3 * t + 5), d, a, 0.1, 0.02))
    for t in (0, 2):
        dd = lm - true[t, :2]
        r = float(np.hypot(*dd)) + rng.uniform(-0.01, 0.01)
        b = math.atan2(dd[1], dd[0]) - true[t, 2] + rng.uniform(-0.005, 0.005)
        edges.append(RangeBearing((3 * t, 3 * t + 1, 3 * t + 2), (9, 10), r, b, 0.01, 0.005))
    adj = {}
    for k, e in enumerate(edges):
        for v in e.vars:
            adj.setdefault(v, []).append(k)
    assert propagate(box, edges, adj, list(range(len(edges))), narrow_theta=True, tol=TOL)
    # fixpoint up to the width-change tolerance: re-applying any operator moves no bound by more than a few
    # tolerances (moves below tol do not re-queue neighbours, so they may accumulate)
    before = bounds(box)
    for e in edges:
        assert e.contract(box, True, TOL) is not None
    assert np.abs(bounds(box) - before).max() < 100 * TOL
    # and the truth is inside (the errors were within the bounds)
    b = bounds(box)
    truth = np.r_[true.ravel(), lm]
    assert ((truth >= b[:, 0] - 1e-9) & (truth <= b[:, 1] + 1e-9)).all()
    # the landmark box is about as wide as the sensor bounds allow from the known pose 0 (r·2h_b ≈ 0.09 m)
    assert (b[9:, 1] - b[9:, 0] < 0.12).all()


def test_local_cycle_pins_the_leg_far_below_the_odometry_bounds():
    ctc, box0, _ = make("shared")
    box = as_box(box0)
    ctc.contract(box, True, TOL)
    w = bounds(box)[:, 1] - bounds(box)[:, 0]
    # odometry alone: ±25 cm, ±5°; the two sightings of one landmark pin the turn to well below ±2°
    assert w[1] < 0.4 * 2 * H_A and w[0] < 2 * H_D
    paper = as_box(box0)
    assert ctc.contract(paper, False, TOL) == [] and bounds(paper).tolist() == [list(b) for b in box0]


# -- negative information and the separation prior --------------------------------------------------------
BAND_BOX = [(0.0, 1.0), (0.0, 1.0), (-1.0, 1.0), (1.5, 3.5), (0.0, 1.0)]  # pose (x, y, θ), landmark (x, y)


def test_outside_band_is_contracting_correct_and_idempotent():
    # "landmark m is not in the visible band [0.1, 2.5) of pose t" (the sensor reported a landmark at ≥ 2.5 m)
    ctc = OutsideBand((0, 1, 2), (3, 4), 0.1, 2.5)
    box = as_box(BAND_BOX)
    rng = np.random.default_rng(5)
    pts = rng.uniform(np.array(BAND_BOX)[:, 0], np.array(BAND_BOX)[:, 1], (200000, 5))
    dist = np.hypot(pts[:, 3] - pts[:, 0], pts[:, 4] - pts[:, 1])
    pts = pts[(dist < 0.1) | (dist >= 2.5)]
    assert len(pts) > 1000
    changed = ctc.contract(box, True, TOL)
    b0, b1 = np.array(BAND_BOX), bounds(box)
    assert (b1[:, 0] >= b0[:, 0]).all() and (b1[:, 1] <= b0[:, 1]).all()
    # landmark x ≥ 2.5 − 1 = 1.5 is what a 1-D argument gives; the hull of the two allowed pieces reaches
    # lx ≥ √(2.5² − 1²) = 2.29 (dy ≤ 1) and x ≤ 3.5 − 2.29 = 1.21 → 1 (no change); tight to 1 mm
    assert changed and b1[3, 0] == pytest.approx(math.sqrt(2.5 ** 2 - 1.0), abs=1e-3)
    assert inside(pts, box).all()  # correctness: every allowed point of the box survives
    assert pts[:, 3].min() < b1[3, 0] + 0.1  # and the new bound is nearly attained by allowed points (tight)
    assert ctc.contract(box, True, TOL) == []  # idempotent
    # a landmark box certainly inside the band refutes the hypothesis; one far away is left alone quickly
    near = as_box([(0.0, 0.1), (0.0, 0.1), (0.0, 0.0), (1.0, 1.2), (0.0, 0.1)])
    assert ctc.contract(near, True, TOL) is None and all(near[i].is_empty() for i in (0, 1, 3, 4))
    far = as_box([(0.0, 1.0), (0.0, 1.0), (0.0, 0.0), (9.0, 9.5), (0.0, 1.0)])
    assert ctc.contract(far, True, TOL) == [] and bounds(far).tolist() == [[0, 1], [0, 1], [0, 0], [9, 9.5], [0, 1]]
    # the sensor's minimum range: a landmark closer than r_min is invisible, so it is allowed
    tiny = as_box([(0.0, 0.01), (0.0, 0.01), (0.0, 0.0), (0.0, 0.02), (0.0, 0.02)])
    assert ctc.contract(tiny, True, TOL) is not None


def test_separation_world_frame_is_correct_and_refutes_coincident_landmarks():
    ctc = Separated((0, 1), (2, 3), 2.0)
    box0 = [(0.0, 1.0), (0.0, 1.0), (1.5, 4.0), (0.0, 1.0)]
    box = as_box(box0)
    pts = np.random.default_rng(6).uniform(np.array(box0)[:, 0], np.array(box0)[:, 1], (200000, 4))
    pts = pts[np.hypot(pts[:, 2] - pts[:, 0], pts[:, 3] - pts[:, 1]) >= 2.0]
    assert ctc.contract(box, True, TOL)
    assert inside(pts, box).all() and bounds(box)[2, 0] > 1.5 + 0.2  # l_b x ≥ √(4 − 1) = 1.73
    same = as_box([(0.0, 1.0), (0.0, 1.0), (0.0, 1.0), (0.0, 1.0)])  # both within 1.5 m of each other
    assert ctc.contract(same, True, TOL) is None


def _reading(pose_xyt, lm_xy):
    d = np.asarray(lm_xy) - pose_xyt[:2]
    return float(np.hypot(*d)), float(math.atan2(d[1], d[0]) - pose_xyt[2])


def test_local_separation_refutes_one_landmark_labelled_twice_and_keeps_two_distinct_ones():
    # poses t−1 = origin heading 0, then turn α and move d; readings of the same / of two landmarks
    p0 = np.array([0.0, 0.0, 0.0])
    a, d = math.radians(10.0), 4.0
    p1 = np.array([d * math.cos(a), d * math.sin(a), a])
    leg = [(d - 0.1, d + 0.1), (a - math.radians(2.0), a + math.radians(2.0))]
    same = SeparatedLocal((0, 1), _reading(p0, (2.0, -2.0)), _reading(p1, (2.0, -2.0)), H_R, H_B, 4.0)
    box = as_box(leg)
    assert same.contract(box, True, TOL) is None  # "two landmarks ≥ 4 m apart" contradicts the readings
    two = SeparatedLocal((0, 1), _reading(p0, (2.0, -2.0)), _reading(p1, (9.0, 2.0)), H_R, H_B, 4.0)
    box = as_box(leg)
    assert two.contract(box, True, TOL) == [] and bounds(box).tolist() == [list(b) for b in leg]
    # sound at the edge: the true distance is 8.06 m, a declared 7.9 m must not refute anywhere in the leg box
    edge = SeparatedLocal((0, 1), _reading(p0, (2.0, -2.0)), _reading(p1, (9.0, 2.0)), H_R, H_B, 7.9)
    assert edge.contract(as_box(leg), True, TOL) == []
