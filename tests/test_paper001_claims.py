"""Paper 001's claim verdicts are computed from the numbers: rows built by hand flip each verdict."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.stats import chi2

from slamcli.reproduce.paper001 import CLAIMS, DEVIATIONS, claim_verdicts, nees_band


def _rows(**change):
    base = [
        {"map": 1, "sensor": "laser", "lap_errors": [0.0073, 0.0037, 0.0027], "final_freq": 0.0027,
         "final_logodds": 0.0040, "nees": [3.1, 2.9] * 10},
        {"map": 1, "sensor": "noisy", "lap_errors": [0.142, 0.135, 0.130], "final_freq": 0.130,
         "final_logodds": 0.136, "nees": [2.8, 3.2] * 10},
    ]
    for k, v in change.items():
        base[1][k] = v
    return base


def verdicts(rows, **kw):
    return {c: v for c, v, _e in claim_verdicts(rows, **kw)}


def test_every_claim_holds_on_good_rows_and_is_marked_untested_without_data():
    v = verdicts(_rows())
    assert list(v) == list(CLAIMS)
    assert all(v[c] == "holds" for c in CLAIMS[:4])
    assert v["linear complexity"] == v["robustness to association"] == "not tested"


@pytest.mark.parametrize("change, claim", [
    ({"lap_errors": [0.142, 0.135, 0.139]}, "convergence over laps"),  # the noisy plateau
    ({"final_freq": 0.001}, "laser better than noisy"),
    ({"final_logodds": 0.12}, "frequentist vs Bayesian map"),
    ({"nees": [0.47, 0.50] * 10}, "consistency"),  # the measured conservative filter, over 20 seeds
])
def test_one_bad_row_flips_its_claim_only(change, claim):
    v = verdicts(_rows(**change))
    assert v[claim] in ("partly", "does NOT hold")
    assert all(v[c] == "holds" for c in CLAIMS[:4] if c != claim)


def test_one_seed_is_not_judged_for_consistency():
    v = claim_verdicts(_rows(nees=[0.5]))
    claim, verdict, evidence = v[3]
    assert claim == "consistency" and verdict == "holds" and "not judged" in evidence  # the other run decides
    rows = _rows(nees=[0.5])
    rows[0]["nees"] = [3.0]
    assert verdicts(rows)["consistency"] == "not tested"


def test_complexity_and_association_verdicts_follow_their_numbers():
    cells = np.array([1e4, 4e4, 1.6e5, 1e6])
    lin = verdicts(_rows(), complexity=list(zip(cells, 1e-6 * cells)))
    quad = verdicts(_rows(), complexity=list(zip(cells, 1e-10 * cells ** 2)))
    assert lin["linear complexity"] == "holds" and quad["linear complexity"] == "does NOT hold"
    ok = [{"label": "ML", "error_known": 0.01, "error": 0.012}]
    bad = [{"label": "wrong ids", "error_known": 0.01, "error": 0.05}]
    assert verdicts(_rows(), association=ok)["robustness to association"] == "holds"
    assert verdicts(_rows(), association=ok + bad)["robustness to association"] == "partly"


def test_nees_band_matches_chi2_quantiles_and_setting_lists_eq19():
    lo, hi = nees_band(20)
    assert lo == pytest.approx(chi2.ppf(0.025, 60) / 20) and hi == pytest.approx(chi2.ppf(0.975, 60) / 20)
    assert 2.0 < lo < 3 < hi < 4.2  # the mean of 20 χ²(3) draws: 3 ± 1.96·√(6/20) ≈ [1.93, 4.07], skewed right
    assert any("eq. 19" in d for d in DEVIATIONS) and any("10×" in d for d in DEVIATIONS)
