"""End-to-end: a small dataset + result written with slamcli.io, evaluated through the API and the CLI."""

import json

import pandas as pd
import pytest
from conftest import make_dataset, make_result
from typer.testing import CliRunner

from slamcli.cli import app
from slamcli.errors import SlamcliError
from slamcli.io import read_result, write_dataset, write_result
from slamcli.types import SolverResult

runner = CliRunner()


@pytest.fixture()
def files(tmp_path):
    ds = make_dataset()
    data = tmp_path / "data.h5"
    write_dataset(data, ds)
    res = tmp_path / "res.h5"
    write_result(res, make_result(ds, data))
    return ds, data, res


def test_evaluate_files_writes_tidy_outputs(files, tmp_path):
    from slamcli.api.evaluate import evaluate_files

    ds, _data, res = files
    out = tmp_path / "ev"
    m = evaluate_files(res, None, out, cutoff=1.0)  # dataset found from the recorded path
    assert m["ate_rmse_m"] == pytest.approx(0.2, abs=1e-12)
    assert m["aligned_ate_rmse_m"] < 1e-9
    assert (m["lm_n_matched"], m["lm_n_missed"], m["lm_n_spurious"]) == (5, 1, 0)
    assert m["pose_nees_mean"] == pytest.approx(1.0, abs=1e-12)  # 0.2² / 0.04 at every step
    assert m["n_iterations"] == 3
    on_disk = json.loads((out / "metrics.json").read_text())
    assert on_disk["ate_rmse_m"] == m["ate_rmse_m"] and on_disk["dataset_hash"].startswith("sha256:")
    it = pd.read_csv(out / "per_iteration.csv")
    assert list(it["iteration"]) == [0, 1, 2]
    assert it["err_mean_m"].iloc[0] > it["err_mean_m"].iloc[2]
    assert len(pd.read_csv(out / "per_step.csv")) == len(ds.truth.poses_xyt)
    lm = pd.read_csv(out / "per_landmark.csv")
    assert len(lm) == 5 and set(lm["assigned_true"]) == {0, 1, 2, 3, 4}
    assert not list(out.glob(".*tmp*"))


def test_hash_mismatch_is_a_clear_error(files, tmp_path):
    from slamcli.api.evaluate import evaluate_files

    _, _, res = files
    other = tmp_path / "other.h5"
    write_dataset(other, make_dataset(seed=5))
    with pytest.raises(SlamcliError, match="hash"):
        evaluate_files(res, other)
    r = runner.invoke(app, ["evaluate", str(res), "--data", str(other), "-o", str(tmp_path / "x")])
    assert r.exit_code == 1
    assert r.output.startswith("error:") and "hash" in r.output and "Traceback" not in r.output
    assert not (tmp_path / "x").exists()


def test_missing_recorded_dataset(files, tmp_path):
    _ds, data, res = files
    data.rename(tmp_path / "moved.h5")
    r = runner.invoke(app, ["evaluate", str(res)])
    assert r.exit_code == 1 and "--data" in r.output
    r = runner.invoke(app, ["evaluate", str(res), "--data", str(tmp_path / "moved.h5"), "-q"])
    assert r.exit_code == 0, r.output
    assert (tmp_path / "res_eval" / "metrics.json").is_file()


def test_cli_evaluate_table_and_not_available(tmp_path):
    ds = make_dataset()
    data = tmp_path / "d.h5"
    write_dataset(data, ds)
    res = tmp_path / "r.h5"
    write_result(res, make_result(ds, data, covariances=False))
    assert read_result(res).pose_cov is None
    r = runner.invoke(app, ["evaluate", str(res), "-o", str(tmp_path / "out"), "--cutoff", "0.5"])
    assert r.exit_code == 0, r.output
    assert "ATE RMSE (unaligned)" in r.output and "OSPA" in r.output
    assert "not available" in r.output
    m = json.loads((tmp_path / "out" / "metrics.json").read_text())
    assert m["pose_nees_mean"] is None and m["pose_nees_note"].startswith("not available")
    assert m["cutoff_m"] == 0.5


def test_bad_cutoff(files):
    _, _, res = files
    r = runner.invoke(app, ["evaluate", str(res), "--cutoff", "0"])
    assert r.exit_code == 1 and "cutoff" in r.output


def test_end_to_end_simulate_solve_evaluate(tmp_path):
    """Real pipeline: loop scenario → odometry solver → evaluate. The odometry solver's path is the dead-reckoned
    odometry, so its ATE must equal the reference odometry ATE computed from the dataset."""
    sim = pytest.importorskip("slamcli.sim")
    from slamcli.api.solve import solve_file

    data = tmp_path / "loop.h5"
    write_dataset(data, sim.simulate_scenario("loop", seed=3))
    res = tmp_path / "odo.h5"
    solve_file(data, "odometry", None, res, seed=0)
    r = runner.invoke(app, ["evaluate", str(res), "-o", str(tmp_path / "ev"), "--rpe-delta", "2", "--rpe-unit", "m"])
    assert r.exit_code == 0, r.output
    m = json.loads((tmp_path / "ev" / "metrics.json").read_text())
    assert m["ate_rmse_m"] == pytest.approx(m["odometry_ate_rmse_m"], rel=1e-9)
    assert m["aligned_ate_rmse_m"] <= m["ate_rmse_m"] + 1e-12
    assert m["rpe_unit"] == "m" and m["rpe_pairs"] > 0
    assert m["pose_nees_mean"] is None  # odometry stores no covariances


@pytest.mark.slow
def test_plot_nees_prints_summary(tmp_path):
    paths = []
    for k in range(2):
        ds = make_dataset(seed=k)
        d = tmp_path / f"d{k}.h5"
        write_dataset(d, ds)
        paths.append(tmp_path / f"r{k}.h5")
        write_result(paths[-1], make_result(ds, d))
    r = runner.invoke(app, ["plot", "nees", *map(str, paths), "-o", str(tmp_path / "n.pdf")])
    assert r.exit_code == 0, r.output
    # every step has error 0.2 m in y with σ² = 0.04 → NEES exactly 1 in both runs; N = 2, d = 3 band
    assert "average pose NEES 1.000" in r.output and "N = 2 runs" in r.output


def test_metrics_json_is_strict_json_with_nan_as_null(tmp_path):
    from slamcli.api.evaluate import evaluate_files

    ds = make_dataset()
    data = tmp_path / "d.h5"
    write_dataset(data, ds)
    r = make_result(ds, data)
    one = SolverResult(r.solver, r.solver_version, {}, r.status, "", r.poses_xyt, r.landmarks_xy[:1], r.assoc,
                       dataset_hash=r.dataset_hash, extra=r.extra)  # 1 landmark: no SE(2) map alignment possible
    write_result(tmp_path / "one.h5", one)
    evaluate_files(tmp_path / "one.h5", out_dir=tmp_path / "ev")

    def reject(name):
        raise AssertionError(f"non-standard JSON constant {name}")

    m = json.loads((tmp_path / "ev" / "metrics.json").read_text(), parse_constant=reject)
    assert m["lm_aligned_rmse_matched_m"] is None and m["lm_n_matched"] == 1
    assert m["per_iteration_note"].startswith("not available")
    assert pd.read_csv(tmp_path / "ev" / "per_iteration.csv").empty
