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
    force: Annotated[bool, typer.Option(
        "--force", help="Replace an existing -o that is a slamcli dataset or result (refused otherwise).")] = False,
) -> None:
    """Export poses (and landmarks) for evo, GTSAM, g2o or pandas.

    TUM lifts [x, y, θ] to SE(3) (z = 0, rotation about z); g2o carries the information matrices the solvers
    use (odometry exact, landmark sightings linearised to Cartesian; GTSAM's reader skips those, so for GTSAM
    use --format gtsam, whose BR sightings readG2o reads).
    """
    with handle_errors():
        from slamcli.api.interop import describe_export, export_file

        check_output(output, inputs=[src, data])
        _refuse_slamcli_file(output, force)
        s = export_file(src, str(fmt), output, data=data, check_hash=not no_hash_check)
        if not quiet:
            typer.echo(f"wrote {output} ({describe_export(s)})")
        if "warning" in s:
            typer.echo(f"warning: {s['warning']}", err=True)


def _refuse_slamcli_file(output: Path, force: bool) -> None:
    """An export is a text file of another tool: it replaces an earlier export, but never a slamcli dataset
    or result (the data it came from) unless ``--force`` (exit 2, as solve's and import's output guard)."""
    from slamcli.io.guard import OutputRefused, file_kind

    if force or not output.is_file() or output.stat().st_size == 0:
        return
    found = file_kind(output)
    if found is not None:
        raise OutputRefused(f"-o {output}: exists and is a slamcli {found}, not an export; --force replaces it")
