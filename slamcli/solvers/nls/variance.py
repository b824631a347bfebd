"""Variance-component estimation (VCE): is a least-squares problem's noise model calibrated, group by group?

At the optimum of a weighted least-squares problem with whitened Jacobian ``J (m, n)`` (full column rank) and
whitened residuals ``e (m,)``, the observations split into groups ``g`` (e.g. odometry x / lateral / heading,
range, bearing). With ``H = JᵀJ`` and ``J_g`` the rows of group ``g``, the group's *redundancy* is

    ρ_g = n_g − tr(J_g H⁻¹ J_gᵀ) = n_g − Σ_ij (H⁻¹)_ij (J_gᵀ J_g)_ij          (Σ_g ρ_g = m − n)

and ``E[e_gᵀ e_g] = ρ_g`` when the group's assumed σ is right (Förstner 1979; Koch, *Parameter estimation
and hypothesis testing in linear models*, §3.6, the "simple iterated" estimator). The variance factor
``r_g = e_gᵀ e_g / ρ_g`` then estimates ``(σ_true / σ_assumed)²``: scale the group's σ by ``√r_g``, re-solve,
repeat until every ``r_g ≈ 1`` (:func:`iterate_variance_components`; the caller solves the re-weighted
problem, this module only estimates).

``H⁻¹`` is needed only on the pattern of ``J_gᵀ J_g`` (pairs of variables that share a factor), which lies on
the pattern of the Cholesky factor of ``H``: the selected inverse (:mod:`slamcli.solvers.nls.selinv`,
CHOLMOD) gives the exact trace at the cost of one factorisation. Without CHOLMOD, small problems
(``n ≤ DENSE_LIMIT``) use the dense inverse; ``method="approx"`` is the common shortcut
``ρ_g ≈ n_g (1 − n/m)`` (every observation equally redundant).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from slamcli.solvers.nls import selinv
from slamcli.solvers.nls.linear import cholmod_available

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
    if not dense and cholmod_available():
        return selinv.SelectedInverse.from_matrix(H).entries
    if H.shape[0] > DENSE_LIMIT:
        raise ValueError(f"exact redundancy of a {H.shape[0]}-variable problem needs CHOLMOD (CVXOPT); "
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
        # H = Σ_g J_gᵀJ_g summed in COO form, so that an entry the groups cancel exactly (odometry x and
        # lateral rows of equal σ do) stays on the pattern as an explicit zero
        rows_of = [J[g == k] for k in [*range(G), -1]]  # each group's rows sliced once
        parts = [sp.coo_matrix(Jk.T @ Jk) for Jk in rows_of]
        H = sp.csc_matrix((np.concatenate([P.data for P in parts]),
                           (np.concatenate([P.row for P in parts]), np.concatenate([P.col for P in parts]))),
                          shape=(n, n))
        inv_at = _inverse_entries(H, dense)
        red = np.array([n_obs[k] - float(np.dot(inv_at(P.row, P.col), P.data)) for k, P in enumerate(parts[:G])])
    with np.errstate(divide="ignore", invalid="ignore"):
        ratio = np.where(red > 0, ssr / red, np.nan)
    return VarianceComponents(n_obs=n_obs, ssr=ssr, redundancy=red, ratio=ratio, method=method)


@dataclass(frozen=True)
class VceRound:
    """One round of the iterated estimator: ``scale (G,)`` = the σ multipliers the round's solve assumed
    (against the σ it started from), ``components`` = what VCE measured at that solve's optimum."""

    scale: np.ndarray
    components: VarianceComponents


@dataclass(frozen=True)
class IteratedVce:
    """The rounds of :func:`iterate_variance_components`; ``converged`` = the last round's variance factors
    are all within the tolerance of 1 (``False``: the round budget ended first)."""

    rounds: tuple[VceRound, ...]
    converged: bool

    @property
    def scale(self) -> np.ndarray:
        """σ multipliers of the last solve (the weights of the optimum the caller ends with)."""
        return self.rounds[-1].scale

    @property
    def ratio(self) -> np.ndarray:
        """Variance factors measured at the last solve (1 = calibrated)."""
        return self.rounds[-1].components.ratio


def iterate_variance_components(
    solve_at: Callable[[np.ndarray], tuple],
    n_groups: int,
    tol: float,
    max_reweights: int,
    on_round: Callable[[VceRound], None] | None = None,
) -> IteratedVce:
    """The simple iterated VCE (module docstring): solve, estimate, scale every group's σ by ``√r_g``, re-solve.

    Parameters
    ----------
    solve_at : ``scale (G,) -> (jacobian, residual, group)``: the caller solves its problem with every group's
        σ multiplied by ``scale`` and returns the whitened Jacobian, whitened residuals and row groups at that
        optimum (as :func:`variance_components` takes them).
    n_groups : G.
    tol : stop when every ``|r_g − 1| ≤ tol`` (groups without observations or redundancy, ``r_g`` NaN, and
        groups fitted exactly, ``r_g = 0``, count as calibrated and keep their σ).
    max_reweights : at most this many re-weighted solves after the first (``1`` = one round: estimate at the
        given σ, re-solve once with ``σ·√r``; the factors at that re-solve are measured and reported).
    on_round : called with every round as it is measured.
    """
    if max_reweights < 0:
        raise ValueError(f"max_reweights must be ≥ 0, got {max_reweights}")
    if not tol > 0:
        raise ValueError(f"tol must be > 0, got {tol}")
    scale = np.ones(int(n_groups))
    rounds: list[VceRound] = []
    while True:
        jacobian, residual, group = solve_at(scale.copy())
        vc = variance_components(jacobian, residual, group, n_groups)
        rounds.append(VceRound(scale=scale.copy(), components=vc))
        if on_round is not None:
            on_round(rounds[-1])
        ratio = np.where(np.isfinite(vc.ratio) & (vc.ratio > 0), vc.ratio, 1.0)
        converged = bool(np.all(np.abs(ratio - 1.0) <= tol))
        if converged or len(rounds) > max_reweights:
            return IteratedVce(rounds=tuple(rounds), converged=converged)
        scale = scale * np.sqrt(ratio)
