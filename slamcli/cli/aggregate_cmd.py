"""``slamcli aggregate``: mean, std, 95 % CI and n per configuration of a finished sweep (like ``evo_res``)."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

from slamcli.cli.app import app, check_output, handle_errors, stdout_console


def _split(values: list[str] | None) -> list[str]:
    return [v.strip() for item in (values or []) for v in item.split(",") if v.strip()]


@app.command("aggregate")
def aggregate_command(
    exp_dir: Annotated[Path, typer.Argument(help="Sweep folder with results.csv, e.g. results/compare.")],
    by: Annotated[list[str] | None, typer.Option(
        "--by", help="Group by these columns (comma list or repeat; solver = label). "
                     "Default: label + every sweep axis.")] = None,
    metric: Annotated[list[str] | None, typer.Option(
        "--metric", "-m", help="Metric column(s) (comma list or repeat). Default: ATE, RPE, map, NEES, time.")] = None,
    out_dir: Annotated[Path | None, typer.Option(
        "-o", "--out-dir", help="Where aggregate.{csv,md,tex} go; default: the sweep folder.")] = None,
    confidence: Annotated[float, typer.Option(help="Confidence level of the t interval.")] = 0.95,
    quiet: Annotated[bool, typer.Option("--quiet", "-q", help="Print nothing; just write the files.")] = False,
) -> None:
    """Summarise completed runs per configuration: CSV (tidy), Markdown and LaTeX tables."""
    with handle_errors():
        from slamcli.errors import ConfigError

        if not 0 < confidence < 1:
            raise ConfigError(f"--confidence: must be in (0, 1), got {confidence}")
        from slamcli.metrics.aggregate import aggregate_dir, cell_text

        if out_dir is not None:
            check_output(out_dir, folder=True)
        try:
            a = aggregate_dir(exp_dir, _split(by), _split(metric), out_dir, confidence)
        except KeyError as exc:  # a results.csv that lacks a column every sweep writes
            raise ConfigError(f"{exp_dir / 'results.csv'}: not a slamcli results table (no column {exc})") from None
        if quiet:
            return
        from rich.table import Table

        # long form (configuration, metric, n, mean, std, CI) so that the table fits an 80-column terminal
        summary = a["summary"]
        by_cols = a["header"][: a["header"].index("n")]
        con = stdout_console()
        table = Table(title=f"{exp_dir.name}: {100 * confidence:g} % t confidence intervals", title_justify="left")
        table.add_column("configuration", overflow="fold", max_width=26)
        table.add_column("metric", overflow="fold", max_width=18)
        for col in ("n", "mean", "std", "CI low", "CI high"):
            table.add_column(col, justify="right")
        g = "{:.4g}".format
        for _, r in summary.iterrows():
            config = " ".join(cell_text(r[c]) if c == "label" else f"{c.rsplit('.', 1)[-1]}={cell_text(r[c])}"
                              for c in by_cols if cell_text(r[c]) != "—")
            table.add_row(config, r["metric"], str(r["n"]), *(g(r[k]) for k in ("mean", "std", "ci_low", "ci_high")))
        con.print(table)
        con.print(a["note"].split(". Cells")[0] + ".", markup=False, highlight=False)
        con.print(f"wrote {', '.join(str(p) for p in a['paths'].values())}", markup=False, highlight=False)
