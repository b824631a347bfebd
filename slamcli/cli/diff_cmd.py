"""``slamcli diff``: are two dataset/result files the same, apart from their timings?"""

from __future__ import annotations

from pathlib import Path

import typer

from slamcli.cli.app import app, handle_errors, printable


@app.command("diff")
def diff_command(
    a: Path = typer.Argument(..., help="First dataset or result file (HDF5)."),
    b: Path = typer.Argument(..., help="Second dataset or result file (HDF5)."),
    paths: bool = typer.Option(False, "--paths", help="Also compare recorded file paths (@dataset_path, "
                               "source_dir, ...), which are skipped by default."),
) -> None:
    """Compare two files field by field, ignoring creation time, timings (docs/schema.md "Timings") and, unless
    --paths, the recorded file paths (where the inputs were, not what they hold).

    Exit status 0 when they agree, 1 when any field differs (one summary line naming the first differences),
    2 when a file cannot be read.
    """
    with handle_errors(exit_code=2):
        from slamcli.io.diff import diff_files

        d = diff_files(a, b, paths=paths)
    typer.echo(printable(d.summary(str(a), str(b))))
    raise typer.Exit(0 if d.same else 1)
