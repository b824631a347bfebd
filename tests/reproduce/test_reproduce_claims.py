"""Claim verdicts of REPORT.md (slamcli.reproduce.outcomes on the rule of slamcli.reproduce.verdicts): every
verdict is computed from the rows it is given — each test feeds rows on both sides of the stated condition and
checks that the verdict flips."""

import pytest

from slamcli.reproduce import outcomes as oc
from slamcli.reproduce import verdicts as vd

R, P, N = vd.REPRODUCED, vd.PARTLY, vd.NOT_REPRODUCED


def test_value_claim_flips_with_the_seeds_at_or_below_the_paper():
    assert oc.value_claim([0.14, 0.141, 0.139], 0.148, "x").verdict == R  # all below, margin 0.008 ≫ spread
    assert oc.value_claim([0.14, 0.15, 0.13], 0.148, "x").verdict == P  # 2 of 3 below
    j = oc.value_claim([0.30, 0.32], 0.148, "x")
    assert j.verdict == N and "0.310" in j.numbers and j.kind == vd.PAPER
    assert oc.value_claim([], 0.148, "x").verdict == N
    assert oc.value_claim([0.03, 0.04], 0.148, "x", kind=vd.FINDING).line().startswith("**Finding — x: supported")


def test_crossing_radius_interpolates_and_sensitivity_names_it():
    assert oc.crossing_radius([0.1, 0.2], [0.1, 0.2], 0.148) == pytest.approx(0.148)
    assert oc.crossing_radius([0.1, 0.2], [0.2, 0.3], 0.148) is None
    rows = [{"rho": 0.1, "model": "exact", "err": 0.10}, {"rho": 0.2, "model": "exact", "err": 0.30},
            {"rho": 0.2, "model": "surface", "err": 0.03}]
    s = oc.sensitivity_sentence(rows, 0.148)
    assert "≈ 0.124 m" in s and "surface-aware 0.030" in s
    above = oc.sensitivity_sentence([{"rho": 0.1, "model": "exact", "err": 0.2},
                                     {"rho": 0.05, "model": "exact", "err": float("nan")}], 0.148)
    assert "stays above" in above and "ρ = 0.05 m: no landmark estimated" in above


def test_lowers_claim_per_seed_with_digits_that_show_the_comparison():
    assert oc.lowers_claim([0.3, 0.31, 0.32], [0.2, 0.21, 0.22], "x").verdict == R
    j = oc.lowers_claim([0.1224], [0.1221], "x")  # one seed: holds, spread not measurable
    assert j.verdict == P and "0.1224 → 0.1221 m" in j.numbers
    assert oc.lowers_claim([0.315, 0.3, 0.31], [0.319, 0.31, 0.3], "x").verdict == N  # 1 of 3
    assert oc.lowers_claim([0.1], [float("nan")], "x").verdict == N


def test_stays_close_claim_flips_at_the_relative_tolerance():
    assert oc.stays_close_claim([1.0, 1.0, 1.0], [1.01, 0.99, 1.0], 0.1, "x").verdict == R
    j = oc.stays_close_claim([0.616, 0.6, 0.62], [0.807, 0.8, 0.75], 0.1, "x")
    assert j.verdict == N and "0.612 → 0.786 m" in j.numbers


def test_bound_and_falls_claims():
    assert oc.bound_claim([10, 12, 11], 35, "x", quantity="q", unit="mm").verdict == R
    assert oc.bound_claim([10, 12, 42.7], 35, "x", quantity="q", unit="mm").verdict == P
    assert oc.bound_claim([40, 394, 42.7], 35, "x", quantity="q", unit="mm").verdict == N
    assert oc.falls_claim([[4, 3, 2, 1], [5, 3, 1, 0.5], [4, 2, 1, 1]], "x", quantity="q", unit="mm").verdict == R
    assert oc.falls_claim([[4, 3, 2, 1], [1, 1, 2, 5]], "x", quantity="q", unit="mm").verdict == N  # 1 of 2


def test_earlier_iterate_claim_compares_the_end_with_the_best_sweep_before_it():
    # init 0.5, best after a sweep 0.30, final 0.34: an earlier iterate was closer to the truth in every seed
    worse_end = [[0.5, 0.30, 0.32, 0.34], [0.5, 0.31, 0.33, 0.35], [0.6, 0.29, 0.31, 0.34]]
    j = oc.earlier_iterate_claim(worse_end, "x")
    assert j.verdict == R and j.kind == vd.FINDING and "0.343 m vs 0.300 m" in j.numbers and "1, 1, 1" in j.numbers
    assert oc.earlier_iterate_claim([[0.5, 0.4, 0.3, 0.2], [0.5, 0.3, 0.2, 0.1]], "x").verdict == N  # decreasing
    # the initialisation (iteration 0) is not an "earlier iterate": lower than the end, yet not counted
    assert oc.earlier_iterate_claim([[0.1, 0.4, 0.3, 0.2], [0.1, 0.5, 0.3, 0.2]], "x").verdict == N
    assert "no seed" in oc.earlier_iterate_claim([[0.5, 0.4]], "x").numbers


def test_faster_claim_counts_never_reached_as_one_more_than_the_maximum():
    assert oc.faster_claim([5, 6, 7], [20, 22, 21], "S = I", "S = 0", 30, "x", "c").verdict == R
    assert oc.faster_claim([None, None], [None, None], "S = I", "S = 0", 30, "x", "c").verdict == N
    j = oc.faster_claim([5, None, 7], [20, 22, 21], "S = I", "S = 0", 30, "x", "c")  # 2 of 3: 31 > 22
    assert j.verdict == P and "counts as 31" in j.numbers


def test_better_initial_claim_and_missing_runs():
    assert oc.better_initial_claim([0.2, 0.21], [0.3, 0.31], "x").verdict == R
    j = oc.better_initial_claim([0.6], [0.3], "x", reason="fewer returns")
    assert j.verdict == N and "fewer returns" in j.numbers
    assert "not compared" in oc.better_initial_claim([0.2], [], "x").numbers


def test_recovery_fails_when_its_stated_condition_fails():
    assert oc.recovery_claim([3.0, 3.1, 2.9], [0.2, 0.3, 0.25], [1, 2, 1], 63, "x").verdict == R  # ≤ 5 % of 63
    j = oc.recovery_claim([1.245, 1.25, 1.24], [1.233, 1.2, 1.1], [40, 41, 41], 63, "x")
    assert j.verdict == N and "FAILED" in j.numbers  # error falls everywhere, 40.7 of 63 missed
    assert oc.recovery_claim([3.0, 3.0, 3.0], [0.2, 0.3, 3.5], [1, 1, 1], 63, "x").verdict == P
    assert oc.recovery_claim([3.0], [3.5], [0], 63, "x").verdict == N


def test_spread_flips_with_the_paired_difference():
    assert "exceeds" in oc.spread([1.0, 1.1, 1.2], [0.5, 0.6, 0.7], "a", "b", "ATE")
    assert "is within" in oc.spread([1.0, 0.4, 1.2], [0.5, 1.0, 0.8], "a", "b", "ATE")
    assert "not tested" in oc.spread([1.0], [0.5], "a", "b", "ATE")


def test_postprocess_claim_is_judged_over_every_run_of_every_base():
    assert oc.postprocess_claim({"ekf": ([1, 1, 1], [0.5, 0.6, 0.55])}, "x").verdict == R
    j = oc.postprocess_claim({"ekf": ([1, 1], [0.5, 1.2]), "graph": ([1], [2])}, "x")
    assert j.verdict == N and "after `ekf` in 1 of 2 runs" in j.numbers and "after `graph` in 0 of 1" in j.numbers
    # worse in 16 of 27 runs: lower in 11, not a majority
    assert oc.postprocess_claim({"ekf": ([1.0] * 27, [0.9] * 11 + [1.1] * 16)}, "x").verdict == N


def test_claims_status_never_says_ok_and_counts_verdicts_and_findings():
    claims = [vd.Judgement("a", vd.PAPER, R, ""), vd.Judgement("b", vd.PAPER, N, ""),
              vd.Judgement("c", vd.PAPER, N, ""), vd.Judgement("d", vd.FINDING, P, "")]
    s = oc.claims_status(claims, True, [])
    assert "ok" not in s.lower().replace("look", "") and "1 reproduced" in s and "2 not reproduced" in s
    assert "1 finding" in s and "partly" not in s
    assert "FAILED" in oc.claims_status(claims[:1], False, ["a run failed"])


def test_nees_note_is_computed_from_the_fraction_inside_the_band():
    assert oc.nees_note(0.95, 3.0, 2.0, 4.0) == "consistent"
    assert oc.nees_note(0.04, 98.6, 0.9, 6.3) == "overconfident"
    assert oc.nees_note(0.5, 1.0, 2.0, 4.0) == "underconfident"
    assert oc.nees_note(0.89, 3.0, 2.0, 4.0) == "inconsistent"


def test_report_title_names_only_the_papers_whose_sections_ran():
    from slamcli.reproduce.report import report_title

    assert report_title(["paper001", "paper001-map4"]) == (
        "# slamcli reproduction of paper 001 (hybrid Bayesian/frequentist occupancy-grid SLAM)")
    title = report_title(["fig5", "nees", "paper004", "real"])
    assert title.index("paper 000") < title.index("paper 004") < title.index("real recordings")
    assert "paper 001" not in title


def test_report_opens_with_the_count_and_a_row_per_claim_and_the_cli_ends_with_the_count():
    from pathlib import Path

    from slamcli.reproduce.report import ReproduceOutcome, Section, verdict_summary

    fig5, fig9, other = Section("fig5", "Fig. 5: x"), Section("fig9", "Fig. 9: y"), Section("paper001", "Paper 001: z")
    fig5.add_claim(oc.lowers_claim([0.3, 0.31, 0.32], [0.2, 0.21, 0.22], "ICM corrects the initial map"))
    fig5.add_claim(oc.value_claim([0.30, 0.31], 0.148, "0.148 m"))
    fig9.add_claim(oc.bound_claim([10, 12, 11], 35, "35 mm", quantity="q", unit="mm", kind=vd.FINDING))
    text = "\n".join(verdict_summary([fig5, fig9, other]))
    assert text.startswith("**Verdicts: 1 reproduced / 0 partly reproduced / 1 not reproduced paper claims; "
                           "1 finding of our own.**")
    rows = [ln for ln in text.splitlines() if ln.startswith("| Fig.")]
    assert len(rows) == 3
    assert rows[0].startswith("| Fig. 5 | ICM corrects the initial map | paper | **reproduced** | mean landmark "
                              "error 0.310 → 0.210 m")
    assert rows[1].startswith("| Fig. 5 | 0.148 m | paper | **not reproduced** |")
    assert rows[2].startswith("| Fig. 9 | 35 mm | finding | **supported** |")
    assert "`paper001`" in text and "not counted" in text  # other papers' sections are named, not silently left out
    claims = fig5.claims + fig9.claims
    ok = ReproduceOutcome(Path("R.md"), [], claims).summary().splitlines()
    bad = ReproduceOutcome(Path("R.md"), [("fig9", "a run failed")], claims).summary().splitlines()
    assert ok[-1] == bad[-1] == vd.count_line(claims) and "1 section(s) failed" in bad[0]
