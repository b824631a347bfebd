"""Set-membership boxes in picture form (paper 004's tables drawn): one rectangle per pose and landmark box
of a hypothesis, each pose's heading interval as a wedge, truth on top. Draws given arrays; computes nothing.
Drawn in the common style (:mod:`~slamcli.plots.style`: colours, labels, legend below the axis).
"""

from __future__ import annotations

import numpy as np

from slamcli.plots import style
from slamcli.plots.curves import legend_below


def plot_boxes(ax, pose_lo, pose_hi, landmark_lo, landmark_hi, true_poses_xyt=None, true_landmarks_xy=None,
               wedge_radius: float = 1.5, title: str | None = None, label: str | None = None,
               color: str = style.ESTIMATE, landmark_color: str = style.EST_LANDMARK) -> None:
    """Draw pose boxes ``(T+1, 3)`` lo/hi (rectangles in x, y + a θ wedge at the box centre) and landmark
    boxes ``(L, 2)`` lo/hi; optional true poses ``(T+1, 3)`` and landmarks ``(L*, 2)`` as markers.

    θ is in our convention (from +x, counter-clockwise, radians, possibly unwrapped); a wedge wider than
    2π is drawn as a full disc.
    """
    from matplotlib.patches import Rectangle, Wedge

    pose_lo, pose_hi = np.asarray(pose_lo, float), np.asarray(pose_hi, float)
    names = []
    for k, (lo, hi) in enumerate(zip(pose_lo, pose_hi)):
        ax.add_patch(Rectangle((lo[0], lo[1]), hi[0] - lo[0], hi[1] - lo[1], fill=False, ec=color, lw=style.THIN_PT,
                               label=(label or "pose boxes") if k == 0 else None))
        c = 0.5 * (lo[:2] + hi[:2])
        span = np.degrees(hi[2] - lo[2])
        if np.isfinite(span):
            t1, t2 = (0.0, 360.0) if span >= 360 else (np.degrees(lo[2]), np.degrees(hi[2]))
            ax.add_patch(Wedge(tuple(c), wedge_radius, t1, t2, fc=color, alpha=0.25, ec="none",
                               label="heading interval θ" if k == 0 else None))
        names.append(ax.annotate(f"r{k + 1}", c, fontsize=style.SMALL_PT - 1, ha="center", va="center"))
    landmark_lo, landmark_hi = np.asarray(landmark_lo, float), np.asarray(landmark_hi, float)
    for j, (lo, hi) in enumerate(zip(landmark_lo, landmark_hi)):
        ax.add_patch(Rectangle((lo[0], lo[1]), hi[0] - lo[0], hi[1] - lo[1], fill=True, fc=landmark_color,
                               alpha=0.3, ec=landmark_color, lw=style.THIN_PT, label="landmark boxes" if j == 0 else None))
        names.append(ax.annotate(f"l{j + 1}", 0.5 * (lo + hi), fontsize=style.SMALL_PT - 1, ha="center", va="bottom"))
    if true_poses_xyt is not None:
        tp = np.asarray(true_poses_xyt, float)
        ax.plot(tp[:, 0], tp[:, 1], ".-", color=style.TRUTH, lw=style.THIN_PT, ms=3, label="True trajectory")
    if true_landmarks_xy is not None:
        tl = np.asarray(true_landmarks_xy, float)
        ax.plot(tl[:, 0], tl[:, 1], "s", mfc="none", mec=style.TRUTH, ms=5, mew=0.8, ls="none",
                label="Real locations")
    allx = np.concatenate([pose_lo[:, 0], pose_hi[:, 0], landmark_lo[:, 0], landmark_hi[:, 0]])
    ally = np.concatenate([pose_lo[:, 1], pose_hi[:, 1], landmark_lo[:, 1], landmark_hi[:, 1]])
    ok = np.isfinite(allx) & np.isfinite(ally)
    if ok.any():
        pad = 1.0 + wedge_radius
        ax.set_xlim(allx[ok].min() - pad, allx[ok].max() + pad)
        ax.set_ylim(ally[ok].min() - pad, ally[ok].max() + pad)
    ax.set_aspect("equal")
    ax.set_xlabel("x (m)")
    ax.set_ylabel("y (m)")
    ax.grid(True, **style.GRID)
    if title:
        ax.set_title(title)
    legend_below(ax, ncol=2)
    hide_crowded(ax, names)


def hide_crowded(ax, texts) -> int:
    """Hide each text of ``texts`` whose extent, measured after a draw at the style's sizes, overlaps one
    kept before it (greedy, in order: r1, r2, ..., then l1, ...); returns how many were hidden."""
    style.apply_style(ax.figure)
    ax.figure.draw_without_rendering()
    kept, hidden = [], 0
    for t in texts:
        box = t.get_window_extent()
        if any(box.overlaps(k) for k in kept):
            t.set_visible(False)
            hidden += 1
        else:
            kept.append(box)
    return hidden
