"""Issue 23 ("nothing lost, ever"): the fault campaign (tests/fault_campaign.py) and the resume / table checks.

The campaign runs ≥ 150 cases in forked children; each must give one ``error:`` line naming the file or
option, a non-zero exit (2 for the output guard), no traceback, no temporary left, every input byte-identical
(sha256 before and after) and a peak RSS below 500 MB. ``python -m benchmarks.faults`` prints the same totals.
"""

from __future__ import annotations

import json
import os

import pandas as pd
import pytest
from fault_campaign import report, run_campaign
from typer.testing import CliRunner

from slamcli.cli import app

runner = CliRunner()


def test_fault_campaign_has_no_traceback_and_loses_nothing(tmp_path):
    t = run_campaign(tmp_path)
    assert t["cases"] >= 150, report(t)
    assert t["traceback"] == 0 and t["loss"] == 0, "\n".join([report(t), *t["problems"]])
    assert not t["problems"], "\n".join([report(t), *t["problems"]])
    assert t["clean"] == t["cases"]
    assert 0 < t["peak_mb"] < 500.0


def _tiny_sweep(tmp_path, name="tiny", replicates=2):
    p = tmp_path / f"{name}.toml"
    p.write_text(f'[experiment]\nname = "{name}"\n[scenario]\nname = "loop"\nparameters = {{n_steps = 30}}\n'
                 f'[[solver]]\nmethod = "odometry"\n[sweep]\nreplicates = {replicates}\n')
    return p


def test_resume_redoes_a_run_whose_metrics_were_corrupted(tmp_path):
    toml = _tiny_sweep(tmp_path)
    assert runner.invoke(app, ["sweep", str(toml), "--out", str(tmp_path / "r"), "-q"]).exit_code == 0
    exp = tmp_path / "r" / "tiny"
    table = pd.read_csv(exp / "results.csv")
    run_id = table.run_id[0]
    good = float(table.ate_rmse_m[0])
    m = json.loads((exp / run_id / "metrics.json").read_text())
    m["ate_rmse_m"] = "lots"
    (exp / run_id / "metrics.json").write_text(json.dumps(m))
    res = runner.invoke(app, ["sweep", str(toml), "--out", str(tmp_path / "r"), "-q"])
    assert res.exit_code == 0, res.output
    after = pd.read_csv(exp / "results.csv").set_index("run_id")
    assert "lots" not in (exp / "results.csv").read_text()
    assert after.ate_rmse_m[run_id] == pytest.approx(good, rel=0, abs=0)  # recomputed: the same seeded run
    assert json.loads((exp / run_id / "metrics.json").read_text())["ate_rmse_m"] == good
    # an untouched run is skipped, not redone: its status.json is the same file
    other = table.run_id[1]
    assert json.loads((exp / other / "status.json").read_text())["sha256"]["metrics.json"].startswith("sha256:")
    assert runner.invoke(app, ["aggregate", str(exp), "-m", "ate_rmse_m", "-q"]).exit_code == 0


def test_results_paths_are_relative_and_equal_for_one_and_two_workers(tmp_path):
    toml = _tiny_sweep(tmp_path, "paths")
    os.chdir(tmp_path)
    assert runner.invoke(app, ["sweep", str(toml), "--out", "one", "-q"]).exit_code == 0
    assert runner.invoke(app, ["sweep", str(toml), "--out", str(tmp_path / "two"), "-j", "2", "-q"]).exit_code == 0
    a = pd.read_csv(tmp_path / "one" / "paths" / "results.csv")
    b = pd.read_csv(tmp_path / "two" / "paths" / "results.csv")
    cols = [c for c in a.columns if c == "path" or c.endswith("_path")]
    assert {"path", "result_path", "dataset_path"} <= set(cols)
    for c in cols:
        assert list(a[c]) == list(b[c]), c
        assert not any(os.path.isabs(v) for v in a[c])
    assert list(a.result_path) == [f"{r}/result.h5" for r in a.run_id]
    from slamcli.sweep.runner import load_results

    back = load_results(tmp_path / "two" / "paths")  # joined onto the sweep folder again
    assert all(os.path.isfile(p) for p in back.result_path)


def test_force_replaces_a_file_of_another_kind_and_same_kind_needs_none(tmp_path):
    from slamcli.api.simulate import simulate_to_file

    ds = tmp_path / "d.h5"
    simulate_to_file("loop", 0, {"n_steps": 20}, ds)
    notes = tmp_path / "notes.txt"
    notes.write_text("x")
    args = ["solve", str(ds), "-m", "odometry", "-q", "-o"]
    assert runner.invoke(app, [*args, str(notes)]).exit_code == 2 and notes.read_text() == "x"
    assert runner.invoke(app, [*args, str(notes), "--force"]).exit_code == 0 and notes.read_bytes()[:4] == b"\x89HDF"
    assert runner.invoke(app, [*args, str(notes)]).exit_code == 0  # a result over a result: re-running is the point


def test_a_previous_output_inside_an_input_folder_may_be_replaced_an_input_may_not(tmp_path):
    import shutil

    from fault_campaign import DATA, sha

    d = tmp_path / "mr"
    shutil.copytree(DATA / "mrclam_excerpt", d)
    args = ["import", "mrclam", str(d), "-q", "-o"]
    assert runner.invoke(app, [*args, str(d / "r1.h5")]).exit_code == 0
    assert runner.invoke(app, [*args, str(d / "r1.h5")]).exit_code == 0  # re-running the import
    before = sha(d / "Robot1_Odometry.dat")
    res = runner.invoke(app, [*args, str(d / "Robot1_Odometry.dat")])
    assert res.exit_code == 2 and sha(d / "Robot1_Odometry.dat") == before
