"""Sweep throughput: runs per minute for 1 vs 2 workers, on short runs (a 100-run EKF sweep of ``loop``,
quick: 12) and on runs of ≥ 1 s (24 runs of EKF with defaults on 1000 steps of ``paper-sim1``, quick: 8; issue
25 item 6: ``-j 2`` ≥ 1.8× ``-j 1``).

Every run is the real pipeline (simulate → solve → evaluate → per-run files), one replicate per run, so each
run also simulates its own dataset. The per-worker start (a spawn interpreter importing what a worker needs,
:data:`WORKER_IMPORTS`) is measured separately (``worker_start_*``), and ``speedup_bound_from_start_cost`` is
the 2-worker speedup that start alone allows (Amdahl, ``N r / (N r / 2 + start)``). Rows:

* ``local`` 1 worker — in-process, serial (what ``slamcli sweep`` does with ``--workers 1``);
* ``local`` 2 workers — spawn ``ProcessPoolExecutor``;
* ``dask`` 2 workers — a throw-away ``LocalCluster`` (full mode only; includes its start-up).

``speedup`` is runs/min relative to the 1-worker row measured in the same invocation; ``reference_speedup``
is what 2 warm processes achieve over 1 on a fixed pure-Python CPU task measured in the same invocation (the
machine's real headroom: 2 on two idle cores, ≈ 1 when other jobs hold the cores), and ``efficiency`` =
speedup / min(reference, workers). On a machine with two idle cores the ideal speedup is 2; spawn start-up (each worker imports numpy/scipy/h5py once) and the coordinator's
table writing are the overheads. ``cpu_utilisation`` (CPU seconds of this process and its finished children
per wall second) and the 1-minute load average show whether the cores were actually available: on a shared
machine a speedup below 1 with utilisation near 1 means the other processes, not the runner, took the cores.
Results: ``benchmarks/results/sweep.csv``.
"""

from __future__ import annotations

import os
import resource
import tempfile
import time

from slamcli.sweep.config import parse_experiment
from slamcli.sweep.expand import expand
from slamcli.sweep.runner import run_sweep

#: the two run lengths: ``short`` (loop, 200 steps, EKF with the true association: ≈ 0.1-0.3 s per run, where
#: per-run overheads dominate) and ``long`` (paper-sim1, 1000 steps of its laser, EKF with defaults: ≈ 1.9 s per
#: run, the case of issue 25 item 6)
KINDS = {
    "short": ({"name": "loop", "parameters": {"n_steps": 200}}, {"method": "ekf", "oracle_association": True}),
    "long": ({"name": "paper-sim1", "parameters": {"n_steps": 1000}}, {"method": "ekf"}),
}
#: what a sweep worker imports before its first run (spawn start method: a fresh interpreter)
WORKER_IMPORTS = ("slamcli.sweep.runner", "slamcli.api.simulate", "slamcli.api.solve", "slamcli.api.evaluate",
                  "slamcli.metrics.summary", "slamcli.solvers.ekf", "slamcli.sim")


def _experiment(n_runs: int, kind: str = "short"):
    scenario, solver = KINDS[kind]
    return parse_experiment(
        {
            "experiment": {"name": f"bench-sweep-{kind}", "root_seed": 1},
            "scenario": scenario,
            "solver": [solver],
            "sweep": {"replicates": n_runs},
        },
        source="bench_sweep",
    )


def worker_start_cost(repeats: int = 3) -> dict:
    """CPU and wall seconds a fresh interpreter needs to start and import :data:`WORKER_IMPORTS` (best of
    ``repeats``): the per-worker overhead of a spawn pool, paid once per worker, not per run."""
    import subprocess
    import sys

    best_cpu, best_wall = float("inf"), float("inf")
    code = "; ".join(f"import {m}" for m in WORKER_IMPORTS)
    for _ in range(repeats):
        c0, t0 = _children_cpu_s(), time.perf_counter()
        subprocess.run([sys.executable, "-c", code], check=True)
        best_wall = min(best_wall, time.perf_counter() - t0)
        best_cpu = min(best_cpu, _children_cpu_s() - c0)
    return {"worker_start_cpu_s": best_cpu, "worker_start_wall_s": best_wall}


def _children_cpu_s() -> float:
    ch = resource.getrusage(resource.RUSAGE_CHILDREN)
    return ch.ru_utime + ch.ru_stime


def _cpu_s() -> float:
    """CPU seconds of this process plus its finished child processes (the pool's workers)."""
    me = resource.getrusage(resource.RUSAGE_SELF)
    ch = resource.getrusage(resource.RUSAGE_CHILDREN)
    return me.ru_utime + me.ru_stime + ch.ru_utime + ch.ru_stime


def _spin(n: int) -> float:
    """Fixed pure-Python CPU work (the reference task)."""
    acc = 0.0
    for i in range(n):
        acc += (i % 7) * 0.5
    return acc


def reference_speedup(chunks: int = 8, n: int = 1_500_000) -> float:
    """Speedup of a fixed CPU-bound task on 2 warm spawn processes vs 1, measured now (the machine's headroom)."""
    import concurrent.futures as cf
    import multiprocessing

    t0 = time.perf_counter()
    for _ in range(chunks):
        _spin(n)
    serial = time.perf_counter() - t0
    with cf.ProcessPoolExecutor(2, mp_context=multiprocessing.get_context("spawn")) as ex:
        list(ex.map(_spin, [1, 1]))  # start both workers before timing
        t0 = time.perf_counter()
        list(ex.map(_spin, [n] * chunks))
        parallel = time.perf_counter() - t0
    return serial / parallel


def run(quick: bool = False) -> list[dict]:
    rows: list[dict] = []
    ref = reference_speedup(chunks=4 if quick else 8)
    start = worker_start_cost()
    for kind, n_runs in (("short", 12 if quick else 100), ("long", 8 if quick else 24)):
        expansion = expand(_experiment(n_runs, kind))
        configs = [("local", 1), ("local", 2)] + ([] if quick or kind == "long" else [("dask", 2)])
        base = None
        for executor, workers in configs:
            with tempfile.TemporaryDirectory(prefix="bench-sweep-") as tmp:
                c0 = _cpu_s()
                t0 = time.perf_counter()
                summary = run_sweep(expansion, tmp, executor=executor, workers=workers, resume=False)
                wall = time.perf_counter() - t0
                cpu = _cpu_s() - c0
            rate = 60.0 * summary.counts.done / wall
            if base is None:
                base = rate
                run_s = wall / max(n_runs, 1)  # mean wall of one run in-process (the -j 1 row)
            # Amdahl with a per-worker start: T2 = N r / 2 + start  →  the speedup the overhead alone allows
            ideal_2 = (n_runs * run_s) / (n_runs * run_s / 2 + start["worker_start_wall_s"])
            rows.append(
                {
                    "runs_kind": kind,
                    "executor": executor,
                    "workers": workers,
                    "runs": n_runs,
                    "completed": summary.counts.done,
                    "failed": summary.counts.failed,
                    "wall_s": wall,
                    "run_wall_s_in_process": run_s,
                    "runs_per_min": rate,
                    "speedup": rate / base if base else float("nan"),
                    "meets_1_8x": bool(workers == 2 and rate / base >= 1.8) if workers == 2 else "",
                    "speedup_bound_from_start_cost": ideal_2 if workers == 2 else "",
                    "reference_speedup": ref,  # 2 vs 1 processes on a fixed CPU task, same run
                    "efficiency": (rate / base) / min(ref, workers) if base and ref > 0 else float("nan"),
                    **start,
                    "cpu_s": cpu,
                    "cpu_utilisation": cpu / wall,  # ≈ workers when the cores are ours alone
                    "load_avg_1min": os.getloadavg()[0],
                    "cpu_count": os.cpu_count(),
                }
            )
    return rows
