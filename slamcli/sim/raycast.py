"""One ray caster for every laser of the simulator: the range to the first wall segment or disc per beam.

A beam from ``o`` in direction ``u = (cos α, sin α)`` meets

* the segment ``p + s·(q − p)``, ``s ∈ [0, 1]``, at ``t = cross(p − o, e) / cross(u, e)`` with
  ``e = q − p`` and ``s = cross(p − o, u) / cross(u, e)`` (no hit when ``cross(u, e) = 0``: a beam parallel
  to a wall grazes it and passes);
* the disc of radius ρ centred at ``c`` at ``t = u·(c − o) − sqrt(ρ² − |c − o|² + (u·(c − o))²)`` when the
  square root is real (the first of the two intersections).

The nearest hit with ``t ≥ 0`` wins; a beam without a hit up to ``max_range`` reads ``max_range``. The disc
laser of ``sim.sensors.laser_scans`` is the special case without segments (tests check the two agree).
Vectorised over beams × primitives in chunks (bounded memory).
"""

from __future__ import annotations

import numpy as np

from slamcli.numerics import GEOMETRY_EPS

_CHUNK = 2_000_000  # beam × primitive pairs per chunk


def cast(
    origins_xy: np.ndarray,
    angles: np.ndarray,
    max_range: float,
    segments_xyxy: np.ndarray | None = None,
    discs_xy: np.ndarray | None = None,
    disc_radius: float = 0.0,
) -> tuple[np.ndarray, np.ndarray]:
    """Noise-free ranges of beams.

    Parameters
    ----------
    origins_xy : ndarray (R, 2)        beam origins, m (world).
    angles : ndarray (R,)              beam directions, rad (world).
    max_range : float                  m.
    segments_xyxy : ndarray (W, 4)     wall segments ``[x1, y1, x2, y2]``, m.
    discs_xy : ndarray (L, 2)          disc centres, m; ``disc_radius`` their radius.

    Returns
    -------
    range_m : ndarray (R,)   first hit (≤ max_range) or ``max_range``.
    hit : ndarray (R,) int64 what was hit: segment index ``w ≥ 0``, disc ``l`` as ``−2 − l``, −1 = nothing.
    """
    o = np.asarray(origins_xy, float).reshape(-1, 2)
    a = np.asarray(angles, float).reshape(-1)
    R = o.shape[0]
    best = np.full(R, float(max_range))
    hit = np.full(R, -1, np.int64)
    ux, uy = np.cos(a), np.sin(a)
    seg = np.zeros((0, 4)) if segments_xyxy is None else np.asarray(segments_xyxy, float).reshape(-1, 4)
    disc = np.zeros((0, 2)) if discs_xy is None else np.asarray(discs_xy, float).reshape(-1, 2)
    if len(seg):
        ex, ey = seg[:, 2] - seg[:, 0], seg[:, 3] - seg[:, 1]
        step = max(1, _CHUNK // len(seg))
        for s0 in range(0, R, step):
            sl = slice(s0, s0 + step)
            px = seg[None, :, 0] - o[sl, 0:1]
            py = seg[None, :, 1] - o[sl, 1:2]
            den = ux[sl, None] * ey[None] - uy[sl, None] * ex[None]  # cross(u, e)
            with np.errstate(divide="ignore", invalid="ignore"):
                t = (px * ey[None] - py * ex[None]) / den  # cross(p − o, e) / cross(u, e)
                s = (px * uy[sl, None] - py * ux[sl, None]) / den  # cross(p − o, u) / cross(u, e)
            ok = (np.abs(den) > GEOMETRY_EPS) & (t >= 0.0) & (s >= 0.0) & (s <= 1.0)
            t = np.where(ok, t, np.inf)
            j = np.argmin(t, axis=1)
            tj = t[np.arange(t.shape[0]), j]
            closer = tj < best[sl]
            best[sl] = np.where(closer, tj, best[sl])
            hit[sl] = np.where(closer, j, hit[sl])
    if len(disc):
        step = max(1, _CHUNK // len(disc))
        rho2 = float(disc_radius) ** 2
        for s0 in range(0, R, step):
            sl = slice(s0, s0 + step)
            cx = disc[None, :, 0] - o[sl, 0:1]
            cy = disc[None, :, 1] - o[sl, 1:2]
            proj = ux[sl, None] * cx + uy[sl, None] * cy
            disc2 = rho2 - (cx * cx + cy * cy) + proj * proj
            t = proj - np.sqrt(np.maximum(disc2, 0.0))
            ok = (disc2 >= 0.0) & (t >= 0.0)
            t = np.where(ok, t, np.inf)
            j = np.argmin(t, axis=1)
            tj = t[np.arange(t.shape[0]), j]
            closer = tj < best[sl]
            best[sl] = np.where(closer, tj, best[sl])
            hit[sl] = np.where(closer, -2 - j, hit[sl])
    return best, hit


def scan(
    poses_xyt: np.ndarray,
    beam_angles: np.ndarray,
    max_range: float,
    range_std: float,
    bearing_std: float,
    rng: np.random.Generator,
    segments_xyxy: np.ndarray | None = None,
    discs_xy: np.ndarray | None = None,
    disc_radius: float = 0.0,
) -> tuple[np.ndarray, np.ndarray]:
    """Noisy scans: every pose casts every beam.

    The beam really leaves at ``θ + α_b + n_θ`` (n_θ ~ N(0, bearing_std²)) while the sensor reports the
    nominal bearing α_b; the reading is ``clip(t + n_r, 0, max_range)``, n_r ~ N(0, range_std²), and a beam
    without a hit reads ``max_range`` exactly (no noise). Draws: ``(P, B, 2)`` standard normals from ``rng``
    for every beam, whatever the noise levels.

    Returns
    -------
    range_m : ndarray (P, B);  hit : ndarray (P, B) int64  (see :func:`cast`)
    """
    poses = np.asarray(poses_xyt, float).reshape(-1, 3)
    alpha = np.asarray(beam_angles, float).reshape(-1)
    P, B = poses.shape[0], alpha.shape[0]
    n = rng.standard_normal((P, B, 2))
    ang = poses[:, 2:3] + alpha[None, :] + bearing_std * n[..., 1]
    org = np.repeat(poses[:, :2], B, axis=0)
    t, hit = cast(org, ang.reshape(-1), max_range, segments_xyxy, discs_xy, disc_radius)
    t, hit = t.reshape(P, B), hit.reshape(P, B)
    r = np.where(hit == -1, max_range, np.clip(t + range_std * n[..., 0], 0.0, max_range))
    return r, hit
