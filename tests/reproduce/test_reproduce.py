"""``slamcli reproduce --quick`` end to end, and honest handling of a missing solver."""

from __future__ import annotations

import re
import shutil
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from conftest import ROOT
from typer.testing import CliRunner

from slamcli.cli import app
from slamcli.reproduce.report import Reproduction

EXPERIMENTS = ROOT / "experiments"  # the shipped files (a wheel: copies in the package)


def _table_rows(report: str, section: str) -> dict[str, list[str]]:
    """Markdown table rows of one report section, keyed by their first cell."""
    body = report.split(f"## {section}", 1)[1].split("\n## ", 1)[0]
    rows = {}
    for line in body.splitlines():
        if line.startswith("| ") and not line.startswith("| quantity") and not line.startswith("| solver"):
            cells = [c.strip() for c in line.strip("|").split("|")]
            rows[cells[0].strip("`")] = cells[1:]
    return rows


@pytest.fixture(scope="module")
def quick_report(tmp_path_factory):
    out = tmp_path_factory.mktemp("reproduce")
    # the packaged experiment files (no --experiments): what a wheel install runs
    res = CliRunner().invoke(app, ["reproduce", "--quick", "--out", str(out), "--quiet"])
    assert res.exit_code == 0, res.output
    assert "all sections' runs completed" in res.output
    report = (out / "REPORT.md").read_text()
    # the CLI's last line is the verdict count, the same count the report opens with
    last = res.output.strip().splitlines()[-1]
    assert re.fullmatch(r"Verdicts: \d+ reproduced / \d+ partly reproduced / \d+ not reproduced paper claims; "
                        r"\d+ findings? of our own\.", last), last
    assert report.splitlines()[2] == f"**{last}** " + report.splitlines()[2].split("** ", 1)[1]
    return out, report


@pytest.mark.slow
def test_quick_report_has_every_section_and_figure(quick_report):
    out, report = quick_report
    for title in ("Fig. 5", "Initialisation study", "Fig. 6", "Fig. 7", "Fig. 9", "ICM as a post-processor",
                  "Solver comparison", "Monte-Carlo pose NEES"):
        assert f"## {title}" in report
    assert "QUICK MODE" in report and "approximate the paper's setting" in report
    figs = re.findall(r"!\[[^\]]*\]\((figures/[^)]+)\)", report)
    assert len(figs) >= 10
    for fig in figs:
        assert (out / fig).stat().st_size > 1000
        assert (out / fig).with_suffix(".pdf").stat().st_size > 1000  # PDF beside every PNG
    assert report.count("Section status:") == 8 and "Every section completed" not in report
    summary = report.split("## Summary", 1)[1].split("\n## ", 1)[0]
    assert "The runs of every section completed. Verdicts: " in summary
    # a section that checks paper claims closes with their verdicts, never with "ok"
    claim_parts = [part for part in report.split("\n## ")[1:] if "**Paper claim" in part]
    # every claim line of the sections is a row of the opening table, and the count adds up
    head = report.split("\n## ", 1)[0]
    table_rows = [ln for ln in head.splitlines() if ln.startswith("| ") and not ln.startswith("| section")]
    n_lines = report.count("**Paper claim — ") + report.count("**Finding — ")
    assert len(table_rows) == n_lines >= 12
    counted = [int(x) for x in re.findall(r"(\d+) (?:reproduced|partly reproduced|not reproduced paper claims|"
                                          r"findings? of our own)", head.splitlines()[2])]
    assert sum(counted) == n_lines
    assert len(claim_parts) >= 5  # Figs 5, 6, 7, 9, post-processing (the init study's answer is a finding)
    for part in claim_parts:
        status = [ln for ln in part.splitlines() if ln.startswith("Section status:")]
        assert len(status) == 1 and "paper claims:" in status[0] and "**ok**" not in status[0]
    assert "0.148" in report and "432.24" in report and "< 35" in report  # the paper's numbers, beside ours


@pytest.mark.slow
def test_quick_report_numbers_come_from_the_runs(quick_report):
    out, report = quick_report
    tidy = pd.read_csv(out / "runs" / "compare" / "results.csv")
    rows = _table_rows(report, "Solver comparison")
    assert set(rows) == set(tidy["label"])  # every registered solver, on the same datasets
    for label, cells in rows.items():
        sub = tidy[(tidy.label == label) & (tidy.status == "completed")]
        assert cells[0] == f"{len(sub)}/{len(tidy[tidy.label == label])}"
        if len(sub):
            ate_mean = float(cells[6].split("±")[0])
            assert ate_mean == pytest.approx(sub["ate_rmse_m"].mean(), abs=1e-3)
    assert tidy.groupby("replicate")["dataset_hash"].nunique().eq(1).all()

    fig5 = pd.read_csv(out / "runs" / "fig5-sim1" / "results.csv")
    s0 = fig5[fig5.label == "icm-S0"]
    assert len(s0) and (s0.status == "completed").all()
    ours = _table_rows(report, "Fig. 5")["final mean landmark error (m, nearest true)"]
    assert ours[0].startswith("0.148") and float(ours[1].split("±")[0]) == pytest.approx(
        s0["paper_err_mean_m"].mean(), abs=1e-3)
    # the outcome sentence states the same numbers and the verdict they imply
    init = _table_rows(report, "Fig. 5")["mean landmark error at the initialisation (m, nearest true)"]
    b, a = float(init[1].split("±")[0]), float(ours[1].split("±")[0])
    verdict = "ICM (icm-S0) lowers" if a < b else "ICM (icm-S0) does not lower"
    assert f"{verdict} the mean landmark error of its initialisation" in report
    assert f"{b:.3f} → {a:.3f} m" in report

    nees = _table_rows(report, "Monte-Carlo pose NEES")
    for cells in nees.values():
        if cells[-1] == "ok":
            assert cells[0] == "3" and cells[1] == "[0.90, 6.34]"  # chi2_9 quantiles 2.700, 19.023, / N=3


def test_missing_solver_is_reported_not_faked(tmp_path):
    exp_dir = tmp_path / "experiments"
    exp_dir.mkdir()
    text = (EXPERIMENTS / "fig9-octagon.toml").read_text().replace('method = "icm"', 'method = "not-a-solver"')
    (exp_dir / "fig9-octagon.toml").write_text(text)
    shutil.copy(EXPERIMENTS / "compare.toml", exp_dir / "compare.toml")
    rep = Reproduction(tmp_path / "out", quick=True, workers=1, experiments_dir=exp_dir, log=lambda s: None)
    sec = rep.octagon_section()
    text = "\n".join(sec.markdown)
    assert "Not run: `icm`" in text and "not-a-solver" in text and "not produced" in text
    assert not sec.figures and "| max per-iteration map change" not in text
    assert not sec.ok and any("not run" in p for p in sec.problems)


@pytest.mark.slow
def test_snapshot_panels_draw_each_iterations_own_trajectory(quick_report, tmp_path):
    from slamcli.io import read_result
    from slamcli.reproduce.report import Section, snapshot_path_xy
    from slamcli.sweep.runner import load_results

    out, report = quick_report
    fig5 = load_results(out / "runs" / "fig5-sim1")  # path columns joined onto the sweep folder
    row = fig5[fig5.status == "completed"].iloc[0]
    result = read_result(Path(row["path"]) / "result.h5")
    assert result.trace.poses_xyt is not None and len(result.trace) >= 3  # ICM records every iteration
    rep = Reproduction(tmp_path / "out", quick=True, workers=1, experiments_dir=EXPERIMENTS, log=lambda s: None)
    sec = Section("t", "t")
    panels = rep._snapshots(sec, "t", row, (0, 1, 10_000), "test")
    last = len(result.trace) - 1
    assert sorted(panels) == [0, 1, last]
    for k, ax in panels.items():
        lines = {ln.get_label(): ln for ln in ax.get_lines()}
        drawn = lines["Estimated trajectory"].get_xydata()
        np.testing.assert_array_equal(drawn, result.trace.poses_at(k)[:, :2])
        np.testing.assert_array_equal(drawn, snapshot_path_xy(result, k))
    np.testing.assert_array_equal(panels[last].get_lines()[2].get_xydata(), result.poses_xyt[:, :2])
    assert not np.array_equal(result.trace.poses_at(0), result.trace.poses_at(1))  # panels really differ
    text = "\n".join(sec.markdown)
    assert "stores no poses" not in text and "trajectory of each panel come from" in text
    assert "trace stores no poses" not in report


def test_snapshot_path_without_trace_poses_only_on_last_panel():
    from slamcli.reproduce.report import snapshot_path_xy
    from slamcli.types import IterationTrace, SolverResult, Status

    poses = np.arange(12.0).reshape(4, 3)
    trace = IterationTrace.from_lists([3.0, 2.0, 1.0], [0.0, 0.1, 0.1], [0.0] * 3, [np.zeros((1, 2))] * 3)
    res = SolverResult(solver="icm", solver_version="0", params={}, status=Status.CONVERGED, message="",
                       poses_xyt=poses, landmarks_xy=np.zeros((1, 2)), assoc=np.zeros(0, np.int64), trace=trace)
    assert snapshot_path_xy(res, 0) is None and snapshot_path_xy(res, 1) is None
    np.testing.assert_array_equal(snapshot_path_xy(res, 2), poses[:, :2])


def test_failed_section_makes_reproduce_exit_nonzero_with_a_summary(tmp_path):
    exp_dir = tmp_path / "experiments"
    exp_dir.mkdir()
    text = (EXPERIMENTS / "fig9-octagon.toml").read_text().replace('method = "icm"', 'method = "not-a-solver"')
    (exp_dir / "fig9-octagon.toml").write_text(text)
    res = CliRunner().invoke(app, ["reproduce", "--quick", "--out", str(tmp_path / "out"), "--experiments",
                                   str(exp_dir), "--section", "fig9", "--quiet"])
    assert res.exit_code == 1
    assert "1 section(s) failed" in res.output and "fig9" in res.output and "not-a-solver" in res.output
    report = (tmp_path / "out" / "REPORT.md").read_text()
    assert "**1 section(s) FAILED**" in report and "Section status: **FAILED**" in report
    bad = CliRunner().invoke(app, ["reproduce", "--quick", "--out", str(tmp_path / "o2"), "--section", "nope"])
    assert bad.exit_code == 1 and "unknown section" in bad.output
    assert "Traceback" not in bad.output and not (tmp_path / "o2").exists()  # nothing created


def test_packaged_experiments_are_the_default_not_the_cwd(tmp_path, monkeypatch):
    from slamcli.reproduce.report import default_experiments_dir

    (tmp_path / "experiments").mkdir()
    (tmp_path / "experiments" / "fig5-sim1.toml").write_text("not toml [")
    monkeypatch.chdir(tmp_path)
    d = default_experiments_dir()
    assert d == EXPERIMENTS and (d / "fig5-sim1.toml").read_text() != "not toml ["
    assert {p.name for p in d.glob("*.toml")} >= {"fig5-sim1.toml", "fig5-mobilesim.toml", "fig6-kinematic.toml",
                                                   "fig7-sim2.toml", "fig9-octagon.toml", "compare.toml", "nees.toml"}
    import tomllib

    pyproject = tomllib.loads((ROOT / "pyproject.toml").read_text())
    assert "*.toml" in pyproject["tool"]["setuptools"]["package-data"]["slamcli.experiments"]


@pytest.mark.slow
def test_report_cites_nothing_outside_the_repository(quick_report):
    out, report = quick_report
    repo = ROOT
    for bad in ("EVALUATION-METHOD", "/work/", "shared/", "STYLE-ANCHORS"):
        assert bad not in report
    for ref in set(re.findall(r"`((?:slamcli|benchmarks|tests)/[^`\s]+)`", report)):
        assert (repo / ref).exists(), ref


@pytest.mark.slow
def test_figures_reference_lines_panel_letters_log_nees(quick_report, monkeypatch):
    out, _ = quick_report
    rep = Reproduction(out, quick=True, workers=1, experiments_dir=EXPERIMENTS, log=lambda s: None)
    saved = {}

    def keep(self, sec, fig, name):
        saved[name] = fig

    monkeypatch.setattr(Reproduction, "_save", keep)
    rep.nees_section()  # finished runs are reused
    rep.fig5_section()
    rep.octagon_section()
    for ax in saved["nees"].axes:
        assert ax.get_yscale() == "log" and ax.get_title().startswith("(")
    err_axes = saved["fig5_errors"].axes
    assert [ax.get_title()[:3] for ax in err_axes][:2] == ["(e)", "(f)"]  # as the paper's Fig. 5e (S = 0), 5f (S = I)
    for ax in err_axes:
        assert any(np.allclose(ln.get_ydata(), 0.148) for ln in ax.get_lines())  # the paper's value
    assert [ax.get_title()[:3] for ax in saved["fig5_maps"].axes] == ["(a)", "(b)"]
    ax9 = saved["fig9_map_change"].axes[0]
    assert any(np.allclose(ln.get_ydata(), 35.0) for ln in ax9.get_lines())
    # the log axis shows the map-change curves: a positive lower limit, and every curve's points inside the limits
    lo, hi = ax9.get_ylim()
    assert ax9.get_yscale() == "log" and lo > 0
    curves = [np.asarray(ln.get_ydata(), float) for ln in ax9.get_lines() if len(ln.get_ydata()) > 2]
    assert curves and all(((c >= lo) & (c <= hi)).all() for c in curves)


def _stat(init, final, below, iters=30):
    return {"init_err": init, "final_err": final, "first_below_1mm": below, "iterations": iters}


def test_icm_figure_sentences_flip_with_the_numbers():
    from slamcli.reproduce.report import Section

    def text(stats, **kw):
        sec = Section("t", "t")
        Reproduction._icm_checks(sec, stats, list(stats), **kw)
        return "\n".join(sec.markdown)

    good = {"icm-S0": [_stat(0.5, 0.2, 20), _stat(0.6, 0.25, 22)], "icm-SI": [_stat(0.5, 0.2, 10), _stat(0.6, 0.2, 12)]}
    bad = {"icm-S0": [_stat(0.3, 0.35, None), _stat(0.3, 0.31, None)], "icm-SI": [_stat(0.3, 0.4, 25), _stat(0.3, 0.4, 28)]}
    t = text(good, paper_final=0.148)
    assert "ICM (icm-S0) lowers the mean landmark error of its initialisation in every seed" in t
    assert "is above the paper's 0.148 m" in t and "icm-SI converges faster than icm-S0" in t
    t = text(bad, paper_final=0.148)
    assert "ICM (icm-S0) does not lower the mean landmark error of its initialisation in any seed" in t
    assert "icm-SI converges faster than icm-S0" in t  # 26.5 < 31 (never reached counts as 31)
    t = text({"icm-S0": bad["icm-S0"], "icm-SI": bad["icm-S0"]}, paper_final=0.148)
    assert "Neither icm-SI nor icm-S0 reaches" in t
    t = text({"icm-S0": [_stat(0.1, 0.12, 3)], "icm-SI": [_stat(0.1, 0.12, 9)]}, paper_final=0.148)
    assert "is below the paper's 0.148 m" in t and "icm-SI converges slower than icm-S0" in t
    close = text({"icm-S0": [_stat(0.3, 0.31, 3)]}, paper_final=None, close_rel=0.1)
    far = text({"icm-S0": [_stat(0.3, 0.5, 3)]}, paper_final=None, close_rel=0.1)
    assert "ICM converges close to its initialisation" in close and "ICM moves away" in far


def test_icm_figure_claims_are_judged_on_the_paper_configurations_only():
    from slamcli.reproduce.report import Section

    stats = {"icm-S0": [_stat(0.5, 0.2, 20), _stat(0.6, 0.25, 22), _stat(0.55, 0.2, 21)],
             "icm-SI": [_stat(0.5, 0.2, 10), _stat(0.6, 0.2, 12), _stat(0.55, 0.2, 11)],
             "icm-S0-drop": [_stat(0.5, 0.6, 5)] * 3}
    sec = Section("t", "t")
    Reproduction._icm_checks(sec, stats, list(stats), paper_final=None, figure="Fig. 5",
                             paper_labels={"icm-S0", "icm-SI"})
    whats = [j.what for j in sec.claims]
    assert whats == ["ICM corrects the initial map (Fig. 5, `icm-S0`)", "ICM corrects the initial map (Fig. 5, `icm-SI`)",
                     "S = I (odometry used) converges faster than S = 0 (Fig. 5)"]
    assert [j.verdict for j in sec.claims] == ["reproduced"] * 3
    text = "\n".join(sec.markdown)
    assert "ICM (icm-S0-drop) does not lower" in text  # a configuration beyond the paper: a sentence, no verdict
    close = Section("t", "t")
    Reproduction._icm_checks(close, {"icm-S0": [_stat(0.616, 0.807, 3)] * 2}, ["icm-S0"], paper_final=None,
                             close_rel=0.1, figure="Fig. 7", paper_labels={"icm-S0"})
    assert close.claims[0].what.startswith("ICM converges close to its initialisation (Fig. 7")
    assert close.claims[0].verdict == "not reproduced" and "0.616 → 0.807 m" in close.claims[0].numbers


def test_scheduler_without_dask_is_one_line_before_any_section(tmp_path):
    res = CliRunner().invoke(app, ["reproduce", "--quick", "--out", str(tmp_path / "out"), "--section", "real-multi",
                                   "--scheduler", "tcp://127.0.0.1:1"])
    assert res.exit_code == 1 and "--scheduler: only meaningful with --executor dask" in res.output
    assert "Traceback" not in res.output and not (tmp_path / "out").exists()


@pytest.mark.slow
def test_reproduce_section_runs_its_sweep_on_a_dask_cluster(tmp_path):
    """``--executor dask`` (a throw-away LocalCluster): the multi-robot section's runs go through Dask and give
    the same table as the same section run in this process."""
    import re

    tables = []
    for name, extra in (("dask", ["--executor", "dask", "-j", "2"]), ("local", ["-j", "1"])):
        res = CliRunner().invoke(app, ["reproduce", "--quick", "--out", str(tmp_path / name), "--section",
                                       "real-multi", "--quiet", *extra])
        assert res.exit_code == 0, res.output
        text = (tmp_path / name / "REPORT.md").read_text()
        tables.append(re.findall(r"^\| [1-5] \|.*$", text, re.M))
    assert len(tables[0]) == 5 and tables[0] == tables[1]
