"""The verdict rule of REPORT.md (slamcli.reproduce.verdicts): hand-written replicate effects on both sides of
every boundary — 80 % of replicates, a majority, the replicate spread, a stated effect size, a failed condition."""

import math
import statistics

import pytest

from slamcli.reproduce import verdicts as vd

R, P, N = vd.REPRODUCED, vd.PARTLY, vd.NOT_REPRODUCED


def test_eighty_percent_boundary():
    # 4 of 5 = 80 % hold, effect far above its spread -> reproduced; 3 of 5 = 60 % -> only a majority: partly
    assert vd.verdict(vd.evidence([1.0, 1.1, 0.9, 1.0, -0.01])) == R
    assert vd.verdict(vd.evidence([1.0, 1.1, 0.9, -0.01, -0.02])) == P
    # 8 of 10 vs 7 of 10
    assert vd.verdict(vd.evidence([1.0] * 8 + [-0.01] * 2)) == R
    assert vd.verdict(vd.evidence([1.0] * 7 + [-0.01] * 3)) == P


def test_majority_boundary():
    assert vd.verdict(vd.evidence([0.1, 0.1, 0.1, -0.1, -0.1])) == P  # 3 of 5
    assert vd.verdict(vd.evidence([0.1, 0.1, -0.1, -0.1])) == N  # 2 of 4 is half, not a majority
    assert vd.verdict(vd.evidence([0.1, 0.1, -0.1, -0.1, -0.1])) == N  # 2 of 5
    assert vd.verdict(vd.evidence([0.1, 0.0, 0.0])) == N  # zero effect does not hold
    assert vd.verdict(vd.evidence([])) == N


def test_spread_boundary_against_the_sample_standard_error():
    small = [0.1, 0.1, 0.1, 0.1, 3.0]  # all hold, but one replicate dominates: mean 0.68
    sd = statistics.stdev(small)
    ev = vd.evidence(small)
    assert ev.spread == pytest.approx(2.0 * sd / math.sqrt(5)) and ev.effect == pytest.approx(0.68)
    assert ev.effect < ev.spread and vd.verdict(ev) == P  # holds everywhere, effect within its spread
    tight = [0.6, 0.7, 0.68, 0.7, 0.72]  # same order of mean, small spread
    assert vd.verdict(vd.evidence(tight)) == R
    # the boundary itself, with hand-set numbers: effect equal to the spread is not larger than it
    assert vd.verdict(vd.Evidence(5, 5, 0.2, 0.2)) == P
    assert vd.verdict(vd.Evidence(5, 5, 0.2001, 0.2)) == R
    # one replicate: the spread cannot be measured, so at most partly
    assert vd.verdict(vd.evidence([5.0])) == P and math.isnan(vd.evidence([5.0]).spread)


def test_a_failed_condition_makes_it_not_reproduced():
    effects = [1.0, 1.1, 0.9]
    assert vd.verdict(vd.evidence(effects, condition_ok=True)) == R
    assert vd.verdict(vd.evidence(effects, condition_ok=False)) == N


def test_a_smaller_effect_than_stated_is_partly():
    effects = [1.0, 1.1, 0.9]
    assert vd.verdict(vd.evidence(effects, stated_effect=0.9)) == R
    assert vd.verdict(vd.evidence(effects, stated_effect=1.5)) == P


def test_explicit_holds_and_non_finite_effects():
    ev = vd.evidence([1.0, float("nan"), None, 2.0], holds=[True, False])
    assert (ev.n, ev.n_hold) == (2, 1)
    assert vd.drop_effects([0.3, None, 0.2], [0.1, 0.5, float("inf")]) == [pytest.approx(0.2)]


def test_show_uses_enough_digits_to_tell_numbers_apart():
    assert vd.show(0.1224, 0.1221) == ["0.1224", "0.1221"]
    assert vd.show(0.1, 0.2) == ["0.100", "0.200"]
    assert vd.show(0.0003) == ["0.0003"]  # a non-zero effect never prints as zero
    assert vd.show(0.5, float("nan")) == ["0.500", "n/a"]
    assert vd.digits_to_show([1.0, 1.0 + 1e-9]) == vd.MAX_DIGITS


def test_judgement_words_count_and_count_line():
    claims = [vd.Judgement("a", vd.PAPER, R, "n"), vd.Judgement("b", vd.PAPER, N, "n"),
              vd.Judgement("c", vd.PAPER, N, "n"), vd.Judgement("d", vd.FINDING, R, "n")]
    assert vd.count(claims) == {R: 1, P: 0, N: 2, vd.FINDING: 1}
    assert vd.count_line(claims) == ("Verdicts: 1 reproduced / 0 partly reproduced / 2 not reproduced paper "
                                     "claims; 1 finding of our own.")
    assert claims[3].line().startswith("**Finding — d: supported**")
    assert claims[1].line() == "**Paper claim — b: not reproduced** (n)."
    j = vd.judge("x", vd.evidence([0.1, 0.2]), "nums", unit="m")
    assert j.verdict == R and "holds in 2 of 2 seeds" in j.rule and "> spread" in j.rule
