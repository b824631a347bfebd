"""``slamcli aggregate``: mean, std, 95 % CI and n per configuration of a finished sweep (like ``evo_res``), or
its leaderboard over the datasets (``--leaderboard``)."""

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
    baseline: Annotated[str | None, typer.Option(
        help="Paired differences against this configuration only (as printed, e.g. 'ekf, gate_prob=0.9'; "
             "with --leaderboard a solver configuration, e.g. 'odometry'); default: every pair.")] = None,
    leaderboard: Annotated[bool, typer.Option(
        "--leaderboard", help="One row per solver configuration, one column group per dataset (ATE vs its "
                              "reference, landmark RMSE, solve time), paired differences against --baseline: "
                              "leaderboard.{csv,md,tex}.")] = False,
    quiet: Annotated[bool, typer.Option("--quiet", "-q", help="Print nothing; just write the files.")] = False,
) -> None:
    """Summarise completed runs per configuration, and paired differences between configurations on the same
    datasets: CSV (tidy), Markdown and LaTeX (siunitx) tables; or a leaderboard of the solvers over the
    datasets (--leaderboard)."""
    with handle_errors():
        from slamcli.errors import ConfigError

        if not 0 < confidence < 1:
            raise ConfigError(f"--confidence: must be in (0, 1), got {confidence}")
        if leaderboard:
            if by or metric:
                raise ConfigError("--leaderboard: its rows are the solver configurations and its metrics fixed; "
                                  "drop --by/--metric")
            _leaderboard(exp_dir, out_dir, confidence, baseline, quiet)
            return
        from slamcli.metrics.aggregate import aggregate_dir

        check_output(out_dir if out_dir is not None else exp_dir, folder=True,
                     inputs=[exp_dir / "results.csv"])
        try:
            a = aggregate_dir(exp_dir, _split(by), _split(metric), out_dir, confidence, baseline)
        except KeyError as exc:  # a results.csv that lacks a column every sweep writes
            raise ConfigError(f"{exp_dir / 'results.csv'}: not a slamcli results table (no column {exc})") from None
        if not quiet:
            _print(a, exp_dir.name, confidence)


def _leaderboard(exp_dir: Path, out_dir: Path | None, confidence: float, baseline: str | None,
                 quiet: bool) -> None:
    """Write the leaderboard files and print its Markdown table."""
    from slamcli.errors import ConfigError
    from slamcli.metrics.aggregate import leaderboard_dir

    check_output(out_dir if out_dir is not None else exp_dir, folder=True, inputs=[exp_dir / "results.csv"])
    try:
        a = leaderboard_dir(exp_dir, baseline, out_dir, confidence)
    except KeyError as exc:
        raise ConfigError(f"{exp_dir / 'results.csv'}: not a slamcli results table (no column {exc})") from None
    if not quiet:
        typer.echo(a["markdown"], nl=False)
        typer.echo(f"wrote {', '.join(str(p) for p in a['paths'].values())}")


def _table(title: str, columns: list[tuple[str, str]]):
    """A rich table whose headers never wrap (each column at least as wide as its header); long cells fold."""
    from rich.table import Table

    table = Table(title=title, title_justify="left")
    for name, justify in columns:
        fold = justify == "fold"
        table.add_column(name, justify="left" if fold else justify, min_width=len(name), no_wrap=not fold,
                         overflow="fold" if fold else "ellipsis")
    return table


def _print(a: dict, name: str, confidence: float) -> None:
    """Long-form summary (configuration, metric, n, mean, std, CI) and the paired differences of the first
    metric: both fit a 100-column terminal without wrapping a header."""
    from slamcli.metrics.aggregate import (
        FLAG_CLIPPED,
        FLAG_FEW,
        config_label,
        decimals,
        p_text,
    )
    from slamcli.metrics.registry import metric_label

    summary, con = a["summary"], stdout_console()
    by_cols = [c for c in summary.columns if c not in ("metric", "n", "mean", "std", "ci_low", "ci_high",
                                                       "ci_clipped", "few")]
    ci = f"{100 * confidence:g} % CI"
    table = _table(f"{name}: mean, std and {ci} (t)", [("configuration", "fold"), ("metric", "fold"),
                                                          ("n", "right"), ("mean", "right"), ("std", "right"),
                                                          (ci, "right")])
    for m, g in summary.groupby("metric", sort=False):
        d = decimals((g["ci_high"] - g["mean"]).tolist(), g["mean"].tolist())
        for _, r in g.iterrows():
            flags = (FLAG_CLIPPED if r["ci_clipped"] else "") + (FLAG_FEW if r["few"] else "")
            cell = "—" if r["ci_low"] != r["ci_low"] else f"[{r['ci_low']:.{d}f}, {r['ci_high']:.{d}f}]"
            table.add_row(config_label([r[c] for c in by_cols], by_cols), metric_label(m), str(r["n"]),
                          _num(r["mean"], d), _num(r["std"], d), cell + flags)
    con.print(table)
    pairs = a["paired"]
    if len(pairs):
        first = pairs["metric"].iloc[0]
        sub = pairs[pairs["metric"] == first]
        d = decimals((sub["ci_high"] - sub["mean_diff"]).tolist(), sub["mean_diff"].tolist())
        pt = _table(f"paired differences A − B, {metric_label(first)} (all metrics: paired.csv)",
                    [("A", "fold"), ("B", "fold"), ("n", "right"), ("mean diff", "right"), (ci, "right"),
                     ("p (t)", "right"), ("p (Wilcoxon)", "right")])
        for _, r in sub.iterrows():
            cell = "—" if r["ci_low"] != r["ci_low"] else f"[{r['ci_low']:.{d}f}, {r['ci_high']:.{d}f}]"
            pt.add_row(r["a"], r["b"], str(r["n"]), _num(r["mean_diff"], d), cell + (FLAG_FEW if r["few"] else ""),
                       p_text(r["p_t"]), p_text(r["p_wilcoxon"]))
        con.print(pt)
    for line in (a["note"].split(". Cells")[0] + ".", a["note"].split(". ", 1)[1].split(". ", 1)[1]):
        con.print(line, markup=False, highlight=False)
    if a["unpaired"]:
        con.print(f"not paired (several runs per dataset): {', '.join(a['unpaired'])}", markup=False,
                  highlight=False)
    con.print(f"wrote {', '.join(str(p) for p in a['paths'].values())}", markup=False, highlight=False)


def _num(v: float, d: int) -> str:
    return "—" if v != v else f"{v:.{d}f}"
