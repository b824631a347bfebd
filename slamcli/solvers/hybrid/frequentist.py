"""The frequentist part of hybrid SLAM (paper 001 §II.A-B): estimator E2 (eq. 20) on an occupancy grid, and the
Bayesian log-odds baseline of §II.D (eq. 24) fed with the belief mean.

One scan ``z`` (B beams) from a belief ``b(s)`` of weighted pose samples ``s_1..s_S``:

* every (sample, beam) ray is traversed through the grid (:func:`slamcli.models.occupancy.traverse`);
* scan likelihood ``p(z | s, P) = Π_b p(r_b | s, P)``, ``p(r | s, P) = (1−ε) Σ_j π_j f_j(r) + ε/r_max`` (max
  range: ``(1−ε) Π_j(1−P_j) + ε``), eq. (15) with the estimate P and an outlier floor ε (thin walls in the
  solver, :func:`scan_log_likelihood` with ``free_margin``); sample weights ``w_s ∝ p(z | s, P) b(s)`` (eq. 14);
* the reading's cell is observed occupied, the cells crossed before it (≥ ``min_traversal`` m) empty;
* ``c_i = Σ w_s 1(q̂_i = O / s, z) / W_i`` and ``A_i = Σ w_s A_i(s) / W_i`` over the pairs observing cell i;
* E2: ``P_i ← Π_[0,1]{ P_i + γ_i · min(1, W_i) · (c_i − P(q̂=O|O) P_i − P(q̂=O|E)(1 − P_i)) }``,
  ``γ = a·n^(−α)`` (n the cell's own clock, or the global step with ``step_clock = "global"``);
* the set B_i of eq. (51): a cell is updated only from beliefs whose mean lies within ``max_cell_dist``.

Only the cells the scan crosses are touched, so the cost per step does not depend on the map size.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy.special import ndtr

from slamcli.models.angles import wrap_angle
from slamcli.models.occupancy import (
    GridSpec,
    RaySegments,
    band_for,
    observation_probs,
    ray_products,
    reading_density,
    traverse,
)

_P_CLIP = 1e-6  # the forward model uses P clipped into [1e-6, 1 − 1e-6] (no log/ratio of exact 0 or 1)


@dataclass(frozen=True)
class ScanGeometry:
    """What the mapper needs to know about the scanner (from the dataset's noise spec and max range)."""

    alphas: np.ndarray  # (B,) nominal beam bearings, rad (robot frame)
    max_range: float
    range_std: float
    bearing_std: float


def effective_sigma(r: np.ndarray, geo: ScanGeometry, use_bearing: bool) -> np.ndarray:
    """Range σ of the sensor model per reading: ``sqrt(σ_r² + (r σ_θ)²)`` when the bearing error is folded
    into range (a beam off by δθ meets a wall ≈ r·δθ away along it; the paper's eq. 32 is range-only)."""
    if not use_bearing:
        return np.full(np.shape(r), geo.range_std)
    return np.sqrt(geo.range_std**2 + (np.asarray(r) * geo.bearing_std) ** 2)


def sigma_points(mean_xyt: np.ndarray, cov: np.ndarray, kappa: float = 1.0) -> tuple[np.ndarray, np.ndarray]:
    """Julier's 2n+1 sigma points of a pose Gaussian (n = 3): ``μ, μ ± columns of chol((n+κ)Σ)``, weights
    ``κ/(n+κ)`` and ``1/(2(n+κ))``; headings wrapped.

    Returns
    -------
    samples : ndarray (7, 3);  weights : ndarray (7,)
    """
    n = 3
    C = np.asarray(cov, float)
    C = 0.5 * (C + C.T) + 1e-12 * np.eye(3)
    try:
        Lc = np.linalg.cholesky((n + kappa) * C)
    except np.linalg.LinAlgError:
        vals, vecs = np.linalg.eigh((n + kappa) * C)
        Lc = vecs * np.sqrt(np.maximum(vals, 0.0))
    pts = np.vstack([mean_xyt, mean_xyt + Lc.T, mean_xyt - Lc.T])
    pts[:, 2] = wrap_angle(pts[:, 2])
    w = np.full(2 * n + 1, 1.0 / (2 * (n + kappa)))
    w[0] = kappa / (n + kappa)
    return pts, w


@dataclass
class RayBatch:
    """All rays of one scan from all samples, traversed; ``segs`` flat over the R = samples × beams rays."""

    segs: RaySegments
    r: np.ndarray  # (R,) reading per ray
    is_max: np.ndarray  # (R,)
    sigma: np.ndarray  # (R,)

    def per_segment(self, v: np.ndarray) -> np.ndarray:
        return v[self.segs.ray]

    def select_samples(self, keep: np.ndarray, n_beams: int) -> RayBatch:
        """The rays of the samples ``keep`` (sorted indices; sample s owns rays ``s·B … s·B + B − 1``),
        renumbered ``0 … len(keep)·B − 1`` in the same order."""
        rs = self.segs
        ray_ok = np.zeros(rs.n_rays, bool)
        ray_ok[(np.asarray(keep)[:, None] * n_beams + np.arange(n_beams)[None, :]).reshape(-1)] = True
        new_id = np.cumsum(ray_ok) - 1
        m = ray_ok[rs.ray]
        ray = new_id[rs.ray[m]]
        n_new = int(ray_ok.sum())
        counts = np.bincount(ray, minlength=n_new)
        first = np.concatenate([[0], np.cumsum(counts)[:-1]])
        segs = RaySegments(ray, rs.cell[m], rs.a[m], rs.b[m], first[ray].astype(np.int64), n_new)
        return RayBatch(segs, self.r[ray_ok], self.is_max[ray_ok], self.sigma[ray_ok])

    def first_sample(self, n_beams: int) -> RayBatch:
        """The rays of the first sample (rays ``0 … n_beams−1``)."""
        return RayBatch(self.segs.first_rays(n_beams), self.r[:n_beams], self.is_max[:n_beams],
                        self.sigma[:n_beams])


def trace_scan(spec: GridSpec, samples_xyt: np.ndarray, ranges: np.ndarray, geo: ScanGeometry, band: int,
               use_bearing: bool) -> RayBatch:
    """Traverse every (sample, beam) ray up to its reading plus the sensor-model band (or to max range)."""
    S, B = samples_xyt.shape[0], len(geo.alphas)
    r = np.tile(np.asarray(ranges, float), S)
    is_max = r >= geo.max_range - 1e-9
    sig = effective_sigma(r, geo, use_bearing)
    ext = (band + 1) * spec.resolution * math.sqrt(2.0) + 6.0 * sig
    length = np.where(is_max, geo.max_range, r + ext)
    origins = np.repeat(samples_xyt[:, :2], B, axis=0)
    angles = (samples_xyt[:, 2:3] + geo.alphas[None, :]).reshape(-1)
    return RayBatch(traverse_segments(spec, origins, angles, length), r, is_max, sig)


def traverse_segments(spec: GridSpec, origins_xy: np.ndarray, angles: np.ndarray, lengths: np.ndarray,
                      n_groups: int = 4) -> RaySegments:
    """:func:`~slamcli.models.occupancy.traverse` of rays of mixed lengths, flattened to :class:`RaySegments`
    (ray order kept). ``traverse`` works on ``(R, 2K)`` arrays with K set by the longest ray, so the rays are
    traversed in ``n_groups`` groups of similar length (sorted, equal counts) — the work follows Σ lengths
    instead of R·max length — and the valid crossings are scattered back in ray order."""
    R = len(lengths)
    if R == 0 or n_groups <= 1:
        max_len = float(np.max(lengths)) if R else 0.0
        return RaySegments.from_traversal(*traverse(spec, origins_xy, angles, lengths, max_len))
    order = np.argsort(lengths, kind="stable")
    parts = []
    counts = np.zeros(R, np.int64)
    for idx in np.array_split(order, min(n_groups, R)):
        if len(idx) == 0:
            continue
        cell, t_in, t_out = traverse(spec, origins_xy[idx], angles[idx], lengths[idx], float(lengths[idx].max()))
        valid = cell >= 0
        counts[idx] = valid.sum(axis=1)
        parts.append((idx, valid, cell, t_in, t_out))
    first = np.concatenate([[0], np.cumsum(counts)[:-1]])
    M = int(counts.sum())
    ray = np.empty(M, np.int64)
    cells = np.empty(M, np.int64)
    a = np.empty(M)
    b = np.empty(M)
    for idx, valid, cell, t_in, t_out in parts:
        rows, _ = np.nonzero(valid)
        rank = (np.cumsum(valid, axis=1) - 1)[valid]  # position within the ray
        pos = first[idx[rows]] + rank
        ray[pos] = idx[rows]
        cells[pos] = cell[valid]
        a[pos] = t_in[valid]
        b[pos] = t_out[valid]
    return RaySegments(ray, cells, a, b, first[ray], R)


def scan_log_likelihood(rb: RayBatch, P_seg: np.ndarray, max_range: float, eps: float,
                        free_margin: float = 0.0, resolution: float = 1.0) -> np.ndarray:
    """``log p(r | s, P)`` per ray ``(R,)``.

    With ``free_margin = 0`` the forward model of the module docstring. With a margin m > 0 the cells the beam
    crosses within m before its reading do not block it (the thin-wall reading of :func:`indicators`: a beam
    meeting a wall at a shallow angle runs through the wall's row of cells before it reaches the wall line)::

        p(r | s, P) = (1−ε) Π_{i: b_i ≤ r−m} (1 − P_i) · Σ_{j: b_j > r−m} P_j f_j(r) + ε/r_max

    Without it a pose from which the beams clip fewer wall cells before their readings is preferred
    (benchmarks/results/design_notes.md)."""
    rs = rb.segs
    if free_margin <= 0:
        _, pi, miss = ray_products(P_seg, rs)
        f = reading_density(rb.per_segment(rb.r), rs.a, rs.b, rb.per_segment(rb.sigma))
        p_hit = np.bincount(rs.ray, pi * f, minlength=rs.n_rays)
    else:
        r = rb.per_segment(rb.r)
        before = rs.b <= r - free_margin
        lg = np.log1p(-np.minimum(P_seg, 1.0 - 1e-12))
        u_pre = np.exp(np.bincount(rs.ray, np.where(before, lg, 0.0), minlength=rs.n_rays))
        near = ~before & (rs.a <= r + 6.0 * rb.per_segment(rb.sigma))
        # a thin wall in cell j stops the beam with probability ∝ its crossing length L_j (≤ 1 for L_j ≤ res),
        # then the reading is uniform over the crossing: P_j (L_j/res)·(1/L_j) = P_j/res — not P_j/L_j, which
        # would favour poses whose readings fall in short corner clips of wall cells
        sg = rb.per_segment(rb.sigma)[near]
        f = (ndtr((r[near] - rs.a[near]) / sg) - ndtr((r[near] - rs.b[near]) / sg)) / resolution
        p_hit = u_pre * np.bincount(rs.ray[near], P_seg[near] * f, minlength=rs.n_rays)
        miss = np.exp(np.bincount(rs.ray, lg, minlength=rs.n_rays))
    lik = np.where(rb.is_max, (1 - eps) * miss + eps, (1 - eps) * p_hit + eps / max_range)
    return np.log(lik)


def indicators(rb: RayBatch, min_traversal: float, free_margin: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
    """``(observed, occupied)`` masks ``(M,)``: 1(q̂ = O / s, z) on ``occupied``, defined where ``observed``.

    A crossed cell counts as observed empty when the beam runs ≥ ``min_traversal`` in it and leaves it at
    least ``free_margin`` before the reading (a beam grazing a wall crosses the wall's cells just before it
    hits the wall line)."""
    rs = rb.segs
    r = rb.per_segment(rb.r)
    mx = rb.per_segment(rb.is_max)
    inside = (rs.a <= r) & (r < rs.b) & ~mx
    before = ((rs.b <= r - free_margin) | mx) & ((rs.b - rs.a) >= min_traversal)
    return inside | before, inside


def _aggregate(cells: np.ndarray, weights: np.ndarray, *values: np.ndarray):
    """Per distinct cell: ``(cells_u, W, Σ w·v / W for each v)``."""
    cu, inv = np.unique(cells, return_inverse=True)
    W = np.bincount(inv, weights, minlength=len(cu))
    outs = [np.bincount(inv, weights * v, minlength=len(cu)) / np.maximum(W, 1e-300) for v in values]
    return cu, W, outs


def _near(spec: GridSpec, cu: np.ndarray, mean_xy: np.ndarray, max_cell_dist: float) -> np.ndarray:
    Wd = spec.shape[1]
    cx = spec.origin_xy[0] + (cu % Wd + 0.5) * spec.resolution
    cy = spec.origin_xy[1] + (cu // Wd + 0.5) * spec.resolution
    return np.hypot(cx - mean_xy[0], cy - mean_xy[1]) <= max_cell_dist


def segment_probs(P: np.ndarray, rb: RayBatch) -> np.ndarray:
    """The current estimate of each segment's cell, clipped into [1e-6, 1 − 1e-6]."""
    return np.clip(P[rb.segs.cell], _P_CLIP, 1 - _P_CLIP)


def e2_update(P: np.ndarray, count: np.ndarray, spec: GridSpec, rb: RayBatch, w_ray: np.ndarray,
              mean_xy: np.ndarray, t: int, *, a: float, alpha: float, step_clock: str, band: int,
              min_traversal: float, max_cell_dist: float, conditional: bool = True,
              free_margin: float = 0.0, clock: np.ndarray | None = None) -> int:
    """One E2 step (eq. 20) in place on the flat grid ``P (H·W,)`` and the update counter ``count``.

    ``clock (H·W,)`` float, optional: the per-cell clock n of γ = a·n^(−α) advances by the weight
    ``min(1, W_i)`` of the samples that observe the cell (a cell seen only from negligible-weight samples
    keeps its step size); without it n = ``count`` (+1 per update).

    Returns the number of cells updated.
    """
    P_seg = segment_probs(P, rb)
    observed, occupied = indicators(rb, min_traversal, free_margin)
    if not observed.any():
        return 0
    a_oo, a_oe = observation_probs(P_seg, rb.segs, rb.per_segment(rb.sigma), band, conditional)
    ww = rb.per_segment(w_ray)[observed]
    cu, W, (c, aoo, aoe) = _aggregate(rb.segs.cell[observed], ww, occupied[observed].astype(float),
                                      a_oo[observed], a_oe[observed])
    near = _near(spec, cu, mean_xy, max_cell_dist)  # B_i (eq. 51)
    cu, W, c, aoo, aoe = cu[near], W[near], c[near], aoo[near], aoe[near]
    count[cu] += 1
    wq = np.minimum(W, 1.0)
    if step_clock != "cell":
        n = np.full(len(cu), float(max(t, 1)))
    elif clock is not None:
        clock[cu] += wq
        n = np.maximum(clock[cu], 1.0)
    else:
        n = count[cu].astype(float)
    gam = a * np.power(n, -alpha) * wq
    p = P[cu]
    P[cu] = np.clip(p + gam * (c - aoo * p - aoe * (1.0 - p)), 0.0, 1.0)
    return int(len(cu))


def logodds_update(L: np.ndarray, count: np.ndarray, spec: GridSpec, rb: RayBatch, mean_xy: np.ndarray, *,
                   eps: float, max_range: float, min_traversal: float, max_cell_dist: float,
                   l_max: float, free_margin: float = 0.0) -> None:
    """Eq. (24), independent cells, from a single pose (the belief mean): in place on log-odds ``L (H·W,)``.

    For an observed cell k of a beam with reading r (first-occupied decomposition along the beam, the other
    cells at their current estimates)::

        p(r | q_k = O) = Σ_{j<k} π_j f_j(r) + U_k f_k(r)
        p(r | q_k = E) = Σ_{j<k} π_j f_j(r) + Σ_{j>k} π_j f_j(r) / (1 − P_k)       (max range: miss/(1 − P_k))
        L_k ← L_k + log p(r | q_k = O) − log p(r | q_k = E)

    each with the outlier floor ε of the frequentist likelihood.
    """
    rs = rb.segs
    P_seg = np.clip(1.0 / (1.0 + np.exp(-L[rs.cell])), _P_CLIP, 1 - _P_CLIP)
    observed, _ = indicators(rb, min_traversal, free_margin)
    if not observed.any():
        return
    U, pi, miss = ray_products(P_seg, rs)
    f = reading_density(rb.per_segment(rb.r), rs.a, rs.b, rb.per_segment(rb.sigma))
    pf = pi * f
    cum = np.cumsum(pf)
    start_base = (cum - pf)[rs.start]  # cumulative sum before the ray's first segment
    pre = cum - pf - start_base
    ray_tot = np.bincount(rs.ray, pf, minlength=rs.n_rays)
    suf = ray_tot[rs.ray] - (cum - start_base)
    one_minus = 1.0 - P_seg
    mx = rb.per_segment(rb.is_max)
    p_o = np.where(mx, eps, (1 - eps) * (pre + U * f) + eps / max_range)
    p_e = np.where(mx, (1 - eps) * miss[rs.ray] / one_minus + eps,
                   (1 - eps) * (pre + np.maximum(suf, 0.0) / one_minus) + eps / max_range)
    dl = np.log(p_o) - np.log(p_e)
    cu, inv = np.unique(rs.cell[observed], return_inverse=True)
    dsum = np.bincount(inv, dl[observed], minlength=len(cu))
    near = _near(spec, cu, mean_xy, max_cell_dist)
    cu, dsum = cu[near], dsum[near]
    count[cu] += 1
    L[cu] = np.clip(L[cu] + dsum, -l_max, l_max)


__all__ = [
    "RayBatch",
    "ScanGeometry",
    "band_for",
    "e2_update",
    "indicators",
    "logodds_update",
    "scan_log_likelihood",
    "segment_probs",
    "sigma_points",
    "trace_scan",
    "traverse_segments",
]
