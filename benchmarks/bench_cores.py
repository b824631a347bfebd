"""What two processes side by side get from this machine's cores: the ceiling of any ``-j 2`` speedup.

Each kernel runs in a warm spawn worker (one BLAS thread), first alone (the other worker idle), then in both
workers at once; each worker times its own kernel. ``slowdown`` = paired time / alone time, and
``pair_speedup`` = 2 × alone / paired is the most that two workers can get over one on that kind of work
(2 on two independent idle cores; less when the two virtual CPUs share a physical core, its caches or the
memory bus). Kernels:

* ``python``: a pure-Python loop (interpreter, branches; :func:`benchmarks.bench_sweep._spin`);
* ``matmul``: 160 × 160 float64 matrix products, in cache (vector FMA units);
* ``stream``: sums over a 256 MB array (memory bandwidth).

Results: ``benchmarks/results/cores.csv``.
"""

from __future__ import annotations

import concurrent.futures as cf
import multiprocessing
import os
import time

from slamcli.sweep.threads import single_threaded_blas

#: seconds each kernel runs alone (about): long enough to dwarf the start skew of two workers (milliseconds)
TARGET_S = 3.0


def _kernel(name: str, reps: int) -> float:
    """Run kernel ``name`` ``reps`` times in this process; its wall time (s)."""
    import numpy as np

    from benchmarks.bench_sweep import _spin

    if name == "matmul":
        a = np.random.default_rng(0).standard_normal((160, 160))
        t0 = time.perf_counter()
        for _ in range(reps):
            a = a @ a
            a /= np.abs(a).max()
        return time.perf_counter() - t0
    if name == "stream":
        x = np.ones(32 * 1024 * 1024)  # 256 MB
        t0 = time.perf_counter()
        for _ in range(reps):
            x.sum()
        return time.perf_counter() - t0
    t0 = time.perf_counter()
    for _ in range(reps):
        _spin(100_000)
    return time.perf_counter() - t0


def run(quick: bool = False) -> list[dict]:
    rows = []
    target = TARGET_S / (3 if quick else 1)
    with single_threaded_blas(), cf.ProcessPoolExecutor(
            2, mp_context=multiprocessing.get_context("spawn")) as ex:
        list(ex.map(_kernel, ["python", "python"], [1, 1]))  # both workers started and warm
        for name in ("python", "matmul", "stream"):
            probe = ex.submit(_kernel, name, 3).result()
            reps = max(3, int(3 * target / max(probe, 1e-6)))
            alone = ex.submit(_kernel, name, reps).result()
            pair = [f.result() for f in [ex.submit(_kernel, name, reps) for _ in range(2)]]
            paired = sum(pair) / 2
            rows.append({"kernel": name, "reps": reps, "alone_s": alone, "paired_s": paired,
                         "slowdown": paired / alone, "pair_speedup": 2 * alone / paired,
                         "load_1min": os.getloadavg()[0]})
    return rows
