"""Summaries of a finished sweep, like ``evo_res``: mean, standard deviation, 95 % confidence interval and n
per configuration, over completed runs only.

For the ``n`` non-NaN values ``x_1..x_n`` of one metric in one configuration::

    mean  x̄ = (1/n) Σ x_i,   std  s = sqrt( Σ (x_i − x̄)² / (n − 1) ),   CI  x̄ ± t_{0.975, n−1} · s / √n

A lower CI end below 0 of a nonnegative metric is clipped and flagged (``ci_clipped``); n < 3 is flagged
(``few``; with 2 runs the interval is ± 12.7 standard errors).

**Paired differences** (:func:`paired`): configurations A and B compared on the datasets both solved (matched
on ``dataset_id``, else on ``replicate`` and the scenario axes), ``d_i = a_i − b_i``: mean, std and CI of
``d``, the paired t test (``scipy.stats.ttest_rel``) and the Wilcoxon signed-rank test
(``scipy.stats.wilcoxon``, exact for small n).

**Leaderboard** (:func:`leaderboard`, :func:`leaderboard_dir`): one row per solver configuration; per dataset
the ATE against its reference, the matched landmark RMSE and the solve time, each with its paired difference
against a baseline configuration.

Column types are kept (:func:`typed_frame`, :func:`read_table`): an integer sweep parameter that some
solvers lack is a nullable ``Int64`` column, never ``10.0``.
"""

from __future__ import annotations

import difflib
import re
from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from slamcli.errors import ConfigError

#: metrics summarised when none are asked for (those present in the table)
DEFAULT_METRICS = ("ate_rmse_m", "aligned_ate_rmse_m", "heading_rmse_rad", "rpe_trans_rmse_m",
                   "lm_rmse_matched_m", "lm_ospa_m", "paper_err_mean_m", "pose_nees_mean", "solve_time_s")
#: what ``--by solver`` means
BY_ALIASES = {"solver": "label"}
_INT_RE = re.compile(r"^[+-]?\d+$")


def typed_frame(rows: Sequence[dict[str, Any]]):
    """DataFrame of dict rows whose columns keep the Python type of their values: all ``int`` (bools
    excluded) → nullable ``Int64``, all ``bool`` → ``boolean``; missing cells are ``<NA>``. Other columns
    as pandas infers them."""
    import pandas as pd

    rows = list(rows)
    df = pd.DataFrame(rows)
    for col in df.columns:
        # the Python values as given (pandas has already turned ints with gaps into floats)
        vals = [r[col] for r in rows if r.get(col) is not None and not (isinstance(r[col], float) and r[col] != r[col])]
        if not vals:
            continue
        if all(isinstance(v, bool) for v in vals):
            df[col] = pd.array([r.get(col) for r in rows], dtype="boolean")
        elif all(isinstance(v, int) and not isinstance(v, bool) for v in vals):
            df[col] = pd.array([r.get(col) for r in rows], dtype="Int64")
    return df


def read_table(exp_dir: str | Path):
    """The tidy results table of a sweep with column types restored from the CSV text: a column whose
    non-empty cells are all integers (``10``, not ``10.0``) becomes ``Int64``; ``True``/``False`` columns
    ``boolean``; other numeric columns ``float64``; the rest stay strings."""
    import pandas as pd

    path = Path(exp_dir) / "results.csv"
    if not path.is_file():
        raise ConfigError(f"{exp_dir}: no results.csv (run `slamcli sweep` first)")
    try:
        raw = pd.read_csv(path, dtype=str, keep_default_na=False)
    except (pd.errors.ParserError, pd.errors.EmptyDataError, UnicodeDecodeError) as exc:
        raise ConfigError(f"{path}: cannot read the results table ({str(exc).splitlines()[0]})") from None
    out = {}
    for col in raw.columns:
        s = raw[col]
        cells = s[s != ""]
        if len(cells) and cells.str.match(_INT_RE).all():
            out[col] = pd.to_numeric(s.replace("", None)).astype("Int64")
        elif len(cells) and cells.isin(["True", "False"]).all():
            out[col] = s.map({"True": True, "False": False, "": None}).astype("boolean")
        else:
            num = pd.to_numeric(cells, errors="coerce")
            if len(cells) and num.notna().all():
                out[col] = pd.to_numeric(s.replace("", None), errors="coerce").astype(float)
            else:
                out[col] = s.replace("", None)
    return pd.DataFrame(out)


def resolve_column(name: str, columns: Iterable[str], what: str = "column") -> str:
    """``name`` as a column: exact, an alias (``solver`` → ``label``), a unique column ending in ``.name``
    (``gate_prob`` → ``solver.ekf.gate_prob``) or a unique ``name_*`` metric (``ate_rmse`` →
    ``ate_rmse_m``); otherwise a one-line :class:`ConfigError` with a "did you mean"."""
    cols = list(columns)
    name = BY_ALIASES.get(name, name)
    if name in cols:
        return name
    for cands in ([c for c in cols if c.endswith("." + name)], [c for c in cols if c.startswith(name + "_")]):
        if len(cands) == 1:
            return cands[0]
        if len(cands) > 1:
            raise ConfigError(f"{what} {name!r} is ambiguous: {', '.join(cands)}")
    close = difflib.get_close_matches(name, cols, n=3, cutoff=0.6)
    hint = f"; did you mean {' or '.join(repr(c) for c in close)}?" if close else ""
    raise ConfigError(f"unknown {what} {name!r}{hint}")


def sweep_axes(df) -> list[str]:
    """Columns that are sweep axes (``scenario.*``, ``solver.<label>.*``, ``evaluate.*``)."""
    return [c for c in df.columns if c.startswith(("scenario.", "solver.", "evaluate."))]


def completed(df):
    """``(completed runs, number of failed/unfinished runs excluded)``."""
    ok = df["status"] == "completed" if "status" in df.columns else df.index == df.index
    return df[ok], int((~ok).sum())


#: fewer runs than this are flagged: the t interval is then too wide (n = 2: ± 12.7 standard errors) or absent
FEW_RUNS = 3
SUMMARY_COLUMNS = ("n", "mean", "std", "ci_low", "ci_high", "ci_clipped", "few")


def summarise(values, confidence: float = 0.95, nonnegative: bool = False) -> dict[str, Any]:
    """``n, mean, std, ci_low, ci_high, ci_clipped, few`` of the finite values (module docstring formulas);
    ``nonnegative``: a lower end below 0 becomes 0 and ``ci_clipped`` is True. ``few``: n < :data:`FEW_RUNS`."""
    import numpy as np
    from scipy import stats

    x = np.asarray(values, float)
    x = x[np.isfinite(x)]
    n = int(x.size)
    nan = float("nan")
    out = {"n": n, "mean": float(x.mean()) if n else nan, "std": nan, "ci_low": nan, "ci_high": nan,
           "ci_clipped": False, "few": n < FEW_RUNS}
    if n < 2:
        return out
    std = float(x.std(ddof=1))
    half = float(stats.t.ppf(0.5 + confidence / 2, n - 1)) * std / np.sqrt(n)
    out.update(std=std, ci_low=out["mean"] - half, ci_high=out["mean"] + half)
    if nonnegative and out["ci_low"] < 0:
        out.update(ci_low=0.0, ci_clipped=True)
    return out


def _columns(df, by, metrics) -> tuple[list[str], list[str]]:
    """Grouping and metric columns (resolved; default ``label``, ``data`` when the runs used several datasets,
    the sweep axes, and :data:`DEFAULT_METRICS`)."""
    import pandas as pd

    several = "data" in df.columns and df["data"].nunique(dropna=False) > 1
    by_cols = [resolve_column(b, df.columns, "--by column") for b in by] if by else \
        ["label", *(["data"] if several else []), *(a for a in sweep_axes(df) if a != "data")]
    if metrics:
        metric_cols = [resolve_column(m, df.columns, "metric") for m in metrics]
    else:  # a default metric no run recorded (e.g. NEES of solvers without covariances) is left out
        metric_cols = [m for m in DEFAULT_METRICS if m in df.columns and df[m].notna().any()]
    for m in metric_cols:
        if df[m].isna().all():
            continue  # an empty column of any dtype: its summary is n = 0
        if not pd.api.types.is_numeric_dtype(df[m]) or pd.api.types.is_bool_dtype(df[m]):
            raise ConfigError(f"metric {m!r} is not numeric")
    return by_cols, metric_cols


def aggregate(df, by: Sequence[str] | None = None, metrics: Sequence[str] | None = None,
              confidence: float = 0.95):
    """Tidy summary: one row per (configuration, metric) with ``n, mean, std, ci_low, ci_high, ci_clipped,
    few`` (:func:`summarise`).

    Parameters
    ----------
    df : the sweep's results table (:func:`read_table`); failed runs must already be removed.
    by : grouping columns (names resolved by :func:`resolve_column`); default ``label`` + every sweep axis.
    metrics : metric columns; default the :data:`DEFAULT_METRICS` present in ``df``.

    Returns
    -------
    (DataFrame, by_columns, metric_columns)   group keys keep their dtypes (``Int64`` stays ``Int64``).
    """
    import pandas as pd

    from slamcli.metrics.registry import metric_info

    by_cols, metric_cols = _columns(df, by, metrics)
    rows = []
    for keys, g in df.groupby(by_cols, dropna=False, sort=True):
        keys = keys if isinstance(keys, tuple) else (keys,)
        for m in metric_cols:
            rows.append({**dict(zip(by_cols, keys)), "metric": m,
                         **summarise(g[m].astype(float).to_numpy(), confidence, metric_info(m).nonnegative)})
    out = pd.DataFrame(rows, columns=[*by_cols, "metric", *SUMMARY_COLUMNS])
    for c in by_cols:  # groupby hands back plain objects; restore each key column's dtype
        out[c] = out[c].astype(df[c].dtype)
    out["n"] = out["n"].astype("Int64")
    return out, by_cols, metric_cols


def cell_text(v) -> str:
    import pandas as pd

    return "—" if v is None or v is pd.NA or (isinstance(v, float) and v != v) else str(v)


# ------------------------------------------------------------------------------------------ paired differences
def dataset_key(df, by_cols: Sequence[str]) -> list[str]:
    """Columns that identify the dataset a run solved: ``dataset_id`` (written by every sweep), else
    ``replicate`` and the scenario axes that are not grouping columns."""
    if "dataset_id" in df.columns:
        return ["dataset_id"]
    if "replicate" not in df.columns:
        raise ConfigError("paired differences need a dataset_id or replicate column")
    return ["replicate", *(c for c in df.columns if c.startswith("scenario.") and c not in by_cols)]


#: paired differences whose standard deviation is below this fraction of their largest magnitude are equal
#: up to round-off (0.1 + 0.9 vs 0.1 + 0.99 ...): the t statistic is then undefined, not 10^15
EQUAL_DIFFS_RTOL = 1e-12
PAIRED_COLUMNS = ("n", "mean_diff", "std_diff", "ci_low", "ci_high", "t", "p_t", "w", "p_wilcoxon", "few")


def paired_stats(a, b, confidence: float = 0.95) -> dict[str, Any]:
    """Paired comparison of ``a`` and ``b`` (same length; element i of both solved the same dataset) over
    the pairs where both are finite (module docstring formulas). NaN where undefined: t and its p when all
    differences are equal (s_d = 0 up to :data:`EQUAL_DIFFS_RTOL`), W and its p when every difference is 0,
    CI for n < 2."""
    import warnings

    import numpy as np
    from scipy import stats

    a, b = np.asarray(a, float), np.asarray(b, float)
    ok = np.isfinite(a) & np.isfinite(b)
    a, b = a[ok], b[ok]
    d = a - b
    n = int(d.size)
    nan = float("nan")
    out = dict.fromkeys(PAIRED_COLUMNS, nan)
    out.update(n=n, few=n < FEW_RUNS, mean_diff=float(d.mean()) if n else nan)
    if n < 2:
        return out
    sd = float(d.std(ddof=1))
    half = float(stats.t.ppf(0.5 + confidence / 2, n - 1)) * sd / np.sqrt(n)
    out.update(std_diff=sd, ci_low=out["mean_diff"] - half, ci_high=out["mean_diff"] + half)
    if sd > EQUAL_DIFFS_RTOL * float(np.abs(d).max()):
        res = stats.ttest_rel(a, b)
        out.update(t=float(res.statistic), p_t=float(res.pvalue))
    if np.any(d != 0):
        with warnings.catch_warnings():  # "sample size too small for normal approximation" at tiny n
            warnings.simplefilter("ignore")
            res = stats.wilcoxon(a, b)
        out.update(w=float(res.statistic), p_wilcoxon=float(res.pvalue))
    return out


def paired(df, by_cols: Sequence[str], metric_cols: Sequence[str], confidence: float = 0.95,
           baseline: str | None = None):
    """Paired differences between configurations on the datasets both solved (:func:`paired_stats` per
    metric): every pair of configurations in table order, or each against ``baseline`` (a configuration
    label as :func:`config_label` writes it). A configuration with several runs of one dataset (a swept axis
    not among ``by_cols``) has no pairing and is listed in the second return value.

    Returns ``(DataFrame with columns a, b, metric, *PAIRED_COLUMNS; labels left out)``; differences are a − b.
    """
    import pandas as pd

    key = dataset_key(df, by_cols)
    configs, unpaired = [], []
    for keys, g in df.groupby(list(by_cols), dropna=False, sort=True):
        label = config_label(keys if isinstance(keys, tuple) else (keys,), by_cols)
        if g.duplicated(key).any():
            unpaired.append(label)
        else:
            configs.append((label, g.set_index(key)))
    names = [c[0] for c in configs]
    if baseline is not None and baseline not in names:
        raise ConfigError(f"--baseline {baseline!r} is not a configuration; choose one of {', '.join(names)}")
    if baseline is None:
        pairs = [(configs[i], configs[j]) for i in range(len(configs)) for j in range(i + 1, len(configs))]
    else:
        base = configs[names.index(baseline)]
        pairs = [(c, base) for c in configs if c[0] != baseline]
    rows = []
    for (la, ga), (lb, gb) in pairs:
        common = ga.index.intersection(gb.index)
        if not len(common):
            continue
        for m in metric_cols:
            rows.append({"a": la, "b": lb, "metric": m, **paired_stats(
                ga.loc[common, m].astype(float).to_numpy(), gb.loc[common, m].astype(float).to_numpy(),
                confidence)})
    return pd.DataFrame(rows, columns=["a", "b", "metric", *PAIRED_COLUMNS]), unpaired


# ---------------------------------------------------------------------------------------------------- tables
#: flags on a table cell: lower interval end clipped at 0; fewer than FEW_RUNS runs
FLAG_CLIPPED, FLAG_FEW = "*", "†"


def decimals(half_widths, means) -> int:
    """One precision per table column: the smallest CI half-width to two significant digits (means to the
    same decimals); without intervals, three significant digits of the smallest non-zero |mean|; 0-6."""
    import math

    hw = [abs(float(h)) for h in half_widths if h is not None and math.isfinite(float(h)) and float(h) > 0]
    if hw:
        d = 1 - math.floor(math.log10(min(hw)))
    else:
        ms = [abs(float(m)) for m in means if m is not None and math.isfinite(float(m)) and float(m) != 0]
        d = 2 - math.floor(math.log10(min(ms))) if ms else 0
    return max(0, min(6, d))


def _half(mean: float, hi: float) -> float:
    return hi - mean  # the upper end is never clipped, so it gives the t half-width


def format_cell(mean: float, hi: float, d: int, clipped: bool = False, few: bool = False,
                tex: bool = False) -> str:
    r"""``mean ± half-width`` at ``d`` decimals with its flags; ``tex``: siunitx ``\num{m \pm h}``."""
    if mean != mean:
        return "--" if tex else "—"
    half = _half(mean, hi)
    num = f"{mean:.{d}f}" + (f" \\pm {half:.{d}f}" if tex and half == half else
                             f" ± {half:.{d}f}" if half == half else "")
    flags = (FLAG_CLIPPED if clipped else "") + (FLAG_FEW if few else "")
    if tex:
        sup = "".join({"*": "*", "†": r"\dagger"}[f] for f in flags)
        return f"\\num{{{num}}}" + (f"$^{{{sup}}}$" if sup else "")
    return num + flags


def _flag(row, key: str) -> bool:
    v = row.get(key, False)
    return bool(v) if v is not None and v == v else False


def wide(summary, by_cols: Sequence[str], metric_cols: Sequence[str], tex: bool = False):
    """Header and rows of a display table: configuration, n, then ``mean ± CI half-width`` per metric, one
    precision per metric column (:func:`decimals`), names and units from the metric registry."""
    from slamcli.metrics.registry import column_label, metric_info, tex_escape

    label = (lambda c: tex_escape(column_label(c))) if tex else column_label
    header = [*(label(c) for c in by_cols), "n",
              *(metric_info(m).tex_label if tex else metric_info(m).label for m in metric_cols)]
    rows = []
    if summary.empty:
        return header, rows
    prec = {m: decimals([_half(r["mean"], r["ci_high"]) for _, r in g.iterrows()], g["mean"])
            for m, g in summary.groupby("metric", sort=False)}
    for keys, g in summary.groupby(list(by_cols), dropna=False, sort=False):
        keys = keys if isinstance(keys, tuple) else (keys,)
        cells = {r["metric"]: format_cell(r["mean"], r["ci_high"], prec[r["metric"]], _flag(r, "ci_clipped"),
                                          _flag(r, "few"), tex) for _, r in g.iterrows()}
        text = [cell_text(k) for k in keys]
        rows.append([*(tex_escape(t) if tex else t for t in text), str(int(g["n"].max())),
                     *(cells.get(m, "--" if tex else "—") for m in metric_cols)])
    return header, rows


def p_text(p: float) -> str:
    """A p-value for a table: three decimals, ``<0.001`` below that, ``—`` when undefined."""
    if p != p:
        return "—"
    return "<0.001" if p < 0.001 else f"{p:.3f}"


def paired_rows(pairs, tex: bool = False) -> tuple[list[str], list[list[str]]]:
    """Header and rows of the paired-differences table (one precision per metric, flags as in :func:`wide`)."""
    from slamcli.metrics.registry import metric_info, tex_escape

    esc = tex_escape if tex else (lambda s: s)
    header = ["A", "B", "metric", "n", "mean diff A − B ± CI", "t", "p (t)", "W", "p (Wilcoxon)"]
    rows = []
    prec = {m: decimals([_half(r["mean_diff"], r["ci_high"]) for _, r in g.iterrows()], g["mean_diff"])
            for m, g in pairs.groupby("metric", sort=False)} if len(pairs) else {}
    for _, r in pairs.iterrows():
        info = metric_info(r["metric"])
        rows.append([esc(r["a"]), esc(r["b"]), info.tex_label if tex else info.label, str(int(r["n"])),
                     format_cell(r["mean_diff"], r["ci_high"], prec[r["metric"]], few=_flag(r, "few"), tex=tex),
                     "—" if r["t"] != r["t"] else f"{r['t']:.2f}", esc(p_text(r["p_t"])),
                     "—" if r["w"] != r["w"] else f"{r['w']:g}", esc(p_text(r["p_wilcoxon"]))])
    if tex:
        header = [esc(h) for h in header]
    return header, rows


def to_markdown(header, rows, note: str = "") -> str:
    lines = ["| " + " | ".join(header) + " |", "|" + "|".join("---" for _ in header) + "|"]
    lines += ["| " + " | ".join(r) + " |" for r in rows]
    if note:
        lines += ["", note]
    return "\n".join(lines) + "\n"


def to_latex(header, rows, caption: str = "", groups: Sequence[tuple[str, int]] = ()) -> str:
    """A ``booktabs`` tabular of cells already in LaTeX (``\\usepackage{booktabs,siunitx}``; numbers as
    ``\\num{m \\pm h}``, units as ``\\si{...}``). ``groups``: ``(name, width)`` column groups over the
    header after its first column (a ``\\multicolumn`` row with ``\\cmidrule`` under each group)."""
    from slamcli.metrics.registry import tex_escape

    out = [r"\begin{table}", r"\centering"]
    if caption:
        out.append(r"\caption{" + tex_escape(caption) + "}")
    out += [r"\begin{tabular}{" + "l" * len(header) + "}", r"\toprule"]
    if groups:
        spans, rules, col = [""], [], 2
        for name, width in groups:
            spans.append(r"\multicolumn{" + f"{width}" + "}{c}{" + tex_escape(name) + "}")
            rules.append(r"\cmidrule(lr){" + f"{col}-{col + width - 1}" + "}")
            col += width
        out += [" & ".join(spans) + r" \\", " ".join(rules)]
    out += [" & ".join(header) + r" \\", r"\midrule"]
    out += [" & ".join(r) + r" \\" for r in rows]
    out += [r"\bottomrule", r"\end{tabular}", r"\end{table}"]
    return "\n".join(out) + "\n"


def _notes(confidence: float) -> str:
    return (f"Cells: mean ± half-width of the {100 * confidence:g} % t confidence interval. "
            f"{FLAG_CLIPPED} lower end below 0 for a non-negative metric, clipped to 0. "
            f"{FLAG_FEW} fewer than {FEW_RUNS} runs.")


def aggregate_dir(exp_dir: str | Path, by: Sequence[str] | None = None, metrics: Sequence[str] | None = None,
                  out_dir: str | Path | None = None, confidence: float = 0.95,
                  baseline: str | None = None) -> dict[str, Any]:
    """Aggregate ``exp_dir/results.csv`` and write ``aggregate.csv`` (tidy), ``paired.csv`` (paired
    differences, :func:`paired`), ``aggregate.md`` and ``aggregate.tex`` (both tables) into ``out_dir``
    (default ``exp_dir``), each atomically.

    Returns ``{"summary", "paired", "unpaired", "header", "rows", "n_runs", "n_excluded", "note", "paths"}``.
    """
    exp_dir = Path(exp_dir)
    df = read_table(exp_dir)
    ok, n_excluded = completed(df)
    summary, by_cols, metric_cols = aggregate(ok, by, metrics, confidence)
    pairs, unpaired = paired(ok, by_cols, metric_cols, confidence, baseline)
    header, rows = wide(summary, by_cols, metric_cols)
    note = (f"{len(ok)} completed runs of {len(df)}; {n_excluded} failed or unfinished run(s) excluded. "
            + _notes(confidence))
    pnote = ("Paired differences A − B over the datasets both solved (same dataset_id); t: paired t test, "
             "W: Wilcoxon signed-rank, two-sided p."
             + (f" Not paired (several runs per dataset; group by every swept axis): {', '.join(unpaired)}."
                if unpaired else ""))
    paths = _write_tables(Path(out_dir) if out_dir is not None else exp_dir, exp_dir.name, summary, pairs,
                          (header, rows), wide(summary, by_cols, metric_cols, tex=True), note, pnote)
    return {"summary": summary, "paired": pairs, "unpaired": unpaired, "header": header, "rows": rows,
            "n_runs": len(df), "n_excluded": n_excluded, "note": note, "paired_note": pnote, "paths": paths}


def _write_tables(out: Path, name: str, summary, pairs, md_table, tex_table, note: str, pnote: str):
    """The four tables, written together (:func:`~slamcli.io.atomic.atomic_files`): all or none."""
    from slamcli.io.atomic import atomic_files

    md = to_markdown(*md_table, note)
    if len(pairs):
        md += "\n" + to_markdown(*paired_rows(pairs), pnote)
    tex = to_latex(*tex_table, f"{name}: {note}")
    if len(pairs):
        tex += "\n" + to_latex(*paired_rows(pairs, tex=True), f"{name}: {pnote}")
    paths = {"csv": out / "aggregate.csv", "paired": out / "paired.csv", "md": out / "aggregate.md",
             "tex": out / "aggregate.tex"}
    with atomic_files(list(paths.values())) as (csv, paired_csv, md_path, tex_path):
        summary.to_csv(csv, index=False)
        pairs.to_csv(paired_csv, index=False)
        md_path.write_text(md, encoding="utf-8")
        tex_path.write_text(tex, encoding="utf-8")
    return paths


@dataclass(frozen=True)
class CompareGroups:
    """Values of one metric per configuration, for :func:`slamcli.plots.figures.draw_compare`.

    labels : (G,) display names of the configurations ("ekf, gate_prob=0.9").
    values : (G,) arrays of the metric over each configuration's completed runs (NaN left out).
    metric : the metric column.     by : the grouping columns.     n_excluded : failed/unfinished runs left out.
    """

    labels: tuple[str, ...]
    values: tuple[Any, ...]
    metric: str
    by: tuple[str, ...]
    n_excluded: int = 0


def config_label(keys: Sequence[Any], by_cols: Sequence[str]) -> str:
    """Display name of one configuration: the solver label bare, every other key as ``name=value``
    (:func:`slamcli.metrics.registry.column_label`); missing values left out."""
    from slamcli.metrics.registry import column_label

    parts = [cell_text(k) if c == "label" else f"{column_label(c)}={cell_text(k)}"
             for k, c in zip(keys, by_cols) if cell_text(k) != "—"]
    return ", ".join(parts) or "—"


def groups_of(df, metric: str, by: str | Sequence[str] = "solver", order: Sequence[str] | None = None,
              n_excluded: int = 0) -> CompareGroups:
    """:class:`CompareGroups` of ``metric`` in the completed-runs table ``df``, grouped by ``by`` (one column
    name, a comma list ``"solver,gate_prob"`` or a sequence; names resolved by :func:`resolve_column`), in
    sorted order of the keys, or in the order of the labels ``order`` when given (others left out)."""
    names = [b.strip() for b in by.split(",")] if isinstance(by, str) else list(by)
    by_cols = [resolve_column(b, df.columns, "--by column") for b in names if b]
    if not by_cols:
        raise ConfigError("--by: give at least one column")
    metric_col = resolve_column(metric, df.columns, "metric")
    labels, values = [], []
    for keys, g in df.groupby(by_cols, dropna=False, sort=True):
        keys = keys if isinstance(keys, tuple) else (keys,)
        labels.append(config_label(keys, by_cols))
        values.append(g[metric_col].astype(float).dropna().to_numpy())
    if order is not None:
        pick = [labels.index(o) for o in order if o in labels]
        labels, values = [labels[k] for k in pick], [values[k] for k in pick]
    return CompareGroups(tuple(labels), tuple(values), metric_col, tuple(by_cols), n_excluded)


def compare_groups(exp_dir: str | Path, metric: str, by: str | Sequence[str] = "solver") -> CompareGroups:
    """:func:`groups_of` over the completed runs of the sweep in ``exp_dir`` (failed runs counted)."""
    df = read_table(exp_dir)
    ok, n_excluded = completed(df)
    return groups_of(ok, metric, by, n_excluded=n_excluded)


# ------------------------------------------------------------------------------------------------ leaderboard
#: leaderboard metrics per dataset, each against the dataset's reference (:data:`REFERENCE_COLUMNS`), and the
#: solver's wall time
LEADERBOARD_METRICS = ("ate_reference_m", "lm_reference_m", "lm_reference_matched", "solve_time_s")
#: ``derived column: {reference kind: results column}``: where ``reference`` is ``truth``, the ATE against the
#: true poses and the landmarks matched to the true ones; where it is ``gps``, the ATE against the GPS fixes
#: after SE(2) alignment and the landmarks matched to the surveyed ones (when the dataset has a survey)
REFERENCE_COLUMNS = {
    "ate_reference_m": {"truth": "ate_rmse_m", "gps": "gps_ate_aligned_rmse_m"},
    "lm_reference_m": {"truth": "lm_rmse_matched_m", "gps": "survey_lm_rmse_m"},
    "lm_reference_matched": {"truth": "lm_n_matched", "gps": "survey_lm_matched"},
}
LEADERBOARD_COLUMNS = ("label", "data", "reference", "metric", *SUMMARY_COLUMNS, "baseline", "n_pairs",
                       "mean_diff", "diff_ci_low", "diff_ci_high", "p_t", "p_wilcoxon")


def by_reference(df, columns: dict[str, str]):
    """Per run, the value of ``columns[reference]`` (``reference`` is the run's dataset reference kind,
    :data:`REFERENCE_COLUMNS`), as float; NaN where that column is absent or the kind is not listed."""
    import numpy as np
    import pandas as pd

    out = pd.Series(np.nan, index=df.index, dtype=float)
    ref = df["reference"] if "reference" in df.columns else pd.Series("truth", index=df.index)
    for kind, col in columns.items():
        if col in df.columns:
            pick = (ref == kind).fillna(False).to_numpy(bool)
            out[pick] = df.loc[pick, col].astype(float)
    return out


def leaderboard(df, baseline: str | None = None, confidence: float = 0.95):
    """Tidy leaderboard of completed runs: one row per (solver configuration — its label and its own swept
    ``solver.<label>.*`` values —, dataset — ``data`` and the swept ``scenario.*`` values —, metric of
    :data:`LEADERBOARD_METRICS` with a value on that dataset) with :func:`summarise`'s columns and, against
    the ``baseline`` label, the paired difference label − baseline on that dataset's runs (:func:`paired`:
    ``n_pairs, mean_diff, diff_ci_low, diff_ci_high, p_t, p_wilcoxon``; NaN for the baseline itself, where
    the baseline did not run, or without a baseline). Labels and datasets keep their order in ``df``."""
    import pandas as pd

    from slamcli.metrics.registry import metric_info

    for col in ("label", "data"):
        if col not in df.columns:
            raise ConfigError(f"a leaderboard needs the results column {col!r} (written by every sweep)")
    df = df.assign(**{k: by_reference(df, cols) for k, cols in REFERENCE_COLUMNS.items()},
                   label=_named(df, "label", "solver."),
                   data=_named(df, "data", "scenario."))
    labels = list(dict.fromkeys(df["label"]))
    if baseline is not None and baseline not in labels:
        raise ConfigError(f"--baseline {baseline!r} is not a solver configuration; choose one of "
                          f"{', '.join(labels)}")
    rows = []
    for data, g in df.groupby("data", sort=False):
        metrics = [m for m in LEADERBOARD_METRICS if m in g.columns and g[m].astype(float).notna().any()]
        pairs = None
        if baseline is not None and baseline in set(g["label"]):
            pairs = paired(g, ["label"], metrics, confidence, baseline)[0].set_index(["a", "metric"])
        for label, gl in g.groupby("label", sort=False):
            for m in metrics:
                row = {"label": label, "data": data, "reference": _first(gl, "reference"), "metric": m,
                       **summarise(gl[m].astype(float).to_numpy(), confidence, metric_info(m).nonnegative),
                       "baseline": baseline or ""}
                d = pairs.loc[(label, m)] if pairs is not None and (label, m) in pairs.index else None
                row.update(n_pairs=int(d["n"]) if d is not None else 0,
                           **{k: float(d[src]) if d is not None else float("nan") for k, src in (
                               ("mean_diff", "mean_diff"), ("diff_ci_low", "ci_low"), ("diff_ci_high", "ci_high"),
                               ("p_t", "p_t"), ("p_wilcoxon", "p_wilcoxon"))})
                rows.append(row)
    out = pd.DataFrame(rows, columns=list(LEADERBOARD_COLUMNS))
    out["n"] = out["n"].astype("Int64")
    out["n_pairs"] = out["n_pairs"].astype("Int64")
    return out


def _named(df, col: str, prefix: str):
    """``col`` with the sweep axes of ``prefix`` that apply to a row appended as ``name=value``: a solver
    configuration ``ekf, gate_prob=0.9`` (its own ``solver.<label>.*`` axes), a dataset ``loop, n_steps=50``
    (the ``scenario.*`` axes)."""
    from slamcli.metrics.registry import column_label

    axes = [c for c in df.columns if c.startswith(prefix)]
    if not axes:
        return df[col].astype(str)

    def name(row) -> str:
        own = [c for c in axes if prefix == "scenario." or c.startswith(f"solver.{row['label']}.")]
        return ", ".join([str(row[col]), *(f"{column_label(c)}={cell_text(row[c])}" for c in own
                                          if cell_text(row[c]) != "—")])
    return df.apply(name, axis=1)


def _first(g, col: str) -> str:
    return str(g[col].iloc[0]) if col in g.columns and len(g) and g[col].iloc[0] is not None else ""


def leaderboard_rows(board, tex: bool = False) -> tuple[list[tuple[str, int]], list[str], list[list[str]]]:
    """Column groups ``[(dataset, width)]``, header and rows of the wide leaderboard: one row per solver
    label, per dataset one column per metric. A cell is ``mean ± CI half-width`` (one precision per column,
    :func:`decimals`; flags as in :func:`wide`), followed for a non-baseline label by ``Δ`` = its paired mean
    difference from the baseline and the paired t test's p (``—`` when undefined, e.g. one recording)."""
    from slamcli.metrics.registry import metric_info, tex_escape

    esc = tex_escape if tex else (lambda s: s)
    labels = list(dict.fromkeys(board["label"]))
    groups, header, columns = [], ["solver"], []
    for data, g in board.groupby("data", sort=False):
        metrics = list(dict.fromkeys(g["metric"]))
        groups.append((str(data), len(metrics)))
        for m in metrics:
            info = metric_info(m)
            header.append(info.tex_label if tex else f"{data}: {info.label}")
            sub = g[g["metric"] == m]
            prec = decimals([_half(r["mean"], r["ci_high"]) for _, r in sub.iterrows()], sub["mean"])
            columns.append({r["label"]: _board_cell(r, prec, tex) for _, r in sub.iterrows()})
    rows = [[esc(str(label)), *(col.get(label, "--" if tex else "—") for col in columns)] for label in labels]
    return groups, header, rows


def _board_cell(r, prec: int, tex: bool) -> str:
    """One leaderboard cell (see :func:`leaderboard_rows`)."""
    from slamcli.metrics.registry import tex_escape

    cell = format_cell(r["mean"], r["ci_high"], prec, _flag(r, "ci_clipped"), _flag(r, "few"), tex)
    if r["baseline"] and r["label"] == r["baseline"]:
        return cell + " (baseline)"
    if r["mean_diff"] != r["mean_diff"]:
        return cell
    delta = f"Δ {r['mean_diff']:+.{prec}f}, p {p_text(r['p_t'])}"
    return cell + f" ({tex_escape(delta) if tex else delta})"


def leaderboard_dir(exp_dir: str | Path, baseline: str | None = None, out_dir: str | Path | None = None,
                    confidence: float = 0.95) -> dict[str, Any]:
    """The leaderboard (:func:`leaderboard`) of ``exp_dir/results.csv``'s completed runs, written as
    ``leaderboard.csv`` (tidy), ``leaderboard.md`` and ``leaderboard.tex`` into ``out_dir`` (default
    ``exp_dir``), all or none. Returns ``{"board", "markdown", "n_runs", "n_excluded", "paths"}``."""
    from slamcli.io.atomic import atomic_files

    exp_dir = Path(exp_dir)
    df = read_table(exp_dir)
    ok, n_excluded = completed(df)
    board = leaderboard(ok, baseline, confidence)
    note = (f"{len(ok)} completed runs of {len(df)}; {n_excluded} failed or unfinished run(s) excluded. "
            "ATE vs reference: against the true poses (truth) or the GPS fixes after SE(2) alignment (gps). "
            + _notes(confidence)
            + (f" Δ: paired mean difference from {baseline} on the same datasets, p: paired t test (Wilcoxon in "
               "leaderboard.csv)." if baseline else ""))
    groups, header, rows = leaderboard_rows(board)
    md = to_markdown(header, rows, note)
    tgroups, theader, trows = leaderboard_rows(board, tex=True)
    tex = to_latex(theader, trows, f"{exp_dir.name} leaderboard: {note}", groups=tgroups)
    out = Path(out_dir) if out_dir is not None else exp_dir
    paths = {"csv": out / "leaderboard.csv", "md": out / "leaderboard.md", "tex": out / "leaderboard.tex"}
    with atomic_files(list(paths.values())) as (csv, md_path, tex_path):
        board.to_csv(csv, index=False)
        md_path.write_text(md, encoding="utf-8")
        tex_path.write_text(tex, encoding="utf-8")
    return {"board": board, "markdown": md, "n_runs": len(df), "n_excluded": n_excluded, "paths": paths}
