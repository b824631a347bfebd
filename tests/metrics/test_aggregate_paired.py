"""`slamcli aggregate` (issue 24 item 5): paired differences per dataset against scipy.stats and a closed form,
intervals clipped and flagged for non-negative metrics and n < 3, terminal tables that fit 100 columns without
a wrapped header, LaTeX with names and units from the metric registry at one precision per column."""

from __future__ import annotations

import math
import re

import numpy as np
import pandas as pd
import pytest
from scipy import stats
from typer.testing import CliRunner

from slamcli.cli import app
from slamcli.metrics.aggregate import aggregate_dir, paired_stats, summarise, typed_frame

runner = CliRunner()


def test_paired_stats_equal_scipy_on_hand_built_data():
    # 8 datasets; B misses dataset 3 (NaN) and A dataset 6: 6 pairs remain
    a = np.array([0.31, 0.27, 0.45, 0.38, 0.29, 0.52, np.nan, 0.33])
    b = np.array([0.25, 0.30, 0.36, np.nan, 0.21, 0.41, 0.40, 0.30])
    s = paired_stats(a, b)
    keep = np.isfinite(a) & np.isfinite(b)
    aa, bb = a[keep], b[keep]
    t = stats.ttest_rel(aa, bb)
    w = stats.wilcoxon(aa, bb)
    assert s["n"] == 6 and not s["few"]
    assert s["mean_diff"] == pytest.approx(np.mean(aa - bb), rel=1e-14)
    assert s["std_diff"] == pytest.approx(np.std(aa - bb, ddof=1), rel=1e-14)
    assert s["t"] == pytest.approx(t.statistic, rel=1e-12) and s["p_t"] == pytest.approx(t.pvalue, rel=1e-12)
    assert s["w"] == pytest.approx(w.statistic) and s["p_wilcoxon"] == pytest.approx(w.pvalue, rel=1e-12)
    ci = stats.t.interval(0.95, 5, loc=np.mean(aa - bb), scale=stats.sem(aa - bb))
    assert (s["ci_low"], s["ci_high"]) == pytest.approx(ci, rel=1e-12)


def test_paired_stats_closed_form():
    """d = (1, 2, 3): d̄ = 2, s_d = 1, t = 2/(1/√3) = 2√3. Student t with 2 dof has the closed-form CDF
    F(x) = 1/2 + x / (2√(x² + 2)), so p = 1 − 2√3/√14 and t_{0.975,2} = 0.95/√(2·0.975·0.025). Wilcoxon: all
    three differences positive, R⁻ = 0 = W, exact p = 2 · (1/2)³ = 0.25."""
    s = paired_stats([11.0, 12.0, 13.0], [10.0, 10.0, 10.0])
    assert s["n"] == 3 and s["mean_diff"] == 2.0 and s["std_diff"] == pytest.approx(1.0, rel=1e-15)
    assert s["t"] == pytest.approx(2 * math.sqrt(3), rel=1e-14)
    assert s["p_t"] == pytest.approx(1 - 2 * math.sqrt(3) / math.sqrt(14), rel=1e-12)
    q = 0.95 / math.sqrt(2 * 0.975 * 0.025)
    assert s["ci_high"] - 2.0 == pytest.approx(q / math.sqrt(3), rel=1e-12)
    assert s["w"] == 0.0 and s["p_wilcoxon"] == pytest.approx(0.25, rel=1e-12)


def test_paired_stats_degenerate_cases():
    same = paired_stats([1.0, 2.0, 3.0], [1.0, 2.0, 3.0])  # every difference 0: no test is defined
    assert same["mean_diff"] == 0.0 and math.isnan(same["t"]) and math.isnan(same["w"])
    one = paired_stats([1.0], [0.5])
    assert one["n"] == 1 and one["few"] and one["mean_diff"] == 0.5 and math.isnan(one["ci_low"])


def test_interval_clipped_and_flagged_for_a_nonnegative_metric():
    # n = 2: x̄ = 0.6, s = √0.02, half = t_{0.975,1} · s/√2 = 12.7062 · 0.1 = 1.27 > 0.6
    s = summarise([0.5, 0.7], nonnegative=True)
    assert s["few"] and s["ci_clipped"] and s["ci_low"] == 0.0
    assert s["ci_high"] == pytest.approx(0.6 + 12.706204736174698 * 0.1, rel=1e-9)
    signed = summarise([0.5, 0.7])  # a metric that may be negative keeps its t interval
    assert not signed["ci_clipped"] and signed["ci_low"] == pytest.approx(0.6 - 1.2706204736174698, rel=1e-9)
    wide_n = summarise([1.0, 2.0, 3.0, 4.0], nonnegative=True)
    assert not wide_n["few"] and not wide_n["ci_clipped"]


def _paired_sweep(d, n_datasets=5):
    """Two solvers on the same datasets (same dataset_id per replicate) plus a third on only 2 of them."""
    rng = np.random.default_rng(7)
    truth = rng.uniform(0.2, 0.4, n_datasets)
    rows = []
    for k in range(n_datasets):
        ds = f"ds{k}"
        for label, v in (("ekf", truth[k] + 0.05 + 0.01 * k), ("icm", truth[k])):
            rows.append({"run_id": f"{label}{k}", "label": label, "method": label, "replicate": k,
                         "dataset_id": ds, "status": "completed", "ate_rmse_m": v,
                         "heading_rmse_rad": v / 10, "solve_time_s": 0.1 + k})
        if k < 2:
            rows.append({"run_id": f"g{k}", "label": "graph-with-a-long-configuration-name", "method": "graph",
                         "replicate": k, "dataset_id": ds, "status": "completed", "ate_rmse_m": truth[k] - 0.01,
                         "heading_rmse_rad": 0.001, "solve_time_s": 0.2})
    d.mkdir(parents=True, exist_ok=True)
    typed_frame(rows).to_csv(d / "results.csv", index=False)
    return pd.DataFrame(rows)


def test_aggregate_dir_pairs_runs_by_dataset(tmp_path):
    df = _paired_sweep(tmp_path / "exp")
    a = aggregate_dir(tmp_path / "exp", by=["solver"], metrics=["ate_rmse", "heading_rmse"])
    p = a["paired"]
    row = p[(p.a == "ekf") & (p.b == "icm") & (p.metric == "ate_rmse_m")].iloc[0]
    e = df[df.label == "ekf"].set_index("dataset_id")["ate_rmse_m"]
    i = df[df.label == "icm"].set_index("dataset_id")["ate_rmse_m"]
    ref = stats.ttest_rel(e.loc[i.index], i)
    assert row["n"] == 5 and row["mean_diff"] == pytest.approx(0.05 + 0.01 * np.mean(range(5)), rel=1e-12)
    assert row["p_t"] == pytest.approx(ref.pvalue, rel=1e-12)
    g = p[(p.a == "ekf") & (p.b.str.startswith("graph")) & (p.metric == "ate_rmse_m")].iloc[0]
    assert g["n"] == 2 and g["few"]  # only the datasets both solved
    assert (tmp_path / "exp" / "paired.csv").is_file()
    base = aggregate_dir(tmp_path / "exp", by=["solver"], metrics=["ate_rmse"], baseline="icm")["paired"]
    assert set(base.b) == {"icm"} and len(base) == 2


def test_swept_axis_left_out_of_by_is_not_paired(tmp_path):
    rows = [{"run_id": f"r{k}{g}", "label": "ekf", "method": "ekf", "replicate": k, "dataset_id": f"d{k}",
             "status": "completed", "solver.ekf.gate_prob": g, "ate_rmse_m": 0.1 * k + g}
            for k in range(3) for g in (0.9, 0.99)]
    rows += [{"run_id": f"o{k}", "label": "odometry", "method": "odometry", "replicate": k, "dataset_id": f"d{k}",
              "status": "completed", "ate_rmse_m": 0.5} for k in range(3)]
    (tmp_path / "e").mkdir()
    typed_frame(rows).to_csv(tmp_path / "e" / "results.csv", index=False)
    a = aggregate_dir(tmp_path / "e", by=["solver"], metrics=["ate_rmse"])
    assert a["unpaired"] == ["ekf"] and a["paired"].empty  # two runs of one dataset: no pairing
    a = aggregate_dir(tmp_path / "e", by=["solver", "gate_prob"], metrics=["ate_rmse"])
    assert a["unpaired"] == [] and len(a["paired"]) == 3


def _header_line(output: str, first: str) -> str:
    lines = output.splitlines()
    k = next(i for i, line in enumerate(lines) if first in line)
    return lines[k]


@pytest.mark.slow
def test_terminal_tables_fit_100_columns_without_wrapped_headers(tmp_path):
    _paired_sweep(tmp_path / "exp")
    r = runner.invoke(app, ["aggregate", str(tmp_path / "exp"), "-o", str(tmp_path / "out")],
                      env={"COLUMNS": "100"})
    assert r.exit_code == 0, r.output
    assert max(len(line) for line in r.output.splitlines()) <= 100
    head = _header_line(r.output, "configuration")
    for name in ("configuration", "metric", "n", "mean", "std", "95 % CI"):
        assert name in head  # every header on one line, none split
    head = _header_line(r.output, "mean diff")
    for name in ("A", "B", "n", "mean diff", "95 % CI", "p (t)", "p (Wilcoxon)"):
        assert name in head
    assert "ATE RMSE (m)" in r.output and "ate_rmse_m" not in r.output
    assert "† fewer than 3 runs" in r.output


def test_latex_has_registry_names_units_and_one_precision_per_column(tmp_path):
    _paired_sweep(tmp_path / "exp")
    aggregate_dir(tmp_path / "exp", by=["solver"], metrics=["ate_rmse", "heading_rmse", "solve_time"])
    tex = (tmp_path / "exp" / "aggregate.tex").read_text()
    assert r"ATE RMSE [\si{\metre}]" in tex and r"heading RMSE [\si{\radian}]" in tex
    assert r"solve time [\si{\second}]" in tex and "rmse\\_m" not in tex and "rmse_m" not in tex
    first = tex.split(r"\midrule")[1].split(r"\bottomrule")[0]
    cols = [line.split(" & ") for line in first.strip().splitlines()]
    for j in (2, 3, 4):  # the metric columns: every \num{m \pm h} of one column has the same decimals
        nums = [re.findall(r"\\num\{(-?\d+\.?(\d*)) \\pm (\d+\.?(\d*))\}", row[j])[0] for row in cols]
        assert len({len(n[1]) for n in nums} | {len(n[3]) for n in nums}) == 1, nums
    assert r"$^{\dagger}$" in tex and r"\textdagger{}" in tex  # n = 2 flagged, and the caption says what † is
    md = (tmp_path / "exp" / "aggregate.md").read_text()
    assert "| A | B | metric | n | mean diff A − B ± CI | t | p (t) | W | p (Wilcoxon) |" in md
