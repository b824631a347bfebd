"""Occupancy-grid figures (paper 001 Figs. 3-9): grey-level maps, map error vs laps, pose errors with 3σ
bounds, the §II.D counterexample trajectories. Draw into given axes; compute no metric."""

from __future__ import annotations

import numpy as np

from slamcli.plots import style


def draw_grid(ax, grid, snapshot: int | None = None, unobserved_alpha: float = 1.0, label: str | None = None,
              colorbar: bool = False):
    """Grey-level occupancy image (white = free, black = occupied, unobserved cells at their prior) of
    ``grid`` (:class:`~slamcli.types.OccupancyGrid`), or of its ``snapshot``-th snapshot, under other artists;
    with ``colorbar`` a bar "occupancy probability" (0-1) beside the axis."""
    prob = grid.prob if snapshot is None else grid.snapshots[snapshot]
    H, W = prob.shape
    x0, y0 = float(grid.origin_xy[0]), float(grid.origin_xy[1])
    ext = (x0, x0 + W * grid.resolution, y0, y0 + H * grid.resolution)
    im = ax.imshow(prob, origin="lower", extent=ext, cmap="gray_r", vmin=0.0, vmax=1.0, interpolation="nearest",
                   zorder=0, alpha=unobserved_alpha)
    if label:
        ax.plot([], [], "s", color="0.3", ms=5, ls="none", label=label)
    if colorbar:
        # an inset of the map axis, so it stays beside the map however wide the legend under it is
        cb = ax.figure.colorbar(im, cax=ax.inset_axes((1.03, 0.0, 0.04, 1.0)))
        cb.set_label("occupancy probability")
        cb.outline.set_linewidth(style.THIN_PT)
    return im


def observed_corners_xy(grid) -> np.ndarray:
    """``(2, 2)`` lower-left and upper-right corners (m) of the cells of ``grid`` observed at least once
    (of the whole grid when it records no counts, or nothing was observed)."""
    H, W = grid.prob.shape
    rows, cols = (np.nonzero(np.asarray(grid.observed) > 0) if grid.observed is not None else ((), ()))
    if not len(rows):
        rows, cols = np.array([0, H - 1]), np.array([0, W - 1])
    o, res = np.asarray(grid.origin_xy, float), float(grid.resolution)
    return np.array([[o[0] + cols.min() * res, o[1] + rows.min() * res],
                     [o[0] + (cols.max() + 1) * res, o[1] + (rows.max() + 1) * res]])


def draw_walls(ax, walls_xyxy, **kw):
    """Wall segments ``(W, 4)`` as thin lines (the true map, subfigure (a))."""
    w = np.asarray(walls_xyxy, float).reshape(-1, 4)
    kw = {"color": style.BAND, "lw": 0.8, **kw}
    for i, s in enumerate(w):
        ax.plot([s[0], s[2]], [s[1], s[3]], label="Walls (true)" if i == 0 else None, **kw)


def plot_map_error_vs_laps(ax, curves: dict, ylabel: str = "total map error Σ|P − P*|", title: str | None = None):
    """``curves``: ``{label: (laps (K,), error (K,))}`` — subfigure (e)."""
    for label, (x, y) in curves.items():
        ax.plot(x, y, "o-", ms=3, label=label)
    ax.set_xlabel("laps")
    ax.set_ylabel(ylabel)
    ax.grid(True, **style.GRID)
    if title:
        ax.set_title(title)
    ax.legend(fontsize=style.SMALL_PT)


def plot_pose_error_3sigma(axes, df, dt: float = 1.0):
    """Subfigures (f)-(h): error in x, y, θ and ±3σ of the filter, one axis each; ``df`` from
    :func:`slamcli.metrics.occupancy.pose_errors_3sigma`."""
    from slamcli.metrics.registry import ANGLE_UNIT

    t = df["step"].to_numpy() * dt
    for ax, c, unit in zip(axes, ("x", "y", "theta"), ("m", "m", ANGLE_UNIT)):
        ax.plot(t, df[f"err_{c}"], lw=0.8, color=style.ESTIMATE, label=f"error {c}")
        ax.plot(t, df[f"bound3_{c}"], lw=0.8, color=style.EST_LANDMARK, ls="--", label="±3σ")
        ax.plot(t, -df[f"bound3_{c}"], lw=0.8, color=style.EST_LANDMARK, ls="--")
        ax.set_ylabel(f"{c} ({unit})")
        ax.grid(True, **style.GRID)
    axes[-1].set_xlabel("time (s)")
    axes[0].legend(fontsize=style.SMALL_PT, loc="upper right")
