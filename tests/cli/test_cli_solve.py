"""``slamcli solve`` and ``slamcli.api.solve``: happy paths, recorded provenance, and every failure mode
ending in exit 1, one line on stderr, no traceback and no output file."""

from __future__ import annotations

import os
import subprocess
import sys

import numpy as np
import pytest
from conftest import tiny_dataset
from typer.testing import CliRunner

from slamcli.api.solve import solve_dataset, solve_file
from slamcli.cli import app
from slamcli.errors import ConfigError, PluginError, SolverError
from slamcli.io import dataset_hash, read_dataset, read_result, write_dataset, write_result
from slamcli.solvers.odometry import OdometrySolver
from slamcli.types import Status

runner = CliRunner()


@pytest.fixture()
def data(tmp_path):
    return write_dataset(tmp_path / "data.h5", tiny_dataset(T=60, n_landmarks=6, seed=2))


def run(*args):
    return runner.invoke(app, [str(a) for a in args], terminal_width=200)


def assert_one_line_error(res, *fragments, code=1):
    assert res.exit_code == code, res.output
    lines = res.stderr.strip().splitlines()
    assert len(lines) == 1, res.stderr
    assert lines[0].startswith("error: ")
    assert "Traceback" not in res.output
    for f in fragments:
        assert f in lines[0], lines[0]


# -- happy paths -----------------------------------------------------------------------------------------
def test_solve_writes_result_with_provenance(data, tmp_path):
    out = tmp_path / "res" / "r.h5"
    res = run("solve", data, "--method", "odometry", "--param", "nn_threshold=0.5", "-o", out)
    assert res.exit_code == 0, res.output
    assert "completed" in res.stdout and "landmarks" in res.stdout and str(out) in res.stdout
    r = read_result(out)
    ds = read_dataset(data)
    assert r.solver == "odometry" and r.status is Status.COMPLETED
    assert r.params == {"use_reported_ids": True, "nn_threshold": 0.5, "min_support": 1}
    assert r.dataset_hash == dataset_hash(ds)
    assert r.extra["dataset_path"] == str(data.resolve())
    assert r.extra["used_truth_association"] is False and r.extra["seed"] == 0
    # the CLI result equals the in-memory API result on the inputs alone
    ref = solve_dataset(ds.inputs, "odometry", {"nn_threshold": 0.5})
    np.testing.assert_array_equal(r.poses_xyt, ref.poses_xyt)
    np.testing.assert_array_equal(r.assoc, ref.assoc)
    np.testing.assert_array_equal(r.landmarks_xy, ref.landmarks_xy)
    assert os.listdir(out.parent) == ["r.h5"]


def test_quiet_prints_nothing(data, tmp_path):
    res = run("solve", data, "--method", "odometry", "--quiet", "-o", tmp_path / "r.h5")
    assert res.exit_code == 0 and res.stdout == "" and res.stderr == ""


def test_oracle_association_is_explicit_and_recorded(data, tmp_path):
    out = tmp_path / "r.h5"
    res = run("solve", data, "--method", "odometry", "--oracle-association", "-o", out)
    assert res.exit_code == 0 and "oracle association" in res.stdout
    r = read_result(out)
    assert r.extra["used_truth_association"] is True
    truth = read_dataset(data).truth.obs_landmark
    real = truth >= 0
    # with the true labels as reported ids every estimated landmark gathers exactly one true landmark
    for k in np.unique(r.assoc[real]):
        assert len(np.unique(truth[real & (r.assoc == k)])) == 1
    assert len(np.unique(r.assoc[real])) == len(np.unique(truth[real]))


def test_oracle_needs_truth(tmp_path):
    import dataclasses

    ds = tiny_dataset(T=10)
    p = write_dataset(tmp_path / "nt.h5", dataclasses.replace(ds, truth=None))
    with pytest.raises(ConfigError, match="has no /truth group"):
        solve_file(p, "odometry", {}, tmp_path / "r.h5", oracle_association=True)
    assert not (tmp_path / "r.h5").exists()


def test_init_path_recorded_and_checked(data, tmp_path):
    first = tmp_path / "a.h5"
    assert run("solve", data, "--method", "odometry", "-q", "-o", first).exit_code == 0
    res = run("solve", data, "--method", "odometry", "--init", first, "-q", "-o", tmp_path / "b.h5")
    assert res.exit_code == 0, res.output
    assert read_result(tmp_path / "b.h5").extra["init_path"] == str(first.resolve())
    other = write_dataset(tmp_path / "other.h5", tiny_dataset(T=20))
    res = run("solve", other, "--method", "odometry", "--init", first, "-o", tmp_path / "c.h5")
    assert_one_line_error(res, "--init", "61 poses", "has 21")
    assert not (tmp_path / "c.h5").exists()


def test_api_progress_and_seed(data, tmp_path):
    seen = []
    r = solve_file(data, "odometry", ["min_support=2"], tmp_path / "r.h5", seed=11,
                   progress=lambda d, t: seen.append((d, t)))
    assert seen and seen[-1][0] == seen[-1][1]
    assert r.extra["seed"] == 11 and r.params["min_support"] == 2


def test_failed_status_is_still_written(data, tmp_path, monkeypatch):
    def failing(self, inputs, *, init=None, rng, progress=None):
        return self.make_result(status=Status.FAILED, poses_xyt=np.full((inputs.n_poses, 3), np.nan),
                                landmarks_xy=np.zeros((0, 2)), assoc=np.full(len(inputs.observations), -1),
                                t_start=0.0, message="diverged at step 3\x1b[2J")

    monkeypatch.setattr(OdometrySolver, "solve", failing)
    res = run("solve", data, "--method", "odometry", "-o", tmp_path / "r.h5")
    # the complete result records why it failed; the exit status tells scripts (as a sweep run does)
    assert res.exit_code == 1 and "failed" in res.stdout and "diverged at step 3" in res.stdout
    r = read_result(tmp_path / "r.h5")
    assert r.status is Status.FAILED and r.message == "diverged at step 3\x1b[2J"
    assert "\x1b" not in res.stdout and "diverged at step 3\\x1b[2J" in res.stdout  # shown, never obeyed
    res = run("solve", data, "--method", "odometry", "-q", "-o", tmp_path / "q.h5")
    assert res.exit_code == 1 and read_result(tmp_path / "q.h5").status is Status.FAILED
    # -q drops the summary, not the reason: one line on stderr naming the solver, the reason and the file
    assert res.stdout == "" and res.stderr.count("\n") == 1, res.output
    assert res.stderr.startswith("error: odometry failed: diverged at step 3\\x1b[2J; ") and "q.h5" in res.stderr


def test_solver_needing_noise_bounds_refuses_in_one_line(data, tmp_path):
    """cuik is set-membership: without declared error bounds it refuses up front and writes nothing."""
    res = run("solve", data, "--method", "cuik", "-o", tmp_path / "r.h5")
    assert_one_line_error(res, "solver 'cuik' needs guaranteed error bounds", "inputs/noise_bounds",
                          "slamcli simulate -s cuik-room")
    assert not (tmp_path / "r.h5").exists()


# -- failures --------------------------------------------------------------------------------------------
def test_unknown_method(data, tmp_path):
    res = run("solve", data, "--method", "nope", "-o", tmp_path / "r.h5")
    assert_one_line_error(res, "unknown solver 'nope'", "available solvers:", "odometry", "ekf")
    assert not (tmp_path / "r.h5").exists()


def test_unknown_param_lists_known_keys(data, tmp_path):
    res = run("solve", data, "--method", "odometry", "--param", "threshold=1", "-o", tmp_path / "r.h5")
    assert_one_line_error(res, "unknown parameter 'threshold'", "known: min_support, nn_threshold, use_reported_ids")
    assert not (tmp_path / "r.h5").exists()


@pytest.mark.parametrize("bad,fragment", [
    ("nn_threshold=abc", "expected a number"),
    ("min_support=1.5", "expected an integer"),
    ("use_reported_ids=maybe", "expected a boolean"),
    ("nn_threshold=-1", "nn_threshold must be > 0"),
    ("nn_threshold", "expected key=value"),
])
def test_bad_param_value(data, tmp_path, bad, fragment):
    res = run("solve", data, "--method", "odometry", "-p", bad, "-o", tmp_path / "r.h5")
    assert_one_line_error(res, fragment)
    assert not (tmp_path / "r.h5").exists()


def test_missing_input(tmp_path):
    res = run("solve", tmp_path / "nope.h5", "--method", "odometry", "-o", tmp_path / "r.h5")
    assert_one_line_error(res, "no such file")


def test_truncated_input(data, tmp_path):
    with open(data, "r+b") as fh:
        fh.truncate(data.stat().st_size // 2)
    out = tmp_path / "r.h5"
    res = run("solve", data, "--method", "odometry", "-o", out)
    assert_one_line_error(res, str(data), "truncated or corrupt")
    assert sorted(os.listdir(tmp_path)) == ["data.h5"]


def test_result_file_given_as_dataset(data, tmp_path):
    assert run("solve", data, "--method", "odometry", "-q", "-o", tmp_path / "r.h5").exit_code == 0
    res = run("solve", tmp_path / "r.h5", "--method", "odometry", "-o", tmp_path / "r2.h5")
    assert_one_line_error(res, "@schema", "expected 'slamcli.dataset'")


def test_refuses_to_overwrite_the_dataset(data):
    before = data.read_bytes()
    res = run("solve", data, "--method", "odometry", "-o", data)
    assert_one_line_error(res, "refusing to overwrite an input", code=2)  # the output guard's usage error
    assert data.read_bytes() == before


def test_solver_exception_is_one_line_and_writes_nothing(data, tmp_path, monkeypatch):
    def boom(self, inputs, *, init=None, rng, progress=None):
        raise ZeroDivisionError("float division by zero\nsecond line")

    monkeypatch.setattr(OdometrySolver, "solve", boom)
    out = tmp_path / "r.h5"
    res = run("solve", data, "--method", "odometry", "-o", out)
    assert_one_line_error(res, "solver 'odometry' failed: ZeroDivisionError: float division by zero")
    assert not out.exists() and sorted(os.listdir(tmp_path)) == ["data.h5"]
    with pytest.raises(SolverError):
        solve_file(data, "odometry", {}, out)


def test_existing_result_survives_a_failing_solve(data, tmp_path, monkeypatch):
    out = tmp_path / "r.h5"
    assert run("solve", data, "--method", "odometry", "-q", "-o", out).exit_code == 0
    before = out.read_bytes()
    monkeypatch.setattr(OdometrySolver, "solve", lambda *a, **k: 1 / 0)
    assert run("solve", data, "--method", "odometry", "-o", out).exit_code == 1
    assert out.read_bytes() == before


def test_contract_breaking_result_is_rejected(data, tmp_path, monkeypatch):
    real = OdometrySolver.solve

    def short(self, inputs, **kw):
        import dataclasses

        r = real(self, inputs, **kw)
        return dataclasses.replace(r, poses_xyt=r.poses_xyt[:-1])

    monkeypatch.setattr(OdometrySolver, "solve", short)
    # -q: the solver ran and drew its progress bar before its output was rejected; only the error remains
    res = run("solve", data, "--method", "odometry", "-q", "-o", tmp_path / "r.h5")
    assert_one_line_error(res, "returned poses_xyt of shape (60, 3), expected (61, 3)")
    assert not (tmp_path / "r.h5").exists()


def test_api_rejects_a_dataset_instead_of_inputs():
    ds = tiny_dataset(T=5)
    with pytest.raises(TypeError, match="expects SlamInputs"):
        solve_dataset(ds, "odometry", {})
    with pytest.raises(PluginError):
        solve_dataset(ds.inputs, "nope", {})


# -- real processes --------------------------------------------------------------------------------------
def cli(*args):
    return subprocess.run([sys.executable, "-m", "slamcli", *map(str, args)], capture_output=True, text=True,
                          timeout=120, check=False)


@pytest.mark.slow
def test_subprocess_solve_and_corrupt_input(data, tmp_path):
    ok = cli("solve", data, "--method", "odometry", "-o", tmp_path / "r.h5")
    assert ok.returncode == 0, ok.stderr
    assert read_result(tmp_path / "r.h5").status is Status.COMPLETED
    bad = tmp_path / "bad.h5"
    bad.write_bytes(data.read_bytes()[:5000])
    out = tmp_path / "r2.h5"
    res = cli("solve", bad, "--method", "odometry", "-o", out)
    assert res.returncode == 1
    assert res.stderr.strip().count("\n") == 0 and "Traceback" not in res.stderr
    assert "truncated or corrupt" in res.stderr
    assert not out.exists()


def test_result_round_trip_keeps_provenance(data, tmp_path):
    r = solve_file(data, "odometry", {}, tmp_path / "r.h5")
    again = read_result(write_result(tmp_path / "copy.h5", read_result(tmp_path / "r.h5")))
    assert again.extra == r.extra and again.dataset_hash == r.dataset_hash
