"""Long work read from a log: off a terminal, ``solve`` and ``sweep`` print plain progress lines at a bounded
rate (``--quiet`` silences them), and tables are not wrapped at 80 columns."""

from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

import pytest
from typer.testing import CliRunner

from slamcli.api.simulate import simulate_to_file
from slamcli.cli import app
from slamcli.sweep.config import load_experiment
from slamcli.sweep.expand import expand

PROGRESS_RE = re.compile(r"^solve ekf: (\d+)% \((\d+)/(\d+)\)")
#: the progress reporter writes about one line per tenth of the work, plus the first and the last
MAX_LINES = 12


@pytest.fixture(scope="module")
def dataset(tmp_path_factory) -> Path:
    path = tmp_path_factory.mktemp("progress") / "loop.h5"
    simulate_to_file("loop", 1, {"n_steps": 1500}, path)
    return path


def _solve(dataset: Path, out: Path, log: Path, *extra: str) -> str:
    """``slamcli solve`` with stdout and stderr redirected to the file ``log``; returns what the file holds."""
    with log.open("w") as fh:
        proc = subprocess.run([sys.executable, "-m", "slamcli", "solve", str(dataset), "-m", "ekf", "-o", str(out),
                               *extra], stdout=fh, stderr=subprocess.STDOUT, timeout=300, check=False)
    text = log.read_text()
    assert proc.returncode == 0, text
    return text


@pytest.mark.slow
def test_solve_redirected_to_a_file_logs_progress_lines(dataset, tmp_path):
    text = _solve(dataset, tmp_path / "r.h5", tmp_path / "solve.log")
    lines = [ln for ln in text.splitlines() if PROGRESS_RE.match(ln)]
    assert 3 <= len(lines) <= MAX_LINES, text
    pcts = [int(PROGRESS_RE.match(ln)[1]) for ln in lines]
    assert pcts == sorted(pcts) and pcts[-1] == 100 and lines[-1].endswith("done")
    middle = lines[1:-1]
    assert middle and all(re.search(r" [\d.e+]+/s, .* elapsed, ETA \d", ln) for ln in middle), lines
    assert "\r" not in text and "\x1b[" not in text  # no bar redrawn in place, no terminal colour codes
    assert "completed ekf" in text  # the summary still follows


@pytest.mark.slow
def test_quiet_silences_the_progress_lines(dataset, tmp_path):
    text = _solve(dataset, tmp_path / "r.h5", tmp_path / "solve.log", "--quiet")
    assert text == ""


WIDE_EXPERIMENT = """
[experiment]
name = "a-rather-long-experiment-name"

[scenario]
name = "loop"
[scenario.parameters]
n_steps = 50

[[solver]]
method = "ekf"
label = "ekf-maximum-likelihood-association"
[solver.params]
association = "ml"

[sweep]
replicates = 2
grid = { "solver.ekf-maximum-likelihood-association.gate_prob" = [0.95, 0.99], "scenario.sensor.max_range" = [5.0, 10.0] }
"""


def test_sweep_table_off_a_terminal_is_not_wrapped(tmp_path):
    """A dry run whose table is wider than 80 columns keeps one row per run on one line."""
    toml = tmp_path / "wide.toml"
    toml.write_text(WIDE_EXPERIMENT)
    runs = expand(load_experiment(toml)).runs
    # off a terminal and with no COLUMNS (pytest-xdist sets it in its workers)
    r = CliRunner().invoke(app, ["sweep", str(toml), "--dry-run", "-o", str(tmp_path / "res")], env={"COLUMNS": None})
    assert r.exit_code == 0, r.output
    rows = [ln for ln in r.output.splitlines() if any(run.run_id in ln for run in runs)]
    assert len(rows) == len(runs) == 8
    assert all("ekf-maximum-likelihood-association" in ln and ln.rstrip().endswith("│") for ln in rows), r.output
    assert max(len(ln) for ln in rows) > 80  # the case that used to wrap
