"""Wall worlds of paper 001 §III: corridors around rectangular blocks ("cyclic corridors"), their features
(corners and mid-points of straight wall segments), the route along the corridor centre lines and the true
occupancy grid.

Layout ``ladder``: an outer rectangle ``[0, width] × [0, height]`` holding ``block_rows × block_cols``
rectangular blocks separated by corridors of width ``corridor``:

    block (r, c) = [w + c(b_w + w), w + c(b_w + w) + b_w] × [w + r(b_h + w), …],
    b_w = (width − (cols+1)·w)/cols,  b_h = (height − (rows+1)·w)/rows.

Map 1 (one 100 m square corridor) is 1 × 1 blocks; Map 2/3 are 1 × 4 / 1 × 10 ladders; Map 4 (city blocks)
is 2 × 10. Every wall is a line segment; the true grid marks each cell a segment passes through.
"""

from __future__ import annotations

import math

import numpy as np

from slamcli.models.occupancy import GridSpec, rasterise_segments
from slamcli.numerics import POINT_EPS_M


def _rect(x0: float, y0: float, x1: float, y1: float) -> list[list[float]]:
    return [[x0, y0, x1, y0], [x1, y0, x1, y1], [x1, y1, x0, y1], [x0, y1, x0, y0]]


def block_size(width: float, height: float, rows: int, cols: int, corridor: float) -> tuple[float, float]:
    """``(b_w, b_h)`` of the blocks, m."""
    return (width - (cols + 1) * corridor) / cols, (height - (rows + 1) * corridor) / rows


def ladder_segments(width: float, height: float, rows: int, cols: int, corridor: float) -> np.ndarray:
    """Wall segments ``(4 + 4·rows·cols, 4)`` ``[x1, y1, x2, y2]``: the outer rectangle, then every block."""
    bw, bh = block_size(width, height, rows, cols, corridor)
    w = corridor
    segs = _rect(0.0, 0.0, width, height)
    for r in range(rows):
        for c in range(cols):
            x0, y0 = w + c * (bw + w), w + r * (bh + w)
            segs += _rect(x0, y0, x0 + bw, y0 + bh)
    return np.asarray(segs, float)


def corner_features(segments_xyxy: np.ndarray, with_midpoints: bool) -> np.ndarray:
    """Features ``(F, 2)``: every distinct segment end point (the corners), then (optionally) every segment's
    mid-point — the feature points paper 001 §III assumes identified ("corners, or mid-points of corridors /
    straight line segments")."""
    seg = np.asarray(segments_xyxy, float).reshape(-1, 4)
    ends = np.round(np.vstack([seg[:, :2], seg[:, 2:]]), 9)
    _, first = np.unique(ends, axis=0, return_index=True)
    pts = [ends[np.sort(first)]]
    if with_midpoints:
        pts.append(0.5 * (seg[:, :2] + seg[:, 2:]))
    return np.vstack(pts)


def corridor_wall_midpoints(width: float, height: float, rows: int, cols: int, corridor: float) -> np.ndarray:
    """Points ``(2·(rows + cols), 2)`` on the outer walls opposite the mid-point of every corridor stretch
    between two adjacent crossings ("mid-points of corridors", paper 001 §III).

    A block wall's mid-point faces the same spot, but the outer walls are single segments as long as the
    world, whose one mid-point leaves stretches of the boundary corridors with a single feature in range,
    where one range-bearing pair cannot fix the heading that wheel noise loses every step (how often:
    benchmarks/results/design_notes.md). On Map 1 these points are exactly the outer walls' mid-points.

        x = 0 and x = width:   y = (s_r + s_{r+1}) / 2,   s_r = w/2 + r (b_h + w)   (street centre lines)
        y = 0 and y = height:  x = (a_c + a_{c+1}) / 2,   a_c = w/2 + c (b_w + w)   (avenue centre lines)
    """
    bw, bh = block_size(width, height, rows, cols, corridor)
    w = corridor
    my = [w / 2 + r * (bh + w) + (bh + w) / 2 for r in range(rows)]
    mx = [w / 2 + c * (bw + w) + (bw + w) / 2 for c in range(cols)]
    pts = [(0.0, y) for y in my] + [(width, y) for y in my] + [(x, 0.0) for x in mx] + [(x, height) for x in mx]
    return np.asarray(pts, float).reshape(-1, 2)


def post_features(width: float, height: float, rows: int, cols: int, corridor: float, spacing: float) -> np.ndarray:
    """Point landmarks (Map 3 "third example"): posts on both sides of every corridor centre line, a quarter
    corridor width off the line, about ``spacing`` m apart along it."""
    bw, bh = block_size(width, height, rows, cols, corridor)
    w = corridor
    xs = [w / 2 + c * (bw + w) for c in range(cols + 1)]
    ys = [w / 2 + r * (bh + w) for r in range(rows + 1)]
    pts = []
    for y in ys:
        n = max(1, round((xs[-1] - xs[0]) / spacing))
        for k in range(n + 1):
            x = xs[0] + (xs[-1] - xs[0]) * k / n
            pts += [(x, y - w / 4), (x, y + w / 4)]
    for x in xs:
        n = max(1, round((ys[-1] - ys[0]) / spacing))
        for k in range(1, n):
            y = ys[0] + (ys[-1] - ys[0]) * k / n
            pts += [(x - w / 4, y), (x + w / 4, y)]
    return np.unique(np.round(np.asarray(pts, float), 9), axis=0)


def ladder_route(width: float, height: float, rows: int, cols: int, corridor: float) -> np.ndarray:
    """Waypoints ``(K, 2)`` of one lap along the corridor centre lines, starting at the lower-left crossing.

    Pass p (p = 0 … rows−1) serpentines over the avenues between street p and street p+1, rightwards for even
    p and leftwards for odd p; then the route returns along the current street and the first avenue to the
    start. Map 1 (1 × 1) is the square loop; Map 4 (2 × 10) gives ≈ 4 km per lap.
    """
    bw, bh = block_size(width, height, rows, cols, corridor)
    w = corridor
    ax = [w / 2 + c * (bw + w) for c in range(cols + 1)]  # avenue x
    sy = [w / 2 + r * (bh + w) for r in range(rows + 1)]  # street y
    pts = [(ax[0], sy[0])]
    col = 0
    for p in range(rows):
        order = range(cols + 1) if p % 2 == 0 else range(cols, -1, -1)
        lo, hi = sy[p], sy[p + 1]
        for i, c in enumerate(order):
            if i > 0:
                pts.append((ax[c], pts[-1][1]))  # along the street to the next avenue
            # at the first avenue of a pass we are at the lower street; then alternate
            target = hi if i % 2 == 0 else lo
            pts.append((ax[c], target))
            col = c
    cur_y = pts[-1][1]
    if col != 0:
        pts.append((ax[0], cur_y))
    if cur_y != sy[0]:
        pts.append((ax[0], sy[0]))
    # drop consecutive duplicates; the last point equals the start (the route is cyclic)
    out = [pts[0]]
    for q in pts[1:]:
        if math.hypot(q[0] - out[-1][0], q[1] - out[-1][1]) > POINT_EPS_M:
            out.append(q)
    if math.hypot(out[-1][0] - out[0][0], out[-1][1] - out[0][1]) < POINT_EPS_M:
        out.pop()
    return np.asarray(out, float)


def route_length(waypoints_xy: np.ndarray) -> float:
    """Length of the closed polyline, m."""
    wp = np.asarray(waypoints_xy, float)
    d = np.diff(np.vstack([wp, wp[:1]]), axis=0)
    return float(np.hypot(d[:, 0], d[:, 1]).sum())


def grid_spec_for(segments_xyxy: np.ndarray, resolution: float, margin: float, offset: float = 0.5) -> GridSpec:
    """Grid covering the walls with ``margin`` m around them; grid lines at ``(k + offset)·resolution``
    (offset ½: walls at multiples of the resolution run through cell centres)."""
    seg = np.asarray(segments_xyxy, float).reshape(-1, 4)
    lo = np.minimum(seg[:, :2], seg[:, 2:]).min(axis=0) - margin
    hi = np.maximum(seg[:, :2], seg[:, 2:]).max(axis=0) + margin
    res = float(resolution)
    o = (np.floor(lo / res - offset) + offset) * res
    shape = np.ceil((hi - o) / res).astype(int)
    return GridSpec((float(o[0]), float(o[1])), res, (int(shape[1]), int(shape[0])))


def true_grid(spec: GridSpec, segments_xyxy: np.ndarray) -> np.ndarray:
    """True occupancy ``(H, W) uint8`` (1 = a wall passes through the cell)."""
    return rasterise_segments(spec, segments_xyxy).astype(np.uint8)


def lap_end_steps(poses_xyt: np.ndarray, start_xy: np.ndarray, tol: float, min_gap: int) -> np.ndarray:
    """Steps at which the robot comes back within ``tol`` of ``start_xy`` after at least ``min_gap`` steps
    away (the first pose of each return), int64 (n_laps_completed,)."""
    d = np.hypot(poses_xyt[:, 0] - start_xy[0], poses_xyt[:, 1] - start_xy[1])
    out = []
    last = 0
    for t in np.flatnonzero(d < tol):
        if t - last >= min_gap:
            out.append(int(t))
            last = int(t)
    return np.asarray(out, np.int64)
