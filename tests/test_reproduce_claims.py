"""Paper-claim verdicts of REPORT.md (slamcli.reproduce.outcomes, issue 22): every verdict is computed from the rows
it is given — each test feeds rows on both sides of the stated condition and checks that the verdict flips."""

import pytest

from slamcli.reproduce import outcomes as oc

R, P, N = oc.REPRODUCED, oc.PARTLY, oc.NOT_REPRODUCED


def test_paper_value_claim_flips_with_the_paper_exact_and_surface_aware_means():
    assert oc.paper_value_claim([0.14, 0.15], [], 0.148, "x")[0] == R  # mean 0.145 ≤ 0.148
    assert oc.paper_value_claim([0.30, 0.32], [0.03, 0.04], 0.148, "x")[0] == P
    v, s = oc.paper_value_claim([0.30, 0.32], [0.20, 0.16], 0.148, "x")
    assert v == N and "0.310" in s and "0.180" in s
    assert oc.paper_value_claim([], [0.03], 0.148, "x")[0] == N


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


def test_map_not_worse_counts_the_seeds_made_worse():
    assert oc.map_not_worse_claim([0.1, 0.1], [0.09, 0.1], "x")[0] == R
    v, s = oc.map_not_worse_claim([0.1, 0.1], [0.5, 0.09], "x")
    assert v == P and "worse in 1 of 2" in s
    assert oc.map_not_worse_claim([0.1], [0.8], "x")[0] == N


def test_falls_compares_last_and_first_quarter():
    assert "every seed" in oc.falls([[4, 3, 2, 1], [2, 1]], "map change")
    assert "1 of 2 seeds only" in oc.falls([[4, 3, 2, 1], [1, 1, 2, 5]], "map change")


def test_better_initial_claim_and_missing_runs():
    assert oc.better_initial_claim([0.2], [0.3], "x")[0] == R
    v, s = oc.better_initial_claim([0.6], [0.3], "x", reason="fewer returns")
    assert v == N and "fewer returns" in s
    assert "not compared" in oc.better_initial_claim([0.2], [], "x")[1]


def test_recovery_needs_lower_error_and_few_missed_landmarks():
    assert oc.recovery_claim([3.0, 3.0], [0.2, 0.3], [1, 2], 63, "x")[0] == R  # 1.5 ≤ 5 % of 63
    assert oc.recovery_claim([3.0, 3.0], [0.2, 0.3], [40, 41], 63, "x")[0] == P
    assert oc.recovery_claim([3.0, 3.0], [0.2, 3.5], [1, 1], 63, "x")[0] == P
    assert oc.recovery_claim([3.0], [3.5], [0], 63, "x")[0] == N


def test_spread_flips_with_the_paired_difference():
    assert "exceeds" in oc.spread([1.0, 1.1, 1.2], [0.5, 0.6, 0.7], "a", "b", "ATE")
    assert "is within" in oc.spread([1.0, 0.4, 1.2], [0.5, 1.0, 0.8], "a", "b", "ATE")
    assert "not tested" in oc.spread([1.0], [0.5], "a", "b", "ATE")


def test_postprocess_claim_counts_runs_per_base():
    assert oc.postprocess_claim({"ekf": ([1, 1], [0.5, 0.9])}, "x")[0] == R
    v, s = oc.postprocess_claim({"ekf": ([1, 1], [0.5, 1.2]), "graph": ([1], [2])}, "x")
    assert v == P and "after `ekf` in 1 of 2 runs" in s and "after `graph` in 0 of 1" in s
    assert oc.postprocess_claim({"ekf": ([1], [2])}, "x")[0] == N


def test_claims_status_never_says_ok_and_counts_verdicts():
    s = oc.claims_status([R, N, N], True, [])
    assert "ok" not in s.lower().replace("look", "") and "1 reproduced" in s and "2 not reproduced" in s
    assert "FAILED" in oc.claims_status([R], False, ["a run failed"])


def test_report_title_names_only_the_papers_whose_sections_ran():
    from slamcli.reproduce.report import report_title

    assert report_title(["paper001", "paper001-map4"]) == (
        "# slamcli reproduction of paper 001 (hybrid Bayesian/frequentist occupancy-grid SLAM)")
    title = report_title(["fig5", "nees", "paper004", "real"])
    assert title.index("paper 000") < title.index("paper 004") < title.index("real recordings")
    assert "paper 001" not in title
