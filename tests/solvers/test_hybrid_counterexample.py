"""Paper 001 §II.D (Fig. 2): the frequentist update converges to the true map from every start; the
Bayesian alternatives without map-map correlations do not keep the truth as a fixed point."""

import numpy as np
import pytest

from slamcli.models.hybrid_counterexample import (
    frequentist_c,
    naive_bayes_p2_after_z1,
    naive_bayes_p2_after_z1_as_printed,
    pose_conditioned_p2_after_z1,
    run_frequentist,
)

GRID = [(p1, p2) for p1 in (0.05, 0.35, 0.65, 0.95) for p2 in (0.05, 0.35, 0.65, 0.95)]


@pytest.mark.parametrize("p3", [0.2, 0.5, 0.8])
def test_frequentist_converges_to_truth_from_every_start(p3):
    for k, p0 in enumerate(GRID):
        tr = run_frequentist(p0, 4000, np.random.default_rng(k), b1=0.4, p3=p3)
        d_end = np.hypot(tr[-1, 0], 1.0 - tr[-1, 1])  # distance to the true map (p1, p2) = (0, 1)
        d_200 = np.hypot(tr[200, 0], 1.0 - tr[200, 1])
        d_0 = np.hypot(p0[0], 1.0 - p0[1])
        assert d_end < 0.02, (p0, tr[-1])
        assert d_end < d_200 < d_0


def test_truth_is_a_fixed_point_of_eq23():
    # (p1, p2) = (0, 1): c1 = 0 for both readings, c2 = 1 for both readings (the paper's sanity check)
    for z in (1, 2):
        c1, c2 = frequentist_c(z, 0.0, 1.0, 0.7, 0.4, 0.6)
        assert (c1, c2) == (0.0, 1.0)


def test_eq22_hand_values():
    p1, p2, p3, b1, b2 = 0.3, 0.6, 0.5, 0.4, 0.6
    pz1 = (1 - p1) * p2 * b1 + (1 - p1) * (1 - p2) * p3 * b2  # 0.168 + 0.084 = 0.252
    pz2 = p1 * b1 + (1 - p1) * p2 * b2  # 0.12 + 0.252 = 0.372
    assert frequentist_c(1, p1, p2, p3, b1, b2) == pytest.approx((0.0, 0.168 / pz1))
    assert frequentist_c(2, p1, p2, p3, b1, b2) == pytest.approx((0.12 / pz2, 1.0))


def test_naive_bayes_not_a_fixed_point_as_printed_and_pose_conditioned():
    b1 = 0.4
    for p3 in (0.2, 0.5, 0.9):
        # eq. (24) as the paper evaluates it: b1 / (b1 + p3 b2) < 1 at the true map
        assert naive_bayes_p2_after_z1_as_printed(0.0, 1.0, p3, b1) == pytest.approx(b1 / (b1 + p3 * (1 - b1)))
        assert naive_bayes_p2_after_z1_as_printed(0.0, 1.0, p3, b1) < 0.9
    # eqs. (25)-(27): p(q2) = b1 after z1, not 1
    assert pose_conditioned_p2_after_z1(1.0, 1.0, 0.0, b1) == pytest.approx(b1)
    # finding: with the strict normaliser (prior p(q2 = E) = 1 − p2 = 0) eq. (24) keeps p2 = 1 — the paper's
    # non-fixed-point claim for eq. (24) rests on its printed normaliser
    assert naive_bayes_p2_after_z1(0.0, 1.0, 0.5, b1) == pytest.approx(1.0)
