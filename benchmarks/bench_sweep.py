"""Sweep throughput: runs per minute of a 100-run EKF sweep (quick: 12 runs) for 1 vs 2 workers.

Every run is the real pipeline (simulate ``loop`` with 200 steps → EKF-SLAM with the true association → evaluate
→ per-run files), one replicate per run, so each run also simulates its own dataset. Rows:

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


def _experiment(n_runs: int):
    return parse_experiment(
        {
            "experiment": {"name": "bench-sweep", "root_seed": 1},
            "scenario": {"name": "loop", "parameters": {"n_steps": 200}},
            "solver": [{"method": "ekf", "oracle_association": True}],
            "sweep": {"replicates": n_runs},
        },
        source="bench_sweep",
    )


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
    n_runs = 12 if quick else 100
    expansion = expand(_experiment(n_runs))
    configs = [("local", 1), ("local", 2)] + ([] if quick else [("dask", 2)])
    rows: list[dict] = []
    base = None
    ref = reference_speedup(chunks=4 if quick else 8)
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
        rows.append(
            {
                "executor": executor,
                "workers": workers,
                "runs": n_runs,
                "completed": summary.counts.done,
                "failed": summary.counts.failed,
                "wall_s": wall,
                "runs_per_min": rate,
                "speedup": rate / base if base else float("nan"),
                "reference_speedup": ref,  # 2 vs 1 processes on a fixed CPU task, same run
                "efficiency": (rate / base) / min(ref, workers) if base and ref > 0 else float("nan"),
                "cpu_s": cpu,
                "cpu_utilisation": cpu / wall,  # ≈ workers when the cores are ours alone
                "load_avg_1min": os.getloadavg()[0],
                "cpu_count": os.cpu_count(),
            }
        )
    return rows
