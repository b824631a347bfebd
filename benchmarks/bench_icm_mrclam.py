"""ICM ``-p preset=real`` against ``graph``'s defaults on UTIAS MRCLAM Dataset 7, robots 1-5 solo.

Per robot: the recording imported by :func:`slamcli.datasets.mrclam.import_mrclam` (the importer's defaults,
as ``slamcli import mrclam mrclam7 --robot N``), then ``graph`` with its defaults and ICM with
``preset=real`` (and any extra ICM rows of :data:`ICM_ROWS`), each solved once in this process. ATE is
:func:`slamcli.metrics.summary.evaluate_result`'s ``ate_rmse_m`` against the motion-capture truth; CPU is
``time.process_time`` around the solve alone, solver modules already imported (numba's one-time kernel load
of ICM is outside it), BLAS single-threaded. Goal: ICM ATE ≤ 1.10 × graph's and CPU ≤ 2 × graph's on every
robot.

Run: ``python -m benchmarks icm_mrclam`` (``--quick``: robot 1 only); also writes
``benchmarks/results/icm_mrclam.md`` with the machine load and each solver's resolved configuration.
"""

from __future__ import annotations

import json
import os
import time
from pathlib import Path

ROBOTS = (1, 2, 3, 4, 5)
#: (label, ICM parameters); the first row is the one the goal is judged on
ICM_ROWS: list[tuple[str, dict]] = [("preset=real", {"preset": "real"})]
ATE_GOAL = 1.10
CPU_GOAL = 2.0
FINDINGS = "## Findings"
OUT_MD = Path(__file__).resolve().parent / "results" / "icm_mrclam.md"


def _solve(inputs, method: str, params: dict):
    """``(result, CPU s)`` of one solve."""
    from slamcli.api.solve import solve_dataset

    t0 = time.process_time()
    res = solve_dataset(inputs, method, params, seed=0)
    return res, time.process_time() - t0


def run(quick: bool = False) -> list[dict]:
    os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
    os.environ.setdefault("OMP_NUM_THREADS", "1")
    import slamcli.solvers.graph  # noqa: F401 - imports (and ICM's numba kernels) outside the timed solves
    from slamcli.solvers.icm import energy

    t0 = time.process_time()
    energy.compiled_kernels()
    kernel_cpu = time.process_time() - t0
    from slamcli.datasets.mrclam import import_mrclam
    from slamcli.datasets.registry import locate
    from slamcli.metrics.summary import EvaluationParams, evaluate_result

    directory = locate("mrclam7")
    rows, configs = [], {}
    load_before = os.getloadavg()
    for robot in (1,) if quick else ROBOTS:
        ds = import_mrclam(directory, robot)

        def ate(res, ds=ds):
            return evaluate_result(res, ds.truth, ds.inputs.odometry_xyt, EvaluationParams(cutoff_m=1.0)).scalars[
                "ate_rmse_m"]

        g, g_cpu = _solve(ds.inputs, "graph", {})
        configs["graph"] = {**g.params, "resolved robust": g.extra.get("robust")}
        g_ate = ate(g)
        for label, params in ICM_ROWS:
            r, cpu = _solve(ds.inputs, "icm", params)
            configs[f"icm {label}"] = r.params
            a = ate(r)
            rows.append({"robot": robot, "icm": label, "graph_ate_m": g_ate, "icm_ate_m": a, "ate_ratio": a / g_ate,
                         "graph_cpu_s": g_cpu, "icm_cpu_s": cpu, "cpu_ratio": cpu / g_cpu,
                         "icm_status": r.status.value, "icm_sweeps": r.extra.get("sweeps"),
                         "icm_polish_lm_iters": sum(p["iterations"] for p in r.extra.get("polishes", [])),
                         "icm_optimum_gap": r.extra.get("optimum_gap"), "graph_iters": g.extra.get("iterations"),
                         "ok": a <= ATE_GOAL * g_ate and cpu <= CPU_GOAL * g_cpu})
    _write_md(rows, configs, load_before, os.getloadavg(), kernel_cpu)
    return rows


def _write_md(rows, configs, load_before, load_after, kernel_cpu: float) -> None:
    lines = ["# ICM preset=real vs graph defaults, MRCLAM Dataset 7 robots solo", "",
             "Written by `python -m benchmarks icm_mrclam` (benchmarks/bench_icm_mrclam.py). "
             f"Goal: ICM ATE ≤ {ATE_GOAL:.2f} × graph's and CPU ≤ {CPU_GOAL:g} × graph's.", "",
             f"Machine: {os.cpu_count()} cores, load average (1, 5, 15 min) {load_before[0]:.1f} / "
             f"{load_before[1]:.1f} / {load_before[2]:.1f} before, {load_after[0]:.1f} / {load_after[1]:.1f} / "
             f"{load_after[2]:.1f} after; CPU = process time of the solve alone, BLAS single-threaded; linear "
             "solver: CHOLMOD (`linear_solver=auto`) for graph and ICM's polish. ICM's numba kernels are loaded once per "
             f"process before the timed solves ({kernel_cpu:.2f} s CPU here, a cost a `slamcli solve` of ICM pays "
             "once).", "",
             "| robot | ICM | graph ATE m | ICM ATE m | ATE ratio | graph CPU s | ICM CPU s | CPU ratio | ICM sweeps "
             "| ICM polish LM iters | graph LM iters | goal met |",
             "|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        lines.append(f"| {r['robot']} | {r['icm']} | {r['graph_ate_m']:.4f} | {r['icm_ate_m']:.4f} | "
                     f"{r['ate_ratio']:.3f} | {r['graph_cpu_s']:.2f} | {r['icm_cpu_s']:.2f} | {r['cpu_ratio']:.2f} | "
                     f"{r['icm_sweeps']} | {r['icm_polish_lm_iters']} | {r['graph_iters']} | "
                     f"{'yes' if r['ok'] else 'no'} |")
    lines += ["", "Resolved configuration of each solver (the result's `params`):", ""]
    for name, cfg in configs.items():
        lines += [f"- **{name}**: `{json.dumps(cfg, default=str)}`"]
    keep = ""  # the hand-written findings below the table survive a re-run
    if OUT_MD.exists() and FINDINGS in OUT_MD.read_text():
        keep = "\n" + OUT_MD.read_text()[OUT_MD.read_text().index(FINDINGS):]
    OUT_MD.parent.mkdir(exist_ok=True)
    OUT_MD.write_text("\n".join(lines) + "\n" + keep)
