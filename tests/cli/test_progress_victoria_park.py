"""A Victoria Park solve with its output redirected to a file writes progress lines into that file while it
runs (not only at the end): the excerpt in ``tests/data`` solved by the EKF with maximum-likelihood
association, as the README's long example, with ``> log 2>&1``."""

from __future__ import annotations

import re
import subprocess
import sys
import time

import pytest
from conftest import DATA
from typer.testing import CliRunner

from slamcli.cli import app
from slamcli.io import read_dataset

PROGRESS_RE = re.compile(r"^solve ekf: (\d+)% \((\d+)/(\d+)\)")
#: s between two looks at the log while the solve runs
POLL_S = 0.02
#: s: the whole solve must end within this (the excerpt takes about a second of CPU)
TIMEOUT_S = 300


@pytest.mark.slow
def test_victoria_park_solve_logs_progress_while_it_runs(tmp_path):
    r = CliRunner().invoke(app, ["import", "victoria-park", str(DATA / "victoria_park_excerpt"), "-q",
                                 "-o", str(tmp_path / "vp.h5")])
    assert r.exit_code == 0, r.output
    n_poses = read_dataset(tmp_path / "vp.h5").inputs.n_poses  # the EKF counts one step per pose
    log = tmp_path / "solve.log"
    seen_running: list[str] = []  # progress lines read from the file before the process ended
    with log.open("w") as fh:
        proc = subprocess.Popen([sys.executable, "-m", "slamcli", "solve", str(tmp_path / "vp.h5"), "-m", "ekf", "-p",
                                 "association=ml", "-o", str(tmp_path / "r.h5")], stdout=fh, stderr=subprocess.STDOUT)
        t0 = time.monotonic()
        while proc.poll() is None and time.monotonic() - t0 < TIMEOUT_S:
            lines = [ln for ln in log.read_text().splitlines() if PROGRESS_RE.match(ln)]
            if proc.poll() is None:
                seen_running = lines or seen_running
            time.sleep(POLL_S)
        assert proc.wait(timeout=TIMEOUT_S) == 0, log.read_text()
    text = log.read_text()
    lines = [ln for ln in text.splitlines() if PROGRESS_RE.match(ln)]
    assert seen_running and int(PROGRESS_RE.match(seen_running[0])[1]) < 100  # in the file before the end
    assert lines[-1].endswith("done") and int(PROGRESS_RE.match(lines[-1])[3]) == n_poses
    assert any("ETA" in ln for ln in lines[1:-1]) and "\x1b[" not in text and "\r" not in text
    assert "completed ekf" in text
