"""``slamcli solve``: run one registered solver on a dataset file and write a result file."""

from __future__ import annotations

import contextlib
from pathlib import Path

import typer

from slamcli.cli.app import (
    app,
    check_output,
    fail,
    handle_errors,
    iteration_count,
    one_line,
    printable,
    progress_bar,
    stdout_console,
)


@app.command("solve")
def solve_command(
    data: Path = typer.Argument(..., help="Dataset file (HDF5, schema slamcli.dataset v1)."),
    method: str = typer.Option(..., "--method", "-m", help="Registered solver name (see `slamcli solvers`)."),
    param: list[str] = typer.Option(
        None, "--param", "-p", help="Solver parameter override key=value (repeatable; see `slamcli solvers NAME`)."
    ),
    init: Path = typer.Option(None, "--init", help="Start from this result file (e.g. its association)."),
    seed: int = typer.Option(0, "--seed", help="Seed of the solver's random stream (particles, orderings)."),
    oracle_association: bool = typer.Option(
        False,
        "--oracle-association",
        help="Give the solver the TRUE association as reported ids (ground truth; recorded in the result).",
    ),
    quiet: bool = typer.Option(False, "--quiet", "-q", help="No progress bar and no summary."),
    out: Path = typer.Option(..., "-o", "--out", help="Result file to write (HDF5, written atomically)."),
    force: bool = typer.Option(False, "--force", help="Replace an existing -o that is not a slamcli result file."),
) -> None:
    """Solve DATA with --method and write the estimate (poses, landmarks, association, ...) to -o."""
    with handle_errors():
        from slamcli.api.solve import make_solver, solve_file

        if not 0 <= seed < 2**63:
            fail(f"--seed: must be in [0, 2^63), got {seed}")
        make_solver(method, list(param or []))  # validate method and params before reading data
        check_output(out, inputs=[data, init], kind="result", force=force)
        # The bar opens on the solver's first progress report, so input errors print only their one line.
        with contextlib.ExitStack() as stack:
            bar: list = []

            def progress(done: int, total: int) -> None:
                if not bar:
                    bar.append(stack.enter_context(progress_bar(f"solve {method}", quiet=quiet)))
                bar[0](done, total)

            result = solve_file(
                data,
                method,
                list(param or []),
                out,
                init_path=init,
                seed=seed,
                oracle_association=oracle_association,
                progress=progress,
            )
        failed = result.status.value == "failed"
        if quiet:
            if failed:  # -q drops the summary, never the reason for a non-zero exit
                reason = one_line(result.message) or "no reason given"
                typer.echo(f"error: {result.solver} failed: {reason}; the result in {printable(str(out))} records it",
                           err=True)
                raise typer.Exit(1)
            return
        n_assoc = int((result.assoc >= 0).sum())
        n_iter = iteration_count(result)  # the solver's count (the trace's row 0 is the initialisation)
        iters = f", {n_iter} iterations" if n_iter is not None else ""
        style = "red" if failed else "green"
        console = stdout_console()
        console.print(
            f"[{style}]{result.status.value}[/{style}] {result.solver} in {result.wall_time_s:.2f} s{iters}: "
            f"{len(result.landmarks_xy)} landmarks, {n_assoc}/{len(result.assoc)} obs. associated",
            highlight=False,
        )
        if oracle_association:
            console.print("  [yellow]oracle association[/yellow]: the true data association was used",
                          highlight=False)
        if result.message:
            console.print(f"  {printable(result.message)}", highlight=False, markup=False)
        console.print(f"  wrote {printable(str(out))}", highlight=False, markup=False, soft_wrap=True)
        if failed:  # the result file records why; the exit status says it to scripts
            raise typer.Exit(1)
