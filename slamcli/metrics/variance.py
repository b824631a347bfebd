"""Variance-component estimation (VCE): is a least-squares problem's noise model calibrated, group by group?

At the optimum of a weighted least-squares problem with whitened Jacobian ``J (m, n)`` (full column rank) and
whitened residuals ``e (m,)``, the observations split into groups ``g`` (e.g. odometry x / lateral / heading,
range, bearing). With ``H = JᵀJ`` and ``J_g`` the rows of group ``g``, the group's *redundancy* is

    ρ_g = n_g − tr(J_g H⁻¹ J_gᵀ) = n_g − Σ_ij (H⁻¹)_ij (J_gᵀ J_g)_ij          (Σ_g ρ_g = m − n)

and ``E[e_gᵀ e_g] = ρ_g`` when the group's assumed σ is right (Förstner 1979; Koch, *Parameter estimation
and hypothesis testing in linear models*, §3.6, the "simple iterated" estimator). The variance factor
``r_g = e_gᵀ e_g / ρ_g`` then estimates ``(σ_true / σ_assumed)²``: scale the group's σ by ``√r_g``, re-solve,
repeat until every ``r_g ≈ 1``.

``H⁻¹`` is needed only on the pattern of ``J_gᵀ J_g`` (pairs of variables that share a factor), which lies on
the pattern of the Cholesky factor of ``H``: the selected inverse (:mod:`slamcli.solvers.nls.selinv`,
CHOLMOD) gives the exact trace at the cost of one factorisation. Without CHOLMOD, small problems
(``n ≤ DENSE_LIMIT``) use the dense inverse; ``method="approx"`` is the common shortcut
``ρ_g ≈ n_g (1 − n/m)`` (every observation equally redundant).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from slamcli.solvers.nls import selinv

#: largest state dimension for the dense-inverse fallback of the exact redundancy (no CHOLMOD)
DENSE_LIMIT = 4000


@dataclass(frozen=True)
class VarianceComponents:
    """Per group: ``n_obs`` rows, ``ssr`` = Σ whitened residual², ``redundancy`` ρ_g, ``ratio`` = ssr / ρ_g
    (the variance factor: the assumed σ is right at 1; the σ to use is ``σ·√ratio``); ``method`` used."""

    n_obs: np.ndarray
    ssr: np.ndarray
    redundancy: np.ndarray
    ratio: np.ndarray
    method: str


def _inverse_entries(H: sp.csc_matrix, dense: bool):
    """``(rows, cols) -> (H⁻¹)[rows, cols]`` for pairs on the pattern of ``H``: selected inverse (CHOLMOD),
    or the dense inverse when ``dense`` or CHOLMOD is missing (``n ≤ DENSE_LIMIT``)."""
    if not dense and selinv.available():
        return selinv.SelectedInverse.from_matrix(H).entries
    if H.shape[0] > DENSE_LIMIT:
        raise ValueError(f"exact redundancy of a {H.shape[0]}-variable problem needs CHOLMOD (scikit-sparse); "
                         "use method='approx'")
    Z = np.linalg.inv(H.toarray())
    return lambda rows, cols: Z[rows, cols]


def variance_components(jacobian, residual, group, n_groups: int | None = None,
                        method: str = "exact", dense: bool = False) -> VarianceComponents:
    """Variance factors of the observation groups at a least-squares optimum (module docstring).

    Parameters
    ----------
    jacobian : sparse or dense (m, n)  whitened Jacobian at the optimum (full column rank).
    residual : ndarray (m,)            whitened residuals at the optimum.
    group : ndarray (m,) int           group of each row, 0..G−1; −1 = in no group (e.g. a prior).
    n_groups : G (default ``max(group) + 1``).
    method : "exact" (trace through ``H⁻¹``) | "approx" (``ρ_g ≈ n_g (1 − n/m)``).
    dense : exact trace through the dense ``H⁻¹`` even when CHOLMOD is installed (small problems, tests).
    """
    if method not in ("exact", "approx"):
        raise ValueError(f"method must be exact or approx, got {method!r}")
    J = sp.csr_matrix(jacobian)
    e = np.asarray(residual, float).ravel()
    g = np.asarray(group, np.int64).ravel()
    m, n = J.shape
    if e.size != m or g.size != m:
        raise ValueError(f"residual ({e.size}) and group ({g.size}) need one entry per Jacobian row ({m})")
    G = int(g.max()) + 1 if n_groups is None else int(n_groups)
    if m <= n:
        raise ValueError(f"no redundancy: {m} rows for {n} unknowns")
    n_obs = np.bincount(g[g >= 0], minlength=G).astype(float)
    ssr = np.bincount(g[g >= 0], weights=e[g >= 0] ** 2, minlength=G)
    if method == "approx":
        red = n_obs * (1.0 - n / m)
    else:
        inv_at = _inverse_entries(sp.csc_matrix(J.T @ J), dense)
        red = np.empty(G)
        for k in range(G):
            Hg = sp.coo_matrix(J[g == k].T @ J[g == k])
            red[k] = n_obs[k] - float(np.dot(inv_at(Hg.row, Hg.col), Hg.data))
    with np.errstate(divide="ignore", invalid="ignore"):
        ratio = np.where(red > 0, ssr / red, np.nan)
    return VarianceComponents(n_obs=n_obs, ssr=ssr, redundancy=red, ratio=ratio, method=method)
