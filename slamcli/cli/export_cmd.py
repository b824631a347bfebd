"""``slamcli export``: a result's estimate or a dataset's ground truth as TUM / KITTI / g2o / CSV."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

from slamcli.cli.app import app, check_output, choice, handle_errors

#: the export formats (slamcli.io.export.FORMATS; the CLI does not import io to keep start-up light)
EXPORT_FORMATS = ("tum", "kitti", "g2o", "gtsam", "csv")


@app.command("export")
def export_command(
    src: Annotated[Path, typer.Argument(help="Result file (estimate) or dataset file (ground truth).")],
    fmt: Annotated[choice("ExportFormat", EXPORT_FORMATS), typer.Option(
        "--format", "-f", help="Output format (gtsam: GTSAM's text format, sightings as BR lines readG2o reads).")],
    output: Annotated[Path, typer.Option("-o", "--output", help="File to write (atomically).")],
    data: Annotated[Path | None, typer.Option(
        "--data", "-d", help="Dataset of a result; default: the one recorded in it.")] = None,
    no_hash_check: Annotated[bool, typer.Option("--no-hash-check", help="Skip the dataset hash check.")] = False,
    quiet: Annotated[bool, typer.Option("--quiet", "-q", help="Print nothing.")] = False,
) -> None:
    """Export poses (and landmarks) for evo, GTSAM, g2o or pandas.

    TUM lifts [x, y, θ] to SE(3) (z = 0, rotation about z); g2o carries the information matrices the solvers
    use (odometry exact, landmark sightings linearised to Cartesian; GTSAM's reader skips those, so for GTSAM
    use --format gtsam, whose BR sightings readG2o reads).
    """
    with handle_errors():
        from slamcli.api.interop import export_file

        check_output(output, inputs=[src, data])
        s = export_file(src, str(fmt), output, data=data, check_hash=not no_hash_check)
        if not quiet:
            edges = f", {s['n_edges']} edges" if "n_edges" in s else ""
            what = "estimate" if s["kind"] == "result" else "ground truth"
            typer.echo(f"wrote {output} ({s['format']}: {what}, {s['n_poses']} poses, "
                       f"{s['n_landmarks']} landmarks{edges})")
        if "warning" in s:
            typer.echo(f"warning: {s['warning']}", err=True)
