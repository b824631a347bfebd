"""Occupancy-grid geometry and the discretised range-sensor model of paper 001 (§III, eqs. 32-34), shared by
the simulator (true grid) and the ``hybrid`` solver (cells a beam crosses, what it would read).

Grid: cell ``(row, col)`` covers ``[x0 + col·res, x0 + (col+1)·res) × [y0 + row·res, …)``; flat index
``row·W + col``; arrays ``(H, W)`` (row = y).

Ray model: a beam crosses cells ``j = 0, 1, …`` over range intervals ``[a_j, b_j)``; if cell ``j`` is the
*first occupied* one, the reading is a wall uniform in that interval plus Gaussian noise σ (eq. 32)::

    f_j(r)  = [Φ((r − a_j)/σ) − Φ((r − b_j)/σ)] / (b_j − a_j)
    Γ_kj    = P(q̂_k = O | first occupied = j) = ∫_{a_k}^{b_k} f_j(r) dr
            = σ/L_j · [G((b_k−a_j)/σ) − G((b_k−b_j)/σ) − G((a_k−a_j)/σ) + G((a_k−b_j)/σ)],
              G(u) = u Φ(u) + φ(u),  L_j = b_j − a_j
    π_j     = P_j Π_{i<j} (1 − P_i)          (independent cells, eq. 1)

and eqs. (33)-(34) become, for an observed cell k (``U_k = Π_{i<k}(1 − P_i)``)::

    P(q̂_k=O | q_k=O) = Σ_{j<k} Γ_kj π_j + Γ_kk U_k
    P(q̂_k=O | q_k=E) = Σ_{j<k} Γ_kj π_j + Σ_{j>k} Γ_kj P_j U_k Π_{k<i<j}(1 − P_i)

The sums run over the band ``|k − j| ≤ band`` of :func:`band_for` (the cells beyond span ≥ 6σ, where Γ_kj is
negligible).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy.special import ndtr

_SQRT_2PI = math.sqrt(2.0 * math.pi)
MIN_SEGMENT = 1e-6  # m: shorter cell crossings (exact corner hits) are dropped


@dataclass(frozen=True)
class GridSpec:
    """Geometry of a grid.

    Attributes
    ----------
    origin_xy : (x0, y0)   lower-left corner of cell (0, 0), m.
    resolution : float     cell side, m.
    shape : (H, W)         rows (y) and columns (x).
    """

    origin_xy: tuple[float, float]
    resolution: float
    shape: tuple[int, int]

    @property
    def n_cells(self) -> int:
        return int(self.shape[0]) * int(self.shape[1])

    def centres_xy(self) -> np.ndarray:
        """Cell centres ``(H, W, 2)``, m."""
        H, W = self.shape
        xs = self.origin_xy[0] + (np.arange(W) + 0.5) * self.resolution
        ys = self.origin_xy[1] + (np.arange(H) + 0.5) * self.resolution
        gx, gy = np.meshgrid(xs, ys)
        return np.stack([gx, gy], -1)

    def extent(self) -> tuple[float, float, float, float]:
        """``(x_min, x_max, y_min, y_max)`` for ``imshow(origin="lower")``."""
        x0, y0 = self.origin_xy
        H, W = self.shape
        return (x0, x0 + W * self.resolution, y0, y0 + H * self.resolution)


def band_for(sigma_max: float, resolution: float) -> int:
    """Smallest even band (segments) spanning ≥ 6·σ_max: ``(⌈(band+1)/2⌉ − 1)·res ≥ 6σ``, at least 2."""
    need = math.ceil(6.0 * sigma_max / resolution)  # grid-line pairs of one family
    return max(2, 2 * need)


def traverse(spec: GridSpec, origins_xy: np.ndarray, angles: np.ndarray, lengths: np.ndarray,
             max_length: float):
    """Cells crossed by rays, in order (exact grid traversal, vectorised over rays).

    All crossings of the x and y grid lines within ``max_length`` are computed in closed form (two arithmetic
    progressions per ray), merged by rank and clipped to the ray's own length; each interval between
    consecutive crossings is one cell.

    Parameters
    ----------
    origins_xy : ndarray (R, 2)   ray starts, m.
    angles : ndarray (R,)         world-frame directions, rad.
    lengths : ndarray (R,)        ray lengths, m (≤ ``max_length``).
    max_length : float            bound on every length (fixes the output width S).

    Returns
    -------
    cell : ndarray (R, S) int64   flat cell index per segment, −1 = no cell (outside the grid / padding /
                                  shorter than ``MIN_SEGMENT``).
    t_in, t_out : ndarray (R, S)  range interval of each segment along its ray, m (valid segments are in
                                  increasing order along a row).
    """
    o = np.asarray(origins_xy, float).reshape(-1, 2)
    ang = np.asarray(angles, float).reshape(-1)
    L = np.minimum(np.asarray(lengths, float).reshape(-1), max_length)
    R = o.shape[0]
    res = float(spec.resolution)
    x0, y0 = spec.origin_xy
    K = int(math.ceil(max_length / res)) + 2
    k = np.arange(K, dtype=float)
    t0s, dts = [], []
    for axis, base in ((0, x0), (1, y0)):
        d = np.cos(ang) if axis == 0 else np.sin(ang)
        u = (o[:, axis] - base) / res  # position in cell units
        pos = d > 0
        first = np.where(pos, np.floor(u) + 1.0, np.ceil(u) - 1.0)  # first grid line strictly ahead
        ok = np.abs(d) > 1e-15
        with np.errstate(divide="ignore", invalid="ignore"):
            t0s.append(np.where(ok, (first - u) * res / d, np.inf))
            dts.append(np.where(ok, res / np.abs(d), np.inf))
    # the crossings of each family are arithmetic progressions t0 + k·Δ; merge them without a sort: the rank
    # of an x crossing is k + #(y crossings before it), of a y crossing k + #(x crossings not after it)
    fin_x, fin_y = np.isfinite(dts[0])[:, None], np.isfinite(dts[1])[:, None]
    tx = np.where(fin_x, t0s[0][:, None] + np.where(fin_x, dts[0][:, None], 0.0) * k[None, :], np.inf)
    ty = np.where(fin_y, t0s[1][:, None] + np.where(fin_y, dts[1][:, None], 0.0) * k[None, :], np.inf)
    with np.errstate(invalid="ignore"):
        ny = np.where(fin_y, np.clip(np.ceil((tx - t0s[1][:, None]) / dts[1][:, None]), 0, K), 0)
        nx = np.where(fin_x, np.clip(np.floor((ty - t0s[0][:, None]) / dts[0][:, None]) + 1, 0, K), 0)
    ny = np.where(np.isnan(ny), K, ny).astype(np.int64)
    nx = np.where(np.isnan(nx), 0, nx).astype(np.int64)
    merged = np.full((R, 2 * K), np.inf)
    np.put_along_axis(merged, k.astype(np.int64)[None, :] + ny, tx, axis=1)
    np.put_along_axis(merged, k.astype(np.int64)[None, :] + nx, ty, axis=1)
    if R and not np.all(merged[:, 1:] >= merged[:, :-1]):  # a tie (exact grid-corner crossing) collided: sort
        merged = np.sort(np.concatenate([tx, ty], axis=1), axis=1)
    t_all = np.concatenate([np.zeros((R, 1)), merged], axis=1)
    t_all = np.minimum(t_all, L[:, None])
    t_in, t_out = t_all[:, :-1], t_all[:, 1:]
    mid = 0.5 * (t_in + t_out)
    px = o[:, 0:1] + mid * np.cos(ang)[:, None]
    py = o[:, 1:2] + mid * np.sin(ang)[:, None]
    H, W = spec.shape
    col = np.floor((px - x0) / res).astype(np.int64)
    row = np.floor((py - y0) / res).astype(np.int64)
    ok = (t_out - t_in > MIN_SEGMENT) & (col >= 0) & (col < W) & (row >= 0) & (row < H)
    cell = np.where(ok, row * W + col, -1)
    return cell, t_in, t_out


def _G(u):
    """``G(u) = u Φ(u) + φ(u)``, the antiderivative of Φ; for |u| > 9 it equals max(u, 0) to double precision
    (φ(9) ≈ 1e-18), so only the arguments near 0 pay for ndtr/exp."""
    u = np.asarray(u, float)
    shape = u.shape
    u = u.reshape(-1)
    out = np.maximum(u, 0.0)
    zero = u == 0.0  # G(0) = φ(0): exact zeros are common (a segment's own ends, shared ends of neighbours)
    idx = np.flatnonzero((np.abs(u) < 9.0) & ~zero)
    um = u[idx]
    out[idx] = um * ndtr(um) + np.exp(-0.5 * um * um) / _SQRT_2PI
    out[zero] = 1.0 / _SQRT_2PI
    return out.reshape(shape)


def reading_density(r, a, b, sigma):
    """``f_j(r)`` (see module docstring): density of a reading ``r`` when the first occupied cell spans
    ``[a, b)``; broadcasts."""
    L = np.maximum(b - a, MIN_SEGMENT)
    return (ndtr((r - a) / sigma) - ndtr((r - b) / sigma)) / L


def gamma(a_k, b_k, a_j, b_j, sigma):
    """``Γ_kj = P(reading in [a_k, b_k) | first occupied cell spans [a_j, b_j))`` (closed form, broadcasts)."""
    L = np.maximum(b_j - a_j, MIN_SEGMENT)
    s = sigma
    g = _G((b_k - a_j) / s) - _G((b_k - b_j) / s) - _G((a_k - a_j) / s) + _G((a_k - b_j) / s)
    return np.clip(s * g / L, 0.0, 1.0)


def tail_prob(a_k, a_j, b_j, sigma):
    """``Q_kj = P(reading ≥ a_k | first occupied cell spans [a_j, b_j))`` — the beam "reaches" cell k
    (closed form ``σ/L_j [G((b_j − a_k)/σ) − G((a_j − a_k)/σ)]``, broadcasts)."""
    L = np.maximum(b_j - a_j, MIN_SEGMENT)
    return np.clip(sigma * (_G((b_j - a_k) / sigma) - _G((a_j - a_k) / sigma)) / L, 0.0, 1.0)


def gamma_tail(a_k, b_k, a_j, b_j, sigma):
    """``(Γ_kj, Q_kj)`` of :func:`gamma` and :func:`tail_prob` together: Q's two G values follow from two of
    Γ's four through ``G(−u) = G(u) − u`` (four G evaluations instead of six)."""
    L = np.maximum(b_j - a_j, MIN_SEGMENT)
    s = sigma
    u3 = (a_k - a_j) / s
    u4 = (a_k - b_j) / s
    g3, g4 = _G(u3), _G(u4)
    g = _G((b_k - a_j) / s) - _G((b_k - b_j) / s) - g3 + g4
    q = (g4 - u4) - (g3 - u3)
    return np.clip(s * g / L, 0.0, 1.0), np.clip(s * q / L, 0.0, 1.0)


@dataclass(frozen=True)
class RaySegments:
    """The valid cell crossings of many rays as flat arrays (ragged rows of :func:`traverse`), in ray order
    and, within a ray, in range order.

    ray (M,) int64 — ray of each segment;  cell (M,) int64;  a, b (M,) — range interval [a, b);
    start (M,) int64 — flat index of the first segment of the same ray;  n_rays : int.
    """

    ray: np.ndarray
    cell: np.ndarray
    a: np.ndarray
    b: np.ndarray
    start: np.ndarray
    n_rays: int

    @staticmethod
    def from_traversal(cell: np.ndarray, t_in: np.ndarray, t_out: np.ndarray) -> RaySegments:
        valid = cell >= 0
        ray, _ = np.nonzero(valid)
        counts = valid.sum(axis=1)
        first = np.concatenate([[0], np.cumsum(counts)[:-1]])
        return RaySegments(ray.astype(np.int64), cell[valid], t_in[valid], t_out[valid],
                           first[ray].astype(np.int64), int(cell.shape[0]))

    def first_rays(self, n: int) -> RaySegments:
        """The segments of rays ``0 … n−1`` (a prefix of the flat arrays)."""
        m = int(np.searchsorted(self.ray, n))
        return RaySegments(self.ray[:m], self.cell[:m], self.a[:m], self.b[:m], self.start[:m], n)

    def same_ray_shift(self, d: int) -> np.ndarray:
        """Mask ``(M − |d|,)``: segment i and i + d belong to the same ray (for d > 0: pairs (i, i+d))."""
        return self.ray[:-d] == self.ray[d:]


def ray_products(P: np.ndarray, rs: RaySegments) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Along each ray: ``U_j = Π_{i<j}(1 − P_i)`` (M,), ``π_j = P_j U_j`` (M,) and the miss probability
    ``Π_all(1 − P_i)`` (n_rays,). P must lie in [0, 1 − 1e-12] (log-space products)."""
    lg = np.log1p(-np.minimum(P, 1.0 - 1e-12))
    cs = np.cumsum(lg)
    excl = cs - lg
    U = np.exp(excl - excl[rs.start])
    tot = np.bincount(rs.ray, lg, minlength=rs.n_rays)
    return U, P * U, np.exp(tot)


def observation_probs(P: np.ndarray, rs: RaySegments, sigma: np.ndarray, band: int, conditional: bool = True):
    """Eqs. (33)-(34) for every segment k: ``P(q̂_k=O | q_k=O)`` and ``P(q̂_k=O | q_k=E)``.

    With ``conditional`` both are divided by the probability that cell k is *observed* at all (the reading
    falls in k or beyond, i.e. the beam reaches k), under q_k = O and q_k = E respectively::

        D_O = Σ_{j<k} π_j Q_kj + U_k Q_kk,
        D_E = Σ_{j<k} π_j Q_kj + U_k − Σ_{j>k} π_j (1 − Q_kj) / (1 − P_k)

    (Q_kj from :func:`tail_prob`): E2 updates a cell only when the scan observes it, so its expected
    indicator is conditional on that event. For a noise-free sensor this makes A the identity, as in the
    §II.D example; the unconditional form (``conditional=False``) is eqs. (33)-(34) verbatim.

    Parameters
    ----------
    P : ndarray (M,)      current estimate of each segment's cell (in [0, 1 − 1e-12]).
    rs : RaySegments
    sigma : ndarray (M,)  range σ of each segment's ray.
    band : int            Γ_kj, Q_kj are evaluated for |k − j| ≤ band (Γ ≈ 0, Q ≈ 0 / 1 beyond).

    Returns
    -------
    a_oo, a_oe : ndarray (M,)
    """
    U, pi, _ = ray_products(P, rs)
    a, b = rs.a, rs.b
    one_minus = np.maximum(1.0 - P, 1e-12)
    g_kk, q_kk = gamma_tail(a, b, a, b, sigma)
    a_oo = g_kk * U
    a_oe = np.zeros_like(a_oo)
    if conditional:
        d_o = U * q_kk
        d_e = U.copy()
    lg = np.log1p(-np.minimum(P, 1.0 - 1e-12))
    cs = np.cumsum(lg)
    for d in range(1, band + 1):
        if len(a) <= d:
            break
        same = rs.same_ray_shift(d)
        k_hi, j_lo = slice(d, None), slice(None, -d)  # (k, j = k − d)
        s_k = sigma[k_hi]
        g_lo, q_lo = gamma_tail(a[k_hi], b[k_hi], a[j_lo], b[j_lo], s_k)
        g = np.where(same, g_lo * pi[j_lo], 0.0)
        a_oo[k_hi] += g
        a_oe[k_hi] += g
        k_lo, j_hi = slice(None, -d), slice(d, None)  # (k, j = k + d)
        s_k = sigma[k_lo]
        g_hi, q_hi = gamma_tail(a[k_lo], b[k_lo], a[j_hi], b[j_hi], s_k)
        # P_j U_k Π_{k<i<j}(1 − P_i) = P_j U_k exp(cs[j−1] − cs[k])
        between = np.exp(cs[d - 1 : len(cs) - 1] - cs[:-d]) if d > 1 else np.ones(len(a) - d)
        h = np.where(same, g_hi * P[j_hi] * U[k_lo] * between, 0.0)
        a_oe[k_lo] += h
        if conditional:
            q = np.where(same, q_lo * pi[j_lo], 0.0)
            d_o[k_hi] += q
            d_e[k_hi] += q
            d_e[k_lo] -= np.where(same, pi[j_hi] * (1.0 - q_hi) / one_minus[k_lo], 0.0)
    if conditional:
        a_oo = a_oo / np.maximum(d_o, 1e-300)
        a_oe = a_oe / np.maximum(d_e, 1e-300)
    return np.clip(a_oo, 0.0, 1.0), np.clip(a_oe, 0.0, 1.0)


def rasterise_segments(spec: GridSpec, segments_xyxy: np.ndarray) -> np.ndarray:
    """Occupied mask ``(H, W) bool``: every cell a wall segment ``[x1, y1, x2, y2]`` passes through."""
    occ = np.zeros(spec.n_cells, bool)
    seg = np.asarray(segments_xyxy, float).reshape(-1, 4)
    if len(seg):
        d = seg[:, 2:] - seg[:, :2]
        length = np.hypot(d[:, 0], d[:, 1])
        ang = np.arctan2(d[:, 1], d[:, 0])
        for a in range(0, len(seg), 256):
            sl = slice(a, a + 256)
            cell, _, _ = traverse(spec, seg[sl, :2], ang[sl], length[sl], float(length[sl].max()) + 1e-9)
            occ[cell[cell >= 0]] = True
            # a zero-length crossing at an exact end point still marks the end cell
        H, W = spec.shape
        for pts in (seg[:, :2], seg[:, 2:]):
            c = np.floor((pts[:, 0] - spec.origin_xy[0]) / spec.resolution).astype(np.int64)
            r = np.floor((pts[:, 1] - spec.origin_xy[1]) / spec.resolution).astype(np.int64)
            ok = (c >= 0) & (c < W) & (r >= 0) & (r < H)
            occ[r[ok] * W + c[ok]] = True
    return occ.reshape(spec.shape)
