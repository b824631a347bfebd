"""Resampling and weight helpers: statistics checked against their definitions."""

from __future__ import annotations

import numpy as np
import pytest

from slamcli.solvers.resampling import (
    effective_sample_size,
    multinomial_resample,
    normalise_log_weights,
    systematic_resample,
)


@pytest.mark.parametrize("P", [1, 7, 100, 1000])
def test_systematic_counts_within_one_of_expected(P):
    rng = np.random.default_rng(P)
    for _ in range(50):
        w = rng.dirichlet(np.full(P, 0.3))
        idx = systematic_resample(w, rng)
        assert idx.shape == (P,) and idx.min() >= 0 and idx.max() < P
        counts = np.bincount(idx, minlength=P)
        assert np.all(np.abs(counts - P * w) < 1.0 + 1e-9)


def test_systematic_is_unbiased():
    """E[count_i] = P w_i: average over many draws."""
    rng = np.random.default_rng(1)
    P = 5
    w = np.array([0.05, 0.15, 0.5, 0.27, 0.03])
    counts = np.zeros(P)
    n = 20000
    for _ in range(n):
        counts += np.bincount(systematic_resample(w, rng), minlength=P)
    np.testing.assert_allclose(counts / n, P * w, atol=0.01)


def test_multinomial_counts_mean_and_variance():
    """Counts ~ Multinomial(P, w): mean P w_i and variance P w_i (1 − w_i)."""
    rng = np.random.default_rng(2)
    P = 10
    w = rng.dirichlet(np.ones(P))
    n = 20000
    C = np.stack([np.bincount(multinomial_resample(w, rng), minlength=P) for _ in range(n)])
    assert np.all(np.abs(C.mean(0) - P * w) <= 5 * np.sqrt(P * w * (1 - w) / n) + 1e-12)
    np.testing.assert_allclose(C.var(0), P * w * (1 - w), rtol=0.1, atol=1e-3)
    # ...which is larger than systematic's for the same weights (low-variance resampling)
    S = np.stack([np.bincount(systematic_resample(w, rng), minlength=P) for _ in range(2000)])
    assert S.var(0).sum() < 0.5 * C.var(0).sum()


def test_zero_weight_never_drawn():
    rng = np.random.default_rng(3)
    w = np.array([0.0, 0.5, 0.0, 0.5, 0.0])
    for f in (systematic_resample, multinomial_resample):
        for _ in range(200):
            assert set(np.unique(f(w, rng))) <= {1, 3}


def test_same_seed_same_indices():
    w = np.random.default_rng(0).dirichlet(np.ones(50))
    for f in (systematic_resample, multinomial_resample):
        a = f(w, np.random.default_rng(42))
        b = f(w, np.random.default_rng(42))
        np.testing.assert_array_equal(a, b)


def test_effective_sample_size_values():
    assert effective_sample_size(np.full(8, 1 / 8)) == pytest.approx(8.0)
    assert effective_sample_size(np.array([0.0, 1.0, 0.0])) == pytest.approx(1.0)
    # 1 / (0.5² + 0.25² + 0.25²) = 1 / 0.375
    assert effective_sample_size(np.array([0.5, 0.25, 0.25])) == pytest.approx(1 / 0.375)


def test_normalise_log_weights():
    lw = np.array([1000.0, 1000.0 + np.log(3.0), -np.inf])  # huge offsets must not overflow
    np.testing.assert_allclose(normalise_log_weights(lw), [0.25, 0.75, 0.0])
    np.testing.assert_allclose(normalise_log_weights(np.full(4, -np.inf)), np.full(4, 0.25))
