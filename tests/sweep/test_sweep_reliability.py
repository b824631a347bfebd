"""Sweep reliability (issue 11): failed solver status, worker/coordinator deaths, concurrent sweeps, swapped
dataset caches and run folders that are links or files. Tiny runs (fake pipeline, ≤ 0.5 s each) keep every
kill test to a few seconds.
"""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import pandas as pd
import pytest
from test_sweep_helpers import FakePipeline, fake_experiment
from typer.testing import CliRunner

from slamcli.cli import app
from slamcli.errors import ConfigError
from slamcli.sweep.config import load_experiment
from slamcli.sweep.expand import LiteralResolver, expand
from slamcli.sweep.runner import run_status, run_sweep, sweep_lock

HERE = Path(__file__).parent
ENV = dict(os.environ, PYTHONPATH=str(HERE) + os.pathsep + os.environ.get("PYTHONPATH", ""))
VERSIONS = {"slamcli": "test", "schema": 1}

SLOW = """
import sys
from test_sweep_helpers import FakePipeline, fake_experiment
from slamcli.sweep.expand import LiteralResolver, expand
from slamcli.sweep.runner import run_sweep
out, name, reps, sleep, workers = sys.argv[1], sys.argv[2], int(sys.argv[3]), float(sys.argv[4]), int(sys.argv[5])
cfg = fake_experiment(name, replicates=reps, solvers=[{"method": "a", "params": {"gain": 1.0, "sleep": sleep}}])
exp = expand(cfg, resolver=LiteralResolver(), run_versions={"slamcli": "test", "schema": 1})
s = run_sweep(exp, out, pipeline=FakePipeline(), workers=workers)
print(s.counts.done, s.counts.failed, s.counts.skipped, flush=True)
"""


def _slow_exp(name: str, reps: int, sleep: float):
    cfg = fake_experiment(name, replicates=reps, solvers=[{"method": "a", "params": {"gain": 1.0, "sleep": sleep}}])
    return expand(cfg, resolver=LiteralResolver(), run_versions=VERSIONS)


def _start(out: Path, name: str, reps: int, sleep: float, workers: int) -> subprocess.Popen:
    return subprocess.Popen([sys.executable, "-c", SLOW, str(out), name, str(reps), str(sleep), str(workers)],
                            env=ENV, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)


def _wait_for(cond, timeout: float = 30.0, what: str = "condition") -> None:
    deadline = time.time() + timeout
    while time.time() < deadline:
        if cond():
            return
        time.sleep(0.02)
    raise AssertionError(f"timed out waiting for {what}")


def _run_tmps(exp_dir: Path) -> list[Path]:
    return [p for p in exp_dir.iterdir() if p.name.startswith(".") and ".tmp-" in p.name] if exp_dir.is_dir() else []


def _finished(exp_dir: Path) -> list[str]:
    return [p.name for p in exp_dir.iterdir() if p.is_dir() and not p.name.startswith(".")
            and p.name != "datasets"] if exp_dir.is_dir() else []


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    try:  # a zombie (exited, not yet reaped by init) counts as gone
        return Path(f"/proc/{pid}/stat").read_text().split(")")[-1].split()[0] != "Z"
    except OSError:
        return False


def _workers_of(pid: int) -> list[int]:
    """Pool workers (spawned ``spawn_main`` children) of process ``pid``."""
    kids = []
    for task in Path(f"/proc/{pid}/task").iterdir():
        kids += [int(k) for k in (task / "children").read_text().split()]
    return [k for k in kids if b"spawn_main" in Path(f"/proc/{k}/cmdline").read_bytes()]


# -- a failed solver status fails the run -------------------------------------------------------------------------


@pytest.mark.slow
def test_failed_solver_status_fails_the_run_is_excluded_and_redone(tmp_path):
    """ISSUE High 1: an EKF whose result says ``failed`` was a completed run with an ATE in results.csv."""
    exp = tmp_path / "div.toml"
    exp.write_text("""
[experiment]
name = "div"
root_seed = 3
[scenario]
name = "loop"
[scenario.parameters]
n_steps = 60
[[solver]]
method = "odometry"
[[solver]]
method = "ekf"
params = { motion_std_scale = 1e200, association = "ml" }
[[solver]]
label = "icm2"
method = "icm"
params = { max_sweeps = 2 }
""")
    res = CliRunner().invoke(app, ["sweep", str(exp), "--out", str(tmp_path / "r"), "-q"])
    assert res.exit_code == 1, res.output
    exp_dir = tmp_path / "r" / "div"
    tidy = pd.read_csv(exp_dir / "results.csv").set_index("label")
    assert tidy.loc["ekf", "status"] == "failed" and tidy.loc["ekf", "solver_status"] == "failed"
    assert pd.isna(tidy.loc["ekf", "ate_rmse_m"])  # excluded from the aggregate table
    assert tidy.loc["odometry", "status"] == "completed" and tidy.loc["odometry", "ate_rmse_m"] > 0
    assert tidy.loc["icm2", "status"] == "completed" and tidy.loc["icm2", "solver_status"] == "max_iterations"
    st = json.loads((exp_dir / tidy.loc["ekf", "run_id"] / "status.json").read_text())
    assert st["status"] == "failed" and "non-finite state or covariance" in st["error"]
    assert not (exp_dir / tidy.loc["ekf", "run_id"] / "metrics.json").exists()
    # a resume redoes the failed run (and only it)
    summary = run_sweep(expand(load_experiment(exp)), tmp_path / "r")
    assert (summary.counts.skipped, summary.counts.failed, summary.counts.done) == (2, 1, 0)
    assert not summary.ok


# -- kill tests ------------------------------------------------------------------------------------------------------


@pytest.mark.slow
def test_kill9_single_worker_sweep_leaves_complete_runs_and_resumes(tmp_path):
    proc = _start(tmp_path, "one", 5, 0.3, 1)
    exp_dir = tmp_path / "one"
    _wait_for(lambda: len(_finished(exp_dir)) >= 1 and _run_tmps(exp_dir), what="a finished and a running run")
    proc.kill()
    proc.wait(timeout=10)
    done_before = _finished(exp_dir)
    assert all(run_status(exp_dir, r) == "completed" for r in done_before)
    assert _run_tmps(exp_dir)  # the interrupted run's temporary folder
    summary = run_sweep(_slow_exp("one", 5, 0.3), tmp_path, pipeline=FakePipeline())
    assert summary.ok and summary.counts.skipped == len(done_before)
    assert summary.counts.done == 5 - len(done_before)
    assert not _run_tmps(exp_dir)


@pytest.mark.slow
def test_kill9_of_coordinator_takes_its_workers_down(tmp_path):
    """ISSUE High 3: after kill -9 of a -j 2 sweep its workers kept starting queued runs and then hung."""
    proc = _start(tmp_path, "orphans", 8, 0.5, 2)
    exp_dir = tmp_path / "orphans"
    _wait_for(lambda: len(_run_tmps(exp_dir)) >= 2, what="two runs in flight")
    workers = _workers_of(proc.pid)
    assert len(workers) == 2
    proc.kill()  # the coordinator only, not its process group
    proc.wait(timeout=10)
    _wait_for(lambda: not any(_alive(w) for w in workers), timeout=10, what="workers to exit")
    seen = set(_finished(exp_dir)) | {p.name for p in _run_tmps(exp_dir)}
    time.sleep(1.0)  # nobody starts a queued run any more
    assert set(_finished(exp_dir)) | {p.name for p in _run_tmps(exp_dir)} == seen
    summary = run_sweep(_slow_exp("orphans", 8, 0.0), tmp_path, pipeline=FakePipeline())
    assert summary.ok  # the lock died with the coordinator


@pytest.mark.slow
def test_killed_worker_fails_only_its_run_and_the_pool_is_rebuilt(tmp_path):
    """ISSUE High 3: one killed worker turned every remaining run into 'failed' (BrokenProcessPool)."""
    exp = _slow_exp("victim", 6, 0.4)
    exp_dir = tmp_path / "victim"
    killed: list[int] = []

    def killer() -> None:
        deadline = time.time() + 60
        while time.time() < deadline and not killed:
            for p in _run_tmps(exp_dir):
                pid = int(p.name.split(".tmp-")[1].split("-")[0])
                if pid != os.getpid():
                    os.kill(pid, signal.SIGKILL)
                    killed.append(pid)
                    return
            time.sleep(0.02)

    t = threading.Thread(target=killer, daemon=True)
    t.start()
    summary = run_sweep(exp, tmp_path, pipeline=FakePipeline(), workers=2)
    t.join(timeout=5)
    assert killed
    assert (summary.counts.failed, summary.counts.done) == (1, 5)
    err = summary.failures[0]["error"]
    assert f"process {killed[0]} was killed by signal 9" in err
    manifest = pd.read_csv(exp_dir / "manifest.csv")
    assert sorted(manifest["status"]) == ["completed"] * 5 + ["failed"]
    failed = manifest[manifest.status == "failed"].iloc[0]
    assert "signal 9" in json.loads((exp_dir / failed["run_id"] / "status.json").read_text())["error"]
    assert not _run_tmps(exp_dir)


@pytest.mark.slow
def test_concurrent_sweeps_on_one_folder_second_is_refused(tmp_path):
    """ISSUE High 4: two sweeps on one folder computed every run twice and broke each other's temp files."""
    proc = _start(tmp_path, "shared", 4, 0.3, 1)
    exp_dir = tmp_path / "shared"
    _wait_for(lambda: (exp_dir / ".sweep.pid").is_file() and (exp_dir / ".sweep.pid").read_text().strip(),
              what="the first sweep's lock")  # the pid is written once the lock is held
    with pytest.raises(ConfigError, match=rf"another sweep \(pid {proc.pid}\) is running"):
        run_sweep(_slow_exp("shared", 4, 0.3), tmp_path, pipeline=FakePipeline())
    out, err = proc.communicate(timeout=60)
    assert proc.returncode == 0, err
    assert out.split() == ["4", "0", "0"]  # the first sweep did every run, once
    assert len((exp_dir / "datasets" / "sim_calls.txt").read_text().split()) == 4
    pids = {json.loads((exp_dir / r / "status.json").read_text())["pid"] for r in _finished(exp_dir)}
    assert pids == {proc.pid}


def test_locked_folder_gives_one_line_from_the_cli(tmp_path):
    exp = tmp_path / "lk.toml"
    exp.write_text('[experiment]\nname = "lk"\n[scenario]\nname = "loop"\n[scenario.parameters]\nn_steps = 20\n'
                   '[[solver]]\nmethod = "odometry"\n')
    (tmp_path / "r" / "lk").mkdir(parents=True)
    with sweep_lock(tmp_path / "r" / "lk"):
        res = CliRunner().invoke(app, ["sweep", str(exp), "--out", str(tmp_path / "r"), "-q"])
    assert res.exit_code == 1
    assert res.stderr.strip().count("\n") == 0 and f"another sweep (pid {os.getpid()})" in res.stderr
    assert not _finished(tmp_path / "r" / "lk")


# -- caches and run folders --------------------------------------------------------------------------------------


def test_swapped_cached_dataset_is_simulated_again(tmp_path):
    """ISSUE: a sweep reused a cached dataset file that had been swapped for another."""
    exp = expand(fake_experiment("swap", replicates=2), resolver=LiteralResolver(), run_versions=VERSIONS)
    first = run_sweep(exp, tmp_path, pipeline=FakePipeline())
    assert first.ok
    exp_dir = tmp_path / "swap"
    before = pd.read_csv(exp_dir / "results.csv").set_index("run_id")["value"]
    a, b = exp.runs[0].dataset.dataset_id, next(r.dataset.dataset_id for r in exp.runs
                                                   if r.dataset.dataset_id != exp.runs[0].dataset.dataset_id)
    ds_dir = exp_dir / "datasets"
    (ds_dir / f"{a}.h5").write_bytes((ds_dir / f"{b}.h5").read_bytes())  # swapped for another replicate's
    victim = exp.runs[0].run_id
    import shutil

    shutil.rmtree(exp_dir / victim)  # forces this run to be redone on the cached dataset
    again = run_sweep(exp, tmp_path, pipeline=FakePipeline())
    # the victim, and every other run of dataset a: their dataset.h5 is a hard link to the swapped file, so
    # the files a later step would read no longer match what they recorded (resume hashes what it keeps)
    on_a = [r.run_id for r in exp.runs if r.dataset.dataset_id == a]
    assert again.ok and again.counts.done == len(on_a) >= 2
    after = pd.read_csv(exp_dir / "results.csv").set_index("run_id")["value"]
    assert all(after[r] == before[r] for r in on_a)  # computed on the right data again
    assert (ds_dir / "sim_calls.txt").read_text().split().count(a) == 2


def test_run_folder_that_is_a_symlink_or_a_file_is_replaced(tmp_path):
    """ISSUE: a run folder that is a symlink (rmtree on a symlink) or a plain file gave a traceback."""
    exp = expand(fake_experiment("links", replicates=1), resolver=LiteralResolver(), run_versions=VERSIONS)
    assert run_sweep(exp, tmp_path, pipeline=FakePipeline()).ok
    exp_dir = tmp_path / "links"
    r1, r2 = (r.run_id for r in exp.runs)
    precious = tmp_path / "precious"
    precious.mkdir()
    (precious / "keep.txt").write_text("mine")
    import shutil

    shutil.copytree(exp_dir / r1, precious / "copy")
    shutil.rmtree(exp_dir / r1)
    (exp_dir / r1).symlink_to(precious / "copy", target_is_directory=True)
    shutil.rmtree(exp_dir / r2)
    (exp_dir / r2).write_text("not a folder")
    summary = run_sweep(exp, tmp_path, pipeline=FakePipeline())
    assert summary.ok and summary.counts.done == 2
    for r in (r1, r2):
        assert (exp_dir / r).is_dir() and not (exp_dir / r).is_symlink()
        assert run_status(exp_dir, r) == "completed"
    assert (precious / "keep.txt").read_text() == "mine" and (precious / "copy" / "status.json").is_file()


@pytest.mark.parametrize("against", ['"/etc/passwd"', '"../../x.h5"', "5", "{a = 1}"])
def test_evaluate_against_outside_the_experiment_folder_or_not_a_path_is_one_line(tmp_path, against):
    exp = tmp_path / "exp"
    exp.mkdir()
    toml = exp / "e.toml"
    toml.write_text('[experiment]\nname = "e"\n[scenario]\nname = "loop"\n[[solver]]\nmethod = "odometry"\n'
                    f"[evaluate]\nagainst = {against}\n")
    res = CliRunner().invoke(app, ["sweep", str(toml), "--dry-run", "-o", str(tmp_path / "out")])
    assert res.exit_code != 0 and "Traceback" not in res.output
    lines = res.output.strip().splitlines()
    assert len(lines) == 1 and "evaluate.against" in lines[0] and str(toml) in lines[0], res.output
    assert not (tmp_path / "out").exists()


def test_evaluate_against_beside_the_experiment_is_made_absolute(tmp_path):
    toml = tmp_path / "e.toml"
    toml.write_text('[experiment]\nname = "e"\n[scenario]\nname = "loop"\n[[solver]]\nmethod = "odometry"\n'
                    '[evaluate]\nagainst = "ref/other.h5"\n')
    assert load_experiment(toml).evaluate["against"] == str(tmp_path / "ref" / "other.h5")
