"""``slamcli reproduce --quick`` end to end, and honest handling of a missing solver."""

from __future__ import annotations

import re
import shutil
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from typer.testing import CliRunner

from slamcli.cli import app
from slamcli.sweep.reproduce import Reproduction

EXPERIMENTS = Path(__file__).resolve().parents[1] / "experiments"


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
    res = CliRunner().invoke(app, ["reproduce", "--quick", "--out", str(out), "--experiments", str(EXPERIMENTS),
                                   "--quiet"])
    assert res.exit_code == 0, res.output
    return out, (out / "REPORT.md").read_text()


def test_quick_report_has_every_section_and_figure(quick_report):
    out, report = quick_report
    for title in ("Fig. 5", "Fig. 6", "Fig. 7", "Fig. 9", "Solver comparison", "Monte-Carlo pose NEES"):
        assert f"## {title}" in report
    assert "QUICK MODE" in report and "approximate the paper's setting" in report
    for fig in re.findall(r"!\[[^\]]*\]\((figures/[^)]+)\)", report):
        assert (out / fig).stat().st_size > 1000
    assert "0.148" in report and "432.24" in report and "< 35" in report  # the paper's numbers, beside ours


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
    if len(s0) and (s0.status == "completed").all():
        ours = _table_rows(report, "Fig. 5")["final mean landmark error (m, nearest true)"]
        assert ours[0].startswith("0.148") and float(ours[1]) == pytest.approx(s0["paper_err_mean_m"].iloc[0],
                                                                               abs=1e-3)

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


def test_snapshot_panels_draw_each_iterations_own_trajectory(quick_report, tmp_path):
    from slamcli.io import read_result
    from slamcli.sweep.reproduce import Section, snapshot_path_xy

    out, report = quick_report
    fig5 = pd.read_csv(out / "runs" / "fig5-sim1" / "results.csv")
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
    from slamcli.sweep.reproduce import snapshot_path_xy
    from slamcli.types import IterationTrace, SolverResult, Status

    poses = np.arange(12.0).reshape(4, 3)
    trace = IterationTrace.from_lists([3.0, 2.0, 1.0], [0.0, 0.1, 0.1], [0.0] * 3, [np.zeros((1, 2))] * 3)
    res = SolverResult(solver="icm", solver_version="0", params={}, status=Status.CONVERGED, message="",
                       poses_xyt=poses, landmarks_xy=np.zeros((1, 2)), assoc=np.zeros(0, np.int64), trace=trace)
    assert snapshot_path_xy(res, 0) is None and snapshot_path_xy(res, 1) is None
    np.testing.assert_array_equal(snapshot_path_xy(res, 2), poses[:, :2])
