"""``graph`` flags its own nearest-neighbour association when the sightings do not fit the estimate.

The reference is the simulator's ground truth (read here, never by the solver): with unbiased odometry every
sighting of ``loop`` goes to its own landmark; with the heading increments 20 % too large
(``odometry.turn_bias = 0.2``) the association built from the dead-reckoned path merges and splits landmarks.
The check must stay quiet on the first and fire on the second; its fraction counts sighting factors only
(counts drawn from χ²₂ against the closed-form quantile ``−2 ln(1 − p)``).
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from slamcli.sim import simulate_scenario
from slamcli.solvers.graph import GraphParams, GraphSlam
from slamcli.solvers.graph.solver import ASSOCIATION_SUSPECT_FRAC, _association_check


def _wrong_rows(assoc: np.ndarray, true_label: np.ndarray) -> float:
    """Fraction of rows whose label's majority true landmark is not their own."""
    bad = 0
    for a in np.unique(assoc[assoc >= 0]):
        lab = true_label[(assoc == a) & (true_label >= 0)]
        if lab.size:
            bad += int(np.sum(lab != np.bincount(lab).argmax()))
    return bad / assoc.size


@pytest.mark.slow
def test_check_is_quiet_on_a_right_association_and_fires_on_a_wrong_one():
    out = {}
    for bias in (0.0, 0.2):
        d = simulate_scenario("loop", seed=0, overrides={"odometry.turn_bias": bias})
        r = GraphSlam(GraphParams()).solve(d.inputs, rng=np.random.default_rng(0))
        assert r.extra["association"] == "nn"
        out[bias] = (r, _wrong_rows(np.asarray(r.assoc), np.asarray(d.truth.obs_landmark)))
    (good, wrong_good), (bad, wrong_bad) = out[0.0], out[0.2]
    assert wrong_good == 0.0 and wrong_bad > 0.02  # the truth says which association is wrong
    assert not good.extra["association_check"]["suspect"]
    assert "association suspect" not in good.message
    assert bad.extra["association_check"]["suspect"]
    assert "association suspect" in bad.message


def test_check_fraction_is_the_share_beyond_the_chi2_gate():
    chi2_2_99 = -2.0 * math.log(1.0 - 0.99)  # χ²₂ quantile in closed form
    rng = np.random.default_rng(4)
    s2 = rng.chisquare(2, size=2000) * np.where(np.arange(2000) < 300, 9.0, 1.0)  # 300 inflated residuals
    over = int(np.sum(s2 > chi2_2_99))
    extra = {"chi2_outliers": {"bearing_range": {"factors": 2000, "dof": 2, "over_95": 0, "over_99": over},
                               "odometry": {"factors": 500, "dof": 3, "over_95": 0, "over_99": 500}}}
    msg = _association_check(extra)
    assert extra["association_check"]["frac_over_chi2_99"] == over / 2000  # odometry rows are not sightings
    assert extra["association_check"]["suspect"] == (over / 2000 > ASSOCIATION_SUSPECT_FRAC)
    assert (msg != "") == extra["association_check"]["suspect"]
