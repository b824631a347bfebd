"""``slamcli import trajectory``: another estimator's TUM/KITTI trajectory → a slamcli result file."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

from slamcli.cli.app import check_output, choice, handle_errors
from slamcli.cli.import_cmd import import_app


@import_app.command("trajectory")
def import_trajectory_command(
    path: Annotated[Path, typer.Argument(help="Trajectory file: TUM (t x y z qx qy qz qw) or KITTI (3x4).")],
    data: Annotated[Path, typer.Option("--data", "-d", help="Dataset the trajectory was estimated on.")],
    output: Annotated[Path, typer.Option("-o", "--output", help="Result file to write (atomically).")],
    fmt: Annotated[choice("TrajectoryFormat", ("tum", "kitti", "auto")), typer.Option(
        "--format", "-f", help="File format; auto: by extension / column count.")] = "auto",
    times: Annotated[Path | None, typer.Option(help="KITTI: times.txt, one stamp per pose.")] = None,
    time_offset: Annotated[float, typer.Option(help="Seconds added to the file's stamps.")] = 0.0,
    extrapolate: Annotated[choice("Extrapolate", ("error", "hold")), typer.Option(
        help="Dataset stamps outside the file's span: error, or hold the end pose.")] = "error",
    name: Annotated[str | None, typer.Option(help="Solver name to record (default imported:<format>).")] = None,
    quiet: Annotated[bool, typer.Option("--quiet", "-q", help="Print nothing.")] = False,
    force: Annotated[bool, typer.Option("--force", help="Replace an existing -o that is not a slamcli result.")] = False,
) -> None:
    """Import another estimator's TUM/KITTI trajectory as a result.

    The trajectory is matched to the dataset's time stamps (interpolated between samples); the result file
    can then be evaluated, plotted and used in sweeps like any slamcli result."""
    with handle_errors():
        from slamcli.api.interop import import_trajectory_file

        check_output(output, inputs=[path, data, times], kind="result", force=force)
        r = import_trajectory_file(path, data, output, fmt=str(fmt), times=times, time_offset=time_offset,
                                   extrapolate=str(extrapolate), name=name)
        if not quiet:
            typer.echo(f"{r.solver} from {path.name}: {r.message}\n  wrote {output}")
