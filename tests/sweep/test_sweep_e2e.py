"""End-to-end sweeps on the real pipeline (simulate → solve → evaluate) and the ``slamcli sweep`` command."""

from __future__ import annotations

import json

import h5py
import numpy as np
import pandas as pd
import pytest
from conftest import ROOT
from typer.testing import CliRunner

from slamcli.cli import app
from slamcli.sweep.config import load_experiment
from slamcli.sweep.expand import dataset_seed, expand
from slamcli.sweep.runner import run_sweep

EXPERIMENT = """
[experiment]
name = "e2e"
root_seed = 11

[scenario]
name = "loop"
[scenario.parameters]
n_steps = 150

[[solver]]
method = "odometry"

[[solver]]
method = "ekf"
oracle_association = true

[evaluate]
cutoff = 1.0

[sweep]
replicates = 2
"""


@pytest.fixture(scope="module")
def swept(tmp_path_factory):
    root = tmp_path_factory.mktemp("e2e")
    path = root / "e2e.toml"
    path.write_text(EXPERIMENT)
    exp = expand(load_experiment(path))
    summary = run_sweep(exp, root / "results")
    return root, path, exp, summary


@pytest.mark.slow
def test_real_pipeline_completes_and_shares_one_dataset_per_replicate(swept):
    root, _, exp, summary = swept
    assert summary.ok, summary.failures
    assert (summary.counts.done, summary.counts.total) == (4, 4)
    exp_dir = root / "results" / "e2e"
    tidy = pd.read_csv(exp_dir / "results.csv")
    assert set(tidy["status"]) == {"completed"}
    for rep in (0, 1):
        rows = tidy[tidy.replicate == rep]
        assert set(rows["label"]) == {"odometry", "ekf"}
        assert rows["dataset_hash"].nunique() == 1  # both solvers solved the same dataset
        assert rows["odometry_ate_rmse_m"].nunique() == 1
        run = next(r for r in exp.runs if r.replicate == rep)
        with h5py.File(exp_dir / "datasets" / f"{run.dataset.dataset_id}.h5", "r") as f:
            assert int(f.attrs["seed"]) == dataset_seed(rep, 11)
    assert tidy[tidy.replicate == 0]["dataset_hash"].iloc[0] != tidy[tidy.replicate == 1]["dataset_hash"].iloc[0]
    # the EKF (true association) beats dead reckoning on average on these replicates
    ate = tidy.groupby("label")["ate_rmse_m"].mean()
    assert ate["ekf"] < ate["odometry"]
    # the EKF reports covariances, the odometry solver does not (metrics say so rather than inventing a number)
    assert tidy[tidy.label == "ekf"]["pose_nees_mean"].notna().all()
    assert tidy[tidy.label == "odometry"]["pose_nees_mean"].isna().all()
    metrics = json.loads((exp_dir / exp.runs[0].run_id / "metrics.json").read_text())
    assert ".tmp-" not in metrics["result_path"] and metrics["result_path"].endswith("result.h5")


def test_cli_resume_skips_everything_and_keeps_numbers(swept):
    root, path, _exp, _ = swept
    before = pd.read_csv(root / "results" / "e2e" / "results.csv")
    res = CliRunner().invoke(app, ["sweep", str(path), "--out", str(root / "results"), "--quiet"])
    assert res.exit_code == 0, res.output
    assert "0 done, 0 failed, 4 skipped of 4" in res.output
    after = pd.read_csv(root / "results" / "e2e" / "results.csv")
    np.testing.assert_array_equal(before["ate_rmse_m"].to_numpy(), after["ate_rmse_m"].to_numpy())
    dry = CliRunner().invoke(app, ["sweep", str(path), "--out", str(root / "results"), "--dry-run"])
    assert dry.exit_code == 0 and "4 completed, 0 to run" in dry.output


def test_cli_failures_exit_nonzero_with_summary(tmp_path):
    path = tmp_path / "bad.toml"
    # EKF with association 'known' on a sensor that reports no ids: every EKF run fails
    path.write_text(EXPERIMENT.replace("oracle_association = true\n", '[solver.params]\nassociation = "known"\n')
                    .replace('name = "e2e"', 'name = "bad"')
                    .replace("replicates = 2", "replicates = 1"))
    res = CliRunner().invoke(app, ["sweep", str(path), "--out", str(tmp_path), "--quiet"])
    assert res.exit_code == 1
    assert "1 done, 1 failed" in res.output and "SolverError" in res.output
    assert (tmp_path / "bad" / "manifest.csv").exists()


def test_cli_config_errors_are_one_line(tmp_path):
    path = tmp_path / "x.toml"
    path.write_text(EXPERIMENT.replace("n_steps = 150", "sensor.colour = 3"))
    res = CliRunner().invoke(app, ["sweep", str(path), "--dry-run"])
    assert res.exit_code == 1
    lines = [ln for ln in res.output.splitlines() if ln.strip()]
    assert len(lines) == 1 and lines[0].startswith(f"error: {path}") and "colour" in lines[0]
    path.write_text(EXPERIMENT.replace('method = "ekf"', 'method = "ekf"\n[solver.params]\nbogus = 1'))
    res = CliRunner().invoke(app, ["sweep", str(path), "--dry-run"])
    assert res.exit_code == 1 and "bogus" in res.output and "Traceback" not in res.output
    path.write_text(EXPERIMENT.replace("cutoff = 1.0", "cutof = 1.0"))
    res = CliRunner().invoke(app, ["sweep", str(path), "--dry-run"])
    assert res.exit_code == 1 and "unknown option 'cutof'" in res.output
    res = CliRunner().invoke(app, ["sweep", str(path), "--executor", "slurm"])
    assert res.exit_code == 2 and "--executor" in res.output and "'local', 'dask'" in res.output


@pytest.mark.slow
def test_experiment_files_in_repo_validate(shared_datasets):
    """Every shipped experiment file parses and expands against the registered solvers and scenarios (the
    recordings they name: the excerpts of tests/data laid out as the shared datasets folder)."""
    from slamcli.solvers import registry

    shared_datasets({"victoria_park": "victoria_park_excerpt", "acfr_carpark": "carpark_excerpt",
                     "mrclam_dataset7": "mrclam_team_excerpt"})

    files = sorted((ROOT / "experiments").glob("*.toml"))
    assert files, "experiments/ holds no experiment files"
    have = set(registry.names())
    for f in files:
        cfg = load_experiment(f)
        if {s.method for s in cfg.solvers} <= have:
            assert expand(cfg).runs
