"""``slamcli plot``: figures from result files (map, errors, nees, mapchange), PNG or PDF."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

from slamcli.cli.app import app, fail, handle_errors

KINDS = ("map", "errors", "nees", "mapchange")


@app.command("plot")
def plot_command(
    kind: Annotated[str, typer.Argument(help="map | errors | nees | mapchange")],
    results: Annotated[list[Path], typer.Argument(
        help="Result file(s): nees takes N Monte-Carlo runs, mapchange overlays several, map/errors take one.")],
    output: Annotated[Path, typer.Option("-o", "--output", help="Image file, .png or .pdf.")],
    data: Annotated[list[Path] | None, typer.Option(
        "--data", "-d", help="Dataset file per result (repeat); default: recorded in each result.")] = None,
    ellipses: Annotated[bool, typer.Option("--ellipses", help="map: draw 2σ covariance ellipses if stored.")] = False,
    pose_ellipse_every: Annotated[int, typer.Option(
        help="map: with --ellipses, a pose ellipse every K poses (0 = none).")] = 0,
    no_hash_check: Annotated[bool, typer.Option("--no-hash-check", help="Skip the dataset hash check.")] = False,
    title: Annotated[str | None, typer.Option(help="Figure title.")] = None,
) -> None:
    """Draw one publication figure; the image is written atomically."""
    with handle_errors():
        if kind not in KINDS:
            fail(f"unknown plot kind {kind!r}; choose one of {', '.join(KINDS)}")
        if output.suffix.lower() not in (".png", ".pdf"):
            fail(f"{output}: unsupported image format {output.suffix or '(none)'!r}; use .png or .pdf")
        if data and len(data) != len(results):
            fail(f"got {len(results)} result(s) but {len(data)} --data file(s); give one per result or none")
        if kind in ("map", "errors") and len(results) != 1:
            fail(f"plot {kind} takes exactly one result, got {len(results)}")
        from slamcli.plots import new_figure, save_figure

        fig, ax = new_figure(*((7.0, 6.0) if kind == "map" else (6.4, 4.4)))
        check = not no_hash_check
        data_paths = list(data) if data else [None] * len(results)
        if kind == "map":
            _map(ax, results[0], data_paths[0], check, ellipses, pose_ellipse_every, title)
        elif kind == "errors":
            _errors(ax, results[0], data_paths[0], check, title)
        elif kind == "mapchange":
            _mapchange(ax, results, title)
        else:
            _nees(ax, results, data_paths, check, title)
        save_figure(fig, output)
        typer.echo(f"wrote {output}")


def _map(ax, result_path, data_path, check, ellipses, every, title):
    from slamcli.api.evaluate import load_result_and_dataset
    from slamcli.plots.maps import plot_map

    # real recordings and imported graphs have no ground truth: then estimate and odometry only
    res, ds, data_path = load_result_and_dataset(result_path, data_path, check_hash=check, require_truth=False)
    truth = ds.truth
    if res.grids:  # occupancy map under the trajectory (paper 001 subfigures (c)/(d))
        from slamcli.plots.grids import draw_grid

        name = "frequentist" if "frequentist" in res.grids else next(iter(res.grids))
        draw_grid(ax, res.grids[name], label=f"occupancy ({name})")
    plot_map(ax, truth.landmarks_xy if truth else None, res.landmarks_xy, truth.poses_xyt[:, :2] if truth else None,
             ds.inputs.odometry_xyt[:, :2], res.poses_xyt[:, :2],
             landmark_cov=res.landmark_cov if ellipses else None, pose_cov=res.pose_cov if ellipses else None,
             ellipse_every=every, title=title or f"{res.solver}: {Path(result_path).name}",
             legend_note=None if truth else "No ground truth in dataset")
    if truth is None:
        typer.echo(f"note: {data_path} has no ground truth; drew the estimate and odometry only")


def _errors(ax, result_path, data_path, check, title):
    from slamcli.api.evaluate import load_result_and_dataset
    from slamcli.errors import SlamcliError
    from slamcli.metrics.landmarks import paper_error_per_iteration
    from slamcli.plots.curves import plot_error_curves

    res, ds, _ = load_result_and_dataset(result_path, data_path, check_hash=check)
    if res.trace is None or len(res.trace) == 0:
        raise SlamcliError(f"{result_path}: no iteration trace (solver {res.solver!r}); plot errors needs one")
    df = paper_error_per_iteration(res.trace, ds.truth.landmarks_xy)
    plot_error_curves(ax, df["iteration"], df["err_min_m"], df["err_mean_m"], df["err_max_m"],
                      title=title or f"{res.solver}: landmark error per iteration")


def _mapchange(ax, result_paths, title):
    import numpy as np

    from slamcli.errors import SlamcliError
    from slamcli.io import read_result
    from slamcli.metrics.landmarks import map_change
    from slamcli.plots.curves import plot_map_change

    for rp in result_paths:
        res = read_result(rp)
        tr = res.trace
        if tr is None or len(tr) < 2:
            raise SlamcliError(f"{rp}: no iteration trace with ≥ 2 iterations (solver {res.solver!r})")
        mc = [0.0] + [map_change(tr.landmarks_at(k - 1), tr.landmarks_at(k)) for k in range(1, len(tr))]
        label = f"{res.solver}: {Path(rp).name}" if len(result_paths) > 1 else None
        plot_map_change(ax, np.arange(len(tr)), np.asarray(mc), label=label)
    ax.set_title(title or "Map change between iterations")


def _nees(ax, result_paths, data_paths, check, title):
    import numpy as np

    from slamcli.api.evaluate import monte_carlo_nees_files
    from slamcli.errors import SlamcliError
    from slamcli.plots.curves import plot_nees

    a, why = monte_carlo_nees_files(result_paths, data_paths, check_hash=check)
    if a is None:
        raise SlamcliError(f"plot nees: {why}")
    plot_nees(ax, np.arange(len(a.anees)), a.anees, a.lower, a.upper, a.dof, a.n_runs, a.fraction_inside,
              title=title or f"Pose NEES over {a.n_runs} runs")
    n_finite = int(np.isfinite(a.anees).sum())
    typer.echo(f"average pose NEES {a.mean:.3f} (time mean, E = {a.dof}); {100 * a.fraction_inside:.1f}% of "
               f"{n_finite} steps inside the 95% band [{a.lower:.2f}, {a.upper:.2f}] for N = {a.n_runs} runs")
