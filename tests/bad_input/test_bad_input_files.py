"""File hygiene and determinism (issue 11): stale temporaries of killed processes, evaluate's output folder
never mixing two runs, timings kept in one documented place, and ``slamcli diff``.
"""

from __future__ import annotations

import json
import os
import re
import shutil
import subprocess
import sys
from pathlib import Path

import h5py
import numpy as np
import pytest
from conftest import ROOT
from test_bad_input_helpers import dead_pid
from typer.testing import CliRunner

from slamcli.api.evaluate import evaluate_files
from slamcli.api.simulate import simulate_to_file
from slamcli.api.solve import solve_file
from slamcli.cli import app
from slamcli.io import read_dataset, read_result
from slamcli.io.atomic import clean_stale_temporaries
from slamcli.io.schema import NONDETERMINISTIC_FIELDS

runner = CliRunner()


@pytest.fixture(scope="module")
def files(tmp_path_factory):
    d = tmp_path_factory.mktemp("hygiene")
    ds = d / "loop.h5"
    simulate_to_file("loop", 5, {"n_steps": 100}, ds)
    a, b = d / "a.h5", d / "b.h5"
    solve_file(ds, "icm", {"max_sweeps": 4}, a, seed=2)
    solve_file(ds, "icm", {"max_sweeps": 4}, b, seed=2)
    return d, ds, a, b


def diff(a, b):
    return runner.invoke(app, ["diff", str(a), str(b)])


# -- stale temporaries ----------------------------------------------------------------------------------------------


def test_temporaries_of_dead_processes_are_removed_by_the_next_write(files, tmp_path):
    """ISSUE: kill -9 of simulate/solve left .NAME.tmp-PID-xxxx files (up to 40 MB) forever."""
    _, ds, _, _ = files
    dead = dead_pid()
    stale_file = tmp_path / f".r.h5.tmp-{dead}-0123abcd"
    stale_file.write_bytes(b"\0" * 100_000)
    stale_dir = tmp_path / f".r_eval.tmp-{dead}-89abcdef"
    stale_dir.mkdir()
    (stale_dir / "metrics.json").write_text("{}")
    live = tmp_path / f".other.h5.tmp-{os.getppid()}-0123abcd"  # a live writer's file is never touched
    live.write_bytes(b"x")
    foreign = tmp_path / ".notes.tmp-keep"  # not our pattern
    foreign.write_text("x")
    res = runner.invoke(app, ["solve", str(ds), "-m", "odometry", "-o", str(tmp_path / "r.h5"), "-q"])
    assert res.exit_code == 0, res.output
    assert not stale_file.exists() and not stale_dir.exists()
    assert live.exists() and foreign.exists()
    assert clean_stale_temporaries(tmp_path) == 0


@pytest.mark.slow
def test_kill9_during_write_then_next_run_cleans_up(files, tmp_path):
    """A real kill -9 in the middle of writing the result: while the HDF5 image is built in memory nothing is
    on disk; once its bytes are in the temporary (the writer SIGKILLs itself after its first os.write) one hidden
    temporary is left, and the next write removes it."""
    _, ds, _, _ = files
    code = f"""
import os, signal
from slamcli.io import atomic, schema
orig = schema.write_array
def dying(*a, **k):
    orig(*a, **k)
    os.kill(os.getpid(), signal.SIGKILL)
schema.write_array = dying
import slamcli.io.result as r
r.write_array = dying
from slamcli.api.solve import solve_file
solve_file({str(ds)!r}, "odometry", {{}}, {str(tmp_path / "r.h5")!r})
"""
    p = subprocess.run([sys.executable, "-c", code], capture_output=True)
    assert p.returncode == -9
    assert not [q for q in tmp_path.iterdir() if ".tmp-" in q.name] and not (tmp_path / "r.h5").exists()
    code = code.replace("schema.write_array = dying", "w = os.write\n"
                        "atomic.os.write = lambda fd, b: (w(fd, b), os.kill(os.getpid(), 9))[0]")
    code = code.replace("r.write_array = dying", "")
    p = subprocess.run([sys.executable, "-c", code], capture_output=True)
    assert p.returncode == -9
    left = [q for q in tmp_path.iterdir() if ".tmp-" in q.name]
    assert len(left) == 1 and not (tmp_path / "r.h5").exists()
    res = runner.invoke(app, ["solve", str(ds), "-m", "odometry", "-o", str(tmp_path / "r2.h5"), "-q"])
    assert res.exit_code == 0
    assert not [q for q in tmp_path.iterdir() if ".tmp-" in q.name]


# -- evaluate writes its folder as a whole -------------------------------------------------------------------------


def _snapshot(d: Path) -> dict[str, bytes]:
    return {p.name: p.read_bytes() for p in sorted(d.iterdir())}


@pytest.mark.slow
def test_evaluate_killed_mid_write_leaves_the_previous_folder_intact(files, tmp_path):
    """ISSUE: kill -9 of evaluate left new files mixed with the previous run's CSVs."""
    _, ds, a, _ = files
    out = tmp_path / "ev"
    evaluate_files(a, ds, out, cutoff=1.0)
    before = _snapshot(out)
    code = f"""
import os, signal, pandas
calls = []
orig = pandas.DataFrame.to_csv
def dying(self, *a, **k):
    calls.append(1)
    if len(calls) == 2:  # metrics.json and per_iteration.csv are written, per_step.csv is half-way
        os.kill(os.getpid(), signal.SIGKILL)
    return orig(self, *a, **k)
pandas.DataFrame.to_csv = dying
from slamcli.api.evaluate import evaluate_files
evaluate_files({str(a)!r}, {str(ds)!r}, {str(out)!r}, cutoff=0.3)
"""
    p = subprocess.run([sys.executable, "-c", code], capture_output=True)
    assert p.returncode == -9
    assert _snapshot(out) == before  # not one new file mixed in
    assert [q for q in tmp_path.iterdir() if ".tmp-" in q.name]  # the dead writer's folder, until next time
    m = evaluate_files(a, ds, out, cutoff=0.3)
    assert json.loads((out / "metrics.json").read_text())["lm_ospa_m"] == pytest.approx(m["lm_ospa_m"])
    assert _snapshot(out) != before
    assert not [q for q in tmp_path.iterdir() if ".tmp-" in q.name]


def test_evaluate_replaces_only_a_folder_it_made(files, tmp_path):
    """ISSUE: ``evaluate -o ev`` deleted ``ev/per_step.csv/thesis.tex`` — entry names were taken for proof that
    evaluate made the folder. Only a folder holding evaluate's marker (and its files) is replaced whole."""
    from slamcli.api.evaluate import EVALUATION_MARKER, OUTPUT_FILES
    from slamcli.errors import SlamcliError

    _, ds, a, _ = files
    out = tmp_path / "ev"
    evaluate_files(a, ds, out)
    assert sorted(p.name for p in out.iterdir()) == sorted((*OUTPUT_FILES, EVALUATION_MARKER))
    (out / "notes.txt").write_text("mine")  # now a user's folder: the four files are replaced in place
    evaluate_files(a, ds, out, cutoff=0.5)
    assert (out / "notes.txt").read_text() == "mine"
    user = tmp_path / "user"
    (user / "per_step.csv").mkdir(parents=True)
    (user / "per_step.csv" / "thesis.tex").write_text("x")
    (user / "metrics.json").write_text("{}")  # no marker: a folder named like outputs is still the user's
    with pytest.raises(SlamcliError, match="per_step.csv: exists and is not a regular file"):
        evaluate_files(a, ds, user)
    assert (user / "per_step.csv" / "thesis.tex").read_text() == "x" and (user / "metrics.json").read_text() == "{}"


def test_evaluate_failure_mid_write_changes_nothing(files, tmp_path, monkeypatch):
    _, ds, a, _ = files
    out = tmp_path / "ev"
    evaluate_files(a, ds, out)
    before = _snapshot(out)
    import pandas

    orig = pandas.DataFrame.to_csv
    calls = []

    def failing(self, *args, **kw):
        calls.append(1)
        if len(calls) == 3:
            raise OSError(28, "No space left on device")
        return orig(self, *args, **kw)

    monkeypatch.setattr(pandas.DataFrame, "to_csv", failing)
    with pytest.raises(Exception, match="No space left"):
        evaluate_files(a, ds, out, cutoff=0.5)
    assert _snapshot(out) == before
    assert not [q for q in tmp_path.iterdir() if ".tmp-" in q.name]


def test_evaluate_into_a_folder_with_other_files_keeps_them(files, tmp_path):
    _, ds, a, _ = files
    out = tmp_path / "mine"
    out.mkdir()
    (out / "notes.txt").write_text("keep me")
    evaluate_files(a, ds, out)
    assert (out / "notes.txt").read_text() == "keep me"
    assert {"metrics.json", "per_step.csv"} <= {p.name for p in out.iterdir()}
    assert not [q for q in out.iterdir() if ".tmp-" in q.name]


# -- determinism: timings in one place, slamcli diff ---------------------------------------------------------------


TIMING_KEY = re.compile(r"(^|_)(s|ms|sec|seconds|time)(_|$)|per_sweep|per_step|wall")


def test_icm_timings_live_in_timings_not_extra(files):
    """ISSUE: ICM's extra_json carried init_s, init_ms_per_step* and s_per_sweep."""
    _, _, a, _ = files
    r = read_result(a)
    assert {"init_s", "init_ms_per_step", "init_ms_per_step_max", "s_per_sweep"} <= set(r.timings)
    assert all(v >= 0 for v in r.timings.values())
    assert not [k for k in r.extra if TIMING_KEY.search(k)], r.extra
    with h5py.File(a, "r") as f:
        assert json.loads(f.attrs["timings_json"]) == r.timings


@pytest.mark.parametrize("method,params", [("ekf", {"association": "ml"}), ("graph", {}),
                                           ("fastslam", {"n_particles": 20, "association": "ml"}), ("odometry", {})])
def test_no_solver_puts_timings_into_extra(files, tmp_path, method, params):
    _, ds, _, _ = files
    r = solve_file(ds, method, params, tmp_path / "r.h5")
    timing_like = [k for k in r.extra if TIMING_KEY.search(k)]
    assert not timing_like, f"{method}: timing keys in extra: {timing_like}"


@pytest.mark.slow
def test_diff_same_seed_is_same_and_ignores_exactly_the_timings(files, tmp_path):
    _, ds, a, b = files
    res = diff(a, b)
    assert res.exit_code == 0, res.output
    assert res.stdout.startswith("same:") and res.stdout.count("\n") == 1
    with h5py.File(a, "r") as fa, h5py.File(b, "r") as fb:  # the files really differ in their timings
        assert fa.attrs["timings_json"] != fb.attrs["timings_json"] or fa.attrs["wall_time_s"] != fb.attrs["wall_time_s"]
    # every ignored field may change ...
    c = tmp_path / "c.h5"
    shutil.copyfile(a, c)
    with h5py.File(c, "r+") as f:
        f.attrs["created_utc"] = "1999-01-01T00:00:00Z"
        f.attrs["wall_time_s"] = 1234.5
        f.attrs["timings_json"] = json.dumps({"init_s": 99.0})
        f["trace/time_s"][...] = 7.0
    assert diff(a, c).exit_code == 0
    assert {"@created_utc", "@wall_time_s", "@timings_json", "trace/time_s"} == set(NONDETERMINISTIC_FIELDS)
    # ... and nothing else may
    for edit, field in ((lambda f: f["poses_xyt"].__setitem__((3, 0), f["poses_xyt"][3, 0] + 1e-12), "poses_xyt"),
                        (lambda f: f.attrs.__setitem__("message", "x"), "@message"),
                        (lambda f: f["trace/objective"].__setitem__(0, 0.0), "trace/objective"),
                        (lambda f: f.attrs.__setitem__("slamcli_version", "0"), "@slamcli_version")):
        d = tmp_path / f"d_{field.replace('/', '_').replace('@', '')}.h5"
        shutil.copyfile(a, d)
        with h5py.File(d, "r+") as f:
            edit(f)
        res = diff(a, d)
        assert res.exit_code == 1, res.output
        assert res.stdout.startswith("different: 1 of") and field in res.stdout


def test_diff_datasets_and_other_seeds(files, tmp_path):
    d, ds, a, _ = files
    ds_again = tmp_path / "again.h5"
    simulate_to_file("loop", 5, {"n_steps": 100}, ds_again)
    res = diff(ds, ds_again)
    assert res.exit_code == 0 and res.stdout.startswith("same:")
    other = tmp_path / "other.h5"
    simulate_to_file("loop", 6, {"n_steps": 100}, other)
    res = diff(ds, other)
    assert res.exit_code == 1 and "@seed" in res.stdout
    s2 = d / "s2.h5"  # beside a.h5: the recorded relative dataset path is the same
    solve_file(ds, "icm", {"max_sweeps": 4}, s2, seed=3)
    res = diff(a, s2)
    assert res.exit_code == 1 and "@extra_json: keys seed 2 vs 3" in res.stdout
    assert diff(a, ds).exit_code == 1  # a result is not a dataset
    bad = runner.invoke(app, ["diff", str(a), str(tmp_path / "missing.h5")])
    assert bad.exit_code == 2 and "missing.h5: no such file" in bad.stderr
    np.testing.assert_array_equal(read_dataset(ds).inputs.controls, read_dataset(ds_again).inputs.controls)


def test_schema_doc_lists_every_nondeterministic_field():
    text = (ROOT / "docs" / "schema.md").read_text()
    section = text.split("## Timings: the only non-deterministic fields", 1)[1].split("\n## ", 1)[0]
    for field in NONDETERMINISTIC_FIELDS:
        assert f"`{field}`" in section
    assert "timings_json" in text.split("## Result schema v1", 1)[1]


def test_a_valid_file_under_a_non_utf8_name_works(files, tmp_path):
    """ISSUE: an input file name that is not valid UTF-8 crashed the error/summary printing."""
    _, ds, _, _ = files
    name = os.fsdecode(bytes(tmp_path) + b"/caf\xe9.h5")
    shutil.copyfile(ds, name)
    res = runner.invoke(app, ["info", name], terminal_width=200)
    assert res.exit_code == 0, res.output
    assert "steps" in res.stdout
