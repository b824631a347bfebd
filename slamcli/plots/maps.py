"""Map figure in the style of paper 000 Figs 5a-d / 9a-c: true and estimated landmarks, true / odometry /
estimated paths, optional covariance ellipses; overlays of several estimates. Draws into a given axis; computes
no metric."""

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
             title: str | None = None, legend_note: str | None = None, label: str | None = None,
             ref_xy=None, pose_robot=None, robot_names=None, extent_xy=None):
    """Draw a SLAM map.

    Parameters
    ----------
    ax : matplotlib Axes
    true_landmarks_xy : ndarray (L, 2) | None     drawn as hollow squares ("Real locations").
    est_landmarks_xy : ndarray (L', 2) | None     drawn as asterisks ("Estimated locations"), smaller the more
                                                  there are (:func:`landmark_marker_pt`).
    true_path_xy, odometry_path_xy, est_path_xy : ndarray (P, 2) | None
                                                  black solid, grey dashed, coloured solid.
    landmark_cov : ndarray (L', 2, 2) | None      ``n_sigma`` ellipses around the estimated landmarks.
    pose_cov : ndarray (P, 3, 3) | None           ``n_sigma`` position ellipses every ``ellipse_every`` poses.
    legend_note : str | None                      extra legend line without a symbol, e.g. "No ground truth in
                                                  dataset" when the true path and landmarks are absent.
    label : str | None                            legend name of the estimate (default "Estimated trajectory").
    ref_xy : ndarray (G, 2) | None                position reference of a real recording (GPS fixes), dots.
    pose_robot : ndarray (P,) int | None          robot index of each pose of a multi-robot problem (stacked
                                                  robot-major): one path and one colour per robot.
    robot_names : list of str | None              legend names of the robots (default "Robot 1", ...).
    extent_xy : ndarray (n, 2) | None             more points the axes must show (the observed part of an
                                                  occupancy grid drawn under the map).

    The axis limits come from the estimate and the reference (:func:`set_map_limits`): a diverging odometry
    is clipped and the legend says so. Start and end of the estimated trajectory (of the true one when there
    is no estimate) are marked: a hollow circle "Start" and a filled diamond "End".
    """
    _draw_reference(ax, true_path_xy, odometry_path_xy, ref_xy, pose_robot)
    if est_path_xy is not None:
        if pose_robot is not None and len(np.unique(pose_robot)) > 1:
            segs = _segments(np.asarray(est_path_xy, float), pose_robot)
            names = robot_names or [f"Robot {r + 1}" for r in range(len(segs))]
            for seg, name, colour in zip(segs, names, style.series_colours(len(segs))):
                ax.plot(*seg.T, "-", color=colour, lw=style.LINE_PT, label=f"{name} ({label})" if label else name)
        else:
            ax.plot(est_path_xy[:, 0], est_path_xy[:, 1], "-", color=style.ESTIMATE, lw=style.LINE_PT,
                    label=label or "Estimated trajectory")
    _draw_true_landmarks(ax, true_landmarks_xy)
    if est_landmarks_xy is not None and len(est_landmarks_xy):
        ax.plot(est_landmarks_xy[:, 0], est_landmarks_xy[:, 1], "*", color=style.EST_LANDMARK,
                ms=landmark_marker_pt(len(est_landmarks_xy)), mew=0, ls="none", label="Estimated locations",
                zorder=1.5)
    mark_ends(ax, est_path_xy if est_path_xy is not None else true_path_xy, pose_robot)
    _draw_ellipses(ax, est_landmarks_xy, landmark_cov, est_path_xy, pose_cov, n_sigma, ellipse_every)
    estimate = [a for a in (est_path_xy, true_path_xy, ref_xy, true_landmarks_xy, extent_xy) if a is not None]
    clipped = set_map_limits(ax, estimate, landmarks=[est_landmarks_xy],
                             baselines={"Odometry": odometry_path_xy})
    return _finish_map(ax, title, [legend_note, *clipped])


#: an overlay's first estimate is drawn this much wider (share of the line width) than its last, so paths that
#: coincide stay visible under one another
OVERLAY_WIDEN = 1.0


def plot_overlay(ax, estimates, true_landmarks_xy=None, true_path_xy=None, odometry_path_xy=None, ref_xy=None,
                 pose_robot=None, title: str | None = None, legend_note: str | None = None):
    """Several estimates of one dataset in one figure (``evo_traj`` style), one colour of the style's cycle
    each (the first widest, :data:`OVERLAY_WIDEN`), named by their label in the legend, over the reference
    drawn once.

    Parameters
    ----------
    estimates : list of (label, path_xy (P, 2), landmarks_xy (L_k, 2) | None)
    pose_robot : ndarray (P,) int | None   robot index of each pose (multi-robot): paths split per robot,
                                           one colour per estimate.
    The other arguments are those of :func:`plot_map`.
    """
    _draw_reference(ax, true_path_xy, odometry_path_xy, ref_xy, pose_robot)
    _draw_true_landmarks(ax, true_landmarks_xy)
    n = len(estimates)
    for j, ((label, path_xy, lm_xy), colour) in enumerate(zip(estimates, style.series_colours(n))):
        path_xy = np.asarray(path_xy, float)
        lw = style.LINE_PT * (1.0 + OVERLAY_WIDEN * (n - 1 - j) / max(n - 1, 1))  # later, thinner lines on top
        for k, seg in enumerate(_segments(path_xy, pose_robot)):
            ax.plot(*seg.T, "-", color=colour, lw=lw, label=label if k == 0 else None)
        if lm_xy is not None and len(lm_xy):
            ax.plot(*np.asarray(lm_xy).T, "*", color=colour, ms=landmark_marker_pt(len(lm_xy)), mew=0,
                    ls="none", alpha=0.8, zorder=1.5)
    if estimates:
        ax.plot([], [], "*", color="0.3", ms=5, ls="none", label="Landmarks (by colour)")
    mark_ends(ax, estimates[0][1] if estimates else true_path_xy, pose_robot)
    primary = [np.asarray(e[1], float) for e in estimates]
    primary += [a for a in (true_path_xy, ref_xy, true_landmarks_xy) if a is not None]
    clipped = set_map_limits(ax, primary, landmarks=[e[2] for e in estimates],
                             baselines={"Odometry": odometry_path_xy})
    return _finish_map(ax, title, [legend_note, *clipped])


def _segments(path_xy, pose_robot):
    """The per-robot pieces of a stacked path (the whole path for one robot)."""
    if pose_robot is None:
        return [path_xy]
    pr = np.asarray(pose_robot)
    return [path_xy[pr == r] for r in np.unique(pr)]


def _draw_reference(ax, true_path_xy, odometry_path_xy, ref_xy, pose_robot):
    """Truth (black, one path per robot), odometry (grey dashed), GPS fixes (black dots)."""
    for name, xy, fmt, colour, lw in (("True trajectory", true_path_xy, "-", style.TRUTH, 0.8),
                                      ("Odometry", odometry_path_xy, "--", style.ODOMETRY, 0.8)):
        if xy is None:
            continue
        for k, seg in enumerate(_segments(np.asarray(xy, float), pose_robot)):
            ax.plot(*seg.T, fmt, color=colour, lw=lw, label=name if k == 0 else None)
    if ref_xy is not None and len(ref_xy):
        ax.plot(*np.asarray(ref_xy, float).T, ".", color=style.TRUTH, ms=2.0, mew=0, ls="none", zorder=1.8,
                label="GPS reference")


def _draw_true_landmarks(ax, true_landmarks_xy):
    if true_landmarks_xy is not None and len(true_landmarks_xy):
        ax.plot(true_landmarks_xy[:, 0], true_landmarks_xy[:, 1], "s", mfc="none", mec=style.TRUTH,
                ms=landmark_marker_pt(len(true_landmarks_xy)), mew=0.8, ls="none", label="Real locations")


def _draw_ellipses(ax, est_landmarks_xy, landmark_cov, est_path_xy, pose_cov, n_sigma, ellipse_every):
    """``n_sigma`` ellipses of the landmarks and of every ``ellipse_every``-th pose, above the markers."""
    from matplotlib.patches import Ellipse

    first = True
    if landmark_cov is not None and est_landmarks_xy is not None:
        for m, P in zip(est_landmarks_xy, landmark_cov):
            if not np.all(np.isfinite(P)):
                continue
            w, h, a = covariance_ellipse(P, n_sigma)
            ax.add_patch(Ellipse(m, w, h, angle=a, fill=False, ec=style.EST_LANDMARK, lw=0.6, alpha=0.8, zorder=3,
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
                                 zorder=3, label=f"{n_sigma:g}σ pose ellipse" if first else None))
            first = False


def _finish_map(ax, title, notes):
    """Axis labels, equal aspect, grid, title and the legend below (notes as lines without a symbol)."""
    ax.set_xlabel("x (m)")
    ax.set_ylabel("y (m)")
    ax.set_aspect("equal", adjustable="datalim")
    ax.grid(True, **style.GRID)
    if title:
        ax.set_title(title)
    for note in notes:
        if note:
            ax.plot([], [], ls="none", label=note)
    legend_below(ax, ncol=2)  # 3 columns overflow a ~4.6 in snapshot panel into its neighbour's legend
    return ax


#: percentiles of the estimated landmarks that set the axis limits (spurious far landmarks are clipped)
LANDMARK_PERCENTILES = (2.0, 98.0)
#: margin around the limits, share of their span
LIMIT_PAD = 0.05


def map_limits(primary, landmarks=()):
    """Axis limits ``(x0, x1, y0, y1)`` of a map: the full extent of the ``primary`` point sets (estimated
    paths, true path, reference fixes, true landmarks; each ``(n, 2)``) and the
    :data:`LANDMARK_PERCENTILES` range of the estimated ``landmarks`` (their full extent up to
    :data:`SPARSE_LANDMARKS` of them), padded by :data:`LIMIT_PAD`;
    None when there is nothing finite."""
    boxes = []
    for xy in primary:
        xy = _finite(xy)
        if len(xy):
            boxes.append(np.r_[xy.min(0), xy.max(0)])
    for xy in landmarks:
        xy = _finite(xy)
        if len(xy) > SPARSE_LANDMARKS:
            boxes.append(np.percentile(xy, LANDMARK_PERCENTILES, axis=0).ravel())
        elif len(xy):
            boxes.append(np.r_[xy.min(0), xy.max(0)])
    if not boxes:
        return None
    b = np.asarray(boxes)
    lo, hi = b[:, :2].min(0), b[:, 2:].max(0)
    pad = LIMIT_PAD * np.maximum(hi - lo, 1.0)
    return lo[0] - pad[0], hi[0] + pad[0], lo[1] - pad[1], hi[1] + pad[1]


def _finite(xy):
    xy = np.asarray(xy if xy is not None else np.empty((0, 2)), float).reshape(-1, 2)
    return xy[np.all(np.isfinite(xy), axis=1)]


def set_map_limits(ax, primary, landmarks=(), baselines=None) -> list[str]:
    """Set the axis limits from :func:`map_limits` (the grid under a hybrid map and a diverging baseline do
    not stretch them) and return legend notes naming what falls outside: each baseline path of ``baselines``
    (``{name: (n, 2) | None}``) that leaves the limits, and the count of estimated landmarks clipped."""
    lim = map_limits(primary, landmarks)
    if lim is None:
        return []
    x0, x1, y0, y1 = lim
    # the data limits, not fixed view limits: the equal aspect may still widen one side of the view
    ax.dataLim.set_points(np.array([[x0, y0], [x1, y1]]))
    ax.ignore_existing_data_limits = False
    ax.margins(0.0)
    ax.autoscale(True)

    def outside(xy):
        xy = _finite(xy)
        return int(np.sum((xy[:, 0] < x0) | (xy[:, 0] > x1) | (xy[:, 1] < y0) | (xy[:, 1] > y1)))

    notes = [f"{name} clipped" for name, xy in (baselines or {}).items()
             if xy is not None and outside(xy)]
    n_out = sum(outside(xy) for xy in landmarks)
    if n_out:
        notes.append(f"{n_out} landmarks clipped")
    return notes


#: landmark marker size (pt) of a sparse map, and the smallest one of a dense map
LANDMARK_PT_MAX, LANDMARK_PT_MIN = 5.0, 1.5
#: up to this many landmarks the markers keep :data:`LANDMARK_PT_MAX`
SPARSE_LANDMARKS = 40


def landmark_marker_pt(n_landmarks: int) -> float:
    """Marker size (pt) for a map of ``n_landmarks``: :data:`LANDMARK_PT_MAX` up to :data:`SPARSE_LANDMARKS`,
    then shrinking as ``1/√n`` (constant total marker area) down to :data:`LANDMARK_PT_MIN`, so a dense map
    does not hide the trajectory under it."""
    n = max(int(n_landmarks), 1)
    return float(np.clip(LANDMARK_PT_MAX * np.sqrt(SPARSE_LANDMARKS / n), LANDMARK_PT_MIN, LANDMARK_PT_MAX))


def mark_ends(ax, path_xy, pose_robot=None) -> None:
    """Mark the first and last point of a path ``(P, 2)`` (of each robot's piece when ``pose_robot`` is
    given): hollow circle "Start", filled diamond "End"."""
    if path_xy is None or not len(path_xy):
        return
    for k, p in enumerate(_segments(np.asarray(path_xy, float), pose_robot)):
        if not len(p):
            continue
        ax.plot(p[0, 0], p[0, 1], "o", mfc="white", mec=style.TRUTH, mew=0.8, ms=5, ls="none", zorder=5,
                label="Start" if k == 0 else None)
        ax.plot(p[-1, 0], p[-1, 1], "D", color=style.TRUTH, ms=3.5, ls="none", zorder=5,
                label="End" if k == 0 else None)
