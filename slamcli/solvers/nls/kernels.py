"""Whitening and M-estimator kernels of the least-squares engine (:func:`robust_kernel`, GTSAM's
``noiseModel.mEstimator`` definitions).
"""

from __future__ import annotations

import numpy as np

from slamcli.solvers.nls.problem import NlsParams


def whiten(L: np.ndarray, r: np.ndarray) -> np.ndarray:
    if L.ndim == 2:
        return r @ L.T
    return np.einsum("fij,fj->fi", L, r)


def kernel_cost(rw: np.ndarray, robust: bool, params: NlsParams):
    """Per-factor cost ``ρ (F,)`` and IRLS weight ``w (F,)`` (None = all ones)."""
    s2 = np.einsum("fk,fk->f", rw, rw)
    if not robust or params.robust == "none":
        return 0.5 * s2, None
    return robust_kernel(s2, params.robust, params.huber_k)


def robust_kernel(s2: np.ndarray, kind: str, k: float) -> tuple[np.ndarray, np.ndarray]:
    """M-estimator cost ``ρ(s)`` and IRLS weight ``w(s) = ρ'(s)/s`` of whitened norms ``s = √s2`` (F,).

    The definitions of GTSAM's ``noiseModel.mEstimator`` (all equal ``½ s²`` to second order at 0)::

        huber           ρ = ½ s²  (s ≤ k),  k s − ½ k²  (s > k)        w = 1,  k / s
        cauchy          ρ = ½ k² log(1 + s²/k²)                         w = k² / (k² + s²)
        geman_mcclure   ρ = ½ k² s² / (k² + s²)                         w = k⁴ / (k² + s²)²
    """
    if kind == "huber":
        s = np.sqrt(s2)
        big = s > k
        rho = np.where(big, k * s - 0.5 * k * k, 0.5 * s2)
        return rho, np.where(big, k / np.where(big, s, 1.0), 1.0)
    k2 = k * k
    if kind == "cauchy":
        return 0.5 * k2 * np.log1p(s2 / k2), k2 / (k2 + s2)
    if kind == "geman_mcclure":
        return 0.5 * k2 * s2 / (k2 + s2), k2 * k2 / (k2 + s2) ** 2
    raise ValueError(f"unknown robust kernel {kind!r}")
