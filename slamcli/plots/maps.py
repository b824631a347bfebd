"""Map figure in the style of paper 000 Figs 5a-d / 9a-c: true and estimated landmarks, true / odometry /
estimated paths, optional covariance ellipses. Draws into a given axis; computes no metric."""

from __future__ import annotations

import numpy as np

from slamcli.plots import style
from slamcli.plots.curves import legend_below


def covariance_ellipse(cov_2x2, n_sigma: float = 2.0):
    """Width, height (m) and angle (deg) of the ``n_sigma`` ellipse of a 2×2 covariance (drawing geometry)."""
    w, V = np.linalg.eigh(0.5 * (np.asarray(cov_2x2, float) + np.asarray(cov_2x2, float).T))
    w = np.clip(w, 0.0, None)
    angle = np.degrees(np.arctan2(V[1, 1], V[0, 1]))
    return 2 * n_sigma * np.sqrt(w[1]), 2 * n_sigma * np.sqrt(w[0]), angle


def plot_map(ax, true_landmarks_xy=None, est_landmarks_xy=None, true_path_xy=None, odometry_path_xy=None,
             est_path_xy=None, landmark_cov=None, pose_cov=None, n_sigma: float = 2.0, ellipse_every: int = 0,
             title: str | None = None, legend_note: str | None = None, label: str | None = None):
    """Draw a SLAM map.

    Parameters
    ----------
    ax : matplotlib Axes
    true_landmarks_xy : ndarray (L, 2) | None     drawn as hollow squares ("Real locations").
    est_landmarks_xy : ndarray (L', 2) | None     drawn as red asterisks ("Estimated locations").
    true_path_xy, odometry_path_xy, est_path_xy : ndarray (T+1, 2) | None
                                                  black solid, grey dashed, blue solid.
    landmark_cov : ndarray (L', 2, 2) | None      ``n_sigma`` ellipses around the estimated landmarks.
    pose_cov : ndarray (T+1, 3, 3) | None         ``n_sigma`` position ellipses every ``ellipse_every`` poses.
    legend_note : str | None                      extra legend line without a symbol, e.g. "No ground truth in
                                                  dataset" when the true path and landmarks are absent.
    label : str | None                            legend name of the estimate (default "Estimated trajectory").

    The start and end of the estimated trajectory (of the true one when there is no estimate) are marked: a
    hollow circle "Start" and a filled diamond "End".
    """
    from matplotlib.patches import Ellipse

    if true_path_xy is not None:
        ax.plot(true_path_xy[:, 0], true_path_xy[:, 1], "-", color=style.TRUTH, lw=0.8, label="True trajectory")
    if odometry_path_xy is not None:
        ax.plot(odometry_path_xy[:, 0], odometry_path_xy[:, 1], "--", color=style.ODOMETRY, lw=0.8,
                label="Odometry")
    if est_path_xy is not None:
        ax.plot(est_path_xy[:, 0], est_path_xy[:, 1], "-", color=style.ESTIMATE, lw=style.LINE_PT,
                label=label or "Estimated trajectory")
    if true_landmarks_xy is not None and len(true_landmarks_xy):
        ax.plot(true_landmarks_xy[:, 0], true_landmarks_xy[:, 1], "s", mfc="none", mec=style.TRUTH, ms=5,
                mew=0.8, ls="none", label="Real locations")
    if est_landmarks_xy is not None and len(est_landmarks_xy):
        ax.plot(est_landmarks_xy[:, 0], est_landmarks_xy[:, 1], "*", color=style.EST_LANDMARK, ms=5, ls="none",
                label="Estimated locations")
    mark_ends(ax, est_path_xy if est_path_xy is not None else true_path_xy)
    first = True
    if landmark_cov is not None and est_landmarks_xy is not None:
        for m, P in zip(est_landmarks_xy, landmark_cov):
            if not np.all(np.isfinite(P)):
                continue
            w, h, a = covariance_ellipse(P, n_sigma)
            ax.add_patch(Ellipse(m, w, h, angle=a, fill=False, ec=style.EST_LANDMARK, lw=0.6, alpha=0.8,
                                 label=f"{n_sigma:g}σ landmark ellipse" if first else None))
            first = False
    if pose_cov is not None and est_path_xy is not None and ellipse_every > 0:
        first = True
        for k in range(0, len(est_path_xy), ellipse_every):
            P = pose_cov[k][:2, :2]
            if not np.all(np.isfinite(P)):
                continue
            w, h, a = covariance_ellipse(P, n_sigma)
            ax.add_patch(Ellipse(est_path_xy[k], w, h, angle=a, fill=False, ec=style.ESTIMATE, lw=0.5, alpha=0.7,
                                 label=f"{n_sigma:g}σ pose ellipse" if first else None))
            first = False
    ax.set_xlabel("x (m)")
    ax.set_ylabel("y (m)")
    ax.set_aspect("equal", adjustable="datalim")
    ax.grid(True, **style.GRID)
    if title:
        ax.set_title(title)
    if legend_note:
        ax.plot([], [], ls="none", label=legend_note)
    legend_below(ax, ncol=2)  # 3 columns overflow a ~4.6 in snapshot panel into its neighbour's legend
    return ax


def mark_ends(ax, path_xy) -> None:
    """Mark the first and last point of a path ``(T+1, 2)``: hollow circle "Start", filled diamond "End"."""
    if path_xy is None or not len(path_xy):
        return
    p = np.asarray(path_xy, float)
    ax.plot(p[0, 0], p[0, 1], "o", mfc="white", mec=style.TRUTH, mew=0.8, ms=5, ls="none", zorder=5,
            label="Start")
    ax.plot(p[-1, 0], p[-1, 1], "D", color=style.TRUTH, ms=3.5, ls="none", zorder=5, label="End")
