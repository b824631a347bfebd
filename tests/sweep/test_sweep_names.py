"""Experiments by name and Hydra-style overrides (issue 24 item 3).

The shipped experiments live in the top-level ``experiments/`` folder and are resolved by name; overrides
``key=value`` / ``key=v1,v2`` are checked like the TOML (the same one-line errors, "did you mean"), and the
resulting runs equal those of a TOML file that spells the same overrides out (hand-written reference).
"""

from __future__ import annotations

import pytest
from conftest import ROOT
from typer.testing import CliRunner

from slamcli import experiments
from slamcli.cli import app
from slamcli.sweep.config import apply_overrides, load_experiment
from slamcli.sweep.expand import RegistryResolver, expand

runner = CliRunner()


def _run(*args):
    return runner.invoke(app, [str(a) for a in args], terminal_width=200)


def test_shipped_experiments_are_the_top_level_folder_and_listed():
    assert experiments.path() == ROOT / "experiments"  # a checkout: no copies inside the package
    assert not list((ROOT / "slamcli" / "experiments").glob("*.toml"))
    names = experiments.names()
    assert names == sorted(p.stem for p in (ROOT / "experiments").glob("*.toml")) and "compare" in names
    res = _run("sweep", "--list")
    assert res.exit_code == 0 and [line.split()[0] for line in res.stdout.splitlines()] == names
    assert "all solvers, unknown correspondences" in res.stdout
    assert "compare" in _run("sweep", "--help").stdout
    assert experiments.find("../pyproject") is None and experiments.find("compare.toml") == ROOT / "experiments" / "compare.toml"


def _n_solver_configs() -> int:
    """The [[solver]] tables of the shipped compare.toml (one run each per replicate)."""
    return (ROOT / "experiments" / "compare.toml").read_text().count("[[solver]]")


def test_name_resolves_and_unknown_name_is_one_line(tmp_path):
    res = _run("sweep", "compare", "--dry-run", "replicates=1")
    assert res.exit_code == 0, res.output
    assert f"compare: {_n_solver_configs()} runs, 1 datasets" in res.stdout
    res = _run("sweep", "compar", "--dry-run")
    assert res.exit_code == 1 and res.stderr.count("\n") == 1
    assert "compar: no such experiment file, and not a shipped experiment (compare," in res.stderr


def test_overrides_equal_the_same_overrides_written_in_toml(tmp_path):
    """``solver.ekf.gate_prob=0.9,0.99 replicates=3 scenario.n_steps=80`` gives exactly the runs (ids = content
    hashes of the resolved configs) of a copy of compare.toml with a [sweep] grid written by hand."""
    src = (ROOT / "experiments" / "compare.toml").read_text()
    assert "[sweep]\nreplicates = 10\n" in src and "[scenario]\nname = \"loop\"\n" in src
    hand = tmp_path / "compare.toml"
    hand.write_text(src.replace("[sweep]\nreplicates = 10\n",
                                '[sweep]\nreplicates = 3\ngrid = { "solver.ekf.gate_prob" = [0.9, 0.99] }\n')
                       .replace('[scenario]\nname = "loop"\n', '[scenario]\nname = "loop"\n[scenario.parameters]\nn_steps = 80\n'))
    cfg = apply_overrides(load_experiment(experiments.find("compare")),
                          ["solver.ekf.gate_prob=0.9,0.99", "replicates=3", "scenario.n_steps=80"],
                          RegistryResolver().known_keys)
    got, want = expand(cfg), expand(load_experiment(hand))
    # the ekf configuration doubles along the axis, every other configuration runs once per replicate
    assert len(got.runs) == 3 * (_n_solver_configs() + 1) == len(want.runs)
    assert sorted(r.run_id for r in got.runs) == sorted(r.run_id for r in want.runs)
    assert got.axes == ("solver.ekf.gate_prob",)


@pytest.mark.parametrize("item, expected", [
    ("solver.ekf.gate_prb=0.9", "solver.ekf.gate_prb: unknown parameter 'gate_prb' of ekf; did you mean 'gate_prob'?"),
    ("solver.ekf.gate_prob=high", "solver.ekf.gate_prob: expected a number, got 'high'"),
    ("scenario.n_step=3", "scenario.n_step: unknown scenario key 'n_step'; did you mean 'n_steps'?"),
    ("solver.ekff.gate_prob=0.9", "no [[solver]] labelled 'ekff'"),
    ("replicates=0", "replicates: must be >= 1, got 0"),
    ("gate_prob", "'gate_prob': expected key=value or key=v1,v2"),
    ("colour.x=1", "keys must be scenario.<dotted key>, solver.<label>.<param>, evaluate.<option> or data"),
])
def test_bad_overrides_are_one_line_like_the_toml(item, expected):
    res = _run("sweep", "compare", item, "--dry-run")
    assert res.exit_code == 1 and res.stderr.count("\n") == 1 and "Traceback" not in res.output
    assert res.stderr.startswith("error: ") and "(command line): " in res.stderr and expected in res.stderr


def test_fixed_override_replaces_an_axis_and_arrays_stay_one_value():
    base = load_experiment(experiments.find("compare"))
    known = RegistryResolver().known_keys
    cfg = apply_overrides(base, ["solver.ekf.gate_prob=0.9,0.99"], known)
    cfg = apply_overrides(cfg, ["solver.ekf.gate_prob=0.95", "solver.icm.S=[2.0]", "replicates=range(2, 4)"], known)
    assert cfg.sweep.grid == () and cfg.sweep.replicates == (2, 3)
    assert cfg.solver("ekf").params["gate_prob"] == 0.95 and cfg.solver("icm").params["S"] == [2.0]


@pytest.mark.slow
def test_sweep_compare_runs_with_two_workers(tmp_path):
    """The shipped comparison by name through the process pool (-j 2), shortened by overrides."""
    res = _run("sweep", "compare", "-j", "2", "--quick", "replicates=1", "scenario.n_steps=40", "-q",
               "--out", tmp_path)
    assert res.exit_code == 0, res.output
    n = _n_solver_configs()
    assert f"compare: {n} done, 0 failed, 0 skipped of {n}" in res.stderr
    assert (tmp_path / "compare" / "results.csv").is_file()
