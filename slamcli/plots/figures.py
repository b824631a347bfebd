"""Figures from slamcli objects (a :class:`~slamcli.types.SolverResult` and its
:class:`~slamcli.types.Dataset`): pick the arrays each figure needs and hand them to the drawing functions of
:mod:`~slamcli.plots.maps` / :mod:`~slamcli.plots.curves`. Shared by ``slamcli plot`` and the Python API
(``slamcli.plot``); the metric values come from :mod:`slamcli.metrics`.
"""

from __future__ import annotations

import numpy as np


def map_context(dataset) -> dict:
    """The reference arrays of a map figure from a dataset: true landmarks and path (None for a GPS-only
    truth), the odometry, the GPS fixes ``ref_xy`` and, for a multi-robot dataset, the robot index of each
    stacked pose and the robots' names."""
    truth, team = dataset.truth, dataset.inputs.robots
    full = truth is not None and not truth.position_reference_only
    return {"true_landmarks_xy": truth.landmarks_xy if full else None,
            "true_path_xy": truth.poses_xyt[:, :2] if full else None,
            "odometry_path_xy": dataset.inputs.odometry_xyt[:, :2],
            "ref_xy": truth.ref_xy if truth is not None else None,
            "pose_robot": np.asarray(team.pose_robot) if team is not None else None,
            "robot_names": [f"Robot {int(n)}" for n in team.robot_number] if team is not None else None}


def _note(ctx) -> str | None:
    if ctx["true_path_xy"] is not None:
        return None
    return "No ground truth in dataset" if ctx["ref_xy"] is None else "GPS only, no true map"


def draw_map(ax, result, dataset, *, ellipses: bool = False, pose_ellipse_every: int = 0, title: str | None = None,
             label: str | None = None, extent_xy=None):
    """Paper-style map of ``result`` over ``dataset`` (truth or GPS reference drawn when the dataset has it,
    one colour per robot of a team); ``label`` names the estimate in the legend; the title defaults to the
    solver's name; ``extent_xy`` ``(n, 2)``: more points the axes must show (an occupancy grid's observed part)."""
    from slamcli.plots.maps import plot_map

    ctx = map_context(dataset)
    return plot_map(ax, ctx["true_landmarks_xy"], result.landmarks_xy, ctx["true_path_xy"], ctx["odometry_path_xy"],
                    result.poses_xyt[:, :2], landmark_cov=result.landmark_cov if ellipses else None,
                    pose_cov=result.pose_cov if ellipses else None, ellipse_every=pose_ellipse_every,
                    title=title if title is not None else result.solver, legend_note=_note(ctx), label=label,
                    ref_xy=ctx["ref_xy"], pose_robot=ctx["pose_robot"], robot_names=ctx["robot_names"], extent_xy=extent_xy)


def draw_overlay(ax, results, dataset, labels=None, *, title: str | None = None):
    """Several results of one dataset in one map (``evo_traj`` style): one colour each, legend names from
    :func:`curve_labels`, the dataset's truth / GPS / odometry drawn once. ValueError when a result's pose
    count differs from the dataset's."""
    from slamcli.plots.maps import plot_overlay

    ctx = map_context(dataset)
    n = dataset.inputs.n_poses
    for r in results:
        if len(r.poses_xyt) != n:
            raise ValueError(f"a {r.solver} result has {len(r.poses_xyt)} poses but the dataset {n}; "
                             "overlay results of the same dataset")
    names = curve_labels([r.solver for r in results], labels)
    est = [(name, r.poses_xyt[:, :2], r.landmarks_xy) for name, r in zip(names, results)]
    return plot_overlay(ax, est, ctx["true_landmarks_xy"], ctx["true_path_xy"], ctx["odometry_path_xy"],
                        ctx["ref_xy"], ctx["pose_robot"], title=title, legend_note=_note(ctx))


def draw_landmark_errors(ax, result, dataset, title: str | None = None):
    """Min/mean/max nearest-true-landmark error per iteration of the result's trace (paper Figs 5e/f)."""
    from slamcli.metrics.landmarks import paper_error_per_iteration
    from slamcli.plots.curves import plot_error_curves

    df = paper_error_per_iteration(result.trace, dataset.truth.landmarks_xy)
    return plot_error_curves(ax, df["iteration"], df["err_min_m"], df["err_mean_m"], df["err_max_m"],
                             title=title or f"{result.solver}: landmark error per iteration")


def pose_errors(result, dataset, n_sigma: float = 3.0):
    """Signed per-step pose error and the estimator's own σ.

    Returns
    -------
    err_xyt (T+1, 3)   ``[x̂ − x, ŷ − y, angle_diff(θ̂, θ)]``.
    sigma_xyt (T+1, 3) | None   ``√diag(pose_cov)``.
    inside (3,) | None          share of steps with ``|err| ≤ n_sigma·σ``, per component.
    """
    from slamcli.models.angles import angle_diff

    est, true = np.asarray(result.poses_xyt, float), np.asarray(dataset.truth.poses_xyt, float)
    if est.shape != true.shape:
        raise ValueError(f"{len(est)} estimated poses but {len(true)} true poses")
    err = np.column_stack([est[:, :2] - true[:, :2], angle_diff(est[:, 2], true[:, 2])])
    if result.pose_cov is None:
        return err, None, None
    sig = np.sqrt(np.clip(np.diagonal(np.asarray(result.pose_cov, float), axis1=1, axis2=2), 0.0, None))
    return err, sig, np.mean(np.abs(err) <= n_sigma * sig, axis=0)


def draw_pose_errors(axes, result, dataset, n_sigma: float = 3.0, title: str | None = None):
    """Per-step pose error with ±nσ bands into three axes; returns the in-band shares (or None)."""
    from slamcli.plots.curves import plot_pose_errors

    err, sig, inside = pose_errors(result, dataset, n_sigma)
    plot_pose_errors(axes, np.arange(len(err)), err, sig, n_sigma, inside,
                     title=title or f"{result.solver}: pose error per step")
    return inside


def map_change_series(result) -> np.ndarray:
    """Map change per iteration of a result's trace, ``(K,)`` (0 for iteration 0)."""
    from slamcli.metrics.landmarks import map_change

    tr = result.trace
    if tr is None or len(tr) < 2:
        raise ValueError(f"no iteration trace with ≥ 2 iterations (solver {result.solver!r})")
    return np.asarray([0.0] + [map_change(tr.landmarks_at(k - 1), tr.landmarks_at(k)) for k in range(1, len(tr))])


def curve_labels(names, labels=None) -> list[str]:
    """Legend names of overlaid curves: ``labels`` when given (one per curve), else ``names`` (solver names),
    numbered "icm (1)", "icm (2)" where a name repeats."""
    if labels:
        if len(labels) != len(names):
            raise ValueError(f"{len(labels)} label(s) for {len(names)} curve(s); give one --label per result")
        return list(labels)
    names = list(names)
    out, seen = [], {}
    for n in names:
        seen[n] = seen.get(n, 0) + 1
        out.append(f"{n} ({seen[n]})" if names.count(n) > 1 else n)
    return out


def draw_mapchange(ax, results, labels=None, *, log: bool = True, title: str | None = None):
    """Overlay the map change per iteration of several results (log axis by default); legend names from
    :func:`curve_labels` (one result: no legend name unless given)."""
    from slamcli.plots.curves import plot_map_change

    names = curve_labels([r.solver for r in results], labels)
    for k, res in enumerate(results):
        mc = map_change_series(res)
        label = names[k] if (labels or len(results) > 1) else None
        plot_map_change(ax, np.arange(len(mc)), mc, label=label, log=log)
    ax.set_title(title or "Map change between iterations")
    return ax


def draw_nees(ax, average, *, log: bool = True, title: str | None = None, label: str | None = None):
    """Monte-Carlo average pose NEES (:class:`~slamcli.metrics.consistency` result) with its χ² band."""
    from slamcli.plots.curves import plot_nees

    a = average
    return plot_nees(ax, np.arange(len(a.anees)), a.anees, a.lower, a.upper, a.dof, a.n_runs, a.fraction_inside,
                     label=label, title=title or nees_title(a.n_runs), log=log)


def nees_title(n_runs: int) -> str:
    """Default NEES title: "Pose NEES over N runs", or "Pose NEES of one run" (no Monte-Carlo average)."""
    return "Pose NEES of one run" if n_runs == 1 else f"Pose NEES over {n_runs} runs"


def draw_compare(ax, groups, *, labels=None, title: str | None = None, log: bool = False):
    """Box + strip plot of a :class:`~slamcli.metrics.aggregate.CompareGroups`: the metric's name and unit
    on the y axis and the grouping columns' names on the x axis (:mod:`slamcli.metrics.registry`);
    ``labels`` renames the groups (one per group); ``log``: logarithmic y axis. ``slamcli plot compare`` and the reproduce report's
    compare figure both draw through this function."""
    from slamcli.metrics.registry import column_label, metric_info
    from slamcli.plots.curves import plot_compare

    names = curve_labels(groups.labels, labels)
    info = metric_info(groups.metric)
    xlabel = ", ".join(column_label(c) for c in groups.by)
    return plot_compare(ax, names, groups.values, info.label, xlabel, title=title, nonnegative=info.nonnegative,
                        log=log)
