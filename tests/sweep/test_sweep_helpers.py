"""A tiny, picklable pipeline for testing the sweep runner without the simulator/solvers.

It is importable by spawned worker processes (the test directory is on ``sys.path``) and by a subprocess
that is killed with SIGKILL in the resume test. It holds no tests.
"""

from __future__ import annotations

import json
import os
import time
from pathlib import Path

import numpy as np

from slamcli.sweep.config import parse_experiment


class FakePipeline:
    """simulate: a JSON "dataset" drawn from the dataset seed; solve: a number from dataset + params + seed.

    Solver params understood: ``gain`` (float), ``fail`` (bool → raise), ``sleep`` (s), ``die`` (bool →
    ``os._exit`` the worker). Every simulate call appends one line to ``datasets/sim_calls.txt``.
    """

    def simulate(self, dataset, out_path: Path) -> None:
        rng = np.random.default_rng(dataset.seed)
        data = {"seed": dataset.seed, "noise": rng.normal(size=4).tolist(), "overrides": dataset.overrides}
        with open(out_path.parent / "sim_calls.txt", "a") as fh:
            fh.write(f"{dataset.dataset_id}\n")
        if dataset.overrides.get("broken"):
            raise ValueError("scenario 'broken' cannot be simulated")
        out_path.write_text(json.dumps(data))

    def solve(self, run, dataset_path: Path, result_path: Path) -> None:
        p = run.param_overrides
        if p.get("sleep"):
            time.sleep(float(p["sleep"]))
        if p.get("die"):
            os._exit(3)
        if p.get("fail"):
            raise RuntimeError(f"solver {run.label} refuses replicate {run.replicate}")
        data = json.loads(Path(dataset_path).read_text())
        rng = np.random.default_rng(run.seed)
        value = float(p.get("gain", 1.0)) * float(np.sum(data["noise"])) + 1e-3 * float(rng.normal())
        result_path.write_text(json.dumps({"value": value, "dataset_noise": data["noise"]}))

    def evaluate(self, run, dataset_path: Path, result_path: Path, out_dir: Path) -> dict:
        res = json.loads(Path(result_path).read_text())
        return {"value": res["value"], "abs_value": abs(res["value"]), "nested": {"pid": os.getpid()}}


def fake_experiment(name: str = "fake", *, replicates=3, grid=None, zip_=None, solvers=None, quick=None):
    """An ExperimentConfig for the fake pipeline (scenario name is irrelevant; LiteralResolver is used)."""
    raw = {
        "experiment": {"name": name, "root_seed": 7},
        "scenario": {"name": "fake", "parameters": {"sensor": {"max_range": 5.0}}},
        "solver": solvers
        or [{"method": "a", "params": {"gain": 1.0}}, {"method": "b", "params": {"gain": 2.0}}],
        "sweep": {"replicates": replicates},
    }
    if grid is not None:
        raw["sweep"]["grid"] = grid
    if zip_ is not None:
        raw["sweep"]["zip"] = zip_
    if quick is not None:
        raw["quick"] = quick
    return parse_experiment(raw, source=f"{name}.toml")


def main(out_dir: str, sleep: float) -> None:
    """Entry point for the kill -9 test: a 2-worker sweep of slow runs."""
    from slamcli.sweep.expand import LiteralResolver, expand
    from slamcli.sweep.runner import run_sweep

    cfg = fake_experiment(
        "killme", replicates=6, solvers=[{"method": "a", "params": {"gain": 1.0, "sleep": sleep}}]
    )
    exp = expand(cfg, resolver=LiteralResolver(), run_versions={"slamcli": "test", "schema": 1})
    run_sweep(exp, out_dir, pipeline=FakePipeline(), workers=2)


if __name__ == "__main__":
    import sys

    main(sys.argv[1], float(sys.argv[2]))
