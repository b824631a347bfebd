"""Defaults a first run trusts (issue 24 item 7): every registered solver with its DEFAULT parameters against
dead reckoning on the paper scenarios.

For each scenario (``paper-sim1``, ``paper-sim2``, ``loop``, ``octagon``) and seed 0-4 the dataset is simulated
once (into a temporary HDF5 file); every registered solver (``slamcli.solvers.registry``) then solves it with ``make_solver(name)`` — no
parameter given — and the solver seed 0. Columns: SE(2)-aligned ATE RMSE of the solver and of the
``odometry`` solver (dead reckoning) on the same data, ``beats_dr`` (aligned ATE strictly below dead
reckoning's), CPU seconds of the solve, number of landmarks (estimated / true), status and message. A solver
run happens in a forked child process with a CPU limit (``CPU_LIMIT_S``); a run that exceeds it, raises, or returns
a non-finite path is a row with ``beats_dr = False`` and the reason in ``note`` — the table explains every
exception instead of dropping it.

``python -m benchmarks defaults [--quick]`` (quick: seeds 0-1, no solver over ``QUICK_CPU_LIMIT_S``).
Writes ``benchmarks/results/defaults.csv``. Uses 1 core at a time (the machine is shared).
"""

from __future__ import annotations

import multiprocessing as mp
import resource
import time

import numpy as np

SCENARIOS = ("paper-sim1", "paper-sim2", "loop", "octagon")
SEEDS = range(5)
CPU_LIMIT_S = 300
QUICK_CPU_LIMIT_S = 60


def _child(conn, data_path: str, method: str, cpu_limit: int) -> None:
    """Read the dataset, solve with defaults, evaluate; send a dict (or the error line) through ``conn``."""
    resource.setrlimit(resource.RLIMIT_CPU, (cpu_limit, cpu_limit + 5))
    try:
        from slamcli.api.solve import make_solver, solver_rng
        from slamcli.io import read_dataset
        from slamcli.metrics.trajectory import ate

        ds = read_dataset(data_path)
        c0 = time.process_time()
        res = make_solver(method).solve(ds.inputs, rng=solver_rng(0))
        cpu = time.process_time() - c0
        ok = bool(np.all(np.isfinite(res.poses_xyt)))
        out = {
            "cpu_s": round(cpu, 2),
            "ate_aligned_m": ate(res.poses_xyt, ds.truth.poses_xyt, align=True)["ate_rmse_m"] if ok else float("nan"),
            "landmarks_est": int(res.landmarks_xy.shape[0]),
            "landmarks_true": int(ds.truth.landmarks_xy.shape[0]),
            "status": res.status.value,
            "message": str(res.message)[:160],
        }
        if method == "ekf":
            out["landmarks_spurious"] = max(0, out["landmarks_est"] - out["landmarks_true"])
        conn.send(out)
    except Exception as exc:  # noqa: BLE001 — any failure of a default run is a row of the table
        conn.send({"error": f"{type(exc).__name__}: {str(exc).splitlines()[0][:200] if str(exc) else ''}"})
    finally:
        conn.close()


def run_one(data_path: str, method: str, cpu_limit: int) -> dict:
    """One default solve in a child process; a CPU-limit kill or crash becomes ``{"error": ...}``."""
    ctx = mp.get_context("fork")  # the child inherits the parent's imports (a spawn costs ≈ 5 s CPU each)
    parent, child = ctx.Pipe(duplex=False)
    proc = ctx.Process(target=_child, args=(child, data_path, method, cpu_limit))
    proc.start()
    child.close()
    try:
        out = parent.recv() if parent.poll(cpu_limit * 4 + 60) else None
    except EOFError:  # the child died before sending (SIGXCPU at the CPU limit, or a crash)
        out = None
    proc.join(10)
    if proc.is_alive():
        proc.kill()
        proc.join()
    if out is None:
        out = {"error": f"no result within the CPU limit of {cpu_limit} s (exit code {proc.exitcode})"}
    return out


def _datasets(tmp: str, seeds) -> dict:
    """Simulate every (scenario, seed) once into ``tmp`` (children read the file: the same data for all)."""
    from slamcli.io import write_dataset
    from slamcli.sim import simulate_scenario

    out = {}
    for seed in seeds:
        for scenario in SCENARIOS:
            path = f"{tmp}/{scenario}-{seed}.h5"
            write_dataset(path, simulate_scenario(scenario, seed=seed))
            out[scenario, seed] = path
    return out


def run(quick: bool = False, partial_csv: str | None = None) -> list[dict]:
    """Every solver's default on every (scenario, seed), seed-major (all scenarios of seed 0 first).

    ``partial_csv``: rewrite this CSV after every row (a long run keeps what it measured so far).
    """
    import tempfile

    from slamcli.solvers import registry

    methods = [s.name for s in registry.available()]
    import slamcli.api.solve  # imported once here, inherited by every forked child
    import slamcli.metrics.trajectory  # noqa: F401

    for m in methods:
        registry.load(m)
    seeds = range(2) if quick else SEEDS
    limit = QUICK_CPU_LIMIT_S if quick else CPU_LIMIT_S
    rows = []
    with tempfile.TemporaryDirectory(prefix="bench-defaults-") as tmp:
        paths = _datasets(tmp, seeds)
        for seed in seeds:
            for scenario in SCENARIOS:
                dr = run_one(paths[scenario, seed], "odometry", limit)
                for method in methods:
                    r = dr if method == "odometry" else run_one(paths[scenario, seed], method, limit)
                    rows.append(_row(scenario, seed, method, r, dr))
                    if partial_csv:
                        _write_csv(partial_csv, rows)
    return rows


def _row(scenario: str, seed: int, method: str, r: dict, dr: dict) -> dict:
    ate_dr = dr.get("ate_aligned_m", float("nan"))
    row = {"scenario": scenario, "seed": seed, "solver": method}
    row.update({k: v for k, v in r.items() if k != "error"})
    row["ate_dr_aligned_m"] = ate_dr
    a = r.get("ate_aligned_m", float("nan"))
    row["beats_dr"] = bool(np.isfinite(a) and a < ate_dr) if method != "odometry" else ""
    row["note"] = r.get("error", "")
    return row


def _write_csv(path: str, rows: list[dict]) -> None:
    import csv
    import os

    keys: list[str] = []
    for r in rows:
        keys += [k for k in r if k not in keys]
    tmp = f"{path}.tmp"
    with open(tmp, "w", newline="") as fh:
        w = csv.DictWriter(fh, fieldnames=keys)
        w.writeheader()
        w.writerows(rows)
    os.replace(tmp, path)


if __name__ == "__main__":  # pragma: no cover
    import sys

    for row in run(quick="--quick" in sys.argv):
        print(row)
