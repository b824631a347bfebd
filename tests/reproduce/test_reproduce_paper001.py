"""Paper 001's claim verdicts are computed from the numbers: rows built by hand flip each verdict."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.stats import chi2

from slamcli.metrics.consistency import chi2_band
from slamcli.reproduce.paper001 import CLAIMS, DEVIATIONS, claim_verdicts, plateaued
from slamcli.reproduce.paper001_studies import (
    loglog_slope,
    nees_class,
    nees_summary,
    read_complexity,
)


def _rows(**change):
    base = [
        {"map": 1, "sensor": "laser", "lap_errors": [0.0073, 0.0037, 0.0027], "final_freq": 0.0027,
         "final_logodds": 0.0040},
        {"map": 1, "sensor": "noisy", "lap_errors": [0.142, 0.135, 0.130], "final_freq": 0.130,
         "final_logodds": 0.136},
    ]
    for k, v in change.items():
        base[1][k] = v
    return base


def _nees(scale=1.0, n_seeds=20, n_steps=300, seed=0):
    """Per-step NEES of a filter whose covariance is ``1/scale`` × the true one: scale · χ²(3) draws."""
    return scale * np.random.default_rng(seed).chisquare(3, size=(n_seeds, n_steps))


def _consistency(*scales, n_seeds=20):
    return [nees_summary(_nees(s, n_seeds, seed=k), f"config {k}") for k, s in enumerate(scales)]


def verdicts(rows, **kw):
    kw.setdefault("consistency", _consistency(1.0, 1.0))
    return {c: v for c, v, _e in claim_verdicts(rows, **kw)}


def test_every_claim_holds_on_good_rows_and_is_marked_untested_without_data():
    v = verdicts(_rows())
    assert list(v) == list(CLAIMS)
    assert all(v[c] == "holds" for c in CLAIMS[:4])
    assert v["linear complexity"] == v["robustness to association"] == "not tested"
    assert verdicts(_rows(), consistency=None)["consistency"] == "not tested"


@pytest.mark.parametrize("change, claim", [
    ({"lap_errors": [0.142, 0.135, 0.139]}, "convergence over laps"),  # the noisy plateau
    ({"final_freq": 0.001}, "laser better than noisy"),
    ({"final_logodds": 0.12}, "frequentist vs Bayesian map"),
])
def test_one_bad_row_flips_its_claim_only(change, claim):
    v = verdicts(_rows(**change))
    assert v[claim] in ("partly", "does NOT hold")
    assert all(v[c] == "holds" for c in CLAIMS[:4] if c != claim)


def test_nees_summary_counts_steps_against_the_band_by_brute_force():
    nees = _nees(0.8, 20, 200, seed=7)
    nees[:, 0] = np.nan  # the known start
    s = nees_summary(nees, "x")
    lo, hi = chi2_band(20, 3)
    inside = above = 0
    for t in range(1, 200):
        m = sum(nees[k, t] for k in range(20)) / 20
        inside += lo <= m <= hi
        above += m > hi
    assert s["inside"] == pytest.approx(inside / 199) and s["above"] == pytest.approx(above / 199)
    assert s["anees_mean"] == pytest.approx(np.mean(nees[:, 1:]))


@pytest.mark.parametrize("scales, verdict", [
    ((1.0, 1.0), "holds"),  # calibrated: ≈ 95 % of the steps inside the band
    ((1.0, 0.15), "partly"),  # one conservative filter (our measured ANEES ≈ 0.3-0.5)
    ((1.0, 3.0), "does NOT hold"),  # one overconfident filter
])
def test_consistency_verdict_follows_the_monte_carlo(scales, verdict):
    assert verdicts(_rows(), consistency=_consistency(*scales))["consistency"] == verdict


def test_fewer_than_20_seeds_are_not_judged():
    c = _consistency(1.0, 3.0, n_seeds=5)
    assert [nees_class(x) for x in c] == ["not judged"] * 2
    claim, verdict, evidence = claim_verdicts(_rows(), consistency=c)[3]
    assert claim == "consistency" and verdict == "not tested" and "not judged" in evidence


def test_loglog_slope_and_stored_table(tmp_path):
    cells = np.array([1e4, 1e5, 1e6])
    assert loglog_slope(cells, 2.5 * cells ** 0.7) == pytest.approx(0.7)
    path = tmp_path / "hybrid.csv"
    path.write_text("world,grid_cells,cpu_ms_per_map_step,other\nA,10000,2.0,x\nB,1000000,2.2,\nC,,3,\n")
    rows = read_complexity(path)
    assert [(r["world"], r["grid_cells"], r["cpu_ms_per_map_step"]) for r in rows] == [("A", 1e4, 2.0),
                                                                                   ("B", 1e6, 2.2)]
    assert read_complexity(tmp_path / "missing.csv") is None
    v = claim_verdicts(_rows(), complexity=[(r["grid_cells"], r["cpu_ms_per_map_step"]) for r in rows])[4]
    assert v[1] == "holds" and f"{np.log(1.1) / np.log(100):.2f}" in v[2]


def test_plateau_rule():
    assert plateaued([0.142, 0.135, 0.139]) and not plateaued([0.0073, 0.0037, 0.0027]) and not plateaued([0.1])


def test_complexity_and_association_verdicts_follow_their_numbers():
    cells = np.array([1e4, 4e4, 1.6e5, 1e6])
    lin = verdicts(_rows(), complexity=list(zip(cells, 1e-6 * cells)))
    quad = verdicts(_rows(), complexity=list(zip(cells, 1e-10 * cells ** 2)))
    assert lin["linear complexity"] == "holds" and quad["linear complexity"] == "does NOT hold"
    ok = [{"label": "ML", "error_known": 0.01, "error": 0.012, "pos_err": 0.02, "pos_err_known": 0.01}]
    bad = [{"label": "wrong ids", "error_known": 0.01, "error": 0.05}]
    assert verdicts(_rows(), association=ok)["robustness to association"] == "holds"
    assert "pose 0.02 vs 0.01 m" in claim_verdicts(_rows(), association=ok)[5][2]
    assert verdicts(_rows(), association=ok + bad)["robustness to association"] == "partly"


def test_nees_band_matches_chi2_quantiles_and_setting_lists_eq19():
    lo, hi = chi2_band(20, 3)
    assert lo == pytest.approx(chi2.ppf(0.025, 60) / 20) and hi == pytest.approx(chi2.ppf(0.975, 60) / 20)
    assert 2.0 < lo < 3 < hi < 4.2  # the mean of 20 χ²(3) draws: 3 ± 1.96·√(6/20) ≈ [1.93, 4.07], skewed right
    assert any("eq. 19" in d for d in DEVIATIONS) and any("10×" in d for d in DEVIATIONS)


def test_first_wrong_association_step():
    from types import SimpleNamespace as NS

    from slamcli.reproduce.paper001 import first_wrong_step

    def m(assoc, truth, steps):
        return {"res": NS(assoc=np.array(assoc)), "ds": NS(truth=NS(obs_landmark=np.array(truth)),
                                                          inputs=NS(observations=NS(step=np.array(steps))))}

    # rows: feature 4 → landmark 0, feature 7 → landmark 1, discarded row, then feature 7 into landmark 0 at step 3
    assert first_wrong_step(m([0, 1, -1, 0], [4, 7, 4, 7], [0, 1, 2, 3])) == 3
    assert first_wrong_step(m([0, 1, 0], [4, 7, 4], [0, 1, 2])) is None
    assert first_wrong_step(m([0, 0], [4, -1], [0, 5])) == 5  # a false return fused into a feature's landmark
    assert first_wrong_step(m([0, 1], [4, -1], [0, 5])) is None  # a false return's own (spurious) landmark


@pytest.mark.parametrize("scale, outcome", [(1.0, "does NOT hold here"), (3.0, "holds here.")])
def test_unstabilised_filter_sentence_follows_the_monte_carlo(scale, outcome):
    from slamcli.reproduce.paper001 import _study_lines

    mc = [nees_summary(_nees(scale, 20, seed=k), f"Map {k} laser, 1×") for k in (1, 2)]
    text = "\n".join(_study_lines([], [], mc, [], None))
    assert outcome in text and f"optimistic in {2 if scale > 1 else 0} of 2" in text
