"""``slamcli info`` on datasets and results; numbers checked against values computed here."""

from __future__ import annotations

import dataclasses

import h5py
import numpy as np
from conftest import tiny_dataset
from typer.testing import CliRunner

from slamcli.cli import app
from slamcli.io import write_dataset, write_result
from slamcli.types import IterationTrace, SolverResult, Status

runner = CliRunner()


def info(path):
    return runner.invoke(app, ["info", str(path)], terminal_width=250)


def row(stdout: str, label: str) -> str:
    """The value cell of the table row whose first cell is ``label``."""
    for line in stdout.splitlines():
        cells = [c.strip() for c in line.strip("│┃ ").split("│")]
        if cells and cells[0] == label:
            return cells[1]
    raise AssertionError(f"no row {label!r} in\n{stdout}")


def test_dataset_summary(tmp_path):
    ds = tiny_dataset(T=50, n_landmarks=6, seed=4, clutter_every=5, gps_every=10)
    p = write_dataset(tmp_path / "d.h5", ds)
    res = info(p)
    assert res.exit_code == 0, res.output
    out = res.stdout
    n_obs = len(ds.inputs.observations)
    n_clutter = int((ds.truth.obs_landmark < 0).sum())
    assert n_clutter > 0
    length = np.linalg.norm(np.diff(ds.truth.poses_xyt[:, :2], axis=0), axis=1).sum()
    assert row(out, "steps") == "50  (51 poses)"
    assert row(out, "dt / duration") == "0.1 s / 5 s"
    assert row(out, "path length") == f"{length:.4g} m  (true)"
    assert row(out, "observations").startswith(f"{n_obs}  ({n_clutter} clutter")
    assert row(out, "landmarks").startswith("6 true")
    assert row(out, "scenario") == "tiny-test   seed 4"
    assert row(out, "GPS") == "6 fixes, σ 0.3 m"
    assert row(out, "max range") == "6 m"
    # scenario parameters table
    assert row(out, "n_landmarks") == "6" and row(out, "T") == "50"


def test_dataset_without_truth(tmp_path):
    ds = tiny_dataset(T=20)
    p = write_dataset(tmp_path / "d.h5", dataclasses.replace(ds, truth=None))
    res = info(p)
    assert res.exit_code == 0, res.output
    assert row(res.stdout, "path length").endswith("(odometry)")
    assert "no ground truth" in row(res.stdout, "landmarks")


def test_result_summary(tmp_path):
    trace = IterationTrace.from_lists([5.0, 2.0, 1.5, 1.49], [0.0, 0.2, 0.01, 0.001], [0.1] * 4,
                                      [np.zeros((3, 2))] * 4)
    r = SolverResult(solver="icm", solver_version="0.1.0", params={"R": [1.0], "max_iterations": 30},
                     status=Status.CONVERGED, message="map change below tol", poses_xyt=np.zeros((11, 3)),
                     landmarks_xy=np.ones((3, 2)), assoc=np.array([0, 1, 2, -1, 0]), trace=trace,
                     wall_time_s=1.25, dataset_hash="sha256:" + "0" * 64,
                     extra={"dataset_path": "/x/d.h5", "used_truth_association": True})
    p = write_result(tmp_path / "r.h5", r)
    res = info(p)
    assert res.exit_code == 0, res.output
    out = res.stdout
    assert row(out, "solver") == "icm 0.1.0"
    assert row(out, "status") == "converged — map change below tol"
    assert row(out, "iterations") == "3"  # 4 trace rows: the initialisation + 3 iterations
    assert row(out, "landmarks") == "3"
    assert row(out, "associated obs.") == "4 of 5"
    assert row(out, "wall time") == "1.25 s"
    assert row(out, "objective first → last") == "5 → 1.49"
    assert "ORACLE" in row(out, "association")
    assert row(out, "params.max_iterations") == "30"


def test_result_certificate_row_gives_the_reason(tmp_path):
    """A certificate that is not certified shows its reason, never a NaN comparison."""
    reason = "the estimate has non-finite poses"
    cert = {"certified": False, "lambda_min": float("nan"), "eta": float("nan"), "sesync_cost": float("nan"),
            "dual_bound": float("nan"), "suboptimality_bound": float("nan"), "lambda_min_method": "none",
            "reason": reason}
    r = SolverResult(solver="graph", solver_version="0.1.0", params={}, status=Status.CONVERGED, message="m",
                     poses_xyt=np.zeros((3, 3)), landmarks_xy=np.zeros((0, 2)), assoc=np.zeros(0, np.int64),
                     wall_time_s=0.1, dataset_hash="sha256:" + "0" * 64, extra={"certificate": cert})
    res = info(write_result(tmp_path / "c.h5", r))
    assert res.exit_code == 0, res.output
    assert row(res.stdout, "optimality certificate") == f"NOT certified: {reason}"


def test_info_bad_files_are_one_line(tmp_path):
    txt = tmp_path / "a.h5"
    txt.write_text("hello")
    other = tmp_path / "b.h5"
    with h5py.File(other, "w") as f:
        f["x"] = 1
    good = write_dataset(tmp_path / "c.h5", tiny_dataset(T=10))
    trunc = tmp_path / "t.h5"
    trunc.write_bytes(good.read_bytes()[: good.stat().st_size // 3])
    for path, fragment in ((txt, "not an HDF5 file"), (other, "@schema"), (trunc, "truncated or corrupt"),
                           (tmp_path / "missing.h5", "no such file")):
        res = info(path)
        assert res.exit_code == 1
        lines = res.stderr.strip().splitlines()
        assert len(lines) == 1 and fragment in lines[0] and str(path) in lines[0], res.stderr
        assert "Traceback" not in res.output


def test_strings_stored_in_a_file_are_shown_escaped_never_obeyed(tmp_path):
    """Terminal escapes (ESC, BEL, CR, a bidi override) and rich markup in a file's attributes or parameter
    names are printed as escapes, never sent to the terminal as they are."""
    hostile = "x\x1b]0;owned\x07\x1b[2J\r\u202e[bold red]y[/bold red]"
    ds = write_dataset(tmp_path / "d.h5", tiny_dataset(T=10))
    with h5py.File(ds, "r+") as f:
        f.attrs["scenario"] = hostile
        f.attrs["scenario_params_json"] = '{"k\\u001b[31m": "v\\u001b[0m"}'
    r = SolverResult(solver="icm", solver_version="0.1.0", params={}, status=Status.FAILED, message=hostile,
                     poses_xyt=np.zeros((3, 3)), landmarks_xy=np.zeros((0, 2)), assoc=np.zeros(0, int),
                     wall_time_s=0.1, dataset_hash="sha256:" + "0" * 64, extra={})
    rp = write_result(tmp_path / "r.h5", r)
    with h5py.File(rp, "r+") as f:
        f.attrs["solver"] = hostile
    for p in (ds, rp):
        res = info(p)
        assert res.exit_code == 0, res.output
        out = res.stdout
        assert not any(c in out for c in "\x1b\x07\r\u202e"), repr(out)
        assert "\\x1b]0;owned\\x07\\x1b[2J\\r\\u202e[bold red]y[/bold red]" in out  # markup shown as text
    assert "k\\x1b[31m" in info(ds).stdout and "v\\x1b[0m" in info(ds).stdout
