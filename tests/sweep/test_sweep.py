"""Sweep config validation, expansion, hashing, seeds, resume and failure handling (fake pipeline)."""

from __future__ import annotations

import dataclasses
import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from test_sweep_helpers import FakePipeline, fake_experiment

from slamcli.errors import ConfigError
from slamcli.sweep.config import load_experiment, parse_experiment, quick_variant
from slamcli.sweep.expand import (
    LiteralResolver,
    canonical_json,
    content_hash,
    dataset_seed,
    expand,
    solver_seed,
)
from slamcli.sweep.runner import run_status, run_sweep

VERS = {"slamcli": "test", "schema": 1}
HERE = Path(__file__).resolve().parent


def _expand(cfg):
    return expand(cfg, resolver=LiteralResolver(), run_versions=VERS)


# -- config validation ---------------------------------------------------------------------------------------


def _write(tmp_path: Path, text: str) -> Path:
    p = tmp_path / "exp.toml"
    p.write_text(text)
    return p


GOOD = """
[experiment]
name = "demo"
root_seed = 3

[scenario]
name = "loop"
[scenario.parameters]
sensor.max_range = 8.0
"noise.range_std" = 0.05

[[solver]]
method = "ekf"
[solver.params]
gate = 9.21

[[solver]]
method = "odometry"

[evaluate]
cutoff_m = 1.0

[sweep]
replicates = "range(0, 4)"
grid = { "scenario.sensor.max_range" = [5.0, 10.0], "solver.ekf.gate" = [5.99, 9.21] }

[quick]
replicates = 1
"scenario.duration" = 10.0
"""


def test_load_good_file(tmp_path):
    cfg = load_experiment(_write(tmp_path, GOOD))
    assert cfg.name == "demo" and cfg.root_seed == 3 and cfg.scenario == "loop"
    assert cfg.scenario_params == {"sensor.max_range": 8.0, "noise.range_std": 0.05}
    assert [s.label for s in cfg.solvers] == ["ekf", "odometry"]
    assert cfg.solvers[0].params == {"gate": 9.21}
    assert cfg.sweep.replicates == (0, 1, 2, 3)
    assert cfg.sweep.grid == (("scenario.sensor.max_range", (5.0, 10.0)), ("solver.ekf.gate", (5.99, 9.21)))
    q = quick_variant(cfg)
    assert q.sweep.replicates == (0,) and q.scenario_params["duration"] == 10.0
    assert q.sweep.grid == cfg.sweep.grid
    # a fixed override of a swept key replaces that axis
    q2 = quick_variant(dataclasses.replace(cfg, quick={"solver.ekf.gate": 7.0}))
    assert q2.sweep.grid == (("scenario.sensor.max_range", (5.0, 10.0)),) and q2.solvers[0].params["gate"] == 7.0
    assert q2.sweep.replicates == cfg.sweep.replicates


@pytest.mark.parametrize(
    "edit, expected",
    [
        (("[experiment]", "[experiment]\ncolour = 1"), r"exp.toml: experiment.colour: unknown key"),
        (("root_seed = 3", 'root_seed = "3"'), r"exp.toml: experiment.root_seed: expected an integer, got '3'"),
        (('name = "demo"', 'name = "a b"'), r"exp.toml: experiment.name: 'a b' must start"),
        (("gate = 9.21\n", "gate = 9.21\n[[solver]]\nmethod = 5\n"), r"solver\[1\].method: expected a string"),
        (('method = "odometry"', 'method = "ekf"'), r"solver\[1\].label: duplicate label 'ekf'"),
        (('"solver.ekf.gate" = [5.99, 9.21]', '"solver.ekf.gate" = []'), r"sweep.grid 'solver.ekf.gate': empty list"),
        (('"solver.ekf.gate"', '"solver.graph.gate"'), r"no \[\[solver\]\] labelled 'graph'"),
        (('"solver.ekf.gate"', '"robot.gate"'), r"sweep.grid 'robot.gate': keys must be scenario"),
        (('replicates = "range(0, 4)"', "replicates = 0"), r"sweep.replicates: must be >= 1"),
        (('replicates = "range(0, 4)"', 'replicates = "many"'), r"sweep.replicates: expected an array"),
        (("[sweep]", "[sweep]\nparallel = true"), r"sweep.parallel: unknown key"),
        (("[evaluate]", "[evaluation]"), r"evaluation: unknown key"),
        (('grid = {', 'zip = { "scenario.a" = [1, 2, 3], "scenario.b" = [1] }\ngrid = {'),
         r"sweep.zip: zipped lists must have equal lengths, got scenario.a=3, scenario.b=1"),
    ],
)
def test_validation_errors_are_one_line_and_name_file_and_key(tmp_path, edit, expected):
    old, new = edit
    assert old in GOOD
    p = _write(tmp_path, GOOD.replace(old, new, 1))
    with pytest.raises(ConfigError, match=expected) as info:
        load_experiment(p)
    assert "\n" not in str(info.value)
    assert str(info.value).startswith(str(p))


def test_empty_grid_and_missing_solver(tmp_path):
    with pytest.raises(ConfigError, match=r"sweep.grid: empty grid"):
        parse_experiment({"experiment": {"name": "x"}, "scenario": {"name": "s"}, "solver": [{"method": "a"}],
                          "sweep": {"grid": {}}}, source="x.toml")
    with pytest.raises(ConfigError, match=r"x.toml: \[\[solver\]\]: missing"):
        parse_experiment({"experiment": {"name": "x"}, "scenario": {"name": "s"}}, source="x.toml")
    with pytest.raises(ConfigError, match=r"not valid TOML"):
        load_experiment(_write(tmp_path, "[experiment\nname="))
    with pytest.raises(ConfigError, match=r"experiment file not found"):
        load_experiment(tmp_path / "nope.toml")


# -- expansion, hashing, seeds ---------------------------------------------------------------------------------


def test_grid_zip_expansion_order_and_counts():
    cfg = fake_experiment(
        replicates=2,
        grid={"scenario.sensor.max_range": [5.0, 10.0], "solver.a.gain": [1.0, 3.0]},
        zip_={"scenario.noise.r": [0.1, 0.2, 0.3], "scenario.noise.b": [1, 2, 3]},
    )
    exp = _expand(cfg)
    # points: 2 (range) × 2 (gain) × 3 (zip) = 12; per point 2 replicates × 2 solvers = 48, but solver b
    # ignores solver.a.gain, so its runs for gain=1 and gain=3 are the same run: 48 - 12 = 36 unique runs.
    assert len(exp.runs) == 36
    assert exp.axes == ("scenario.sensor.max_range", "solver.a.gain", "scenario.noise.r", "scenario.noise.b")
    first = exp.runs[0]
    assert first.label == "a" and first.replicate == 0
    assert first.point == {"scenario.sensor.max_range": 5.0, "solver.a.gain": 1.0,
                           "scenario.noise.r": 0.1, "scenario.noise.b": 1}
    # b's runs carry no solver.a.* value
    assert all("solver.a.gain" not in r.point for r in exp.runs if r.label == "b")
    # first key varies slowest
    ranges = [r.point["scenario.sensor.max_range"] for r in exp.runs]
    assert ranges == sorted(ranges)
    # one dataset per (scenario config, replicate): 2 ranges × 3 zip × 2 replicates
    assert len(exp.datasets) == 12
    for ds in exp.datasets:
        users = [r for r in exp.runs if r.dataset.dataset_id == ds.dataset_id]
        assert {r.label for r in users} == {"a", "b"}
    # deterministic: expanding twice gives identical ids in the same order
    assert [r.run_id for r in _expand(cfg).runs] == [r.run_id for r in exp.runs]


def test_seeds_follow_default_rng_list_form_and_are_shared_across_solvers():
    exp = _expand(fake_experiment(replicates=[0, 5]))
    for r in exp.runs:
        want = int(np.random.default_rng([0, r.replicate, 7]).integers(0, 2**63 - 1))
        assert r.dataset.seed == want == dataset_seed(r.replicate, 7)
        assert r.seed == int(np.random.default_rng([1, r.replicate, 7]).integers(0, 2**63 - 1))
    a5, b5 = [r for r in exp.runs if r.replicate == 5]
    assert a5.dataset == b5.dataset  # common random numbers: same dataset for every solver
    assert dataset_seed(0, 7) != dataset_seed(1, 7) != dataset_seed(0, 8)
    assert solver_seed(0, 7, 1) != solver_seed(0, 7, 0)


def test_dataset_seeds_replicate_uses_the_replicate_id_as_simulator_seed(tmp_path):
    raw = {"experiment": {"name": "named-seeds", "root_seed": 7}, "scenario": {"name": "fake"},
           "solver": [{"method": "a"}, {"method": "b"}],
           "sweep": {"replicates": [0, 5], "dataset_seeds": "replicate"}}
    exp = _expand(parse_experiment(raw, source="named-seeds.toml"))
    assert sorted({(r.replicate, r.dataset.seed) for r in exp.runs}) == [(0, 0), (5, 5)]
    assert {r.seed for r in exp.runs if r.replicate == 5} == {solver_seed(5, 7)}  # solver seeds still derived
    raw["sweep"]["dataset_seeds"] = "fixed"
    with pytest.raises(ConfigError, match=r"named-seeds.toml: sweep.dataset_seeds: 'fixed' is not one of"):
        parse_experiment(raw, source="named-seeds.toml")


def test_run_id_is_a_content_hash_of_the_resolved_config():
    exp = _expand(fake_experiment(replicates=1))
    r = exp.runs[0]
    assert r.run_id == content_hash(r.config()) and len(r.run_id) == 12
    # canonical JSON: key order and int/float-looking layout do not matter, values and versions do
    assert canonical_json({"b": 1, "a": [1.5, (2, 3)]}) == '{"a":[1.5,[2,3]],"b":1}'
    other_version = expand(fake_experiment(replicates=1), resolver=LiteralResolver(),
                           run_versions={"slamcli": "other", "schema": 1})
    assert other_version.runs[0].run_id != r.run_id
    changed = _expand(fake_experiment(replicates=1, solvers=[{"method": "a", "params": {"gain": 1.0000001}},
                                                             {"method": "b", "params": {"gain": 2.0}}]))
    assert changed.runs[0].run_id != r.run_id and changed.runs[1].run_id == exp.runs[1].run_id


# -- runner ---------------------------------------------------------------------------------------------------------


def test_sweep_writes_artefacts_tables_and_shares_datasets(tmp_path):
    exp = _expand(fake_experiment(replicates=3, grid={"solver.b.gain": [2.0, -1.0]}))
    assert len(exp.runs) == 9  # a: 3 replicates; b: 3 replicates × 2 gains
    summary = run_sweep(exp, tmp_path, pipeline=FakePipeline())
    assert summary.ok and (summary.counts.done, summary.counts.failed, summary.counts.skipped) == (9, 0, 0)
    exp_dir = tmp_path / "fake"
    # one simulation per replicate, shared by every solver run of that replicate
    assert len((exp_dir / "datasets" / "sim_calls.txt").read_text().split()) == 3
    for r in exp.runs:
        d = exp_dir / r.run_id
        assert {p.name for p in d.iterdir()} >= {"config.json", "dataset.h5", "result.h5", "metrics.json",
                                                 "status.json", "run.log"}
        cfg = json.loads((d / "config.json").read_text())
        assert cfg["run_id"] == r.run_id and content_hash({k: v for k, v in cfg.items()
                                                           if k not in ("run_id", "point")}) == r.run_id
        st = json.loads((d / "status.json").read_text())
        assert st["status"] == "completed" and st["run_id"] == r.run_id and {"git", "host", "wall_time_s", "solve_cpu_s"} <= set(st)
        assert os.path.samefile(d / "dataset.h5", exp_dir / "datasets" / f"{r.dataset.dataset_id}.h5")
    # paired comparison: b with gain 2 is exactly twice a's signal on the same dataset (up to the 1e-3 solver noise)
    tidy = pd.read_csv(exp_dir / "results.csv")
    assert len(tidy) == 9 and set(tidy["status"]) == {"completed"}
    assert (tidy["solve_cpu_s"] >= 0).all()  # the worker's CPU time of each solve, beside its wall time
    for rep in range(3):
        va = tidy[(tidy.label == "a") & (tidy.replicate == rep)]["value"].item()
        vb = tidy[(tidy.label == "b") & (tidy.replicate == rep) & (tidy["solver.b.gain"] == 2.0)]["value"].item()
        assert abs(vb - 2 * va) < 1e-2
    assert "nested.pid" in tidy.columns
    manifest = pd.read_csv(exp_dir / "manifest.csv")
    assert list(manifest["run_id"]) == [r.run_id for r in exp.runs]
    parquet = pd.read_parquet(exp_dir / "results.parquet")
    assert list(parquet["run_id"]) == list(tidy["run_id"])


def test_fail_soft_then_resume_redoes_only_failures(tmp_path):
    cfg = fake_experiment(replicates=2, solvers=[{"method": "a", "params": {"gain": 1.0}},
                                                 {"method": "bad", "params": {"fail": True}}])
    exp = _expand(cfg)
    summary = run_sweep(exp, tmp_path, pipeline=FakePipeline())
    assert (summary.counts.done, summary.counts.failed) == (2, 2) and not summary.ok
    assert {f["label"] for f in summary.failures} == {"bad"}
    assert all("RuntimeError: solver bad refuses replicate" in f["error"] for f in summary.failures)
    bad = next(r for r in exp.runs if r.label == "bad")
    st = json.loads((tmp_path / "fake" / bad.run_id / "status.json").read_text())
    assert st["status"] == "failed" and "Traceback" in st["traceback"]
    assert "run failed" in (tmp_path / "fake" / bad.run_id / "run.log").read_text()
    manifest = pd.read_csv(tmp_path / "fake" / "manifest.csv")
    assert sorted(manifest["status"]) == ["completed", "completed", "failed", "failed"]

    good = [r for r in exp.runs if r.label == "a"]
    mtimes = {r.run_id: (tmp_path / "fake" / r.run_id / "status.json").stat().st_mtime_ns for r in good}
    again = run_sweep(exp, tmp_path, pipeline=FakePipeline())
    assert (again.counts.skipped, again.counts.failed, again.counts.done) == (2, 2, 0)
    for r in good:  # completed runs untouched
        assert (tmp_path / "fake" / r.run_id / "status.json").stat().st_mtime_ns == mtimes[r.run_id]
    # datasets are reused on resume: still one simulation per replicate
    assert len((tmp_path / "fake" / "datasets" / "sim_calls.txt").read_text().split()) == 2
    fresh = run_sweep(exp, tmp_path, pipeline=FakePipeline(), resume=False)
    assert (fresh.counts.skipped, fresh.counts.done) == (0, 2)


def test_simulation_failure_fails_every_run_of_the_dataset(tmp_path):
    cfg = fake_experiment(replicates=1, grid={"scenario.broken": [False, True]})
    exp = _expand(cfg)
    summary = run_sweep(exp, tmp_path, pipeline=FakePipeline())
    assert (summary.counts.done, summary.counts.failed) == (2, 2)
    assert all("simulating dataset" in f["error"] or "cannot be simulated" in f["error"] for f in summary.failures)
    assert not any(p.name.startswith(".") for p in (tmp_path / "fake" / "datasets").iterdir())


@pytest.mark.slow
def test_process_pool_matches_serial_and_survives_a_dying_worker(tmp_path):
    cfg = fake_experiment(replicates=3)
    exp = _expand(cfg)
    run_sweep(exp, tmp_path / "serial", pipeline=FakePipeline())
    par = run_sweep(exp, tmp_path / "pool", pipeline=FakePipeline(), workers=2)
    assert par.ok
    s = pd.read_csv(tmp_path / "serial" / "fake" / "results.csv")
    p = pd.read_csv(tmp_path / "pool" / "fake" / "results.csv")
    np.testing.assert_array_equal(s["value"].to_numpy(), p["value"].to_numpy())  # order-independent seeds
    assert (p["nested.pid"] != os.getpid()).all()
    # datasets are simulated once each (phase 1), then the runs of a dataset spread over the workers
    assert len((tmp_path / "pool" / "fake" / "datasets" / "sim_calls.txt").read_text().split()) == 3

    dying = _expand(fake_experiment("dying", replicates=1, solvers=[{"method": "a", "params": {"die": True}}]))
    summary = run_sweep(dying, tmp_path / "pool", pipeline=FakePipeline(), workers=2)
    assert summary.counts.failed == 1 and "worker failed" in summary.failures[0]["error"]



@pytest.mark.slow
def test_sweeps_sharing_one_pool_start_its_workers_once(tmp_path):
    from slamcli.sweep.runner import make_executor

    first, second = (_expand(fake_experiment(name, replicates=3)) for name in ("first", "second"))
    with make_executor("local", 2) as pool:
        for exp in (first, second):
            assert run_sweep(exp, tmp_path / "shared", pipeline=FakePipeline(), pool=pool).ok
    run_sweep(second, tmp_path / "serial", pipeline=FakePipeline())
    shared = [pd.read_csv(tmp_path / "shared" / name / "results.csv") for name in ("first", "second")]
    pids = set(shared[0]["nested.pid"]) | set(shared[1]["nested.pid"])
    assert len(pids) <= 2 and os.getpid() not in pids  # the second sweep ran on the first one's two workers
    serial = pd.read_csv(tmp_path / "serial" / "second" / "results.csv")
    np.testing.assert_array_equal(serial["value"].to_numpy(), shared[1]["value"].to_numpy())


@pytest.mark.slow
def test_two_threads_sharing_a_pool_survive_a_dying_worker_with_one_rebuild(tmp_path):
    """``reproduce`` overlaps sections: two sweeps in two threads on one pool, and a run of one kills its worker.
    The pool is rebuilt once (a second rebuild would cancel the runs the first sweep handed to the new pool),
    the dying run fails naming its exit, and the other sweep completes with the serial numbers."""
    import threading

    from slamcli.sweep.runner import make_executor

    slow = _expand(fake_experiment("slow", replicates=4, solvers=[{"method": "a", "params": {"sleep": 0.5}}]))
    dying = _expand(fake_experiment("dying", replicates=1,
                                    solvers=[{"method": "a", "params": {"sleep": 0.2, "die": True}}]))
    out, starts = {}, []
    with make_executor("local", 2) as pool:
        start = pool._start
        pool._start = lambda: (starts.append(1), start())[1]  # counts the rebuilds
        threads = [threading.Thread(target=lambda e=e: out.__setitem__(
            e.experiment.name, run_sweep(e, tmp_path / "shared", pipeline=FakePipeline(), pool=pool)))
            for e in (slow, dying)]
        for th in threads:
            th.start()
        for th in threads:
            th.join(timeout=120)
    assert len(starts) == 1
    assert out["dying"].counts.failed == 1 and "exited with code 3" in out["dying"].failures[0]["error"]
    assert out["slow"].ok and out["slow"].counts.done == 4
    run_sweep(slow, tmp_path / "serial", pipeline=FakePipeline())
    serial, shared = (pd.read_csv(tmp_path / d / "slow" / "results.csv") for d in ("serial", "shared"))
    np.testing.assert_array_equal(serial["value"].to_numpy(), shared["value"].to_numpy())


RUN_S = 1.2


@pytest.mark.parametrize("sig", [signal.SIGKILL, signal.SIGINT], ids=["kill-9", "ctrl-c"])
@pytest.mark.slow
def test_interrupt_leaves_no_half_run_and_resume_finishes(tmp_path, sig):
    env = dict(os.environ, PYTHONPATH=str(HERE) + os.pathsep + os.environ.get("PYTHONPATH", ""))
    # runs of 1.2 s: the poll below must see two finished runs and signal before the next two finish, which
    # on a loaded 2-core machine took > 0.4 s (all six finished before the Ctrl-C landed)
    # the default Ctrl-C handler, whatever disposition the test process's own parent left for SIGINT
    code = ("import signal; signal.signal(signal.SIGINT, signal.default_int_handler); "
            f"import test_sweep_helpers as h; h.main({str(tmp_path)!r}, {RUN_S})")
    proc = subprocess.Popen([sys.executable, "-c", code], env=env, start_new_session=True)
    exp_dir = tmp_path / "killme"
    deadline = time.time() + 30
    while time.time() < deadline:
        done = [p for p in exp_dir.glob("*/status.json")] if exp_dir.exists() else []
        if len(done) >= 2:
            break
        time.sleep(0.05)
    os.killpg(proc.pid, sig)  # the coordinator and its workers, mid-sweep
    proc.wait(timeout=30)
    visible = [p for p in exp_dir.iterdir() if p.is_dir() and not p.name.startswith(".") and p.name != "datasets"]
    assert 2 <= len(visible) < 6
    for d in visible:  # every visible run directory is complete
        assert run_status(exp_dir, d.name) == "completed"
    if sig == signal.SIGINT:  # a Ctrl-C still writes the tables of what finished
        assert "missing" in set(pd.read_csv(exp_dir / "manifest.csv")["status"])
    cfg = fake_experiment("killme", replicates=6, solvers=[{"method": "a", "params": {"gain": 1.0, "sleep": RUN_S}}])
    exp = _expand(cfg)
    summary = run_sweep(exp, tmp_path, pipeline=FakePipeline(), workers=1)
    assert summary.counts.skipped == len(visible) and summary.counts.done == 6 - len(visible)
    assert not any(p.name.startswith(".") and ".tmp-" in p.name for p in exp_dir.iterdir())
    assert set(pd.read_csv(exp_dir / "manifest.csv")["status"]) == {"completed"}


@pytest.mark.slow
def test_dask_existing_cluster_gives_the_same_numbers(tmp_path):
    """The sweep runs unchanged on an existing Dask cluster (here a LocalCluster reached by its address)."""
    pytest.importorskip("dask.distributed")
    import cloudpickle
    import test_sweep_helpers
    from dask.distributed import LocalCluster

    cloudpickle.register_pickle_by_value(test_sweep_helpers)  # workers cannot import the tests directory
    try:
        exp = _expand(fake_experiment(replicates=2))
        run_sweep(exp, tmp_path / "serial", pipeline=test_sweep_helpers.FakePipeline())
        with LocalCluster(n_workers=2, threads_per_worker=1, processes=True, dashboard_address=None) as cluster:
            summary = run_sweep(exp, tmp_path / "dask", pipeline=test_sweep_helpers.FakePipeline(),
                                executor="dask", scheduler=cluster.scheduler_address)
    finally:
        cloudpickle.unregister_pickle_by_value(test_sweep_helpers)
    assert summary.ok and summary.counts.done == 4
    s = pd.read_csv(tmp_path / "serial" / "fake" / "results.csv")
    d = pd.read_csv(tmp_path / "dask" / "fake" / "results.csv")
    np.testing.assert_array_equal(s["value"].to_numpy(), d["value"].to_numpy())
    assert (d["nested.pid"] != os.getpid()).all()  # computed in the cluster's worker processes


class _AgainstPipeline(FakePipeline):
    """The fake pipeline, reporting the ``against`` path and the output folder it was handed."""

    def evaluate(self, run, dataset_path, result_path, out_dir):
        return {**super().evaluate(run, dataset_path, result_path, out_dir),
                "against_seen": run.evaluate["against"], "out_seen": str(out_dir)}


def test_relative_paths_are_made_absolute_before_any_worker_sees_them(tmp_path, monkeypatch):
    """A worker may run in another directory (Dask): the results folder and a file-valued ``[evaluate]``
    option reach it absolute, resolved against the directory the sweep was started from; run ids keep
    hashing the options as written."""
    monkeypatch.chdir(tmp_path)
    cfg = dataclasses.replace(fake_experiment(replicates=1), evaluate={"against": "ref/other.h5"})
    exp = _expand(cfg)
    summary = run_sweep(exp, "rel-out", pipeline=_AgainstPipeline())
    assert summary.ok and summary.exp_dir == tmp_path / "rel-out" / "fake"
    tidy = pd.read_csv(tmp_path / "rel-out" / "fake" / "results.csv")
    assert sorted(tidy["run_id"]) == sorted(r.run_id for r in exp.runs)
    assert set(tidy["against_seen"]) == {str(tmp_path / "ref" / "other.h5")}
    assert all(Path(p).is_absolute() and Path(p).parent == summary.exp_dir for p in tidy["out_seen"])
    config = json.loads((summary.exp_dir / exp.runs[0].run_id / "config.json").read_text())
    assert config["evaluate"]["against"] == str(tmp_path / "ref" / "other.h5")


def test_progress_lines_count_finished_runs_and_a_resume_reports_only_skips(tmp_path):
    from slamcli.sweep.runner import progress_lines

    exp = _expand(fake_experiment(replicates=3))  # 6 runs
    lines: list[str] = []
    run_sweep(exp, tmp_path, pipeline=FakePipeline(), progress=progress_lines("sweep fake", lines.append))
    assert lines[0].startswith("sweep fake: 0% (0/6 runs; 0 done, 0 failed, 0 skipped)")
    assert len(lines) == 7  # the start, then every run (each is more than a tenth of the sweep)
    assert lines[-1].startswith("sweep fake: 100% (6/6 runs; 6 done, 0 failed, 0 skipped)")
    assert lines[-1].endswith(", done")
    again: list[str] = []
    run_sweep(exp, tmp_path, pipeline=FakePipeline(), progress=progress_lines("sweep fake", again.append))
    assert len(again) == 1 and again[0].startswith("sweep fake: 100% (6/6 runs; 0 done, 0 failed, 6 skipped)")


@pytest.mark.slow
def test_local_pool_workers_spawned_on_demand_inherit_one_blas_thread(monkeypatch):
    """The pool spawns workers at submit time, after it is built: they must still see one BLAS thread (a
    worker with the machine's default thread count gives other numbers than a one-thread Dask worker)."""
    import os

    from slamcli.sweep.runner import make_executor

    for key in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
        monkeypatch.delenv(key, raising=False)
    with make_executor("local", 2) as ex:
        seen = [ex.submit(os.getenv, "OPENBLAS_NUM_THREADS").result(timeout=120) for _ in range(2)]
    assert seen == ["1", "1"]
    assert os.getenv("OPENBLAS_NUM_THREADS") is None  # the coordinator's own environment is given back
