"""Issue 25's scoreboard: every slamcli / GTSAM ratio of the graph optimiser in one table (CSV + Markdown).

One invocation, every side in its own fresh child process with single-threaded BLAS
(``OMP_NUM_THREADS=OPENBLAS_NUM_THREADS=MKL_NUM_THREADS=1``), the two sides alternating (ours first in the
1st, 3rd, … repeat, GTSAM first in the others); CPU time (``resource.getrusage``: user + system), never wall time, since the
machine may be shared. Rows (``case``):

* ``lm`` — Levenberg-Marquardt on the grid-city world of :mod:`benchmarks.bench_scale` (known association,
  10k / 50k / 100k poses; ``--quick``: 2k): the same factor graph, start (chained odometry, landmarks from
  their first sighting) and settings (GTSAM 4's LM schedule, relative tolerance and iteration cap of
  ``GraphParams``). CPU of the optimisation only (ours ``nls.solve`` on the built problem, GTSAM
  ``LevenbergMarquardtOptimizer.optimize``); ``rss`` = the child's peak resident set (reading the dataset,
  building the graph, solving). Goals: CPU ratio ≤ 1.0, peak-RSS ratio ≤ 1.2.
* ``posegraph`` — the six public pose graphs (:mod:`benchmarks.bench_posegraph_defaults`): ``graph`` with
  defaults (init=auto, certificate, restart, marginals) against GTSAM LM's optimisation (medians of alternating
  repeats after a warm-up); ``certified``, the start used and the cost in GTSAM's graph are reported, the ratio
  without marginals (``covariance=false``) as ``ratio_nocov`` and the marginals' CPU as ``cpu_marginals_s``
  (also as a percentage of GTSAM LM's CPU, ``marginals_pct_gtsam``).
  Goal ≤ 1.0.
* ``startup`` — a 1k-pose pose graph, whole process (:mod:`benchmarks.bench_graph_startup`). Goal ≤ 1.5.
* ``sweep_worker_start`` — a sweep worker's start (spawn interpreter + its imports, CPU s,
  :func:`benchmarks.bench_sweep.worker_start_cost`): the per-worker overhead of ``sweep -j 2``.

Run: ``python -m benchmarks graph_gtsam [--quick]`` → ``benchmarks/results/graph_gtsam.csv`` and
``graph_gtsam.md``. ``SLAMCLI_BENCH_LM_SIZES=10001,50001`` restricts the LM sizes, ``SLAMCLI_BENCH_PARTS=lm``
(comma list of lm, posegraph, startup, sweep) the parts; the rows of the parts not run are kept from the
previous ``graph_gtsam.csv``, so ``SLAMCLI_BENCH_PARTS=startup python -m benchmarks graph_gtsam`` refreshes
only the start-up row.
"""

from __future__ import annotations

import json
import os
import resource
import statistics
import subprocess
import sys
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
SIZES = (10_001, 50_001, 100_001)
QUICK_SIZES = (2_001,)
REPEATS = {10_001: 3, 50_001: 2, 100_001: 1, 2_001: 2}
PARTS = ("lm", "posegraph", "startup", "sweep")
#: the ``case`` column of each part's rows
CASES = {"lm": "lm", "posegraph": "posegraph", "startup": "startup", "sweep": "sweep_worker_start"}


def _cpu_s() -> float:
    r = resource.getrusage(resource.RUSAGE_SELF)
    return r.ru_utime + r.ru_stime


def lm_child(n_poses: int, side: str) -> dict:
    """One LM solve of the grid-city world in this process (see the module docstring)."""
    import numpy as np

    from benchmarks.bench_scale import dataset_path
    from slamcli.io import read_dataset
    from slamcli.solvers import frontend, graph, nls

    inputs = read_dataset(dataset_path(n_poses)).inputs
    p = graph.GraphParams()
    assoc, old_of_new = frontend.compact_labels(frontend.associate_reported(inputs.observations), p.min_obs)
    poses0 = graph.odometry_initial_poses(inputs)
    lm0 = frontend.landmarks_from_observations(poses0, inputs.observations, assoc, old_of_new.size)
    if side == "gtsam":
        import gtsam

        from benchmarks.bench_graph import gtsam_graph

        g, v0 = gtsam_graph(inputs, assoc, p.prior_std, poses0, lm0)
        lmp = gtsam.LevenbergMarquardtParams()
        lmp.setRelativeErrorTol(p.rel_cost_tol)
        lmp.setAbsoluteErrorTol(0.0)
        lmp.setMaxIterations(p.max_iterations)
        c0 = _cpu_s()
        opt = gtsam.LevenbergMarquardtOptimizer(g, v0, lmp)
        out = opt.optimize()
        cpu = _cpu_s() - c0
        cost, iters = float(g.error(out)), int(opt.iterations())
    else:
        gp = graph.build_gtsam_problem(inputs, assoc, poses0, lm0, p)
        c0 = _cpu_s()
        res = nls.solve(gp.problem, gp.x0, p.nls_params("none", 1.0))
        cpu = _cpu_s() - c0
        cost, iters = float(res.cost), int(res.iterations)
    solver = "GTSAM multifrontal Cholesky" if side == "gtsam" else res.linear_solver
    return {"side": side, "linear_solver": solver, "poses": int(inputs.n_poses), "cpu_s": cpu, "cost": cost, "iterations": iters,
            "peak_rss_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0,
            "finite": bool(np.isfinite(cost))}


def _env() -> dict:
    return dict(os.environ, OMP_NUM_THREADS="1", OPENBLAS_NUM_THREADS="1", MKL_NUM_THREADS="1")


def _child(args: list[str]) -> dict:
    r = subprocess.run([sys.executable, "-m", "benchmarks.bench_graph_gtsam", *args], env=_env(),
                       cwd=HERE.parent, capture_output=True, text=True)
    lines = [ln for ln in r.stdout.splitlines() if ln.startswith("{")]
    if r.returncode != 0 or not lines:
        tail = (r.stderr.strip().splitlines() or ["no output"])[-1]
        return {"error": f"exit {r.returncode}: {tail}"}
    return json.loads(lines[-1])


def lm_rows(sizes) -> list[dict]:
    rows = []
    for n in sizes:
        runs: dict[str, list[dict]] = {"ours": [], "gtsam": []}
        for rep in range(REPEATS.get(n, 1)):
            for side in ("ours", "gtsam") if rep % 2 == 0 else ("gtsam", "ours"):
                runs[side].append(_child(["--lm", str(n), side]))
        a, b = runs["ours"], runs["gtsam"]
        err = next((r["error"] for r in a + b if "error" in r), None)
        row = {"case": "lm", "what": f"LM CPU, grid city {n} poses", "poses": n, "repeats": len(a)}
        if err:
            rows.append({**row, "error": err})
            continue
        cpu_a, cpu_b = (statistics.median(r["cpu_s"] for r in x) for x in (a, b))
        rss_a, rss_b = (max(r["peak_rss_mb"] for r in x) for x in (a, b))
        rows.append({**row, "slamcli": round(cpu_a, 3), "gtsam": round(cpu_b, 3),
                     "ratio": round(cpu_a / cpu_b, 3), "goal": 1.0, "met": cpu_a <= cpu_b,
                     "rss_slamcli_mb": round(rss_a, 1), "rss_gtsam_mb": round(rss_b, 1),
                     "rss_ratio": round(rss_a / rss_b, 3), "rss_goal": 1.2, "rss_met": rss_a <= 1.2 * rss_b,
                     "linear_solver": a[0]["linear_solver"],
                     "iterations_slamcli": a[0]["iterations"], "iterations_gtsam": b[0]["iterations"],
                     "cost_slamcli": a[0]["cost"], "cost_gtsam": b[0]["cost"]})
    return rows


def posegraph_rows(quick: bool) -> list[dict]:
    from benchmarks.bench_posegraph_defaults import run as pg_run

    rows = []
    for r in pg_run(quick=quick):
        rows.append({"case": "posegraph", "what": f"pose graph {r['dataset']}, default solve CPU",
                     "poses": r["poses"], "slamcli": r["cpu_graph_s"], "gtsam": r["cpu_gtsam_lm_s"],
                     "ratio": r["ratio"], "goal": 1.0, "met": r["ratio"] <= 1.0 and bool(r["certified"]),
                     "ratio_nocov": r["ratio_nocov"], "cpu_marginals_s": r["cpu_marginals_s"],
                     "marginals_pct_gtsam": r["marginals_pct_gtsam"],
                     "certified": r["certified"], "init": r["init"],
                     "cost_slamcli": r["cost_graph"], "cost_gtsam": r["cost_gtsam_lm_odometry"],
                     "cost_gtsam_chordal": r["cost_gtsam_lm_chordal"], "restart": r["restart"]})
    return rows


def startup_rows(quick: bool) -> list[dict]:
    from benchmarks.bench_graph_startup import run as st_run

    r = st_run(quick=quick)[0]
    return [{"case": "startup", "what": f"whole process, {r['poses']}-pose pose graph, defaults",
             "poses": r["poses"], "repeats": r["repeats"], "slamcli": r["cpu_slamcli_s"], "gtsam": r["cpu_gtsam_s"],
             "ratio": r["ratio"], "goal": 1.5, "met": r["ratio"] <= 1.5, "ratio_nocov": r["ratio_nocov"],
             "cpu_imports_s": r["cpu_imports_s"], "cpu_gtsam_import_s": r["cpu_gtsam_import_s"],
             "cpu_numpy_star_s": r["cpu_numpy_star_s"], "cpu_scipy_linalg_s": r["cpu_scipy_linalg_s"],
             **{k: v for k, v in r.items() if k.startswith("instr_")}}]


def sweep_rows() -> list[dict]:
    from benchmarks.bench_sweep import worker_start_cost

    s = worker_start_cost()
    return [{"case": "sweep_worker_start", "what": "sweep worker start (spawn + imports), CPU s",
             "slamcli": round(s["worker_start_cpu_s"], 3), "wall_s": round(s["worker_start_wall_s"], 3)}]


def machine_state(load_before: tuple[float, float, float], parts: tuple[str, ...]) -> str:
    """One line naming the machine state of a run: the parts it measured, cores, load averages before and after,
    BLAS threads, and the sparse linear solver ``linear_solver="auto"`` takes on this install."""
    from importlib.metadata import PackageNotFoundError, version

    from slamcli.solvers.nls import cholmod_available

    try:
        cvx = f"CHOLMOD (CVXOPT {version('cvxopt')})" if cholmod_available() else "SciPy SuperLU"
    except PackageNotFoundError:
        cvx = "CHOLMOD" if cholmod_available() else "SciPy SuperLU"
    after = os.getloadavg()
    kept = [p for p in PARTS if p not in parts]
    return (f"Run {time.strftime('%Y-%m-%d')} of {', '.join(parts)}"
            + (f" (rows of {', '.join(kept)} kept from earlier runs)" if kept else "")
            + f": linear solver {cvx}; {os.cpu_count()} cores, load average {load_before[0]:.2f} before / "
            f"{after[0]:.2f} after; single-threaded BLAS on both sides.")


def write_markdown(rows: list[dict], path: Path, kept_lines: dict[tuple, str] | None = None,
                   state: str = "") -> None:
    """The table under the ``state`` line; a row whose ``(case, what)`` is in ``kept_lines`` is written as that
    earlier line."""
    lines = [state, ""] if state else []
    lines += ["| case | what | slamcli CPU s | GTSAM CPU s | ratio | goal | met | details |",
              "|---|---|---|---|---|---|---|---|"]
    skip = {"case", "what", "slamcli", "gtsam", "ratio", "goal", "met"}
    for r in rows:
        det = ", ".join(f"{k}={v:.4g}" if isinstance(v, float) else f"{k}={v}" for k, v in r.items()
                        if k not in skip and v not in ("", None))
        cells = [r.get(k, "") for k in ("case", "what", "slamcli", "gtsam", "ratio", "goal", "met")]
        line = "| " + " | ".join(str(c) for c in cells) + f" | {det} |"
        lines.append((kept_lines or {}).get((r.get("case"), r.get("what")), line))
    tmp = path.with_suffix(".md.tmp")
    tmp.write_text("\n".join(lines) + "\n")
    tmp.replace(path)


def previous_rows(path: Path) -> list[dict]:
    """The rows of an earlier run's CSV (numbers parsed back, empty cells left out); ``[]`` when there is none."""
    from benchmarks.bench_defaults import read_csv

    return [{k: v for k, v in r.items() if v != ""} for r in read_csv(str(path))]


def previous_md_lines(path: Path) -> dict[tuple, str]:
    """The table lines of an earlier run's Markdown by ``(case, what)`` (a kept row keeps its line as it was)."""
    if not path.exists():
        return {}
    cells = (line.strip("| ").split(" | ") for line in path.read_text().splitlines() if line.startswith("| "))
    return {(c[0], c[1]): "| " + " | ".join(c) + " |" for c in cells if len(c) > 2}


def run(quick: bool = False) -> list[dict]:
    parts = tuple(p for p in os.environ.get("SLAMCLI_BENCH_PARTS", ",".join(PARTS)).split(",") if p)
    unknown = sorted(set(parts) - set(PARTS))
    if unknown:
        raise SystemExit(f"SLAMCLI_BENCH_PARTS: unknown part(s) {', '.join(unknown)}; known: {', '.join(PARTS)}")
    env_sizes = os.environ.get("SLAMCLI_BENCH_LM_SIZES")
    sizes = tuple(int(s) for s in env_sizes.split(",")) if env_sizes else (QUICK_SIZES if quick else SIZES)
    kept = previous_rows(HERE / "results" / "graph_gtsam.csv")
    measure = {"lm": lambda: lm_rows(sizes), "posegraph": lambda: posegraph_rows(quick),
               "startup": lambda: startup_rows(quick), "sweep": sweep_rows}
    rows: list[dict] = []
    t0, load0 = time.perf_counter(), os.getloadavg()
    for part in PARTS:  # the table's order, whichever parts run
        rows += measure[part]() if part in parts else [r for r in kept if r.get("case") == CASES[part]]
    (HERE / "results").mkdir(exist_ok=True)
    md_lines = previous_md_lines(HERE / "results" / "graph_gtsam.md")
    kept_lines = {k: md_lines[k] for k in ((r["case"], r["what"]) for r in kept if r.get("case") in
                                           {CASES[p] for p in PARTS if p not in parts}) if k in md_lines}
    write_markdown(rows, HERE / "results" / "graph_gtsam.md", kept_lines, machine_state(load0, parts))
    print(f"graph_gtsam: {time.perf_counter() - t0:.0f} s", file=sys.stderr)
    return rows


if __name__ == "__main__":  # pragma: no cover
    if "--lm" in sys.argv:
        i = sys.argv.index("--lm")
        print(json.dumps(lm_child(int(sys.argv[i + 1]), sys.argv[i + 2])), flush=True)
    else:
        for row in run(quick="--quick" in sys.argv):
            print(json.dumps(row), flush=True)
