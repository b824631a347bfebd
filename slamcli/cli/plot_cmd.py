"""``slamcli plot``: figures from result files (map, errors, nees, mapchange, boxes) and sweeps (compare); PNG, PDF
or SVG."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

from slamcli.cli.app import app, check_output, fail, handle_errors

KINDS = ("map", "errors", "nees", "mapchange", "compare", "boxes")
#: default sizes (inches): one paper column wide (slamcli.plots.style.COLUMN_IN)
_SIZES = {"map": (3.5, 3.6), "errors": (3.5, 2.6), "nees": (3.5, 2.6), "mapchange": (3.5, 2.6),
          "compare": (3.5, 2.6), "boxes": (3.5, 3.6)}
#: the three stacked pose-error panels of `plot errors` need this height unless --size is given
_POSE_ERRORS_HEIGHT = 4.2


@app.command("plot")
def plot_command(
    kind: Annotated[str, typer.Argument(help="map | errors | nees | mapchange | compare | boxes")],
    results: Annotated[list[Path], typer.Argument(
        help="Result file(s): nees takes N Monte-Carlo runs, mapchange and map overlay several (map: results "
             "of one dataset, one colour each), errors takes one; compare takes a sweep folder.")],
    output: Annotated[Path, typer.Option("-o", "--output", help="Image file: .png, .pdf or .svg.")],
    data: Annotated[list[Path] | None, typer.Option(
        "--data", "-d", help="Dataset file per result (repeat); default: recorded in each result.")] = None,
    ellipses: Annotated[bool, typer.Option("--ellipses", help="map: draw 2σ covariance ellipses if stored.")] = False,
    pose_ellipse_every: Annotated[int, typer.Option(
        help="map: with --ellipses, a pose ellipse every K poses (0 = none).")] = 0,
    sigma: Annotated[float, typer.Option(
        help="errors: half-width of the pose error band in σ (results with covariances).")] = 3.0,
    metric: Annotated[str, typer.Option(help="compare: metric column, e.g. ate_rmse.")] = "ate_rmse_m",
    by: Annotated[str, typer.Option(
        help="compare: group by these columns, a comma list as in aggregate (solver = label), "
             "e.g. solver,gate_prob.")] = "solver",
    label: Annotated[list[str] | None, typer.Option(
        "--label", help="Legend name (repeat): one per result for mapchange and map, "
                        "of the curve for nees, one per group for compare. Default: solver names.")] = None,
    linear: Annotated[bool, typer.Option(
        "--linear", help="nees/mapchange: linear y axis instead of logarithmic.")] = False,
    log: Annotated[bool, typer.Option("--log", help="compare: logarithmic y axis.")] = False,
    dpi: Annotated[int, typer.Option(help="Raster resolution (PNG).")] = 200,
    size: Annotated[str | None, typer.Option(
        help="Figure size WIDTHxHEIGHT in inches, e.g. 3.5x2.6, or column (3.5x2.6) / page (7.16x3.2). "
             "Default: one column wide.")] = None,
    no_hash_check: Annotated[bool, typer.Option("--no-hash-check", help="Skip the dataset hash check.")] = False,
    title: Annotated[str | None, typer.Option(help="Figure title.")] = None,
    quiet: Annotated[bool, typer.Option("--quiet", "-q", help="Print nothing.")] = False,
    hypothesis: Annotated[int, typer.Option(help="boxes: which surviving hypothesis to draw (0 = first).")] = 0,
) -> None:
    """Draw one publication figure; the format follows the extension; written atomically."""
    with handle_errors():
        if kind not in KINDS:
            fail(f"unknown plot kind {kind!r}; choose one of {', '.join(KINDS)}")
        from slamcli.plots import check_format, new_figure, parse_size, save_figure

        check_format(output)
        if dpi <= 0:
            fail(f"--dpi: must be > 0, got {dpi}")
        if not sigma > 0:
            fail(f"--sigma: must be > 0, got {sigma}")
        if pose_ellipse_every < 0:
            fail(f"--pose-ellipse-every: must be >= 0 (0 = none), got {pose_ellipse_every}")
        if data and len(data) != len(results):
            fail(f"got {len(results)} result(s) but {len(data)} --data file(s); give one per result or none")
        if kind in ("errors", "compare", "boxes") and len(results) != 1:
            what = "sweep folder" if kind == "compare" else "result"
            fail(f"plot {kind} takes exactly one {what}, got {len(results)}")
        # a sweep folder (plot compare) is read through its results.csv: figures beside it may be re-drawn
        check_output(output, inputs=[*(r / "results.csv" if r.is_dir() else r for r in results), *(data or [])])
        w, h = parse_size(size, _SIZES[kind])
        _check_raster(w, h, dpi)
        _check_title(title)
        labels = _check_labels(kind, label, len(results))
        check = not no_hash_check
        data_paths = list(data) if data else [None] * len(results)
        echo = (lambda msg: None) if quiet else typer.echo
        if kind == "errors":
            fig = _errors(results[0], data_paths[0], check, title, (w, h), sigma, echo, sized=size is not None)
        else:
            fig, ax = new_figure(w, h)
            if kind == "map" and len(results) > 1:
                _overlay(ax, results, data_paths, check, title, echo, labels)
            elif kind == "map":
                _map(ax, results[0], data_paths[0], check, ellipses, pose_ellipse_every, title, echo,
                     label=labels[0] if labels else None)
            elif kind == "mapchange":
                _mapchange(ax, results, title, log=not linear, labels=labels)
            elif kind == "compare":
                _compare(ax, results[0], metric, by, title, echo, labels=labels, log=log)
            elif kind == "boxes":
                _boxes(ax, results[0], data_paths[0], check, hypothesis, title)
            else:
                _nees(ax, results, data_paths, check, title, echo, log=not linear,
                      label=labels[0] if labels else None)
        try:
            save_figure(fig, output, dpi=dpi)
        except MemoryError:  # the estimate passed, but this process may not have that much (RLIMIT_AS, ...)
            fail(f"--dpi {dpi}: a {round(w * dpi)}x{round(h * dpi)} pixel canvas does not fit in the memory this "
                 "process may use; use a smaller --dpi or --size")
        echo(f"wrote {output}")


#: matplotlib's Agg renderer refuses images of 2^16 pixels or more per side
MAX_PIXELS_PER_SIDE = 2**16
#: bytes per pixel of the Agg canvas (RGBA, 8 bits each)
RGBA_BYTES = 4


def _check_raster(width_in: float, height_in: float, dpi: int) -> None:
    """Refuse a ``--dpi`` whose canvas matplotlib cannot allocate (before any file is read)."""
    from slamcli.params import check_allocation

    px_w, px_h = round(width_in * dpi), round(height_in * dpi)
    if max(px_w, px_h) >= MAX_PIXELS_PER_SIDE:
        fail(f"--dpi {dpi}: a {width_in:g}x{height_in:g} in figure would be {px_w}x{px_h} pixels; matplotlib "
             f"draws at most {MAX_PIXELS_PER_SIDE - 1} per side")
    check_allocation("--dpi", dpi, float(px_w) * px_h * RGBA_BYTES, f"a {px_w}x{px_h} pixel canvas")


def _check_labels(kind: str, labels: list[str] | None, n_results: int) -> list[str] | None:
    """``--label`` values, checked against what the kind draws (one line on a mismatch)."""
    if not labels:
        return None
    for lab in labels:
        _check_title(lab, "--label")
    if kind in ("errors", "boxes"):
        fail(f"--label: plot {kind} has no legend name to set")
    overlay = kind == "mapchange" or kind == "map" and n_results > 1
    if overlay and len(labels) != n_results:
        fail(f"--label: got {len(labels)} label(s) for {n_results} result(s); give one per result")
    if kind in ("map", "nees") and not overlay and len(labels) != 1:
        fail(f"--label: plot {kind} draws one estimate; give one --label, got {len(labels)}")
    return labels


def _check_title(title: str | None, option: str = "--title") -> None:
    """Refuse a ``--title`` whose ``$...$`` part matplotlib's mathtext cannot parse (one line, not at save)."""
    if not title:
        return
    from matplotlib import cbook
    from matplotlib.mathtext import MathTextParser

    if not cbook.is_math_text(title):
        return
    try:
        MathTextParser("path").parse(title)
    except ValueError as exc:
        import re

        m = re.search(r"(found .*?)\s*\(at char (\d+)\)", str(exc))
        why = f"{m.group(1)} at character {m.group(2)}" if m else "parse error"
        fail(f"{option} {title!r}: not valid mathtext ({why}); escape a literal dollar sign as \\$")


def _map(ax, result_path, data_path, check, ellipses, every, title, echo=typer.echo, label=None):
    from slamcli.api.evaluate import load_result_and_dataset
    from slamcli.plots.figures import draw_map
    from slamcli.plots.grids import observed_corners_xy

    # real recordings and imported graphs have no ground truth: then estimate and odometry only
    res, ds, data_path = load_result_and_dataset(result_path, data_path, check_hash=check, require_truth=False)
    if res.grids:  # occupancy map under the trajectory (paper 001 subfigures (c)/(d))
        from slamcli.plots.grids import draw_grid

        name = "frequentist" if "frequentist" in res.grids else next(iter(res.grids))
        draw_grid(ax, res.grids[name], label=f"{name} grid", colorbar=True)  # short: the legend fits 2 columns
    extent = observed_corners_xy(res.grids[name]) if res.grids else None
    draw_map(ax, res, ds, ellipses=ellipses, pose_ellipse_every=every, title=title, label=label, extent_xy=extent)
    if ds.truth is None or ds.truth.position_reference_only:
        echo(f"note: {data_path} has no ground truth; drew the estimate and odometry only")
    if ellipses and res.landmark_cov is None and res.pose_cov is None:
        echo(f"note: {result_path} stores no covariances (solver {res.solver!r}); no ellipses drawn")


def _overlay(ax, result_paths, data_paths, check, title, echo, labels=None):
    """Several results of one dataset in one map; the dataset is the first result's (or the first --data)."""
    from slamcli.api.evaluate import load_result_and_dataset
    from slamcli.errors import SlamcliError
    from slamcli.io import read_result
    from slamcli.plots.figures import draw_overlay

    res0, ds, data_path = load_result_and_dataset(result_paths[0], data_paths[0], check_hash=check,
                                                  require_truth=False)
    results = [res0, *(read_result(rp) for rp in result_paths[1:])]
    for rp, r in zip(result_paths[1:], results[1:]):
        if len(r.poses_xyt) != ds.inputs.n_poses:
            raise SlamcliError(f"{rp}: {len(r.poses_xyt)} poses but {data_path} has {ds.inputs.n_poses}; "
                               "plot map overlays results of the same dataset")
    draw_overlay(ax, results, ds, labels, title=title)
    if ds.truth is None or ds.truth.position_reference_only:
        echo(f"note: {data_path} has no ground truth; drew the estimates and odometry only")


def _errors(result_path, data_path, check, title, size, n_sigma, echo, sized=False):
    """Landmark error per iteration for a result with an iteration trace (paper Figs 5e/f); otherwise the
    per-step pose error with ±nσ bands from the result's pose covariances (or without bands)."""
    from slamcli.api.evaluate import load_result_and_dataset
    from slamcli.errors import SlamcliError
    from slamcli.plots import new_figure
    from slamcli.plots.figures import draw_landmark_errors, draw_pose_errors

    res, ds, _ = load_result_and_dataset(result_path, data_path, check_hash=check)
    if res.trace is not None and len(res.trace) > 0:
        fig, ax = new_figure(*size)
        draw_landmark_errors(ax, res, ds, title)
        return fig
    fig, axes = new_figure(size[0], size[1] if sized else _POSE_ERRORS_HEIGHT, nrows=3, sharex=True)
    try:
        inside = draw_pose_errors(axes, res, ds, n_sigma, title)
    except ValueError as exc:
        raise SlamcliError(f"{result_path}: {exc}") from None
    if inside is not None:
        echo("steps inside ±{:g}σ: x {:.1f}%, y {:.1f}%, heading {:.1f}%".format(n_sigma, *(100 * inside)))
    else:
        echo(f"note: {result_path} stores no pose covariances; drew the error without σ bands")
    return fig


def _mapchange(ax, result_paths, title, log=True, labels=None):
    from slamcli.errors import SlamcliError
    from slamcli.io import read_result
    from slamcli.plots.figures import draw_mapchange

    results = [read_result(rp) for rp in result_paths]
    try:
        draw_mapchange(ax, results, labels, log=log, title=title)
    except ValueError as exc:
        bad = next(rp for rp, r in zip(result_paths, results) if r.trace is None or len(r.trace) < 2)
        raise SlamcliError(f"{bad}: {exc}") from None


def _nees(ax, result_paths, data_paths, check, title, echo, log=True, label=None):
    import numpy as np

    from slamcli.api.evaluate import monte_carlo_nees_files
    from slamcli.errors import SlamcliError
    from slamcli.plots.figures import draw_nees

    a, why = monte_carlo_nees_files(result_paths, data_paths, check_hash=check)
    if a is None:
        raise SlamcliError(f"plot nees: {why}")
    draw_nees(ax, a, log=log, title=title, label=label)
    n_finite = int(np.isfinite(a.anees).sum())
    echo(f"average pose NEES {a.mean:.3f} (time mean, E = {a.dof}) over N = {a.n_runs} runs;\n"
         f"{100 * a.fraction_inside:.1f}% of {n_finite} steps inside the 95% band [{a.lower:.2f}, {a.upper:.2f}]")


def _compare(ax, exp_dir, metric, by, title, echo, labels=None, log=False):
    import numpy as np

    from slamcli.errors import SlamcliError
    from slamcli.metrics.aggregate import compare_groups
    from slamcli.plots.figures import draw_compare

    g = compare_groups(exp_dir, metric, by)
    if not g.labels or all(len(v) == 0 for v in g.values):
        raise SlamcliError(f"{exp_dir}: no completed run has a value of {g.metric!r}")
    if labels and len(labels) != len(g.labels):
        raise SlamcliError(f"--label: got {len(labels)} label(s) for {len(g.labels)} group(s) "
                           f"({'; '.join(g.labels)}); give one per group")
    if log and any(np.any(np.asarray(v, float) <= 0) for v in g.values):
        raise SlamcliError(f"--log: {g.metric} has values <= 0, which a logarithmic axis cannot show")
    draw_compare(ax, g, labels=labels, title=title, log=log)
    echo(f"{sum(len(v) for v in g.values)} runs in {len(g.labels)} groups; {g.n_excluded} failed run(s) excluded")


def _boxes(ax, result_path, data_path, check, hypothesis, title):
    from slamcli.api.evaluate import load_result_and_dataset
    from slamcli.errors import SlamcliError
    from slamcli.plots.boxes import plot_boxes

    res, ds, _ = load_result_and_dataset(result_path, data_path, check_hash=check, require_truth=False)
    hb = res.hypotheses
    if hb is None or len(hb) == 0:
        raise SlamcliError(f"{result_path}: no hypotheses group (solver {res.solver!r}); plot boxes needs a "
                           "set-membership result such as cuik")
    if not 0 <= hypothesis < len(hb):
        raise SlamcliError(f"--hypothesis {hypothesis}: the result has {len(hb)} hypotheses (0..{len(hb) - 1})")
    L = int(hb.n_landmarks[hypothesis])
    truth = ds.truth
    plot_boxes(ax, hb.pose_lo[hypothesis], hb.pose_hi[hypothesis], hb.landmark_lo[hypothesis, :L],
               hb.landmark_hi[hypothesis, :L], truth.poses_xyt if truth else None,
               truth.landmarks_xy if truth else None,
               title=title or f"{res.solver}: hypothesis {hypothesis + 1} of {len(hb)}")
