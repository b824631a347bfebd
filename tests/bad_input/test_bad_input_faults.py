"""Issue 23 ("nothing lost, ever"): the fault campaign (tests/bad_input/fault_campaign.py) and the resume / table checks.

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


@pytest.mark.slow
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


@pytest.mark.slow
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


@pytest.mark.slow
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


def _flip_middle(p):
    """Change one byte in the middle of ``p`` in place (the same inode: every hard link sees it)."""
    with open(p, "r+b") as fh:
        fh.seek(p.stat().st_size // 2)
        b = fh.read(1)
        fh.seek(-1, os.SEEK_CUR)
        fh.write(bytes([b[0] ^ 0xFF]))


@pytest.mark.parametrize("damage", ["config.json", "dataset.h5", "result.h5", "metrics.json", "shared-dataset",
                                    "shared-dataset-replaced", "old-status-truncated-result"])
@pytest.mark.slow
def test_resume_redoes_a_run_whose_kept_files_changed(tmp_path, damage):
    """ISSUE: resume kept runs "completed" over a corrupted dataset.h5 (the hard link of the shared
    datasets/<id>.h5) and over a truncated result.h5 when status.json (an older run) had no sha256. Every
    file a later step reads is hashed; a damaged one, or a status without hashes, means redo. Reference: the
    first, undamaged sweep's table (the redone runs are the same seeded runs)."""
    from slamcli.io import read_dataset, read_result

    toml = _tiny_sweep(tmp_path, "kept", replicates=2)
    assert runner.invoke(app, ["sweep", str(toml), "--out", str(tmp_path / "r"), "-q"]).exit_code == 0
    exp = tmp_path / "r" / "kept"
    first = pd.read_csv(exp / "results.csv").set_index("run_id")
    run_id = first.index[0]
    d = exp / run_id
    status_before = (d / "status.json").read_text()
    shared = exp / "datasets" / f"{json.loads(status_before)['dataset_id']}.h5"
    if damage == "shared-dataset":
        _flip_middle(shared)
    elif damage == "shared-dataset-replaced":  # another inode with other bytes: the runs' links still agree
        data = shared.read_bytes()
        shared.unlink()
        shared.write_bytes(data[: len(data) // 2])
    elif damage == "old-status-truncated-result":
        st = json.loads(status_before)
        del st["sha256"]
        (d / "status.json").write_text(json.dumps(st))
        (d / "result.h5").write_bytes((d / "result.h5").read_bytes()[:1000])
    else:
        _flip_middle(d / damage)
    res = runner.invoke(app, ["sweep", str(toml), "--out", str(tmp_path / "r"), "-q"])
    assert res.exit_code == 0, res.output
    assert (d / "status.json").read_text() != status_before  # redone, not skipped
    after = pd.read_csv(exp / "results.csv").set_index("run_id")
    assert after.ate_rmse_m[run_id] == pytest.approx(first.ate_rmse_m[run_id], rel=0, abs=0)
    for r in first.index:  # every kept or redone run reads back, through its own names and the shared one
        read_dataset(exp / r / "dataset.h5")
        read_result(exp / r / "result.h5")
    read_dataset(shared)
    untouched = [r for r in first.index if r != run_id and damage not in ("shared-dataset",)]
    for r in untouched:  # the other runs were checked and kept (another dataset, or a link still valid)
        assert json.loads((exp / r / "status.json").read_text())["sha256"]["dataset.h5"].startswith("sha256:")
