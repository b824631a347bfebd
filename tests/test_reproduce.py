"""``slamcli reproduce --quick`` end to end, and honest handling of a missing solver."""

from __future__ import annotations

import re
import shutil
from pathlib import Path

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
    for label, cells in nees.items():
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
