"""Summaries of a finished sweep, like ``evo_res``: mean, standard deviation, 95 % confidence interval and n
per configuration, over completed runs only.

For the ``n`` values ``x_1..x_n`` of one metric in one configuration (NaN values are not counted)::

    mean  x̄ = (1/n) Σ x_i
    std   s = sqrt( Σ (x_i − x̄)² / (n − 1) )                (sample standard deviation, ddof = 1)
    CI    x̄ ± t_{0.975, n−1} · s / √n                        (Student t, two-sided 95 %; NaN for n < 2)

Column types are kept (:func:`typed_frame`, :func:`read_table`): an integer sweep parameter that some
solvers do not have is a nullable ``Int64`` column (``10`` and ``<NA>``), never ``10.0``.
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


def summarise(values, confidence: float = 0.95) -> dict[str, float]:
    """``n, mean, std, ci_low, ci_high`` of the finite values (module docstring formulas)."""
    import numpy as np
    from scipy import stats

    x = np.asarray(values, float)
    x = x[np.isfinite(x)]
    n = int(x.size)
    nan = float("nan")
    if n == 0:
        return {"n": 0, "mean": nan, "std": nan, "ci_low": nan, "ci_high": nan}
    mean = float(x.mean())
    if n < 2:
        return {"n": 1, "mean": mean, "std": nan, "ci_low": nan, "ci_high": nan}
    std = float(x.std(ddof=1))
    half = float(stats.t.ppf(0.5 + confidence / 2, n - 1)) * std / np.sqrt(n)
    return {"n": n, "mean": mean, "std": std, "ci_low": mean - half, "ci_high": mean + half}


def aggregate(df, by: Sequence[str] | None = None, metrics: Sequence[str] | None = None,
              confidence: float = 0.95):
    """Tidy summary: one row per (configuration, metric) with ``n, mean, std, ci_low, ci_high``.

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

    by_cols = [resolve_column(b, df.columns, "--by column") for b in by] if by else \
        ["label"] + sweep_axes(df)
    if metrics:
        metric_cols = [resolve_column(m, df.columns, "metric") for m in metrics]
    else:
        metric_cols = [m for m in DEFAULT_METRICS if m in df.columns]
    for m in metric_cols:
        if not pd.api.types.is_numeric_dtype(df[m]) or pd.api.types.is_bool_dtype(df[m]):
            raise ConfigError(f"metric {m!r} is not numeric")
    rows = []
    for keys, g in df.groupby(by_cols, dropna=False, sort=True):
        keys = keys if isinstance(keys, tuple) else (keys,)
        for m in metric_cols:
            rows.append({**dict(zip(by_cols, keys)), "metric": m,
                         **summarise(g[m].astype(float).to_numpy(), confidence)})
    out = pd.DataFrame(rows, columns=[*by_cols, "metric", "n", "mean", "std", "ci_low", "ci_high"])
    for c in by_cols:  # groupby hands back plain objects; restore each key column's dtype
        out[c] = out[c].astype(df[c].dtype)
    out["n"] = out["n"].astype("Int64")
    return out, by_cols, metric_cols


def cell_text(v) -> str:
    import pandas as pd

    return "—" if v is None or v is pd.NA or (isinstance(v, float) and v != v) else str(v)


def _fmt(mean: float, lo: float, hi: float) -> str:
    if mean != mean:
        return "—"
    if lo != lo:
        return f"{mean:.4g}"
    return f"{mean:.4g} ± {(hi - lo) / 2:.2g}"


def wide(summary, by_cols: Sequence[str], metric_cols: Sequence[str]) -> tuple[list[str], list[list[str]]]:
    """Header and rows of a display table: configuration, n, then ``mean ± CI half-width`` per metric."""
    header = [*by_cols, "n", *metric_cols]
    rows = []
    if summary.empty:
        return header, rows
    for keys, g in summary.groupby(list(by_cols), dropna=False, sort=False):
        keys = keys if isinstance(keys, tuple) else (keys,)
        cells = {r["metric"]: _fmt(r["mean"], r["ci_low"], r["ci_high"]) for _, r in g.iterrows()}
        rows.append([*map(cell_text, keys), str(int(g["n"].max())), *(cells.get(m, "—") for m in metric_cols)])
    return header, rows


def to_markdown(header, rows, note: str = "") -> str:
    lines = ["| " + " | ".join(header) + " |", "|" + "|".join("---" for _ in header) + "|"]
    lines += ["| " + " | ".join(r) + " |" for r in rows]
    if note:
        lines += ["", note]
    return "\n".join(lines) + "\n"


def _tex(s: str) -> str:
    for a, b in (("\\", r"\textbackslash{}"), ("_", r"\_"), ("%", r"\%"), ("&", r"\&"), ("#", r"\#"),
                 ("±", r"$\pm$"), ("—", "--")):
        s = s.replace(a, b)
    return s


def to_latex(header, rows, caption: str = "") -> str:
    """A ``booktabs`` tabular (``\\usepackage{booktabs}``)."""
    spec = "l" * len(header)
    out = [r"\begin{table}", r"\centering"]
    if caption:
        out.append(r"\caption{" + _tex(caption) + "}")
    out += [r"\begin{tabular}{" + spec + "}", r"\toprule", " & ".join(_tex(h) for h in header) + r" \\",
            r"\midrule"]
    out += [" & ".join(_tex(c) for c in r) + r" \\" for r in rows]
    out += [r"\bottomrule", r"\end{tabular}", r"\end{table}"]
    return "\n".join(out) + "\n"


def aggregate_dir(exp_dir: str | Path, by: Sequence[str] | None = None, metrics: Sequence[str] | None = None,
                  out_dir: str | Path | None = None, confidence: float = 0.95) -> dict[str, Any]:
    """Aggregate ``exp_dir/results.csv`` and write ``aggregate.csv`` (tidy), ``aggregate.md`` and
    ``aggregate.tex`` into ``out_dir`` (default ``exp_dir``), each atomically.

    Returns ``{"summary", "header", "rows", "n_runs", "n_excluded", "paths"}``.
    """
    from slamcli.io import atomic_path

    exp_dir = Path(exp_dir)
    df = read_table(exp_dir)
    ok, n_excluded = completed(df)
    summary, by_cols, metric_cols = aggregate(ok, by, metrics, confidence)
    header, rows = wide(summary, by_cols, metric_cols)
    note = (f"{len(ok)} completed runs of {len(df)}; {n_excluded} failed or unfinished run(s) excluded. "
            f"Cells: mean ± half-width of the {100 * confidence:g} % t confidence interval.")
    out = Path(out_dir) if out_dir is not None else exp_dir
    paths = {}
    with atomic_path(out / "aggregate.csv") as tmp:
        summary.to_csv(tmp, index=False)
    paths["csv"] = out / "aggregate.csv"
    with atomic_path(out / "aggregate.md") as tmp:
        tmp.write_text(to_markdown(header, rows, note), encoding="utf-8")
    paths["md"] = out / "aggregate.md"
    with atomic_path(out / "aggregate.tex") as tmp:
        tmp.write_text(to_latex(header, rows, f"{exp_dir.name}: {note}"), encoding="utf-8")
    paths["tex"] = out / "aggregate.tex"
    return {"summary": summary, "header": header, "rows": rows, "n_runs": len(df), "n_excluded": n_excluded,
            "note": note, "paths": paths}


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
