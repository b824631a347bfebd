"""``slamcli plot``: figures from result files (map, errors, nees, mapchange, boxes) and sweeps (compare); PNG, PDF
or SVG."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

from slamcli.cli.app import app, check_output, fail, handle_errors

KINDS = ("map", "errors", "nees", "mapchange", "compare", "boxes")
_SIZES = {"map": (7.0, 6.0), "errors": (6.4, 4.4), "nees": (6.4, 4.4), "mapchange": (6.4, 4.4),
          "compare": (6.4, 4.4), "boxes": (7.0, 6.0)}


@app.command("plot")
def plot_command(
    kind: Annotated[str, typer.Argument(help="map | errors | nees | mapchange | compare | boxes")],
    results: Annotated[list[Path], typer.Argument(
        help="Result file(s): nees takes N Monte-Carlo runs, mapchange overlays several, map/errors take "
             "one; compare takes a sweep folder.")],
    output: Annotated[Path, typer.Option("-o", "--output", help="Image file: .png, .pdf or .svg.")],
    data: Annotated[list[Path] | None, typer.Option(
        "--data", "-d", help="Dataset file per result (repeat); default: recorded in each result.")] = None,
    ellipses: Annotated[bool, typer.Option("--ellipses", help="map: draw 2σ covariance ellipses if stored.")] = False,
    pose_ellipse_every: Annotated[int, typer.Option(
        help="map: with --ellipses, a pose ellipse every K poses (0 = none).")] = 0,
    sigma: Annotated[float, typer.Option(
        help="errors: half-width of the pose error band in σ (results with covariances).")] = 3.0,
    metric: Annotated[str, typer.Option(help="compare: metric column, e.g. ate_rmse.")] = "ate_rmse_m",
    by: Annotated[str, typer.Option(help="compare: group by this column (solver = label).")] = "solver",
    linear: Annotated[bool, typer.Option(
        "--linear", help="nees/mapchange: linear y axis instead of logarithmic.")] = False,
    dpi: Annotated[int, typer.Option(help="Raster resolution (PNG).")] = 200,
    size: Annotated[str | None, typer.Option(help="Figure size WIDTHxHEIGHT in inches, e.g. 3.5x2.6.")] = None,
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
        if data and len(data) != len(results):
            fail(f"got {len(results)} result(s) but {len(data)} --data file(s); give one per result or none")
        if kind in ("map", "errors", "compare", "boxes") and len(results) != 1:
            what = "sweep folder" if kind == "compare" else "result"
            fail(f"plot {kind} takes exactly one {what}, got {len(results)}")
        check_output(output)
        w, h = parse_size(size, _SIZES[kind])
        check = not no_hash_check
        data_paths = list(data) if data else [None] * len(results)
        echo = (lambda msg: None) if quiet else typer.echo
        if kind == "errors":
            fig = _errors(results[0], data_paths[0], check, title, (w, h), sigma, echo)
        else:
            fig, ax = new_figure(w, h)
            if kind == "map":
                _map(ax, results[0], data_paths[0], check, ellipses, pose_ellipse_every, title, echo)
            elif kind == "mapchange":
                _mapchange(ax, results, title, log=not linear)
            elif kind == "compare":
                _compare(ax, results[0], metric, by, title, echo)
            elif kind == "boxes":
                _boxes(ax, results[0], data_paths[0], check, hypothesis, title)
            else:
                _nees(ax, results, data_paths, check, title, echo, log=not linear)
        save_figure(fig, output, dpi=dpi)
        echo(f"wrote {output}")


def _map(ax, result_path, data_path, check, ellipses, every, title, echo=typer.echo):
    from slamcli.api.evaluate import load_result_and_dataset
    from slamcli.plots.figures import draw_map

    # real recordings and imported graphs have no ground truth: then estimate and odometry only
    res, ds, data_path = load_result_and_dataset(result_path, data_path, check_hash=check, require_truth=False)
    if res.grids:  # occupancy map under the trajectory (paper 001 subfigures (c)/(d))
        from slamcli.plots.grids import draw_grid

        name = "frequentist" if "frequentist" in res.grids else next(iter(res.grids))
        draw_grid(ax, res.grids[name], label=f"occupancy ({name})")
    draw_map(ax, res, ds, ellipses=ellipses, pose_ellipse_every=every,
             title=title or f"{res.solver}: {Path(result_path).name}")
    if ds.truth is None or ds.truth.position_reference_only:
        echo(f"note: {data_path} has no ground truth; drew the estimate and odometry only")


def _errors(result_path, data_path, check, title, size, n_sigma, echo):
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
    fig, axes = new_figure(size[0], max(size[1], 5.5), nrows=3, sharex=True)
    try:
        inside = draw_pose_errors(axes, res, ds, n_sigma, title)
    except ValueError as exc:
        raise SlamcliError(f"{result_path}: {exc}") from None
    if inside is not None:
        echo("steps inside ±{:g}σ: x {:.1f}%, y {:.1f}%, heading {:.1f}%".format(n_sigma, *(100 * inside)))
    else:
        echo(f"note: {result_path} stores no pose covariances; drew the error without σ bands")
    return fig


def _mapchange(ax, result_paths, title, log=True):
    from slamcli.errors import SlamcliError
    from slamcli.io import read_result
    from slamcli.plots.figures import draw_mapchange

    results = [read_result(rp) for rp in result_paths]
    labels = [f"{r.solver}: {Path(rp).name}" for r, rp in zip(results, result_paths)] if len(results) > 1 else None
    try:
        draw_mapchange(ax, results, labels, log=log, title=title)
    except ValueError as exc:
        bad = next(rp for rp, r in zip(result_paths, results) if r.trace is None or len(r.trace) < 2)
        raise SlamcliError(f"{bad}: {exc}") from None


def _nees(ax, result_paths, data_paths, check, title, echo, log=True):
    import numpy as np

    from slamcli.api.evaluate import monte_carlo_nees_files
    from slamcli.errors import SlamcliError
    from slamcli.plots.figures import draw_nees

    a, why = monte_carlo_nees_files(result_paths, data_paths, check_hash=check)
    if a is None:
        raise SlamcliError(f"plot nees: {why}")
    draw_nees(ax, a, log=log, title=title)
    n_finite = int(np.isfinite(a.anees).sum())
    echo(f"average pose NEES {a.mean:.3f} (time mean, E = {a.dof}) over N = {a.n_runs} runs;\n"
         f"{100 * a.fraction_inside:.1f}% of {n_finite} steps inside the 95% band [{a.lower:.2f}, {a.upper:.2f}]")


def _compare(ax, exp_dir, metric, by, title, echo):
    from slamcli.errors import SlamcliError
    from slamcli.metrics.aggregate import compare_groups
    from slamcli.plots.curves import plot_compare

    labels, values, metric_col, by_col, n_excluded = compare_groups(exp_dir, metric, by)
    if not labels or all(len(v) == 0 for v in values):
        raise SlamcliError(f"{exp_dir}: no completed run has a value of {metric_col!r}")
    plot_compare(ax, labels, values, metric_col, by_col, title=title or f"{Path(exp_dir).name}: {metric_col}")
    echo(f"{sum(len(v) for v in values)} runs in {len(labels)} groups; {n_excluded} failed run(s) excluded")


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
               title=title or f"{res.solver}: hypothesis {hypothesis} of {len(hb)} ({L} landmarks)")
