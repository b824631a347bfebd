"""`slamcli aggregate` and `plot compare`: means/std/CI against hand computations, dtypes kept, failed runs
excluded and counted."""

import math

import numpy as np
import pandas as pd
import pytest
from conftest import write_sweep_table
from typer.testing import CliRunner

from slamcli.cli import app
from slamcli.errors import ConfigError
from slamcli.metrics.aggregate import aggregate_dir, read_table, resolve_column, summarise

runner = CliRunner()


def test_typed_frame_and_csv_keep_integer_columns(tmp_path):
    df = write_sweep_table(tmp_path / "exp")
    assert str(df["solver.ekf.provisional_min_hits"].dtype) == "Int64"
    col = pd.read_csv(tmp_path / "exp" / "results.csv", dtype=str)["solver.ekf.provisional_min_hits"]
    assert col.dropna().tolist() == ["2", "2", "2", "2", "5", "5", "2"]  # written as 2, not 2.0
    back = read_table(tmp_path / "exp")
    assert str(back["solver.ekf.provisional_min_hits"].dtype) == "Int64"
    assert back["solver.ekf.provisional_min_hits"].isna().sum() == 3  # the odometry rows
    assert back["ate_rmse_m"].dtype == np.float64 and back["replicate"].dtype == "Int64"


def test_summarise_matches_hand_computation():
    s = summarise([1.0, 2.0, 3.0, 4.0, float("nan")])
    # hand: mean 2.5; s² = (2.25 + 0.25 + 0.25 + 2.25)/3 = 5/3; t_{0.975,3} = 3.182446305 (t table)
    half = 3.182446305284263 * math.sqrt(5 / 3) / 2
    assert s["n"] == 4 and s["mean"] == pytest.approx(2.5, rel=1e-15)
    assert s["std"] == pytest.approx(math.sqrt(5 / 3), rel=1e-14)
    assert s["ci_low"] == pytest.approx(2.5 - half, rel=1e-9) and s["ci_high"] == pytest.approx(2.5 + half, rel=1e-9)
    one = summarise([7.0])
    assert one["n"] == 1 and one["mean"] == 7.0 and math.isnan(one["std"]) and math.isnan(one["ci_low"])


def test_aggregate_dir_writes_three_tables(tmp_path):
    write_sweep_table(tmp_path / "exp")
    a = aggregate_dir(tmp_path / "exp", metrics=["ate_rmse"])
    s = a["summary"]
    assert a["n_excluded"] == 1 and a["n_runs"] == 10
    assert str(s["solver.ekf.provisional_min_hits"].dtype) == "Int64"
    ekf2 = s[(s.label == "ekf") & (s["solver.ekf.provisional_min_hits"] == 2)].iloc[0]
    assert ekf2["n"] == 4 and ekf2["mean"] == pytest.approx(2.5)  # the failed run is not in it
    ekf5 = s[(s.label == "ekf") & (s["solver.ekf.provisional_min_hits"] == 5)].iloc[0]
    # n = 2: t_{0.975,1} = 12.7062047 ; s = 0.1414214
    assert ekf5["mean"] == pytest.approx(0.6) and ekf5["ci_high"] - ekf5["mean"] == pytest.approx(
        12.706204736174698 * math.sqrt(0.02) / math.sqrt(2), rel=1e-9)
    odo = s[s.label == "odometry"].iloc[0]
    assert odo["mean"] == pytest.approx(12.0) and odo["std"] == pytest.approx(2.0)
    assert pd.isna(odo["solver.ekf.provisional_min_hits"])
    md = (tmp_path / "exp" / "aggregate.md").read_text()
    # one precision per column: the smallest half-width (ekf 5: 12.71 · 0.1414 / √2 = 1.27) to 2 digits
    assert "| solver | provisional_min_hits | n | ATE RMSE (m) |" in md
    assert "| ekf | 2 | 4 | 2.5 ± 2.1 |" in md and "| ekf | 5 | 2 | 0.6 ± 1.3*† |" in md
    assert "1 failed or unfinished run(s) excluded" in md
    tex = (tmp_path / "exp" / "aggregate.tex").read_text()
    assert r"\toprule" in tex and r"\num{2.5 \pm 2.1}" in tex and r"ATE RMSE [\si{\metre}]" in tex
    assert "ate\\_rmse" not in tex and r"\num{0.6 \pm 1.3}$^{*\dagger}$" in tex
    back = pd.read_csv(tmp_path / "exp" / "aggregate.csv")
    assert len(back) == 3 and set(back["metric"]) == {"ate_rmse_m"}


def test_a_full_disk_while_writing_the_tables_leaves_none_of_them(tmp_path, monkeypatch):
    """ISSUE: ``aggregate -o agg`` on a nearly full disk left aggregate.csv while its error said nothing was
    written. The four tables are written together: the third failing leaves none (and no temporary)."""
    import pathlib

    write_sweep_table(tmp_path / "exp")
    out = tmp_path / "agg"
    orig = pathlib.Path.write_text

    def full(self, *a, **k):
        if ".aggregate.tex" in self.name:
            raise OSError(28, "No space left on device", str(self))
        return orig(self, *a, **k)

    monkeypatch.setattr(pathlib.Path, "write_text", full)
    res = CliRunner().invoke(app, ["aggregate", str(tmp_path / "exp"), "-m", "ate_rmse", "-o", str(out), "-q"])
    assert res.exit_code == 1 and "No space left" in res.stderr and "aggregate.tex" in res.stderr, res.output
    assert list(out.iterdir()) == []
    monkeypatch.setattr(pathlib.Path, "write_text", orig)
    assert CliRunner().invoke(app, ["aggregate", str(tmp_path / "exp"), "-m", "ate_rmse", "-o", str(out),
                                    "-q"]).exit_code == 0
    assert sorted(p.name for p in out.iterdir()) == ["aggregate.csv", "aggregate.md", "aggregate.tex", "paired.csv"]


def test_by_solver_and_cli(tmp_path):
    write_sweep_table(tmp_path / "exp")
    r = runner.invoke(app, ["aggregate", str(tmp_path / "exp"), "--by", "solver", "-m", "ate_rmse_m",
                            "-o", str(tmp_path / "out")], env={"COLUMNS": "80"})
    assert r.exit_code == 0, r.output
    assert "1 failed or unfinished run(s) excluded" in r.output
    assert max(len(line) for line in r.output.splitlines()) <= 80
    assert "ATE RMSE (m)" in r.output and "ate_rmse_m" not in r.output
    s = pd.read_csv(tmp_path / "out" / "aggregate.csv")
    ekf = s[s.label == "ekf"].iloc[0]
    vals = [1.0, 2.0, 3.0, 4.0, 0.5, 0.7]
    assert ekf["n"] == 6 and ekf["mean"] == pytest.approx(np.mean(vals)) and ekf["std"] == pytest.approx(
        np.std(vals, ddof=1))
    r = runner.invoke(app, ["aggregate", str(tmp_path / "exp"), "--by", "lable"])
    assert r.exit_code == 1 and "did you mean 'label'" in r.output and len(r.output.strip().splitlines()) == 1


def test_resolve_column_suffix_and_prefix():
    cols = ["label", "solver.ekf.gate_prob", "ate_rmse_m", "aligned_ate_rmse_m"]
    assert resolve_column("gate_prob", cols) == "solver.ekf.gate_prob"
    assert resolve_column("ate_rmse", cols) == "ate_rmse_m"
    assert resolve_column("solver", cols) == "label"
    with pytest.raises(ConfigError, match="did you mean"):
        resolve_column("ate_rsme_m", cols)


def test_plot_compare(tmp_path):
    write_sweep_table(tmp_path / "exp")
    out = tmp_path / "c.png"
    r = runner.invoke(app, ["plot", "compare", str(tmp_path / "exp"), "--metric", "ate_rmse", "--by", "solver",
                            "-o", str(out)])
    assert r.exit_code == 0, r.output
    assert "9 runs in 2 groups; 1 failed run(s) excluded" in r.output
    assert out.read_bytes()[:4] == b"\x89PNG"
    from slamcli.metrics.aggregate import compare_groups
    from slamcli.plots import new_figure
    from slamcli.plots.figures import draw_compare

    g = compare_groups(tmp_path / "exp", "ate_rmse", "solver")
    assert g.labels == ("ekf", "odometry") and sorted(g.values[1]) == [10.0, 12.0, 14.0]
    _, ax = new_figure()
    draw_compare(ax, g)
    np.testing.assert_allclose(np.sort(ax.lines[-1].get_ydata()), [10.0, 12.0, 14.0])  # every run drawn
    # names and units from the registry, not raw column names
    assert ax.get_ylabel() == "ATE RMSE (m)" and ax.get_xlabel() == "solver"
    assert [t.get_text() for t in ax.get_xticklabels()] == ["ekf\n(n=6)", "odometry\n(n=3)"]


def test_plot_compare_by_two_columns_as_aggregate(tmp_path):
    """`--by solver,provisional_min_hits` groups like aggregate does (it failed before: one column only)."""
    write_sweep_table(tmp_path / "exp")
    out = tmp_path / "c.pdf"
    r = runner.invoke(app, ["plot", "compare", str(tmp_path / "exp"), "--by", "solver,provisional_min_hits",
                            "-o", str(out), "--label", "A", "--label", "B", "--label", "C"])
    assert r.exit_code == 0, r.output
    assert "9 runs in 3 groups" in r.output
    from slamcli.metrics.aggregate import compare_groups

    g = compare_groups(tmp_path / "exp", "ate_rmse", "solver,provisional_min_hits")
    assert g.labels == ("ekf, provisional_min_hits=2", "ekf, provisional_min_hits=5", "odometry")
    a = aggregate_dir(tmp_path / "exp", by=["solver", "provisional_min_hits"], metrics=["ate_rmse"])["summary"]
    np.testing.assert_allclose([v.mean() for v in g.values], a["mean"].to_numpy())  # same groups, same order
    r = runner.invoke(app, ["plot", "compare", str(tmp_path / "exp"), "--by", "solver,provisional_min_hits",
                            "-o", str(tmp_path / "d.png"), "--label", "A"])
    assert r.exit_code == 1 and "1 label(s) for 3 group(s)" in r.output and not (tmp_path / "d.png").exists()


@pytest.mark.slow
def test_real_sweep_keeps_int_parameter(tmp_path):
    toml = tmp_path / "e.toml"
    toml.write_text("""
[experiment]
name = "agg"
[scenario]
name = "loop"
[scenario.parameters]
n_steps = 40
[[solver]]
method = "odometry"
[[solver]]
method = "ekf"
[solver.params]
association = "ml"
[sweep]
replicates = 2
grid = { "solver.ekf.provisional_min_hits" = [2, 3] }
""")
    r = runner.invoke(app, ["sweep", str(toml), "-o", str(tmp_path / "res"), "-q"])
    assert r.exit_code == 0, r.output
    col = pd.read_csv(tmp_path / "res" / "agg" / "results.csv", dtype=str)["solver.ekf.provisional_min_hits"]
    assert sorted(col.dropna()) == ["2", "2", "3", "3"]  # not 2.0 although the odometry rows have none
    a = aggregate_dir(tmp_path / "res" / "agg", by=["solver", "provisional_min_hits"], metrics=["ate_rmse"])
    s = a["summary"]
    hits = s["solver.ekf.provisional_min_hits"]
    assert str(hits.dtype) == "Int64" and hits.iloc[:2].tolist() == [2, 3] and pd.isna(hits.iloc[2])
    table = read_table(tmp_path / "res" / "agg")
    for _, row in s.iterrows():  # every mean recomputed by hand from the run table
        sel = table[(table.label == row.label) & (table.status == "completed")]
        if not pd.isna(row["solver.ekf.provisional_min_hits"]):
            sel = sel[sel["solver.ekf.provisional_min_hits"] == row["solver.ekf.provisional_min_hits"]]
        assert row["n"] == 2 and row["mean"] == pytest.approx(sum(sel.ate_rmse_m) / 2, rel=1e-12)


def test_default_metrics_leave_out_one_no_run_recorded(tmp_path):
    """Solvers without covariances leave the NEES columns empty (text notes beside them, so the column may
    come back as text): the default metrics skip an empty column, an explicitly named one summarises to n = 0,
    and a column of text is still refused by name."""
    from slamcli.metrics.aggregate import aggregate

    rows = [{"run_id": f"r{k}", "label": "odometry", "status": "completed", "ate_rmse_m": 1.0 + k,
             "pose_nees_mean": None, "pose_nees_note": "not available"} for k in range(2)]
    df = pd.DataFrame(rows).astype({"pose_nees_mean": object})
    table, _, metrics = aggregate(df)
    assert "ate_rmse_m" in metrics and "pose_nees_mean" not in metrics
    table, _, _ = aggregate(df, metrics=["pose_nees_mean"])
    assert table["n"].tolist() == [0]
    with pytest.raises(ConfigError, match="metric 'pose_nees_note' is not numeric"):
        aggregate(df, metrics=["pose_nees_note"])
