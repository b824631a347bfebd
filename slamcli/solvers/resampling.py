"""Particle-filter weight handling and resampling, as pure functions of a ``numpy.random.Generator``.

All functions take *normalised* weights ``w (P,)`` (``Σ w = 1``) unless stated otherwise and return
ancestor indices ``idx (P,)``: new particle ``j`` is a copy of old particle ``idx[j]``.

References: paper 002 §14.4.1 ("Resample", Algorithm 1 last loop: draw ``k`` with probability ∝ ``w[k]``);
Kitagawa (1996) / Carpenter, Clifford & Fearnhead (1999) for systematic (low-variance) resampling.
"""

from __future__ import annotations

import math

import numpy as np


def normalise_log_weights(log_w: np.ndarray) -> np.ndarray:
    """Normalised weights ``w (P,)`` from log-weights ``(P,)``: ``w_i = exp(l_i − max l) / Σ_j exp(l_j − max l)``.

    A log-weight of ``-inf`` gives weight 0; if every log-weight is ``-inf`` (or NaN) the weights fall back to
    uniform, so a degenerate step never produces NaN particles.
    """
    log_w = np.asarray(log_w, float)
    top = float(np.max(log_w))
    if math.isfinite(top):  # no NaN / +inf (max propagates them): −inf entries get exp(−inf) = 0 as below
        w = np.exp(log_w - top)
        return w / w.sum()
    finite = np.isfinite(log_w)
    if not finite.any():
        return np.full(log_w.shape, 1.0 / log_w.size)
    w = np.where(finite, np.exp(log_w - np.max(log_w[finite])), 0.0)
    return w / w.sum()


def effective_sample_size(w: np.ndarray) -> float:
    """Effective sample size ``ESS = 1 / Σ w_i²`` of normalised weights (``1 ≤ ESS ≤ P``)."""
    w = np.asarray(w, float)
    return float(1.0 / np.dot(w, w))


def _searchsorted_cdf(w: np.ndarray, u: np.ndarray) -> np.ndarray:
    """Indices ``i`` with ``cdf[i-1] ≤ u < cdf[i]`` for points ``u`` in ``[0, 1)``."""
    cdf = np.cumsum(w)
    cdf[-1] = 1.0  # guard against round-off leaving the last bin short of 1
    return np.minimum(np.searchsorted(cdf, u, side="right"), w.size - 1)


def systematic_resample(w: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """Systematic (low-variance) resampling: one uniform ``u₀ ~ U[0, 1/P)``, points ``u_j = u₀ + j/P``.

    Particle ``i`` is copied either ``⌊P w_i⌋`` or ``⌈P w_i⌉`` times (counts within ±1 of ``P w_i``), and the
    expected count is exactly ``P w_i``.

    Returns
    -------
    idx : ndarray (P,) int64, sorted ascending.
    """
    w = np.asarray(w, float)
    P = w.size
    u = (rng.random() + np.arange(P)) / P
    return _searchsorted_cdf(w, u).astype(np.int64)


def multinomial_resample(w: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """Multinomial resampling: ``P`` independent draws ``k ~ Categorical(w)`` (paper 002, Algorithm 1).

    Counts are ``Multinomial(P, w)`` distributed (variance ``P w_i (1 − w_i)``, larger than systematic's).

    Returns
    -------
    idx : ndarray (P,) int64, sorted ascending (sorting keeps copies of one ancestor adjacent; the draw is
        exchangeable so this does not change the distribution).
    """
    w = np.asarray(w, float)
    u = np.sort(rng.random(w.size))
    return _searchsorted_cdf(w, u).astype(np.int64)


RESAMPLERS = {"systematic": systematic_resample, "multinomial": multinomial_resample}
