"""cuik on the paper 004 room and beyond: soundness, correspondence, wrong bounds, Table 1, graph cross-check.

Every number asserted here is measured in the test; the paper's Table 1 comes from slamcli.reproduce.paper004.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

pytest.importorskip("slamcli.solvers.cuik.contractors")  # loads codac after h5py (see there)

from slamcli.api.solve import solve_dataset
from slamcli.metrics import sets
from slamcli.reproduce.paper004 import (
    PAPER_SET,
    corrupt_loop_closure,
    feasible_extent,
    loop_closure_rows,
    our_widths,
    table1_widths,
    with_true_association,
)
from slamcli.sim.simulate import simulate_scenario
from slamcli.types import Status


def solve(inputs, **params):
    return solve_dataset(inputs, "cuik", params)


@pytest.mark.slow
def test_soundness_is_100_percent_over_200_bounded_noise_runs():
    n_sound, n_runs, widths = 0, 200, []
    for seed in range(n_runs):
        ds = simulate_scenario("cuik-room", seed)
        r = solve(with_true_association(ds), association="reported")
        assert r.status is Status.COMPLETED and len(r.hypotheses) == 1
        m = sets.set_metrics(r.hypotheses, ds.truth.poses_xyt, ds.truth.landmarks_xy, ds.truth.obs_landmark)
        n_sound += m["soundness"] == 1.0
        widths.append(m["true_landmark_width_mean"])
    assert n_sound == n_runs
    # the boxes are informative, not the whole room: landmark boxes average well below the 30 m room
    assert 0.5 < np.mean(widths) < 10.0


@pytest.mark.slow
def test_unknown_correspondence_keeps_the_true_graph_over_50_seeds_and_counts_hypotheses():
    # types only (doors vs corridors), the room's declared 5 m landmark separation and the closest-landmark
    # sensor's negative information: measured 2 graphs in every one of 50 seeds (4 and 5 landmarks: the truth
    # and l1 split into the start sighting and the loop-closing ones), the truth always first
    counts, ranks = [], []
    for seed in range(50):
        ds = simulate_scenario("cuik-room", seed)
        r = solve(ds.inputs)
        assert r.status is Status.COMPLETED and r.extra["negative_information"] and r.extra["min_separation"] == 5.0
        m = sets.set_metrics(r.hypotheses, ds.truth.poses_xyt, ds.truth.landmarks_xy, ds.truth.obs_landmark)
        assert m["true_correspondence_survived"], f"seed {seed}: true correspondence refuted"
        assert m["soundness"] == 1.0, f"seed {seed}: truth outside the true hypothesis' boxes"
        assert m["n_hypotheses_distinct"] == m["n_hypotheses"]  # merged up to relabelling as they arise
        ranks.append(m["true_hypothesis_index"])
        counts.append(m["n_hypotheses"])
    assert counts == [2] * 50 and ranks == [0] * 50


def _refines(assoc, truth) -> bool:
    """Every label of ``assoc`` groups sightings of one true landmark (a split of the truth, no wrong merge)."""
    return all(truth[i] == truth[k] for i in range(len(assoc)) for k in range(len(assoc)) if assoc[i] == assoc[k])


@pytest.mark.slow
def test_without_a_separation_prior_no_sound_rule_can_prune_the_40_graphs():
    # sensor-only pruning (negative information on): still the 40 graphs — every one refines the true partition
    # (Bell(3)·2·2·2 = 40 ways to split l1's 3 and the other landmarks' 2 sightings), and a split is realised by
    # twin landmarks at the same spot, which produce exactly these readings (ties allowed). Each graph's boxes
    # contain the true landmark of every label: all 40 are consistent, so no sound rule can discard one.
    ds = simulate_scenario("cuik-room", 3, {"bounded.declared_separation": 0.0})
    r = solve(ds.inputs)
    hb, truth = r.hypotheses, ds.truth.obs_landmark
    assert r.extra["negative_information"] and len(hb) == 40 and sets.n_distinct(hb) == 40
    for h in range(len(hb)):
        assert _refines(hb.assoc[h], truth)
        labels = {int(a): int(t) for a, t in zip(hb.assoc[h], truth)}
        for a, t in labels.items():
            assert sets.points_in_boxes(ds.truth.landmarks_xy[t][None], hb.landmark_lo[h, a][None],
                                        hb.landmark_hi[h, a][None]).all()
        assert sets.poses_in_boxes(ds.truth.poses_xyt, hb.pose_lo[h], hb.pose_hi[h], slack=1e-9).all()
    assert np.bincount(hb.n_landmarks).tolist() == [0, 0, 0, 0, 1, 6, 13, 13, 6, 1]


def test_a_too_small_declared_bound_is_caught_by_an_empty_box():
    # bounds declared 5× too small: the readings are the same, and every box empties at a re-observation from
    # the next pose (a local cycle, paper 004 Fig. 1) or at a first sighting whose closest-landmark negative
    # information is violated (50 of 50 seeds in the reproduce section)
    where = []
    for seed in range(8):
        honest = simulate_scenario("cuik-room", seed)
        wrong = simulate_scenario("cuik-room", seed, {"bounded.declared_scale": 0.2})
        np.testing.assert_array_equal(honest.inputs.observations.range_m, wrong.inputs.observations.range_m)
        assert solve(with_true_association(honest), association="reported").status is Status.COMPLETED
        r = solve(with_true_association(wrong), association="reported")
        assert r.status is Status.FAILED and "empty" in r.message
        i = r.extra["refuted_at_observation"]
        lm = wrong.truth.obs_landmark
        assert i >= 1
        where.append("cycle" if lm[i - 1] == lm[i] else "negative" if not (lm[:i] == lm[i]).any() else "other")
        if where[-1] == "negative":  # without the negative information this sighting refutes nothing
            r0 = solve(with_true_association(wrong), association="reported", negative_information=False)
            assert r0.status is Status.COMPLETED or r0.extra["refuted_at_observation"] > i
    assert "other" not in where and "negative" in where and "cycle" in where


def test_an_error_beyond_its_bound_at_the_room_loop_closure_empties_every_box():
    # seed 1: the sightings of l1 that close the room's loop (poses 7 and 8) carry errors of exactly 5× their
    # bounds (range and bearing). Caught at the loop closure here; across 50 seeds the full set catches this in
    # a minority of runs and the paper set in none (reproduce section) — elsewhere the error hides in the
    # slack the other bounds leave.
    ds = simulate_scenario("cuik-room", 1)
    rows = loop_closure_rows(ds)
    assert ds.inputs.observations.step[rows].tolist() == [7, 8]
    bad = corrupt_loop_closure(ds, 5.0, np.random.default_rng(1))
    r = solve(bad, association="reported")
    assert r.status is Status.FAILED and r.extra["refuted_at_observation"] in rows.tolist()
    assert solve(bad, association="reported", **PAPER_SET).status is Status.COMPLETED
    assert solve(with_true_association(ds), association="reported").status is Status.COMPLETED


@pytest.mark.slow
def test_table1_paper_set_reproduced_and_full_set_narrower():
    exact = simulate_scenario("cuik-room", 0, {"bounded.exact_readings": True})
    known = with_true_association(exact)
    paper = our_widths(solve(known, association="reported", **PAPER_SET).hypotheses, 0)
    full_r = solve(known, association="reported", narrow_theta=True, shave_slices=4, bisect_leaves=64)
    full = our_widths(full_r.hypotheses, 0)
    tw = table1_widths()
    # the paper-exact operator set reproduces Table 1's early rows within 2 % (before any cycle closes)
    for k in ("r2", "r3", "r4", "r5", "r9", "l1", "l2"):
        np.testing.assert_allclose(paper[k], tw[k], rtol=0.02, err_msg=k)
    # the full set (θ narrowing, local cycles, closest-landmark negative information, 3B, bisection): every box
    # at most as wide as Table 1's (l2 was 0.05 % wider before the closest-landmark constraint: 2.355 × 2.811 m
    # now against the paper's 2.363 × 2.975 m) and clearly narrower from r4 on
    for k in tw:
        ok = np.isfinite(tw[k])
        assert (full[k][ok] <= tw[k][ok] + 1e-9).all(), k
    assert full["l2"][0] < tw["l2"][0] - 0.005 and full["l2"][1] < tw["l2"][1] - 0.1
    for k in ("r4", "r5", "r6", "r7", "r8", "r9", "l3", "l4"):
        assert (full[k][:2] < 0.85 * tw[k][:2]).all(), k
    lm_ours = np.mean([full[f"l{j}"][:2] for j in range(1, 5)])
    lm_paper = np.mean([tw[f"l{j}"][:2] for j in range(1, 5)])
    assert lm_ours < 0.6 * lm_paper


@pytest.mark.slow
def test_no_sound_method_gets_below_1m_here_and_our_boxes_reach_the_feasible_spread():
    # two genuine solutions of the bounded-error problem per coordinate — now also obeying the closest-landmark
    # sensor (every other landmark at least as far as the reported one) — must both lie in every sound box, so
    # their spread bounds its width from below: l3 x 7.78 m (8.39 m without the closest-landmark constraint;
    # l2 x 2.31 m in the reproduce section), so "< 1 m" is impossible on this data; our box contains both
    # extremes and is within 10 % of the spread
    exact = simulate_scenario("cuik-room", 0, {"bounded.exact_readings": True})
    r = solve(with_true_association(exact), association="reported", shave_slices=4, bisect_leaves=64)
    hb = r.hypotheses
    inv = {v: k for k, v in sets.landmark_map(hb.assoc[0], exact.truth.obs_landmark).items()}
    for true_j, spread_min, ratio in ((2, 7.0, 1.10),):  # l3 x
        lo, hi, viol = feasible_extent(exact, ("landmark", true_j, 0), maxiter=100)
        assert viol < 1e-6 and hi - lo > spread_min
        b_lo, b_hi = hb.landmark_lo[0, inv[true_j], 0], hb.landmark_hi[0, inv[true_j], 0]
        assert b_lo - 1e-6 <= lo and hi <= b_hi + 1e-6
        assert b_hi - b_lo < ratio * (hi - lo)


def test_graph_estimate_lies_inside_the_cuik_boxes():
    # least squares inside the boxes of the paper's constraints; the closest-landmark negative information can
    # exclude it: seed 0's `graph` estimate puts l1 0.23 m closer to pose 1 than the reported corridor (a tie in
    # the truth), which the sensor model forbids — so one pose box no longer contains it
    fractions, with_neg = [], []
    for seed in range(3):
        ds = simulate_scenario("cuik-room", seed)
        known = with_true_association(ds)
        g = solve_dataset(known, "graph", {})
        for neg, acc in ((False, fractions), (True, with_neg)):
            c = solve(known, association="reported", negative_information=neg)
            e = sets.estimate_inside(c.hypotheses, 0, g.poses_xyt, g.landmarks_xy, g.assoc)
            acc += [e["pose_inside_fraction"], e["landmark_inside_fraction"]]
        if seed == 0:
            o, L, p1 = known.observations, g.landmarks_xy, g.poses_xyt[1, :2]
            j1 = int(g.assoc[0])  # l1, seen from pose 0
            assert int(g.assoc[1]) != j1
            assert np.hypot(*(L[j1] - p1)) < o.range_m[1] - known.noise_bounds.range_half_width - 0.2
    assert fractions == [1.0] * 6
    assert with_neg == [8 / 9, 1.0, 1.0, 1.0, 1.0, 1.0]


@pytest.mark.slow
def test_corridors_run_with_the_hypothesis_cap():
    ds = simulate_scenario("cuik-corridors", 1)
    assert len(ds.truth.landmarks_xy) >= 12 and ds.inputs.n_poses - 1 >= 40
    r = solve(ds.inputs, max_hypotheses=2)
    assert r.status is Status.TRUNCATED and "cap" in r.message
    live = r.extra["live_hypotheses_per_step"]
    assert len(live) == ds.inputs.n_poses and max(live) == 2
    assert r.extra["hypotheses_dropped_by_cap"] > 0 and len(r.hypotheses) == 2
    # with the true association every box still contains the truth on the long run
    k = solve(with_true_association(ds), association="reported")
    m = sets.set_metrics(k.hypotheses, ds.truth.poses_xyt, ds.truth.landmarks_xy, ds.truth.obs_landmark)
    assert m["soundness"] == 1.0


def test_merge_up_to_relabelling_intersects_boxes():
    from slamcli.solvers.cuik.contractors import Interval as I
    from slamcli.solvers.cuik.hypotheses import Hypothesis, canonical_key, merge_relabelled

    pose = [I(0, 1), I(0, 1), I(0, 1)]
    a = Hypothesis(box=[I(x) for x in pose] + [I(0, 2), I(0, 2), I(5, 9), I(5, 9)], assoc=[0, 1, 0],
                   landmark_type=[0, 1])
    b = Hypothesis(box=[I(0.5, 1), I(0, 1), I(0, 1)] + [I(6, 8), I(6, 8), I(1, 3), I(1, 3)], assoc=[1, 0, 1],
                   landmark_type=[1, 0])
    assert canonical_key(a.assoc) == canonical_key(b.assoc) == (0, 1, 0)
    kept, merged = merge_relabelled([a, b])
    assert merged == 1 and len(kept) == 1
    box = kept[0].box
    assert (box[0].lb(), box[0].ub()) == (0.5, 1.0)
    assert (box[3].lb(), box[3].ub()) == (1.0, 2.0)  # a's label 0 ↔ b's label 1
    assert (box[5].lb(), box[5].ub()) == (6.0, 8.0)


def test_without_declared_bounds_cuik_fails_cleanly():
    from slamcli.errors import SolverError
    from slamcli.solvers.cuik.solver import CuikSlam

    ds = simulate_scenario("loop", 0, {"n_steps": 20})
    # called directly, the solver returns a FAILED result that says why ...
    r = CuikSlam().solve(ds.inputs, rng=np.random.default_rng(0))
    assert r.status is Status.FAILED and "noise_bounds" in r.message and r.hypotheses is None
    # ... and the file-level workflow refuses up front in one line
    with pytest.raises(SolverError, match="needs guaranteed error bounds"):
        solve(ds.inputs)


@pytest.mark.slow
def test_files_and_cli_round_trip(tmp_path):
    from typer.testing import CliRunner

    from slamcli.cli import app
    from slamcli.io import dataset_hash, read_dataset, read_result, write_dataset

    ds = simulate_scenario("cuik-room", 4)
    back = read_dataset(write_dataset(tmp_path / "c.h5", ds))
    nb, nb2 = ds.inputs.noise_bounds, back.inputs.noise_bounds
    assert nb2 is not None and nb2.odometry_model == "turn_move"
    np.testing.assert_array_equal(nb.odometry_half_width, nb2.odometry_half_width)
    assert (nb.range_half_width, nb.bearing_half_width) == (nb2.range_half_width, nb2.bearing_half_width)
    np.testing.assert_array_equal(back.inputs.observations.landmark_type, ds.inputs.observations.landmark_type)
    assert dataset_hash(back) == dataset_hash(ds)
    assert dataset_hash(dataclasses.replace(ds, inputs=dataclasses.replace(ds.inputs, noise_bounds=None))) != \
        dataset_hash(ds)

    runner = CliRunner()
    for args in (["solve", tmp_path / "c.h5", "-m", "cuik", "-o", tmp_path / "r.h5", "--quiet"],
                 ["evaluate", tmp_path / "r.h5", "-o", tmp_path / "ev", "--quiet"],
                 ["plot", "boxes", tmp_path / "r.h5", "-o", tmp_path / "b.png"]):
        res = runner.invoke(app, [str(a) for a in args])
        assert res.exit_code == 0, res.output
    r = read_result(tmp_path / "r.h5")
    direct = solve(ds.inputs)
    np.testing.assert_array_equal(r.hypotheses.assoc, direct.hypotheses.assoc)
    np.testing.assert_array_equal(r.hypotheses.pose_lo, direct.hypotheses.pose_lo)
    np.testing.assert_array_equal(r.hypotheses.landmark_hi, direct.hypotheses.landmark_hi)
    import json

    m = json.loads((tmp_path / "ev" / "metrics.json").read_text())
    assert m["set_soundness"] == 1.0 and m["set_true_correspondence_survived"] is True
    assert m["set_n_hypotheses"] == len(direct.hypotheses)
    assert (tmp_path / "b.png").stat().st_size > 10_000


def test_loop_closure_error_scenario_parameter_puts_exactly_k_bounds_on_the_loop_closing_sightings():
    # the sweep's way to ask for the wrong-bound data: honest readings except the sightings of l1 after pose 0,
    # whose range and bearing errors are exactly 5 declared half-widths (closed form against the truth)
    honest = simulate_scenario("cuik-room", 1)
    bad = simulate_scenario("cuik-room", 1, {"bounded.loop_closure_error": 5.0})
    obs, nb, tr = bad.inputs.observations, bad.inputs.noise_bounds, bad.truth
    rows = loop_closure_rows(bad)
    other = np.setdiff1d(np.arange(len(obs)), rows)
    np.testing.assert_array_equal(obs.range_m[other], honest.inputs.observations.range_m[other])
    np.testing.assert_array_equal(obs.bearing_rad[other], honest.inputs.observations.bearing_rad[other])
    d = tr.landmarks_xy[tr.obs_landmark[rows]] - tr.poses_xyt[obs.step[rows], :2]
    true_b = np.arctan2(d[:, 1], d[:, 0]) - tr.poses_xyt[obs.step[rows], 2]
    np.testing.assert_allclose(np.abs(obs.range_m[rows] - np.hypot(d[:, 0], d[:, 1])), 5 * nb.range_half_width,
                               rtol=1e-9)
    np.testing.assert_allclose(np.abs(obs.bearing_rad[rows] - true_b), 5 * nb.bearing_half_width, rtol=1e-9)
    # the same readings as the harness's corruption of the honest data (seeded signs)
    ref = corrupt_loop_closure(honest, 5.0, np.random.default_rng(1)).observations
    np.testing.assert_array_equal(obs.range_m, ref.range_m)
    np.testing.assert_array_equal(obs.bearing_rad, ref.bearing_rad)
