"""``slamcli.plot``: the figures of ``slamcli plot`` for notebooks, drawn into a given matplotlib axis.

Each function takes objects or file paths and returns the axis (or axes); with ``ax=None`` it makes a
new pyplot figure. ``slamcli.plots.save_figure(fig, "x.pdf")`` writes one atomically.
"""

from __future__ import annotations

from slamcli.api.facade import _dataset, _is_path, _result


def _ax(ax, size=(3.5, 2.6), fn: str = "plot"):
    """``ax`` (checked: one matplotlib Axes), or a new pyplot axis in the slamcli style (one column wide,
    the style's colour cycle)."""
    if ax is not None:
        return _one_axes(ax, fn)
    import matplotlib.pyplot as plt

    from slamcli.plots.style import style_axes

    ax = plt.subplots(figsize=size, layout="constrained")[1]
    style_axes(ax)
    return ax


def _one_axes(ax, fn: str):
    """``ax`` when it is one matplotlib Axes; else a one-line TypeError naming what ``fn`` expects."""
    from matplotlib.axes import Axes

    if isinstance(ax, Axes):
        return ax
    what = type(ax).__name__
    if hasattr(ax, "__len__"):
        what += f" of {len(ax)}"
    raise TypeError(f"slamcli.plot.{fn}: ax must be one matplotlib Axes, got {what}")


def _three_axes(ax):
    """Three stacked axes (x, y, θ) for the pose-error panels: a sequence of 3 Axes as given, or one Axes
    split into three in its place (its subplot slot)."""
    from matplotlib.axes import Axes

    if not isinstance(ax, Axes):
        axes = list(ax) if hasattr(ax, "__len__") else []
        if len(axes) != 3 or not all(isinstance(a, Axes) for a in axes):
            raise TypeError("slamcli.plot.errors: ax must be one matplotlib Axes (split into x, y, θ panels) "
                            f"or a sequence of 3 Axes, got {type(ax).__name__}")
        return axes
    spec = ax.get_subplotspec()
    if spec is None:
        raise TypeError("slamcli.plot.errors: the pose-error panels need an Axes made by subplots (or 3 Axes)")
    fig = ax.figure
    ax.remove()
    gs = spec.subgridspec(3, 1, hspace=0.05)
    first = fig.add_subplot(gs[0])
    return [first, fig.add_subplot(gs[1], sharex=first), fig.add_subplot(gs[2], sharex=first)]


def _pair(r, ds):
    result = _result(r)
    if ds is None:
        if not _is_path(r):
            raise TypeError("give the dataset of an in-memory result")
        from slamcli.api.evaluate import load_result_and_dataset

        return load_result_and_dataset(r, None, require_truth=False)[:2]
    return result, _dataset(ds)


def map(r, ds=None, *, ax=None, ellipses: bool = False, pose_ellipse_every: int = 0, title: str | None = None,
        label: str | None = None, labels=None):
    """Paper-style map: true and estimated landmarks and paths (+ covariance ellipses, start/end markers);
    ``label`` names the estimate in the legend. ``r`` a list of results of one dataset: all of them
    overlaid, one colour each, ``labels`` one legend name per result (default: solver names)."""
    from slamcli.plots.figures import draw_map, draw_overlay

    if isinstance(r, (list, tuple)):
        results = [_pair(x, ds) for x in r]
        return draw_overlay(_ax(ax, (3.5, 3.6), "map"), [x[0] for x in results], results[0][1], labels,
                            title=title)
    result, dataset = _pair(r, ds)
    return draw_map(_ax(ax, (3.5, 3.6), "map"), result, dataset, ellipses=ellipses,
                    pose_ellipse_every=pose_ellipse_every, title=title, label=label)


def errors(r, ds=None, *, ax=None, n_sigma: float = 3.0, title: str | None = None):
    """Landmark error per iteration (results with a trace), else per-step pose error with ±nσ bands; for
    the latter ``ax`` is one Axes (split into x, y, θ panels in its place) or a sequence of three."""
    from slamcli.plots.figures import draw_landmark_errors, draw_pose_errors

    result, dataset = _pair(r, ds)
    if result.trace is not None and len(result.trace) > 0:
        return draw_landmark_errors(_ax(ax, fn="errors"), result, dataset, title)
    if ax is None:
        import matplotlib.pyplot as plt

        ax = plt.subplots(3, 1, sharex=True, figsize=(3.5, 4.2), layout="constrained")[1]
    else:
        ax = _three_axes(ax)
    draw_pose_errors(ax, result, dataset, n_sigma, title)
    return ax


def mapchange(results, *, ax=None, labels=None, log: bool = True, title: str | None = None):
    """Map change per iteration of one or several results (log axis); ``labels``: one legend name per
    result (default: solver names, numbered where they repeat)."""
    from slamcli.plots.figures import draw_mapchange

    results = results if isinstance(results, (list, tuple)) else [results]
    return draw_mapchange(_ax(ax, fn="mapchange"), [_result(r) for r in results], labels, log=log, title=title)


def nees(results, datasets, *, ax=None, confidence: float = 0.95, log: bool = True, title: str | None = None,
         label: str | None = None):
    """Monte-Carlo average pose NEES of N runs with the two-sided χ² band; ``label`` names the curve."""
    from slamcli.errors import SlamcliError
    from slamcli.metrics.summary import monte_carlo_pose_nees
    from slamcli.plots.figures import draw_nees

    pairs = [(_result(r), _dataset(d).truth) for r, d in zip(results, datasets, strict=True)]
    avg, why = monte_carlo_pose_nees(pairs, confidence)
    if avg is None:
        raise SlamcliError(f"nees: {why}")
    return draw_nees(_ax(ax, fn="nees"), avg, log=log, title=title, label=label)


def compare(exp_dir, metric: str = "ate_rmse_m", by="solver", *, ax=None, labels=None, title: str | None = None,
            log: bool = False):
    """Box + strip plot of a metric per configuration over a sweep's completed runs; ``by``: a column, a
    comma list (``"solver,gate_prob"``) or a list; axis names and units from the metric registry; ``log``:
    logarithmic y axis."""
    from slamcli.metrics.aggregate import compare_groups
    from slamcli.plots.figures import draw_compare

    return draw_compare(_ax(ax, fn="compare"), compare_groups(exp_dir, metric, by), labels=labels, title=title,
                        log=log)
