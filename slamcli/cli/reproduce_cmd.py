"""``slamcli reproduce``: the paper's figures and ``REPORT.md`` from the experiments in ``experiments/``."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

from slamcli.cli.app import app, check_output, fail, handle_errors, stderr_console
from slamcli.cli.sweep_cmd import ExecutorOption, SchedulerOption


@app.command("reproduce")
def reproduce_command(
    out: Annotated[Path, typer.Option("--out", "-o", help="Output directory (REPORT.md, figures/, runs/).")] = Path(
        "results/reproduce"
    ),
    quick: Annotated[bool, typer.Option("--quick", help="Few seeds, short runs: a smoke check (< 3 min).")] = False,
    workers: Annotated[
        int | None, typer.Option("--workers", "-j", help="Parallel workers (default: 1 with --quick, else 2).")
    ] = None,
    experiments: Annotated[
        Path | None, typer.Option("--experiments", help="Directory of experiment files (default: the files shipped "
                                                         "in the package, slamcli/experiments; ./experiments only "
                                                         "when given here).")
    ] = None,
    section: Annotated[
        list[str] | None, typer.Option("--section", help="Run only this report section (repeatable), e.g. fig5.")
    ] = None,
    quiet: Annotated[bool, typer.Option("--quiet", "-q", help="No progress messages.")] = False,
    executor: ExecutorOption = "local",
    scheduler: SchedulerOption = None,
) -> None:
    """Run the paper experiments (Figs. 5, 6, 7, 9, post-processing, solver comparison, Monte-Carlo NEES) and
    write REPORT.md; exits 1 with a summary when any section fails."""
    from slamcli.sweep.threads import one_blas_thread  # before NumPy loads

    one_blas_thread()
    with handle_errors():
        from slamcli.reproduce.report import reproduce

        if workers is not None and workers < 1:
            fail(f"--workers: must be >= 1, got {workers}")
        if scheduler and str(executor) != "dask":
            fail("--scheduler: only meaningful with --executor dask")
        check_output(out, folder=True, option="--out", inputs=[experiments])
        con = stderr_console()
        if experiments is not None and not experiments.is_dir():
            fail(f"--experiments: {experiments} is not a directory")
        result = reproduce(
            out, quick=quick, workers=workers, experiments_dir=experiments,
            log=(lambda s: None) if quiet else (lambda s: con.print(s, markup=False)), only=section or None,
            executor=str(executor), scheduler=scheduler,
        )
        con.print(result.summary(), markup=False, soft_wrap=True)  # the count stays one line, the last
        if not result.ok:
            raise typer.Exit(1)
