"""Map figure in the style of paper 000 Figs 5a-d / 9a-c: true and estimated landmarks, true / odometry /
estimated paths, optional covariance ellipses. Draws into a given axis; computes no metric."""

from __future__ import annotations

import numpy as np

from slamcli.plots.curves import legend_below


def covariance_ellipse(cov_2x2, n_sigma: float = 2.0):
    """Width, height (m) and angle (deg) of the ``n_sigma`` ellipse of a 2×2 covariance (drawing geometry)."""
    w, V = np.linalg.eigh(0.5 * (np.asarray(cov_2x2, float) + np.asarray(cov_2x2, float).T))
    w = np.clip(w, 0.0, None)
    angle = np.degrees(np.arctan2(V[1, 1], V[0, 1]))
    return 2 * n_sigma * np.sqrt(w[1]), 2 * n_sigma * np.sqrt(w[0]), angle


def plot_map(ax, true_landmarks_xy=None, est_landmarks_xy=None, true_path_xy=None, odometry_path_xy=None,
             est_path_xy=None, landmark_cov=None, pose_cov=None, n_sigma: float = 2.0, ellipse_every: int = 0,
             title: str | None = None, legend_note: str | None = None):
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
    """
    from matplotlib.patches import Ellipse

    if true_path_xy is not None:
        ax.plot(true_path_xy[:, 0], true_path_xy[:, 1], "-", color="black", lw=1.0, label="True trajectory")
    if odometry_path_xy is not None:
        ax.plot(odometry_path_xy[:, 0], odometry_path_xy[:, 1], "--", color="0.45", lw=1.0, label="Odometry")
    if est_path_xy is not None:
        ax.plot(est_path_xy[:, 0], est_path_xy[:, 1], "-", color="tab:blue", lw=1.3, label="Estimated trajectory")
    if true_landmarks_xy is not None and len(true_landmarks_xy):
        ax.plot(true_landmarks_xy[:, 0], true_landmarks_xy[:, 1], "s", mfc="none", mec="black", ms=6,
                mew=1.0, ls="none", label="Real locations")
    if est_landmarks_xy is not None and len(est_landmarks_xy):
        ax.plot(est_landmarks_xy[:, 0], est_landmarks_xy[:, 1], "*", color="tab:red", ms=6, ls="none",
                label="Estimated locations")
    first = True
    if landmark_cov is not None and est_landmarks_xy is not None:
        for m, P in zip(est_landmarks_xy, landmark_cov):
            if not np.all(np.isfinite(P)):
                continue
            w, h, a = covariance_ellipse(P, n_sigma)
            ax.add_patch(Ellipse(m, w, h, angle=a, fill=False, ec="tab:red", lw=0.7, alpha=0.8,
                                 label=f"{n_sigma:g}σ landmark ellipse" if first else None))
            first = False
    if pose_cov is not None and est_path_xy is not None and ellipse_every > 0:
        first = True
        for k in range(0, len(est_path_xy), ellipse_every):
            P = pose_cov[k][:2, :2]
            if not np.all(np.isfinite(P)):
                continue
            w, h, a = covariance_ellipse(P, n_sigma)
            ax.add_patch(Ellipse(est_path_xy[k], w, h, angle=a, fill=False, ec="tab:blue", lw=0.6, alpha=0.7,
                                 label=f"{n_sigma:g}σ pose ellipse" if first else None))
            first = False
    ax.set_xlabel("x (m)")
    ax.set_ylabel("y (m)")
    ax.set_aspect("equal", adjustable="datalim")
    ax.grid(True, lw=0.3, alpha=0.5)
    if title:
        ax.set_title(title)
    if legend_note:
        ax.plot([], [], ls="none", label=legend_note)
    legend_below(ax, ncol=2)  # 3 columns overflow a ~4.6 in snapshot panel into its neighbour's legend
    return ax
