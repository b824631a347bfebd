"""Range-bearing sensors: a point sensor and a multi-beam laser hitting landmark discs; clutter.

Both are vectorised over scans, processed in chunks so that memory stays bounded for 100k-step runs. Each
returns rows ``(step, range, bearing, landmark)`` sorted by step and then by bearing (scan order), so the row
order inside a scan carries no hint of which rows are clutter.

Random draws: the *sensor* stream gives detection and noise draws for true returns only (their number depends
on geometry, not on the noise level), the *clutter* stream gives the false returns. Changing the clutter rate
therefore leaves the true returns' noise unchanged, and changing noise levels leaves which landmarks were
detected unchanged.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from slamcli.models.angles import wrap_angle
from slamcli.numerics import GEOMETRY_EPS
from slamcli.sim.config import ClutterConfig, SensorConfig

_CHUNK_PAIRS = 400_000  # (scan, landmark) pairs per chunk: bounds memory to a few tens of MB


@dataclass(frozen=True)
class Returns:
    """Sensor rows, sorted by (step, bearing).

    step : ndarray (N,) int64; range_m, bearing_rad : ndarray (N,); landmark : ndarray (N,) int64 (−1 = clutter
    or max-range reading).
    """

    step: np.ndarray
    range_m: np.ndarray
    bearing_rad: np.ndarray
    landmark: np.ndarray

    @staticmethod
    def concat(parts: list[Returns]) -> Returns:
        if not parts:
            z = np.zeros(0)
            return Returns(z.astype(np.int64), z, z.copy(), z.astype(np.int64))
        return Returns(
            np.concatenate([p.step for p in parts]).astype(np.int64),
            np.concatenate([p.range_m for p in parts]),
            np.concatenate([p.bearing_rad for p in parts]),
            np.concatenate([p.landmark for p in parts]).astype(np.int64),
        )


def _chunks(n_scans: int, n_landmarks: int):
    size = max(1, _CHUNK_PAIRS // max(1, n_landmarks))
    for a in range(0, n_scans, size):
        yield a, min(n_scans, a + size)


def _clutter(
    scan_steps: np.ndarray, cfg: SensorConfig, clutter: ClutterConfig, rng: np.random.Generator
) -> Returns:
    """Poisson(rate) false returns per scan, uniform in range and in bearing over the field of view."""
    counts = rng.poisson(clutter.rate, size=len(scan_steps)) if clutter.rate > 0 else np.zeros(len(scan_steps), int)
    n = int(counts.sum())
    half = min(cfg.fov_rad, 2 * math.pi) / 2
    return Returns(
        np.repeat(scan_steps, counts).astype(np.int64),
        rng.uniform(cfg.min_range, cfg.max_range, n),
        wrap_angle(rng.uniform(-half, half, n)),
        np.full(n, -1, np.int64),
    )


def _sort(r: Returns) -> Returns:
    order = np.lexsort((r.bearing_rad, r.step))
    return Returns(r.step[order], r.range_m[order], r.bearing_rad[order], r.landmark[order])


def point_scans(
    poses_xyt: np.ndarray,
    landmarks_xy: np.ndarray,
    scan_steps: np.ndarray,
    cfg: SensorConfig,
    clutter: ClutterConfig,
    rng_sensor: np.random.Generator,
    rng_clutter: np.random.Generator,
) -> Returns:
    """Point range-bearing sensor: one noisy observation of each visible landmark centre.

    Visible: ``min_range ≤ r ≤ max_range`` and ``|b| ≤ fov/2``; reported with probability ``detection_prob``;
    ``z = [clip(r + σ_r n₁, 0, max_range), wrap(b + σ_b n₂)]`` (a sensor never reads beyond its max range).
    """
    L = len(landmarks_xy)
    half = cfg.fov_rad / 2
    parts = []
    tree = _LandmarkIndex(landmarks_xy, cfg.max_range) if L else None
    # The chunks are those of the all-pairs version (their boundaries order the random draws), so the output
    # is identical to it; the candidate search per chunk is a KD-tree ball query: O(T log L + visible pairs).
    for a, b in _chunks(len(scan_steps), L):
        if L == 0:
            break
        steps = scan_steps[a:b]
        si, li, r_v, b_v = tree.candidates(poses_xyt[steps], cfg.min_range, cfg.max_range)
        vis = np.ones(len(si), bool)
        if cfg.fov_deg < 360:
            vis &= np.abs(b_v) <= half
        si, li, r_v, b_v = si[vis], li[vis], r_v[vis], b_v[vis]
        # Draw for every visible pair, whatever detection_prob and the noise levels are (stream stability).
        u = rng_sensor.random(len(si))
        n = rng_sensor.standard_normal((len(si), 2))
        keep = u < cfg.detection_prob
        si, li, n = si[keep], li[keep], n[keep]
        parts.append(
            Returns(
                steps[si],
                np.clip(r_v[keep] + cfg.range_std * n[:, 0], 0.0, cfg.max_range),
                wrap_angle(b_v[keep] + cfg.bearing_std * n[:, 1]),
                li.astype(np.int64),
            )
        )
    parts.append(_clutter(scan_steps, cfg, clutter, rng_clutter))
    return _sort(Returns.concat(parts))


def beam_angles(cfg: SensorConfig) -> tuple[np.ndarray, float]:
    """Beam bearings ``(B,)`` (rad, robot frame) and their spacing Δ: evenly from −fov/2 to +fov/2
    (181 beams over 180° → Δ = 1°); a 360° scan spaces B beams by 2π/B from −π."""
    B = cfg.n_beams
    if cfg.fov_deg >= 360:
        delta = 2 * math.pi / B
        return -math.pi + delta * np.arange(B), delta
    delta = cfg.fov_rad / (B - 1)
    return -cfg.fov_rad / 2 + delta * np.arange(B), delta


def _candidates(poses_xyt: np.ndarray, landmarks_xy: np.ndarray, r_min: float, r_max: float):
    """(scan row, landmark) pairs with ``r_min ≤ ‖m − p‖ ≤ r_max`` and their centre range and bearing — the
    gathered form of :func:`slamcli.models.observation.range_bearing`, ``[‖m − p‖, wrap(atan2(Δy, Δx) − θ)]``.
    A squared-distance gate runs first, so ``atan2`` is evaluated only for pairs in range."""
    dx = landmarks_xy[None, :, 0] - poses_xyt[:, None, 0]
    dy = landmarks_xy[None, :, 1] - poses_xyt[:, None, 1]
    d2 = dx * dx + dy * dy
    si, li = np.nonzero((d2 >= r_min * r_min) & (d2 <= r_max * r_max))
    dx, dy = dx[si, li], dy[si, li]
    r = np.hypot(dx, dy)
    ok = (r >= r_min) & (r <= r_max)
    si, li, dx, dy, r = si[ok], li[ok], dx[ok], dy[ok], r[ok]
    return si, li, r, wrap_angle(np.arctan2(dy, dx) - poses_xyt[si, 2])


class _LandmarkIndex:
    """KD-tree over the landmarks for the point sensor's visibility query (``scipy.spatial.cKDTree``).

    :meth:`candidates` returns exactly what :func:`_candidates` (all scan × landmark pairs, O(S·L)) returns,
    in the same order: the tree proposes the landmarks within a slightly enlarged radius of each pose, and
    the same floating-point gates as :func:`_candidates` then decide (the tree's own distance arithmetic
    never decides a borderline pair). With an infinite range every pair is a candidate and the all-pairs
    form is used.
    """

    def __init__(self, landmarks_xy: np.ndarray, r_max: float):
        self.landmarks_xy = np.asarray(landmarks_xy, float)
        self.tree = None
        if math.isfinite(r_max):
            from scipy.spatial import cKDTree

            self.tree = cKDTree(self.landmarks_xy)

    def candidates(self, poses_xyt: np.ndarray, r_min: float, r_max: float):
        """``(scan row, landmark, range, bearing)`` of the pairs with ``r_min ≤ ‖m − p‖ ≤ r_max`` (see
        :func:`_candidates`), rows in (scan row, landmark) order."""
        if self.tree is None:
            return _candidates(poses_xyt, self.landmarks_xy, r_min, r_max)
        near = self.tree.query_ball_point(poses_xyt[:, :2], r_max * (1 + 1e-9) + 1e-9, return_sorted=True)
        counts = np.fromiter((len(x) for x in near), np.int64, len(near))
        si = np.repeat(np.arange(len(near)), counts)
        li = np.fromiter((j for x in near for j in x), np.int64, int(counts.sum()))
        # the same arithmetic, in the same order, as the all-pairs version
        dx = self.landmarks_xy[li, 0] - poses_xyt[si, 0]
        dy = self.landmarks_xy[li, 1] - poses_xyt[si, 1]
        d2 = dx * dx + dy * dy
        ok = (d2 >= r_min * r_min) & (d2 <= r_max * r_max)
        si, li, dx, dy = si[ok], li[ok], dx[ok], dy[ok]
        r = np.hypot(dx, dy)
        ok = (r >= r_min) & (r <= r_max)
        si, li, dx, dy, r = si[ok], li[ok], dx[ok], dy[ok], r[ok]
        return si, li, r, wrap_angle(np.arctan2(dy, dx) - poses_xyt[si, 2])


def _ray_hits(si: np.ndarray, li: np.ndarray, d: np.ndarray, b: np.ndarray, radius: float, cfg: SensorConfig):
    """All (scan, beam, landmark) ray–disc intersections of one chunk, from candidate pairs (scan row ``si``,
    landmark ``li``) with centre range ``d > radius`` and bearing ``b``.

    A beam at bearing α meets the disc of radius R whose centre is at range d, bearing b, iff
    ``|δ| ≤ β = asin(R/d)`` with ``δ = α − b``; the first intersection is at
    ``t = d cos δ − sqrt(R² − d² sin² δ)``.

    Returns (scan_row, beam, t, landmark) arrays.
    """
    alpha0, delta = -math.pi if cfg.fov_deg >= 360 else -cfg.fov_rad / 2, beam_angles(cfg)[1]
    B = cfg.n_beams
    beta = np.arcsin(np.minimum(radius / d, 1.0))
    rows_s, rows_k, rows_t, rows_l = [], [], [], []
    for shift in (-2 * math.pi, 0.0, 2 * math.pi):  # a disc straddling ±π can meet beams on both sides
        bs = b + shift
        k_lo = np.maximum(np.ceil((bs - beta - alpha0) / delta), 0).astype(np.int64)
        k_hi = np.minimum(np.floor((bs + beta - alpha0) / delta), B - 1).astype(np.int64)
        n_k = np.maximum(k_hi - k_lo + 1, 0)
        tot = int(n_k.sum())
        if tot == 0:
            continue
        rep = np.repeat(np.arange(len(d)), n_k)
        start = np.concatenate([[0], np.cumsum(n_k)[:-1]])
        k = k_lo[rep] + (np.arange(tot) - start[rep])
        dlt = alpha0 + k * delta - bs[rep]
        dd = d[rep]
        t = dd * np.cos(dlt) - np.sqrt(np.maximum(radius**2 - (dd * np.sin(dlt)) ** 2, 0.0))
        ok = (t >= cfg.min_range) & (t <= cfg.max_range)
        rows_s.append(si[rep][ok])
        rows_k.append(k[ok])
        rows_t.append(t[ok])
        rows_l.append(li[rep][ok])
    if not rows_s:
        e = np.zeros(0, np.int64)
        return e, e, np.zeros(0), e
    return np.concatenate(rows_s), np.concatenate(rows_k), np.concatenate(rows_t), np.concatenate(rows_l)


def _nearest_per_key(key: np.ndarray, t: np.ndarray, *cols: np.ndarray):
    """Keep, for every key, the row with the smallest ``t``; output sorted by key."""
    order = np.lexsort((t, key))
    ks = key[order]
    first = np.ones(len(ks), bool)
    first[1:] = ks[1:] != ks[:-1]
    sel = order[first]
    return (key[sel], t[sel]) + tuple(c[sel] for c in cols)


def laser_scans(
    poses_xyt: np.ndarray,
    landmarks_xy: np.ndarray,
    landmark_radius: float,
    scan_steps: np.ndarray,
    cfg: SensorConfig,
    clutter: ClutterConfig,
    rng_sensor: np.random.Generator,
    rng_clutter: np.random.Generator,
) -> Returns:
    """Multi-beam laser (paper 000 §5): nearest disc hit per beam, then the paper's preprocessing.

    Per chunk of scans: ray–disc hits → nearest per (scan, beam) (occlusion) → beam dropout with probability
    ``1 − detection_prob`` → range noise ``σ_r`` and bearing noise ``σ_b`` on the beam angle → clutter beams
    (replace a beam's reading when nearer) → ``drop_isolated`` → max-range readings unless ``drop_max_range``.
    """
    L = len(landmarks_xy)
    B = cfg.n_beams
    alphas, _delta = beam_angles(cfg)
    wrap360 = cfg.fov_deg >= 360
    parts = []
    for a, b in _chunks(len(scan_steps), L):
        steps = scan_steps[a:b]
        S = len(steps)
        if L:
            # the robot inside a disc sees nothing of it; a disc farther than max_range + R cannot be hit
            ci, cl, cd, cb = _candidates(poses_xyt[steps], landmarks_xy, landmark_radius * (1 + GEOMETRY_EPS),
                                         cfg.max_range + landmark_radius)
            s_i, k_i, t_i, l_i = _ray_hits(ci, cl, cd, cb, landmark_radius, cfg)
        else:
            s_i = k_i = l_i = np.zeros(0, np.int64)
            t_i = np.zeros(0)
        key, t, lm = _nearest_per_key(s_i * B + k_i, t_i, l_i)
        # sensor stream: detection and noise draws for every true hit (independent of the noise levels)
        u = rng_sensor.random(len(key))
        n = rng_sensor.standard_normal((len(key), 2))
        keep = u < cfg.detection_prob
        key, lm, n = key[keep], lm[keep], n[keep]
        rng_m = np.clip(t[keep] + cfg.range_std * n[:, 0], 0.0, cfg.max_range)  # a sensor never reads > max
        brg_noise = cfg.bearing_std * n[:, 1]
        # clutter beams: Poisson(rate) per scan, a random beam reads a uniform range if nearer than its return
        if clutter.rate > 0:
            cnt = rng_clutter.poisson(clutter.rate, size=S)
            nc = int(cnt.sum())
            c_key = np.repeat(np.arange(S), cnt) * B + rng_clutter.integers(0, B, nc)
            c_rng = rng_clutter.uniform(cfg.min_range, cfg.max_range, nc)
            key, rng_m, lm, brg_noise = _nearest_per_key(
                np.concatenate([key, c_key]),
                np.concatenate([rng_m, c_rng]),
                np.concatenate([lm, np.full(nc, -1, np.int64)]),
                np.concatenate([brg_noise, np.zeros(nc)]),
            )
        if cfg.drop_isolated and len(key):
            keep = _has_similar_neighbour(key, rng_m, B, cfg.isolation_gap, wrap360)
            key, rng_m, lm, brg_noise = key[keep], rng_m[keep], lm[keep], brg_noise[keep]
        scan, beam = key // B, key % B
        part = Returns(steps[scan], rng_m, wrap_angle(alphas[beam] + brg_noise), lm)
        if not cfg.drop_max_range:
            empty = np.ones(S * B, bool)
            empty[key] = False
            ek = np.nonzero(empty)[0]
            part = Returns.concat(
                [part, Returns(steps[ek // B], np.full(len(ek), cfg.max_range), alphas[ek % B].copy(),
                               np.full(len(ek), -1, np.int64))]
            )
        parts.append(part)
    return _sort(Returns.concat(parts))


def _has_similar_neighbour(key: np.ndarray, r: np.ndarray, B: int, gap: float, wrap360: bool) -> np.ndarray:
    """Mask of returns (sorted unique ``key = scan·B + beam``) with a return on an adjacent beam of the same
    scan whose range differs by at most ``gap`` (paper 000 §5: isolated returns are sensing errors)."""
    scan, beam = key // B, key % B
    ok = np.zeros(len(key), bool)
    for step in (-1, 1):
        nb = beam + step
        valid = (nb >= 0) & (nb < B)
        if wrap360:
            nb = nb % B
            valid[:] = True
        nkey = scan * B + nb
        pos = np.clip(np.searchsorted(key, nkey), 0, len(key) - 1)
        found = valid & (key[pos] == nkey)
        ok |= found & (np.abs(r[pos] - r) <= gap)
    return ok
