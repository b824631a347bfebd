"""``slamcli sweep``: expand an experiment file into runs and execute them (resumable, fail-soft, parallel)."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

from slamcli.cli.app import (
    app,
    check_output,
    choice,
    echo_stderr,
    fail,
    handle_errors,
    rich_progress,
    stderr_console,
    stderr_is_terminal,
    stdout_console,
)

#: the sweep executors (slamcli.sweep.runner.make_executor)
EXECUTORS = ("local", "dask")
#: the options of the commands that run sweeps (sweep, reproduce): where the runs go
ExecutorOption = Annotated[choice("Executor", EXECUTORS), typer.Option(
    "--executor", help="local: a process pool (spawn); dask: a Dask cluster (--scheduler).")]
SchedulerOption = Annotated[str | None, typer.Option(
    "--scheduler", help="Existing Dask scheduler (tcp://host:8786); default: a LocalCluster.")]


def _shipped_names() -> str:
    from slamcli import experiments

    return ", ".join(experiments.names()) or "none"


@app.command("sweep")
def sweep_command(
    experiment: Annotated[str | None, typer.Argument(
        help=f"Experiment: a shipped name ({_shipped_names()}; see --list) or a TOML file.", show_default=False)] = None,
    overrides: Annotated[list[str] | None, typer.Argument(
        help="Overrides key=value (fixed) or key=v1,v2 (a grid axis), validated like the file: "
             "solver.ekf.gate_prob=0.9,0.99 replicates=20 scenario.n_steps=200 data=mrclam7,loop; "
             "solver=ekf,graph keeps those [[solver]] labels, +solver=mine adds a registered solver.",
        show_default=False)] = None,
    list_names: Annotated[bool, typer.Option("--list", help="List the shipped experiments and exit.")] = False,
    workers: Annotated[int, typer.Option("--workers", "-j", help="Parallel workers (1 = in this process).")] = 1,
    executor: ExecutorOption = "local",
    scheduler: SchedulerOption = None,
    resume: Annotated[bool, typer.Option("--resume/--no-resume", help="Skip runs completed on disk.")] = True,
    dry_run: Annotated[bool, typer.Option("--dry-run", help="List the runs and what is done; run nothing.")] = False,
    quick: Annotated[bool, typer.Option("--quick", help="Apply the file's [quick] table (few seeds).")] = False,
    quiet: Annotated[bool, typer.Option("--quiet", "-q", help="No progress bar.")] = False,
    out: Annotated[Path, typer.Option("--out", "-o", help="Results root; runs go to OUT/<experiment>/.")] = Path(
        "results"
    ),
) -> None:
    """Run every configuration of an experiment: results/<experiment>/<run_id>/ + manifest.csv + results.csv."""
    from slamcli.sweep.threads import one_blas_thread  # before NumPy loads

    one_blas_thread()
    with handle_errors():
        from slamcli.sweep.config import apply_overrides, load_experiment, quick_variant
        from slamcli.sweep.expand import RegistryResolver, expand

        if list_names:
            _print_list()
            return
        if experiment is None:
            fail("give an experiment name or file (slamcli sweep --list shows the shipped ones)")
        if workers < 1:
            fail(f"--workers: must be >= 1, got {workers}")
        cfg = load_experiment(_experiment_file(experiment))
        if quick:
            cfg = quick_variant(cfg)
        if overrides:
            cfg = apply_overrides(cfg, overrides, RegistryResolver().known_keys)
        expansion = expand(cfg)
        for line in expansion.skipped:  # [sweep] absent = "skip": one line per recording left out
            echo_stderr(line)
        if dry_run:
            _print_dry_run(expansion, out)
            return
        check_output(out, folder=True, option="--out", inputs=[experiment])
        summary = _run(expansion, out, workers, str(executor), scheduler, resume, quiet)
        _print_summary(summary)
        if not summary.ok:
            raise typer.Exit(1)


def _experiment_file(arg: str) -> Path:
    """An existing file as given, else the shipped experiment of that name; one line naming both otherwise."""
    from slamcli import experiments
    from slamcli.errors import ConfigError

    p = Path(arg)
    if p.is_file():
        return p
    found = experiments.find(arg)
    if found is None:
        raise ConfigError(f"{arg}: no such experiment file, and not a shipped experiment ({_shipped_names()})")
    return found


def _print_list() -> None:
    import tomllib

    from slamcli import experiments

    for name in experiments.names():
        with open(experiments.path() / f"{name}.toml", "rb") as fh:
            desc = tomllib.load(fh).get("experiment", {}).get("description", "")
        typer.echo(f"{name:<16} {desc}")


def _run(expansion, out, workers, executor, scheduler, resume, quiet):
    from slamcli.sweep.runner import progress_lines, run_sweep

    if quiet or not stderr_is_terminal():  # off a terminal: plain lines a log can read
        return run_sweep(
            expansion, out, executor=executor, workers=workers, scheduler=scheduler, resume=resume,
            progress=None if quiet else progress_lines(f"sweep {expansion.experiment.name}", echo_stderr),
        )
    from rich.progress import TextColumn

    counts = TextColumn("[green]{task.fields[done]} done[/] [red]{task.fields[failed]} failed[/] "
                        "[dim]{task.fields[skipped]} skipped[/]")
    with rich_progress(counts) as prog:
        from rich.markup import escape

        task = prog.add_task(escape(f"sweep {expansion.experiment.name}"), total=len(expansion.runs),
                             done=0, failed=0, skipped=0)
        started = {"skipped": None}

        def update(c) -> None:
            if started["skipped"] is None:
                # skipped runs are not work: restart the ETA clock from what remains
                started["skipped"] = c.skipped
                prog.reset(task, total=c.total - c.skipped, done=0, failed=0, skipped=c.skipped)
            prog.update(task, completed=c.done + c.failed, done=c.done, failed=c.failed, skipped=c.skipped)

        return run_sweep(
            expansion, out, executor=executor, workers=workers, scheduler=scheduler, resume=resume,
            progress=update,
        )


def _print_dry_run(expansion, out) -> None:
    from rich.table import Table

    from slamcli.sweep.runner import run_status

    exp_dir = Path(out) / expansion.experiment.name
    table = Table(title=f"{expansion.experiment.name}: {len(expansion.runs)} runs, "
                        f"{len(expansion.datasets)} datasets → {exp_dir}")
    labelled = "data" not in expansion.axes  # the data column, unless it is a swept axis
    for col in ("run_id", "solver", "replicate", "dataset", *(["data"] if labelled else []), *expansion.axes,
                "on disk"):
        table.add_column(col)
    n_done = 0
    for r in expansion.runs:
        st = run_status(exp_dir, r.run_id)
        n_done += st == "completed"
        table.add_row(r.run_id, r.label, str(r.replicate), r.dataset.dataset_id,
                      *([r.dataset.label] if labelled else []), *[str(r.point.get(a, "—")) for a in expansion.axes],
                      st)
    con = stdout_console()
    con.print(table)
    con.print(f"{n_done} completed, {len(expansion.runs) - n_done} to run")


def _print_summary(summary) -> None:
    from rich.markup import escape
    from rich.table import Table

    c = summary.counts
    con = stderr_console()
    con.print(
        f"{summary.experiment}: {c.done} done, {c.failed} failed, {c.skipped} skipped of {c.total} "
        f"in {summary.wall_time_s:.1f} s → {escape(str(summary.exp_dir))}"
    )
    for name, path in summary.tables.items():
        con.print(f"  {name}: {escape(str(path))}")
    if summary.failures:
        t = Table(title=f"{len(summary.failures)} failed runs (traceback in <run_id>/status.json and run.log)")
        for col in ("run_id", "solver", "replicate", "error"):
            t.add_column(col)
        for f in summary.failures[:25]:
            t.add_row(f["run_id"], f["label"], str(f["replicate"]), escape(str(f.get("error") or "")))
        con.print(t)
        if len(summary.failures) > 25:
            con.print(f"... and {len(summary.failures) - 25} more (see manifest.csv)")
