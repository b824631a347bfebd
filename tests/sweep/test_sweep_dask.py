"""A sweep on a real ``distributed`` cluster (``dask scheduler`` + two ``dask worker`` processes on 127.0.0.1)
started from another working directory than the workers', with a relative ``-o``, a worker killed mid-run."""

from __future__ import annotations

import contextlib
import os
import re
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

pytest.importorskip("distributed")

EXPERIMENT = """
[experiment]
name = "dask-relative"
root_seed = 5

[scenario]
name = "loop"
[scenario.parameters]
n_steps = 2000

[[solver]]
method = "odometry"

[[solver]]
method = "ekf"
oracle_association = true

[sweep]
replicates = 3
"""

#: how long the cluster may take to come up, and a whole sweep to finish, on a loaded machine
START_TIMEOUT_S = 90.0
SWEEP_TIMEOUT_S = 300.0
#: columns that differ between two honest executions of the same run (clocks, where, which process)
VOLATILE = ("wall_time_s", "solve_time_s", "solve_cpu_s", "metric.wall_time_s", "path", "dataset_path", "result_path")
SUMMARY_RE = re.compile(r"(\d+) done, (\d+) failed, (\d+) skipped of (\d+)")


def _free_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _wait_for_port(port: int, proc: subprocess.Popen) -> None:
    deadline = time.monotonic() + START_TIMEOUT_S
    while time.monotonic() < deadline:
        assert proc.poll() is None, "the dask scheduler exited while starting"
        with contextlib.suppress(OSError), socket.create_connection(("127.0.0.1", port), timeout=1):
            return
        time.sleep(0.2)
    raise AssertionError(f"no dask scheduler on 127.0.0.1:{port} after {START_TIMEOUT_S} s")


def _wait_for_workers(address: str, n: int) -> None:
    from distributed import Client

    with Client(address, timeout=f"{START_TIMEOUT_S}s") as client:
        client.wait_for_workers(n, timeout=START_TIMEOUT_S)


@contextlib.contextmanager
def _dask_cluster(scheduler_dir: Path, worker_dirs: list[Path]):
    """A ``dask scheduler`` and one ``dask worker --nthreads 1 --no-nanny`` per folder (its working directory)
    on 127.0.0.1; yields ``(address, processes)`` (scheduler first) and stops them all, by PID, on exit.
    Without a nanny the process started here runs the tasks (its pid names the run's temporary folder), so
    killing it kills a worker mid-run."""
    port = _free_port()
    address = f"tcp://127.0.0.1:{port}"
    env = dict(os.environ, OMP_NUM_THREADS="1", OPENBLAS_NUM_THREADS="1", MKL_NUM_THREADS="1")
    procs: list[subprocess.Popen] = []
    try:
        procs.append(subprocess.Popen(
            [sys.executable, "-m", "dask", "scheduler", "--host", "127.0.0.1", "--port", str(port),
             "--no-dashboard"], cwd=scheduler_dir, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL))
        _wait_for_port(port, procs[0])
        for d in worker_dirs:
            d.mkdir(exist_ok=True)
            procs.append(subprocess.Popen(
                [sys.executable, "-m", "dask", "worker", address, "--nthreads", "1", "--no-nanny",
                 "--host", "127.0.0.1", "--no-dashboard"],
                cwd=d, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL))
        _wait_for_workers(address, len(worker_dirs))
        yield address, procs
    finally:
        for p in reversed(procs):
            if p.poll() is None:
                p.send_signal(signal.SIGTERM)
        for p in procs:
            with contextlib.suppress(subprocess.TimeoutExpired):
                p.wait(timeout=30)
            if p.poll() is None:
                p.kill()
                p.wait()


def _sweep(cwd: Path, *args: str, wait: bool = True):
    cmd = [sys.executable, "-m", "slamcli", "sweep", "exp.toml", "-o", "res", "--quiet", *args]
    proc = subprocess.Popen(cmd, cwd=cwd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    if not wait:
        return proc
    out, err = proc.communicate(timeout=SWEEP_TIMEOUT_S)
    return proc.returncode, out + err


def _counts(text: str) -> tuple[int, int, int, int]:
    m = SUMMARY_RE.search(text)
    assert m, text
    return tuple(int(g) for g in m.groups())


def _kill_when_running(proc: subprocess.Popen, sweep: subprocess.Popen, exp_dir: Path) -> None:
    """SIGKILL the worker ``proc`` once a run has finished and the worker holds a run's temporary folder."""
    deadline = time.monotonic() + SWEEP_TIMEOUT_S
    mine = f".tmp-{proc.pid}-"
    while time.monotonic() < deadline and sweep.poll() is None:
        if exp_dir.is_dir():
            names = [p.name for p in exp_dir.iterdir()]
            finished = [n for n in names if (exp_dir / n / "status.json").is_file()]
            if finished and any(mine in n and n.startswith(".") for n in names):
                proc.kill()
                proc.wait(timeout=30)
                return
        time.sleep(0.02)
    raise AssertionError("the sweep ended before the worker could be killed mid-run")


def _numbers_equal(a_csv: Path, b_csv: Path) -> None:
    """Two sweeps' results.csv: the same runs, all completed, every column equal but the volatile ones."""
    a = pd.read_csv(a_csv).set_index("run_id").sort_index()
    b = pd.read_csv(b_csv).set_index("run_id").sort_index()
    assert list(a.index) == list(b.index) and set(a["status"]) == {"completed"}
    compared = [c for c in b.columns if c not in VOLATILE]
    numeric = [c for c in compared if pd.api.types.is_numeric_dtype(b[c])]
    np.testing.assert_array_equal(a[numeric].to_numpy(float), b[numeric].to_numpy(float))
    text_cols = [c for c in compared if c not in numeric]
    pd.testing.assert_frame_equal(a[text_cols], b[text_cols])


@pytest.mark.slow
def test_dask_sweep_with_relative_out_keeps_results_survives_a_killed_worker_and_resumes(tmp_path):
    client_dir = tmp_path / "client"
    client_dir.mkdir()
    (client_dir / "exp.toml").write_text(EXPERIMENT)
    worker_dirs = [tmp_path / f"worker{i}" for i in range(2)]
    exp_dir = client_dir / "res" / "dask-relative"
    with _dask_cluster(tmp_path, worker_dirs) as (address, procs):
        sweep = _sweep(client_dir, "--executor", "dask", "--scheduler", address, wait=False)
        _kill_when_running(procs[2], sweep, exp_dir)
        out, err = sweep.communicate(timeout=SWEEP_TIMEOUT_S)
        # the scheduler hands the killed worker's task to the other worker: nothing is lost
        assert _counts(out + err) == (6, 0, 0, 6), out + err

        # every run is in the client's -o folder, nothing in the workers' working directories
        assert not [p for d in worker_dirs for p in d.rglob("status.json")]
        rc, text = _sweep(client_dir, "--executor", "dask", "--scheduler", address)
        assert rc == 0, text
        assert _counts(text) == (0, 0, 6, 6)  # the resume finds every finished run

    assert not any(".tmp-" in p.name for p in exp_dir.iterdir())  # the killed worker's run folder is gone
    serial_dir = tmp_path / "serial"
    serial_dir.mkdir()
    (serial_dir / "exp.toml").write_text(EXPERIMENT)
    rc, text = _sweep(serial_dir, "-j", "1")
    assert rc == 0 and _counts(text) == (6, 0, 0, 6), text
    serial_csv = serial_dir / "res" / "dask-relative" / "results.csv"
    assert pd.read_csv(serial_csv)["ate_rmse_m"].notna().all()
    _numbers_equal(exp_dir / "results.csv", serial_csv)


# -- one experiment file over recordings and a simulation: -j 2 with a kill, then the same file on Dask -----

MIXED = """
[experiment]
name = "real-mixed"
root_seed = 11
{robots}
[[data]]
recording = "victoria-park"
duration = 300
label = "victoria-park-300s"

[[data]]
recording = "acfr-carpark"

[[data]]
scenario = "loop"
[data.parameters]
n_steps = 600

[[solver]]
method = "ekf"
[solver.params]
association = "auto"

[[solver]]
method = "graph"
[solver.params]
association = "auto"

[[solver]]
method = "isam"
[solver.params]
association = "auto"

[[solver]]
method = "icm"
label = "icm-real"
[solver.params]
preset = "real"

[sweep]
replicates = 2
""".format(robots="".join(f'\n[[data]]\nrecording = "mrclam7"\nrobot = {r}\nlabel = "mrclam7-r{r}"\n'
                          for r in range(1, 6)))
#: 5 MRCLAM robots + Victoria Park + car park (one replicate each) + loop × 2 replicates, times 4 solvers
MIXED_RUNS = (5 + 1 + 1 + 2) * 4


def _kill_sweep_after_first_run(sweep: subprocess.Popen, exp_dir: Path) -> None:
    """SIGKILL the whole sweep (its process group: the client and its pool) once a run has finished."""
    deadline = time.monotonic() + SWEEP_TIMEOUT_S
    while time.monotonic() < deadline and sweep.poll() is None:
        if exp_dir.is_dir() and any((p / "status.json").is_file() for p in exp_dir.iterdir() if p.is_dir()):
            os.killpg(sweep.pid, signal.SIGKILL)
            sweep.wait(timeout=30)
            return
        time.sleep(0.05)
    raise AssertionError("the sweep ended before it could be killed mid-run")


@pytest.mark.slow
def test_recordings_and_a_simulation_in_one_file_local_kill_resume_leaderboard_then_dask(tmp_path,
                                                                                       shared_datasets):
    shared_datasets({"mrclam_dataset7": "mrclam_team_excerpt", "acfr_carpark": "carpark_excerpt",
                     "victoria_park": "victoria_park_excerpt"})
    local = tmp_path / "local"
    local.mkdir()
    (local / "exp.toml").write_text(MIXED)
    exp_dir = local / "res" / "real-mixed"

    cmd = [sys.executable, "-m", "slamcli", "sweep", "exp.toml", "-o", "res", "--quiet", "-j", "2"]
    sweep = subprocess.Popen(cmd, cwd=local, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                             start_new_session=True)
    _kill_sweep_after_first_run(sweep, exp_dir)
    rc, text = _sweep(local, "-j", "2")
    assert rc == 0, text
    done, failed, skipped, total = _counts(text)
    assert (failed, total) == (0, MIXED_RUNS) and skipped >= 1 and done + skipped == MIXED_RUNS, text
    table = pd.read_csv(exp_dir / "results.csv")
    # each run names its dataset and the reference it is scored against (truth, GPS or the survey)
    by_data = table.groupby("data")["reference"].first().to_dict()
    assert set(by_data) == {f"mrclam7-r{r}" for r in range(1, 6)} | {"victoria-park-300s", "acfr-carpark", "loop"}
    assert by_data["loop"] == "truth" and by_data["mrclam7-r1"] == "truth" and by_data["victoria-park-300s"] == "gps"

    res = subprocess.run([sys.executable, "-m", "slamcli", "aggregate", "res/real-mixed", "--leaderboard",
                          "--baseline", "graph"], cwd=local, capture_output=True, text=True, timeout=120)
    assert res.returncode == 0, res.stderr
    board = pd.read_csv(exp_dir / "leaderboard.csv")
    ate = board[board["metric"] == "ate_reference_m"]
    assert set(ate["label"]) == {"ekf", "graph", "isam", "icm-real"}
    assert set(ate["data"]) == set(by_data)
    # the paired test against graph is defined where there are replicates (the simulation: 2 pairs)
    loop = ate[(ate["data"] == "loop") & (ate["label"] != "graph")]
    assert (loop["n_pairs"] == 2).all() and loop["mean_diff"].notna().all()
    assert ate[ate["label"] == "graph"]["mean_diff"].isna().all()

    # the same file, unchanged, on a dask scheduler with two workers: the same numbers run for run
    remote = tmp_path / "remote"
    remote.mkdir()
    (remote / "exp.toml").write_text(MIXED)
    with _dask_cluster(tmp_path, [tmp_path / "worker0", tmp_path / "worker1"]) as (address, _):
        rc, text = _sweep(remote, "--executor", "dask", "--scheduler", address)
        assert rc == 0 and _counts(text) == (MIXED_RUNS, 0, 0, MIXED_RUNS), text
    _numbers_equal(remote / "res" / "real-mixed" / "results.csv", exp_dir / "results.csv")
