"""``[[solver]] init_from``: a run that starts from another run's result on the same dataset.

Parse-time errors, expansion order and ids, execution order (in this process and with ``-j 2``), resume, a
failed initial run, and the real pipeline against :func:`slamcli.api.solve.solve_dataset` given the same init.
"""

from __future__ import annotations

import json
import shutil
import time
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from test_sweep_helpers import FakePipeline, fake_experiment

from slamcli.errors import ConfigError
from slamcli.sweep.expand import LiteralResolver, expand
from slamcli.sweep.runner import run_sweep

VERS = {"slamcli": "test", "schema": 1}
#: the fake "post-processor" adds this multiple of its initial estimate's value to its own
INIT_WEIGHT = 10.0


class InitPipeline(FakePipeline):
    """FakePipeline whose solve also reads ``init_path`` (the initial run's result) when given: its value is
    its own plus :data:`INIT_WEIGHT` × the initial value; a missing file raises (a run started too early)."""

    def solve(self, run, dataset_path: Path, result_path: Path, init_path: Path | None = None) -> None:
        super().solve(run, dataset_path, result_path)
        if init_path is None:
            return
        own = json.loads(result_path.read_text())
        init = json.loads(Path(init_path).read_text())  # FileNotFoundError when the initial run is not done
        own.update(value=own["value"] + INIT_WEIGHT * init["value"], init_value=init["value"])
        result_path.write_text(json.dumps(own))


def _solvers(base_sleep: float = 0.0, base_gain: float = 1.0, base_fail: bool = False):
    """The dependent first in the file, so the expansion has to reorder."""
    return [{"method": "post", "params": {"gain": 0.5}, "init_from": "base"},
            {"method": "base", "params": {"gain": base_gain, "sleep": base_sleep, "fail": base_fail}},
            {"method": "plain", "params": {"gain": 2.0}}]


def _expand(cfg):
    return expand(cfg, resolver=LiteralResolver(), run_versions=VERS)


def _values(root: Path) -> pd.DataFrame:
    return pd.read_csv(root / "fake" / "results.csv").set_index("run_id")


@pytest.mark.parametrize("solvers, expected", [
    ([{"method": "a", "init_from": "b"}], "solver 'a' init_from: 'b' is not the label of a [[solver]]"),
    ([{"method": "a", "init_from": "bb"}, {"method": "b"}], "did you mean 'b'?"),
    ([{"method": "a", "init_from": "b"}, {"method": "b", "init_from": "a"}], "init_from: cycle a -> b -> a"),
    ([{"method": "a", "init_from": "a"}], "init_from: cycle a -> a"),
    ([{"method": "a", "init_from": 1}], "solver[0].init_from: expected a string"),
])
def test_a_missing_or_cyclic_label_is_one_line_at_parse_time(solvers, expected):
    with pytest.raises(ConfigError) as err:
        fake_experiment(solvers=solvers)
    msg = str(err.value)
    assert msg.startswith("fake.toml: ") and expected in msg and "\n" not in msg


def test_expansion_puts_the_initial_run_first_and_hashes_it_into_the_dependent():
    exp = _expand(fake_experiment(replicates=2, solvers=_solvers()))
    for rep in (0, 1):
        runs = [r for r in exp.runs if r.replicate == rep]
        assert [r.label for r in runs] == ["base", "post", "plain"]
        base, post, plain = runs
        assert post.init_run == base.run_id and post.dataset == base.dataset
        assert base.init_run == "" == plain.init_run
    # another initial configuration gives the dependent another id; a run that starts from nothing keeps its own
    other = _expand(fake_experiment(replicates=2, solvers=_solvers(base_gain=3.0)))
    ids = {(r.label, r.replicate): r.run_id for r in exp.runs}
    ids2 = {(r.label, r.replicate): r.run_id for r in other.runs}
    assert all(ids[("post", k)] != ids2[("post", k)] for k in (0, 1))
    assert all(ids[("plain", k)] == ids2[("plain", k)] for k in (0, 1))
    without = _expand(fake_experiment(replicates=2, solvers=_solvers()[1:]))
    assert {r.run_id for r in without.runs} <= set(ids.values())  # adding init_from elsewhere changes no id


def test_solver_selection_that_drops_the_initial_solver_is_one_line():
    import dataclasses

    cfg = fake_experiment(solvers=_solvers())
    kept = dataclasses.replace(cfg, solvers=cfg.solvers[:1])  # what `slamcli sweep FILE solver=post` keeps
    with pytest.raises(ConfigError, match="init_from: 'base' is not the label"):
        _expand(kept)


@pytest.mark.slow
@pytest.mark.parametrize("workers", [1, 2])
def test_the_dependent_runs_on_its_initial_result(tmp_path, workers):
    # with -j 2 the initial run is slow: a dependent submitted beside it would find no result.h5 and fail
    exp = _expand(fake_experiment(replicates=2, solvers=_solvers(base_sleep=0.4 if workers == 2 else 0.0)))
    summary = run_sweep(exp, tmp_path, pipeline=InitPipeline(), workers=workers)
    assert summary.ok and summary.counts.done == 6
    t = _values(tmp_path)
    for post in (r for r in exp.runs if r.init_run):
        res = json.loads((tmp_path / "fake" / post.run_id / "result.h5").read_text())
        assert res["init_value"] == pytest.approx(t.loc[post.init_run, "value"])
        assert t.loc[post.run_id, "init_run"] == post.init_run
        st = [json.loads((tmp_path / "fake" / i / "status.json").read_text()) for i in (post.init_run, post.run_id)]
        assert st[0]["finished_utc"] <= st[1]["started_utc"]
    assert t.loc[[r.run_id for r in exp.runs if not r.init_run], "init_run"].isna().all()


@pytest.mark.slow
def test_serial_and_two_workers_give_the_same_values(tmp_path):
    exp = _expand(fake_experiment(replicates=2, solvers=_solvers()))
    run_sweep(exp, tmp_path / "serial", pipeline=InitPipeline())
    run_sweep(exp, tmp_path / "pool", pipeline=InitPipeline(), workers=2)
    s, p = _values(tmp_path / "serial"), _values(tmp_path / "pool")
    np.testing.assert_array_equal(s.loc[p.index, "value"].to_numpy(), p["value"].to_numpy())


@pytest.mark.slow
@pytest.mark.parametrize("workers", [1, 2])
def test_resume_reruns_only_the_dependent_from_the_initial_result_on_disk(tmp_path, workers):
    exp = _expand(fake_experiment(replicates=1, solvers=_solvers()))
    run_sweep(exp, tmp_path, pipeline=InitPipeline())
    post = next(r for r in exp.runs if r.init_run)
    before = _values(tmp_path).loc[post.run_id, "value"]
    base_mtime = (tmp_path / "fake" / post.init_run / "status.json").stat().st_mtime_ns
    shutil.rmtree(tmp_path / "fake" / post.run_id)
    again = run_sweep(exp, tmp_path, pipeline=InitPipeline(), workers=workers)
    assert (again.counts.skipped, again.counts.done) == (2, 1)
    assert _values(tmp_path).loc[post.run_id, "value"] == before
    assert (tmp_path / "fake" / post.init_run / "status.json").stat().st_mtime_ns == base_mtime


@pytest.mark.slow
@pytest.mark.parametrize("workers", [1, 2])
def test_a_failed_initial_run_fails_its_dependent_with_one_line(tmp_path, workers):
    exp = _expand(fake_experiment(replicates=1, solvers=_solvers(base_fail=True)))
    summary = run_sweep(exp, tmp_path, pipeline=InitPipeline(), workers=workers)
    post = next(r for r in exp.runs if r.init_run)
    errors = {f["label"]: f["error"] for f in summary.failures}
    assert set(errors) == {"base", "post"}
    assert errors["post"] == f"RuntimeError: its initial estimate, run {post.init_run}, is failed: nothing to start from"


def test_real_pipeline_matches_the_api_given_the_same_initial_estimate(tmp_path):
    """ICM started from odometry through the sweep = solve_dataset(icm, init=solve_dataset(odometry))."""
    from slamcli.api.solve import solve_dataset
    from slamcli.io import read_dataset, read_result
    from slamcli.sweep.config import parse_experiment

    cfg = parse_experiment({
        "experiment": {"name": "fake", "root_seed": 3},
        "scenario": {"name": "loop", "parameters": {"n_steps": 40}},
        "solver": [{"method": "odometry"},
                   {"method": "icm", "init_from": "odometry", "params": {"max_sweeps": 2}}],
    }, source="fake.toml")
    exp = expand(cfg)
    t0 = time.perf_counter()
    assert run_sweep(exp, tmp_path).ok, "sweep failed"
    assert time.perf_counter() - t0 < 60
    base, post = exp.runs
    inputs = read_dataset(tmp_path / "fake" / base.run_id / "dataset.h5").inputs
    init = solve_dataset(inputs, "odometry", {}, seed=base.seed)
    expected = solve_dataset(inputs, "icm", {"max_sweeps": 2}, seed=post.seed, init=init)
    got = read_result(tmp_path / "fake" / post.run_id / "result.h5")
    np.testing.assert_allclose(got.poses_xyt, expected.poses_xyt, rtol=0, atol=1e-12)
    np.testing.assert_allclose(got.landmarks_xy, expected.landmarks_xy, rtol=0, atol=1e-12)
    not_started = solve_dataset(inputs, "icm", {"max_sweeps": 2}, seed=post.seed)  # the init must matter
    assert not np.allclose(not_started.poses_xyt, expected.poses_xyt) or \
        not_started.landmarks_xy.shape != expected.landmarks_xy.shape
