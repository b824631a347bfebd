"""Estimator consistency: NEES per pose / landmark and the Monte-Carlo average NEES with its χ² band.

Conventions (EVALUATION-METHOD.md §A1): the NEES is stored **un-normalised**, so its expected value is the
dimension d (3 for a planar pose, 2 for a landmark). For N independent runs

    ε̄_k = (1/N) Σ_i ε_k^(i),   N·ε̄_k ~ χ²(N·d)   ⇒   95 % band  [χ²⁻¹(0.025, N d)/N, χ²⁻¹(0.975, N d)/N]

(Bar-Shalom et al. pp. 234-235; Forster et al. TRO 2017 eq. 58). The band is applied per step across runs,
never as a time average within one run. A result without covariances has no NEES: the functions here return
``None`` together with a reason rather than a number.

Covariances are world-frame ``[x, y, θ]`` marginals (the ``SolverResult`` contract); the error is
``e = x_true − x̂`` with the heading wrapped.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.special import gammaincinv

from slamcli.models.angles import wrap_pose_error


def chi2_ppf(q, dof):
    """Quantile of the χ²(dof) distribution, ``F⁻¹(q) = 2 P⁻¹(dof/2, q)`` with ``P`` the regularised lower
    incomplete gamma function (``F(x) = P(dof/2, x/2)``), by ``scipy.special.gammaincinv``.

    Equal to ``scipy.stats.chi2.ppf(q, dof)`` (``tests/metrics/test_metrics_lazy_imports.py``) without importing
    ``scipy.stats``, which costs ≈ 0.4-1 s and most of ``slamcli.metrics``' import in every sweep worker and
    ``evaluate``.
    """
    return 2.0 * gammaincinv(0.5 * np.asarray(dof, float), np.asarray(q, float))


def nees(err, cov) -> np.ndarray:
    """``ε = eᵀ P⁻¹ e`` for a batch, solving ``P x = e`` (no explicit inverse).

    Entries whose covariance is not positive definite (e.g. the exactly known start pose with P = 0, or a
    non-finite block) get NaN: the NEES is undefined there, not zero.

    Parameters
    ----------
    err : ndarray (..., d)
    cov : ndarray (..., d, d)

    Returns
    -------
    ndarray (...)
    """
    e = np.asarray(err, float)
    P = np.asarray(cov, float)
    if P.shape != e.shape + e.shape[-1:]:
        raise ValueError(f"covariance shape {P.shape} does not match error shape {e.shape}")
    lead = e.shape[:-1]
    d = e.shape[-1]
    e2 = e.reshape(-1, d)
    P2 = P.reshape(-1, d, d)
    out = np.full(e2.shape[0], np.nan)
    finite = np.all(np.isfinite(P2), axis=(1, 2)) & np.all(np.isfinite(e2), axis=1)
    if finite.any():
        Ps = 0.5 * (P2[finite] + np.swapaxes(P2[finite], 1, 2))
        w = np.linalg.eigvalsh(Ps)
        pd_ok = w[:, 0] > 1e-12 * np.maximum(w[:, -1], 1e-300)
        idx = np.flatnonzero(finite)[pd_ok]
        if idx.size:
            x = np.linalg.solve(Ps[pd_ok], e2[idx][..., None])[..., 0]
            out[idx] = np.einsum("ni,ni->n", e2[idx], x)
    return out.reshape(lead)


def pose_nees(est_xyt, true_xyt, pose_cov) -> np.ndarray:
    """Pose NEES per step, d = 3, ``e = wrap([x, y, θ]_true − [x, y, θ]_est)``.

    Parameters
    ----------
    est_xyt, true_xyt : ndarray (T+1, 3)
    pose_cov : ndarray (T+1, 3, 3)

    Returns
    -------
    ndarray (T+1,)  NaN where the covariance is singular (typically step 0).
    """
    est = np.asarray(est_xyt, float)
    true = np.asarray(true_xyt, float)
    if est.shape != true.shape:
        raise ValueError(f"estimated poses {est.shape} and true poses {true.shape} differ in length")
    return nees(wrap_pose_error(true - est), pose_cov)


def landmark_nees(est_xy, true_xy, landmark_cov, true_of_est) -> np.ndarray:
    """Landmark NEES per *estimated* landmark, d = 2, against the true landmark it was assigned to.

    Parameters
    ----------
    est_xy : ndarray (L', 2), true_xy : ndarray (L, 2), landmark_cov : ndarray (L', 2, 2)
    true_of_est : ndarray (L',) int   assigned true landmark per estimate (−1 = unmatched → NaN),
                                       e.g. :meth:`slamcli.metrics.landmarks.Assignment.true_of_est`.

    Returns
    -------
    ndarray (L',)
    """
    est = np.asarray(est_xy, float).reshape(-1, 2)
    true = np.asarray(true_xy, float).reshape(-1, 2)
    t = np.asarray(true_of_est, np.int64)
    out = np.full(len(est), np.nan)
    m = t >= 0
    if m.any():
        out[m] = nees(true[t[m]] - est[m], np.asarray(landmark_cov, float)[m])
    return out


def chi2_band(n_runs: int, dof: int, confidence: float = 0.95) -> tuple[float, float]:
    """Two-sided band for the average NEES of ``n_runs`` runs of a ``dof``-dimensional error:
    ``chi2.ppf([α/2, 1 − α/2], N d) / N`` (N = 50, d = 3 gives [2.36, 3.72])."""
    if n_runs < 1 or dof < 1:
        raise ValueError(f"need n_runs ≥ 1 and dof ≥ 1, got {n_runs}, {dof}")
    a = (1.0 - confidence) / 2.0
    lo, hi = chi2_ppf(np.array([a, 1.0 - a]), n_runs * dof) / n_runs
    return float(lo), float(hi)


@dataclass(frozen=True)
class AverageNees:
    """Monte-Carlo average NEES curve with its χ² band.

    Attributes
    ----------
    anees : ndarray (K,)     ε̄_k; NaN at steps where any run has no NEES (the band assumes all N runs).
    lower, upper : float     band for N runs of dimension d.
    fraction_inside : float  fraction of the finite steps with lower ≤ ε̄_k ≤ upper (NaN if none finite).
    n_runs : int ; dof : int ; confidence : float
    """

    anees: np.ndarray
    lower: float
    upper: float
    fraction_inside: float
    n_runs: int
    dof: int
    confidence: float

    @property
    def mean(self) -> float:
        """Time average of ε̄_k over finite steps (a summary only; not a χ² statistic)."""
        f = np.isfinite(self.anees)
        return float(np.mean(self.anees[f])) if f.any() else float("nan")


def average_nees(nees_runs, dof: int, confidence: float = 0.95) -> AverageNees:
    """Average NEES over runs, per step, and the fraction of steps inside the χ² band.

    Parameters
    ----------
    nees_runs : ndarray (N, K)   NEES of run i at step k (un-normalised, E = dof).
    dof : int                    dimension d of the error (3 pose, 2 landmark).
    """
    E = np.atleast_2d(np.asarray(nees_runs, float))
    n = E.shape[0]
    lo, hi = chi2_band(n, dof, confidence)
    ok = np.all(np.isfinite(E), axis=0)
    anees = np.full(E.shape[1], np.nan)
    anees[ok] = E[:, ok].mean(axis=0)
    frac = float(np.mean((anees[ok] >= lo) & (anees[ok] <= hi))) if ok.any() else float("nan")
    return AverageNees(anees, lo, hi, frac, n, dof, confidence)


def covariance_unavailable_reason(cov, what: str, solver: str = "") -> str | None:
    """``None`` when ``cov`` can be used for NEES, else a one-line reason ("not available: ...")."""
    who = f"solver {solver!r}" if solver else "the result"
    if cov is None:
        return f"not available: {who} stores no {what} covariances"
    c = np.asarray(cov, float)
    if c.size == 0:
        return f"not available: {who} stores an empty {what} covariance array"
    if not np.isfinite(c).any():
        return f"not available: {who} {what} covariances are all non-finite"
    return None
