"""Landmark layouts and waypoint paths (both drawn from the *world* random stream only)."""

from __future__ import annotations

import numpy as np

from slamcli.errors import ConfigError
from slamcli.numerics import POINT_EPS_M
from slamcli.sim.config import PathConfig, WorldConfig


def _subdivide(corners_xy: np.ndarray, spacing: float, closed: bool) -> np.ndarray:
    """Insert points about ``spacing`` m apart along each straight edge of a polyline ``(K, 2)``."""
    if spacing <= 0:
        return corners_xy
    pts = [corners_xy[0]]
    ends = np.vstack([corners_xy[1:], corners_xy[:1]]) if closed else corners_xy[1:]
    starts = corners_xy if closed else corners_xy[:-1]
    for a, b in zip(starts, ends):
        n = max(1, round(float(np.hypot(*(b - a))) / spacing))
        for k in range(1, n + 1):
            pts.append(a + (b - a) * k / n)
    out = np.array(pts)
    return out[:-1] if closed else out  # closed: the last point repeats the first


def make_waypoints(cfg: PathConfig, rng: np.random.Generator) -> np.ndarray:
    """Waypoints ``(K, 2)`` of the path, m.

    ``jitter`` perturbs every waypoint by ``N(0, jitter² I)`` (an irregular path like paper 000 §5).
    """
    if cfg.kind == "explicit":
        wp = np.asarray(cfg.waypoints, float).reshape(-1, 2)
    elif cfg.kind == "rect":
        c = np.array([[cfg.x_min, cfg.y_min], [cfg.x_max, cfg.y_min], [cfg.x_max, cfg.y_max], [cfg.x_min, cfg.y_max]])
        wp = _subdivide(c, cfg.spacing, closed=True)
    elif cfg.kind == "serpentine":
        corners = []
        for k, y in enumerate(cfg.lanes):
            xs = (cfg.x_min, cfg.x_max) if k % 2 == 0 else (cfg.x_max, cfg.x_min)
            corners += [(xs[0], y), (xs[1], y)]
        wp = _subdivide(np.array(corners, float), cfg.spacing, closed=False)
    elif cfg.kind == "ellipse":
        a = np.linspace(0.0, 2 * np.pi, cfg.n_points, endpoint=False) - np.pi / 2
        cx, cy = (cfg.x_min + cfg.x_max) / 2, (cfg.y_min + cfg.y_max) / 2
        rx, ry = (cfg.x_max - cfg.x_min) / 2, (cfg.y_max - cfg.y_min) / 2
        wp = np.stack([cx + rx * np.cos(a), cy + ry * np.sin(a)], -1)
    else:  # pragma: no cover - Literal validated by the config
        raise ConfigError(f"path.kind: unknown {cfg.kind!r}")
    if cfg.jitter > 0:
        wp = wp + rng.normal(0.0, cfg.jitter, size=wp.shape)
    return wp


def _dist_to_polyline(p: np.ndarray, poly: np.ndarray, closed: bool) -> np.ndarray:
    """Distance ``(N,)`` from points ``p (N, 2)`` to a polyline ``(K, 2)``."""
    a = poly if closed else poly[:-1]
    b = np.vstack([poly[1:], poly[:1]]) if closed else poly[1:]
    if len(a) == 0:
        return np.hypot(*(p - poly[0]).T)
    ab = b - a  # (S, 2)
    ap = p[:, None, :] - a[None]  # (N, S, 2)
    den = np.maximum(np.einsum("sk,sk->s", ab, ab), 1e-300)
    s = np.clip(np.einsum("nsk,sk->ns", ap, ab) / den, 0.0, 1.0)
    d = ap - s[..., None] * ab[None]
    return np.sqrt(np.min(np.einsum("nsk,nsk->ns", d, d), axis=1))


def octagon_points(radius: float) -> np.ndarray:
    """The 8 vertices of a regular octagon of circumradius ``radius`` centred at the origin, plus the centre
    (9, 2) — the cones of paper 000 §6 (Fig. 8(b))."""
    a = np.arange(8) * (np.pi / 4)
    return np.vstack([np.stack([radius * np.cos(a), radius * np.sin(a)], -1), [[0.0, 0.0]]])


def make_landmarks(cfg: WorldConfig, waypoints_xy: np.ndarray, cyclic: bool, rng: np.random.Generator) -> np.ndarray:
    """Landmark positions ``(L, 2)``, m.

    ``jitter`` (Gaussian, m) is applied to generated layouts, not to ``extra_landmarks``.
    """
    if cfg.layout == "rows":
        xs = np.arange(cfg.x_min, cfg.x_max + POINT_EPS_M, cfg.col_spacing)
        ys = cfg.row_y0 + cfg.row_spacing * np.arange(cfg.n_rows)
        gx, gy = np.meshgrid(xs, ys)
        lm = np.stack([gx.ravel(), gy.ravel()], -1)
    elif cfg.layout == "octagon":
        lm = octagon_points(cfg.octagon_radius)
    elif cfg.layout == "random":
        lm = _random_layout(cfg, waypoints_xy, cyclic, rng)
    else:
        lm = np.zeros((0, 2))
    if cfg.jitter > 0 and len(lm):
        lm = lm + rng.normal(0.0, cfg.jitter, size=lm.shape)
    extra = np.asarray(cfg.extra_landmarks, float).reshape(-1, 2)
    return np.vstack([lm, extra]) if len(extra) else lm


def _random_layout(cfg: WorldConfig, waypoints_xy: np.ndarray, cyclic: bool, rng: np.random.Generator) -> np.ndarray:
    """Rejection sampling in batches: uniform in the box, ``min_separation`` apart, ``path_clearance`` from
    the path. Deterministic given ``rng``."""
    out: list[np.ndarray] = []
    stale = 0  # consecutive batches that placed nothing: the box is (practically) full
    for _ in range(200):
        if len(out) >= cfg.n_landmarks or stale >= 10:
            break
        n_before = len(out)
        cand = np.stack(
            [rng.uniform(cfg.x_min, cfg.x_max, 256), rng.uniform(cfg.y_min, cfg.y_max, 256)], -1
        )
        cand = cand[_dist_to_polyline(cand, waypoints_xy, cyclic) >= cfg.path_clearance]
        for c in cand:
            if len(out) >= cfg.n_landmarks:
                break
            if not out or np.min(np.hypot(*(np.asarray(out) - c).T)) >= cfg.min_separation:
                out.append(c)
        stale = stale + 1 if len(out) == n_before else 0
    if len(out) < cfg.n_landmarks:
        raise ConfigError(
            f"world: cannot place {cfg.n_landmarks} random landmarks with min_separation={cfg.min_separation} "
            f"and path_clearance={cfg.path_clearance} in the box"
        )
    return np.asarray(out).reshape(-1, 2)
