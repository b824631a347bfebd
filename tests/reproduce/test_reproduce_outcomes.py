"""Every outcome sentence of REPORT.md flips its wording when its numbers cross the stated condition."""

from __future__ import annotations

import math

from slamcli.reproduce import outcomes as oc


def test_lowers_every_none_some():
    assert oc.lowers([0.3, 0.4], [0.2, 0.1], "error").startswith("ICM lowers the error in every seed")
    assert oc.lowers([0.3, 0.4], [0.35, 0.5], "error").startswith("ICM does not lower the error in any seed")
    assert "in 1 of 2 seeds only" in oc.lowers([0.3, 0.4], [0.2, 0.5], "error")
    assert oc.lowers([0.3], [0.3], "error").startswith("ICM does not lower")  # equal is not lower
    assert "0.300 → 0.200 m" in oc.lowers([0.3], [0.2], "error")
    assert "cannot be said" in oc.lowers([math.nan], [0.2], "error")
    assert "in every run" in oc.lowers([1.0], [0.5], "ATE", who="X", item="run")


def test_versus_paper_sides():
    assert "is below the paper's 0.148 m" in oc.versus_paper([0.10, 0.12], 0.148, "error")
    assert "is above the paper's 0.148 m" in oc.versus_paper([0.20, 0.30], 0.148, "error")
    assert "equal to" in oc.versus_paper([0.148], 0.148, "error")
    assert "No completed run" in oc.versus_paper([], 0.148, "error")
    assert "0.1479 ± 0.000 m (1 seed) is below the paper's 0.1480 m" in oc.versus_paper([0.1479], 0.148, "error")


def test_faster_flips_and_counts_never_reached():
    assert oc.faster([5, 7], [10, 12], "S = I", "S = 0", "crit", 30).startswith("S = I converges faster than S = 0")
    assert oc.faster([10, 12], [5, 7], "S = I", "S = 0", "crit", 30).startswith("S = I converges slower than S = 0")
    assert "equally fast" in oc.faster([5], [5], "a", "b", "crit", 30)
    # a seed that never reaches the criterion counts as n_max + 1
    assert oc.faster([None], [30], "a", "b", "crit", 30).startswith("a converges slower")
    assert oc.faster([None, None], [None], "a", "b", "crit", 30).startswith("Neither a nor b reaches crit")


def test_stays_close_threshold():
    assert oc.stays_close([1.0, 1.0], [1.05, 0.95], 0.1, "err").startswith("ICM converges close")
    assert oc.stays_close([1.0, 1.0], [1.2, 0.8], 0.1, "err").startswith("ICM moves away")


def test_within_bound():
    assert "stays below the paper's 35 mm in every seed" in oc.within_bound([10, 34.9], 35, "change", "mm")
    assert "exceeds the paper's 35 mm in 1 of 2 seeds" in oc.within_bound([10, 35], 35, "change", "mm")


def test_ratio_direction():
    assert "is lower than `b`'s" in oc.ratio([1.0], [2.0], "`a`", "`b`", "x") and "ratio 0.50" in oc.ratio(
        [1.0], [2.0], "`a`", "`b`", "x")
    assert "is higher than `b`'s" in oc.ratio([3.0], [2.0], "`a`", "`b`", "x")
    assert "cannot be compared" in oc.ratio([], [2.0], "`a`", "`b`", "x")


def test_nees_verdict_sides():
    assert "is consistent" in oc.nees_verdict(0.95, 3.0, 2.0, 4.0, "ekf")
    assert "is overconfident" in oc.nees_verdict(0.5, 9.0, 2.0, 4.0, "ekf")
    assert "is underconfident" in oc.nees_verdict(0.5, 1.0, 2.0, 4.0, "ekf")
    assert "is consistent" not in oc.nees_verdict(0.89, 3.0, 2.0, 4.0, "ekf")


def test_section_status_and_pm():
    assert "**ok**" in oc.section_status(True, [])
    assert "**FAILED** — a; b" in oc.section_status(False, ["a", "b"])
    assert oc.pm([1.0, 3.0]) == "2.000 ± 1.000" and oc.pm([math.nan]) == "n/a"


def test_pm_range():
    assert oc.pm_range([1.0, 3.0, float("nan")]) == "2.000 ± 1.000 (1.000-3.000)" and oc.pm_range([]) == "n/a"
