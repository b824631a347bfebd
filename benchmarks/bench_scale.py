"""Scale table (issue 17): slamcli against a reference at 10k / 50k / 100k poses, time and peak memory.

Every measurement runs in a fresh child process (``python -m benchmarks.bench_scale --worker TASK``) that
reports its wall time, CPU time (user + system) and peak resident set size (``resource.getrusage``
``ru_maxrss``), so one row's memory never leaks into another's. Children run with single-threaded BLAS
(``OPENBLAS_NUM_THREADS=1``, as in the issue's measurements) and under an address-space limit
(``SLAMCLI_SCALE_MEM_GB``, default 8 GiB — twice the 4 GB goal, so that a solver that would need a dense
T×L block fails with a MemoryError instead of pushing the shared machine into swap) and a time limit
(``SLAMCLI_SCALE_TIMEOUT`` s, default 1500). A child that fails is a row with ``status`` saying how.

World: *grid city* (:func:`grid_city`) — the ``paper-sim1`` scenario scaled up: rows of landmarks every
10 m (5 m apart along a row) over 250 m, a serpentine path between them long enough for T steps at
1 m/s, a 180° point sensor of 18 m range reporting landmark ids (≈ 10 observations per pose), no
clutter. Datasets are simulated once and cached in ``benchmarks/results/scale_data/``.

Rows (``row`` column; ``impl`` is slamcli or the reference of that row; ``ratio`` = slamcli / reference
wall time of the same size in the same run, ``cpu_ratio`` the same for CPU time — steadier on a loaded
machine — and ``rss_ratio`` for peak RSS):

* ``graph+marginals`` — ``graph`` with default parameters (``covariance=true``) vs GTSAM 4
  ``LevenbergMarquardtOptimizer`` on the same factor graph and start + ``gtsam.Marginals`` of every pose
  and landmark. Goal: peak RSS < 4 GB at 100k, time ≤ 1.5× GTSAM. ``details`` also hold the marginals'
  own share on both sides (``marginals_s`` / ``marginals_cpu_s``; ours: the selected inverse of H on
  CHOLMOD's factor, :mod:`slamcli.solvers.nls.selinv`, or the SciPy Schur path without CHOLMOD).
* ``icm-joint`` — ``icm`` with ``accelerate=joint``, reported correspondences, vs GTSAM LM (no marginals)
  on the same data. Goal: < 4 GB at 100k.
* ``ekf`` (size = state dimension n = 103 / 1003 / 4003) — :mod:`benchmarks.bench_ekf`'s scale world, our
  filter vs its in-place BLAS reference (one ``dgemm`` rank-2 update on a preallocated P). Goal ≤ 1.2×.
* ``startup`` — ``slamcli --help``, ``slamcli solvers``, ``slamcli info D.h5`` (10k dataset): median wall
  of several runs; CPU time too, which a loaded machine inflates less. Goal < 0.5 s.
* ``simulate`` — simulating the grid-city world (KD-tree point sensor) vs the previous all-pairs point
  sensor query (same output). Goal: ≈ linear in T.
* ``hdf5-write`` / ``hdf5-read`` — ``write_dataset`` / ``read_dataset`` vs ``np.savez`` / ``np.load`` of
  the same arrays (trade-off in docs/schema.md).

Sizes and rows can be chosen (the 100k rows take long): ``python -m benchmarks.bench_scale --sizes
10001,50001 --rows graph,ekf`` or the environment variables ``SLAMCLI_SCALE_SIZES`` /
``SLAMCLI_SCALE_ROWS`` with ``python -m benchmarks scale``. ``--quick``: one 2k-pose world, short EKF runs.
"""

from __future__ import annotations

import json
import math
import os
import statistics
import subprocess
import sys
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
DATA = HERE / "results" / "scale_data"
SIZES = (10_001, 50_001, 100_001)
QUICK_SIZES = (2_001,)
ROWS = ("startup", "simulate", "hdf5", "ekf", "graph", "icm")
EKF_N = (103, 1003, 4003)  # L = 50, 500, 2000 landmarks (issue 25 item 5)


# --------------------------------------------------------------------------------------------------------
# the world
# --------------------------------------------------------------------------------------------------------
def grid_city(n_poses: int) -> dict:
    """Scenario overrides of ``paper-sim1`` for a grid-city world with ``n_poses`` poses (see module doc)."""
    n_steps = n_poses - 1
    n_lanes = max(1, math.ceil(n_steps * 0.1 * 1.0 / 250.0))
    return {
        "n_steps": n_steps, "dt": 0.1,
        "world.layout": "rows", "world.x_min": 0.0, "world.x_max": 250.0, "world.n_rows": n_lanes + 1,
        "world.row_y0": 0.0, "world.row_spacing": 10.0, "world.col_spacing": 5.0, "world.jitter": 0.3,
        "path.kind": "serpentine", "path.x_min": -2.0, "path.x_max": 252.0, "path.y_min": -5.0,
        "path.y_max": 10.0 * n_lanes + 5.0, "path.lanes": tuple(5.0 + 10.0 * k for k in range(n_lanes)),
        "path.spacing": 5.0, "path.jitter": 0.3, "path.cyclic": True,
        "robot.v_max": 1.0,
        "sensor.kind": "point", "sensor.max_range": 18.0, "sensor.min_range": 0.1, "sensor.fov_deg": 180.0,
        "sensor.range_std": 0.05, "sensor.bearing_std": 0.01, "sensor.detection_prob": 1.0,
        "sensor.report_ids": True, "clutter.rate": 0.0,
    }


def dataset_path(n_poses: int) -> Path:
    """The cached grid-city dataset of ``n_poses`` poses (simulated and written on first use)."""
    path = DATA / f"grid-city-{n_poses}.h5"
    if not path.exists():
        from slamcli.io import write_dataset
        from slamcli.sim import simulate_scenario

        DATA.mkdir(parents=True, exist_ok=True)
        write_dataset(path, simulate_scenario("paper-sim1", seed=0, overrides=grid_city(n_poses)))
    return path


# --------------------------------------------------------------------------------------------------------
# child side: one task, measured
# --------------------------------------------------------------------------------------------------------
def _rss_mb() -> float:
    import resource

    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0  # Linux: KiB


def _cpu_s() -> float:
    import resource

    r = resource.getrusage(resource.RUSAGE_SELF)
    return r.ru_utime + r.ru_stime


def _gtsam_solve(inputs, marginals: bool) -> dict:
    """GTSAM LM (+ all marginals) on the graph ``graph`` builds (reported ids, same start)."""
    import gtsam

    from benchmarks.bench_graph import gtsam_graph
    from slamcli.solvers import frontend, graph

    params = graph.GraphParams()
    assoc = frontend.associate_reported(inputs.observations)
    L = int(assoc.max()) + 1
    poses0 = graph.odometry_initial_poses(inputs)
    lm0 = frontend.landmarks_from_observations(poses0, inputs.observations, assoc, L)
    g, v0 = gtsam_graph(inputs, assoc, params.prior_std, poses0, lm0)
    lmp = gtsam.LevenbergMarquardtParams()
    lmp.setRelativeErrorTol(params.rel_cost_tol)
    lmp.setAbsoluteErrorTol(0.0)
    lmp.setMaxIterations(params.max_iterations)
    t0 = time.perf_counter()
    opt = gtsam.LevenbergMarquardtOptimizer(g, v0, lmp)
    vals = opt.optimize()
    out = {"iterations": int(opt.iterations()), "cost": float(g.error(vals)), "solve_s": time.perf_counter() - t0}
    if marginals:
        t1, c1 = time.perf_counter(), _cpu_s()
        marg = gtsam.Marginals(g, vals)
        for t in range(inputs.n_poses):
            marg.marginalCovariance(gtsam.symbol("x", t))
        for j in range(L):
            marg.marginalCovariance(gtsam.symbol("l", j))
        out["marginals_s"] = time.perf_counter() - t1
        out["marginals_cpu_s"] = _cpu_s() - c1
    return out


def _solver(name: str, overrides: dict):
    from slamcli.params import build_params
    from slamcli.solvers import registry

    cls = registry.load(name)
    return cls(build_params(cls.Params, overrides))


def _task(task: dict) -> dict:
    """Run one measured task in this process; returns the row's measured fields."""
    import numpy as np

    kind, size = task["kind"], int(task["size"])
    extra: dict = {}
    if kind in ("graph", "icm", "gtsam-marginals", "gtsam-lm", "hdf5-write", "hdf5-read", "savez", "npload"):
        from slamcli.io import read_dataset

        ds = read_dataset(dataset_path(size), with_truth=kind in ("hdf5-write", "savez"))
        extra["observations"] = len(ds.inputs.observations)
    if kind in ("ekf", "ekf-reference"):
        from benchmarks.bench_ekf import ekf_scale_world

        inputs = ekf_scale_world(size, int(task["steps"]))
    rss0, cpu0, t0 = _rss_mb(), _cpu_s(), time.perf_counter()
    status = "ok"
    if kind == "graph":
        from slamcli.solvers import graph
        from slamcli.solvers.nls import cholmod_available

        marg: dict = {}
        laplace = graph.laplace_marginals

        def timed(*a, **k):  # the marginals' own share of the solve (wall, CPU, peak RSS before them)
            w, c = time.perf_counter(), _cpu_s()
            marg["peak_rss_before_marginals_mb"] = _rss_mb()
            try:
                return laplace(*a, **k)
            finally:
                marg.update(marginals_s=time.perf_counter() - w, marginals_cpu_s=_cpu_s() - c)

        graph.laplace_marginals = timed
        res = _solver("graph", {}).solve(ds.inputs, rng=np.random.default_rng(0))
        status = res.status.value
        extra.update(iterations=res.extra.get("iterations"), landmarks=len(res.landmarks_xy),
                     has_marginals=res.pose_cov is not None and res.landmark_cov is not None,
                     marginals_path="selected inverse (CHOLMOD)" if cholmod_available() else "SciPy Schur",
                     message=res.message[:120], **marg)
    elif kind == "icm":
        res = _solver("icm", {"accelerate": "joint", "correspondences": "reported"}).solve(
            ds.inputs, rng=np.random.default_rng(0))
        status = res.status.value
        extra.update(sweeps=len(res.trace) if res.trace is not None else None, landmarks=len(res.landmarks_xy),
                     message=res.message[:120],
                     **{k: v for k, v in res.extra.items() if "joint" in k or "memory" in k.lower()})
    elif kind in ("gtsam-marginals", "gtsam-lm"):
        extra.update(_gtsam_solve(ds.inputs, marginals=kind == "gtsam-marginals"))
    elif kind in ("simulate", "simulate-allpairs"):
        from slamcli.sim import sensors, simulate_scenario

        if kind == "simulate-allpairs":  # the point sensor's previous O(T·L) query (identical output)
            sensors._LandmarkIndex.candidates = lambda self, p, r0, r1: sensors._candidates(
                p, self.landmarks_xy, r0, r1)
        d = simulate_scenario("paper-sim1", seed=0, overrides=grid_city(size))
        extra.update(landmarks=len(d.truth.landmarks_xy), observations=len(d.inputs.observations))
    elif kind in ("hdf5-write", "savez"):
        out = DATA / f"tmp-{os.getpid()}"
        if kind == "hdf5-write":
            from slamcli.io import write_dataset

            write_dataset(out.with_suffix(".h5"), ds)
            path = out.with_suffix(".h5")
        else:
            np.savez(out.with_suffix(".npz"), **_arrays(ds))
            path = out.with_suffix(".npz")
        extra["file_mb"] = path.stat().st_size / 1e6
        path.unlink()
    elif kind == "hdf5-read":
        from slamcli.io import read_dataset as rd

        rd(dataset_path(size))
    elif kind == "npload":
        path = DATA / f"tmp-{os.getpid()}.npz"
        np.savez(path, **_arrays(ds))
        del ds
        rss0, cpu0, t0 = _rss_mb(), _cpu_s(), time.perf_counter()
        with np.load(path) as z:
            _ = {k: z[k] for k in z.files}
        path.unlink()
    elif kind in ("ekf", "ekf-reference"):
        from benchmarks.bench_ekf import blas_reference_ekf

        if kind == "ekf":
            res = _solver("ekf", {"association": "known"}).solve(inputs, rng=np.random.default_rng(0))
            poses, n_upd = res.poses_xyt, res.extra["n_updates"]
        else:
            poses, n_upd = blas_reference_ekf(inputs)
        extra.update(updates=n_upd, us_per_update=(time.perf_counter() - t0) / max(n_upd, 1) * 1e6,
                     pose_digest=float(np.abs(poses).sum()))  # equal digests: both filters computed the same
    else:
        raise ValueError(f"unknown task {kind!r}")
    return {"status": status, "wall_s": time.perf_counter() - t0, "cpu_s": _cpu_s() - cpu0,
            "peak_rss_mb": _rss_mb(), "rss_before_mb": rss0, **extra}


def _arrays(ds) -> dict:
    """The dataset's arrays, for the ``np.savez`` yardstick."""
    o, inp = ds.inputs.observations, ds.inputs
    out = {f"obs_{k}": getattr(o, k) for k in ("step", "range_m", "bearing_rad", "sensor", "reported_id", "offsets")}
    out.update(timestamps=inp.timestamps, x0=inp.x0, controls=inp.controls, odometry_xyt=inp.odometry_xyt)
    if ds.truth is not None:
        out.update(poses_xyt=ds.truth.poses_xyt, landmarks_xy=ds.truth.landmarks_xy,
                   obs_landmark=ds.truth.obs_landmark)
    return out


# --------------------------------------------------------------------------------------------------------
# parent side
# --------------------------------------------------------------------------------------------------------
def _child_env() -> dict:
    env = dict(os.environ)
    env.update(OPENBLAS_NUM_THREADS="1", OMP_NUM_THREADS="1", MKL_NUM_THREADS="1", PYTHONPATH=str(ROOT))
    return env


def _limits(mem_gb: float):
    def apply():  # runs in the child before exec
        import resource

        lim = int(mem_gb * 2**30)
        resource.setrlimit(resource.RLIMIT_AS, (lim, lim))

    return apply


def measure(task: dict, *, timeout: float | None = None, mem_gb: float | None = None) -> dict:
    """Run ``task`` in a child process; the measured fields, or a ``status`` saying how it failed."""
    timeout = timeout or float(os.environ.get("SLAMCLI_SCALE_TIMEOUT", 1500))
    mem_gb = mem_gb or float(os.environ.get("SLAMCLI_SCALE_MEM_GB", 8))
    cmd = [sys.executable, "-m", "benchmarks.bench_scale", "--worker", json.dumps(task)]
    t0 = time.perf_counter()
    proc = subprocess.Popen(cmd, cwd=ROOT, env=_child_env(), stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            text=True, preexec_fn=_limits(mem_gb))
    try:
        stdout, stderr = proc.communicate(timeout=timeout)
    except subprocess.TimeoutExpired:
        hwm = _vm_hwm_mb(proc.pid)  # the peak RSS so far, read before the kill
        proc.kill()
        proc.communicate()
        return {"status": f"timeout after {timeout:.0f} s", "wall_s": time.perf_counter() - t0, "peak_rss_mb": hwm}
    for line in reversed(stdout.splitlines()):
        if line.startswith("{"):
            m = json.loads(line)
            if "MemoryError" in str(m.get("status")):
                m["status"] = f"{m['status']} (under the {mem_gb:g} GiB address-space limit)"
            return m
    err = [ln for ln in stderr.strip().splitlines() if ln.strip()]
    last = err[-1][:160] if err else f"exit {proc.returncode}"
    if "MemoryError" in stderr or "bad_alloc" in stderr:
        last = f"MemoryError under the {mem_gb:g} GiB address-space limit ({last})"
    return {"status": f"failed: {last}", "wall_s": time.perf_counter() - t0}


def _vm_hwm_mb(pid: int) -> float | str:
    """Peak resident set size of a running process (``VmHWM`` in /proc, Linux), MB."""
    try:
        for line in Path(f"/proc/{pid}/status").read_text().splitlines():
            if line.startswith("VmHWM:"):
                return int(line.split()[1]) / 1024.0
    except OSError:
        pass
    return ""


def _startup_cmd(args: list[str], repeats: int) -> dict:
    """Median / min wall, CPU and peak RSS of ``slamcli ARGS`` started ``repeats`` times as a fresh process."""
    code = ("import json, resource, subprocess, sys, time\n"
            "t0 = time.perf_counter(); r = subprocess.run(sys.argv[1:], capture_output=True)\n"
            "wall = time.perf_counter() - t0; u = resource.getrusage(resource.RUSAGE_CHILDREN)\n"
            "print(json.dumps({'rc': r.returncode, 'wall': wall, 'cpu': u.ru_utime + u.ru_stime,"
            " 'rss': u.ru_maxrss / 1024}))\n")
    exe = str(Path(sys.executable).with_name("slamcli"))
    runs = []
    for _ in range(repeats):
        out = subprocess.run([sys.executable, "-c", code, exe, *args], capture_output=True, text=True,
                             env=_child_env(), cwd=ROOT)
        r = json.loads(out.stdout.strip().splitlines()[-1])
        if r["rc"] != 0:
            return {"status": f"failed: exit {r['rc']}"}
        runs.append(r)
    return {"status": "ok", "wall_s": statistics.median(r["wall"] for r in runs),
            "wall_min_s": min(r["wall"] for r in runs), "cpu_s": statistics.median(r["cpu"] for r in runs),
            "peak_rss_mb": max(r["rss"] for r in runs), "repeats": repeats}


def _row(row: str, size: int, impl: str, m: dict, goal: str = "") -> dict:
    keep = ("status", "wall_s", "cpu_s", "peak_rss_mb", "rss_before_mb")
    out = {"row": row, "size": size, "impl": impl, **{k: m.get(k, "") for k in keep}, "goal": goal}
    rest = {k: v for k, v in m.items() if k not in keep}
    out["details"] = json.dumps(rest, default=str, sort_keys=True) if rest else ""
    return out


def _pair(rows: list[dict], row: str, size: int, ours: dict, ref: dict, ref_impl: str, goal: str,
          ours_impl: str = "slamcli") -> None:
    a, b = _row(row, size, ours_impl, ours, goal), _row(row, size, ref_impl, ref)
    finished = not any(str(m.get("status", "")).startswith(("timeout", "failed")) for m in (ours, ref))
    for key, col in (("wall_s", "ratio"), ("cpu_s", "cpu_ratio"), ("peak_rss_mb", "rss_ratio")):
        x, y = ours.get(key), ref.get(key)
        ok = finished and isinstance(x, (int, float)) and isinstance(y, (int, float)) and y > 0
        a[col] = round(x / y, 3) if ok else ""  # no ratio against a run that did not finish
    rows += [a, b]
    _progress(a)
    _progress(b)


def _progress(r: dict) -> None:
    print(f"  {r['row']:<16} {r['size']:>7} {r['impl']:<22} {r['status']:<10} wall={_f(r.get('wall_s'))} s "
          f"rss={_f(r.get('peak_rss_mb'))} MB ratio={r.get('ratio', '')}", file=sys.stderr, flush=True)


def _f(v) -> str:
    return f"{v:.3g}" if isinstance(v, (int, float)) else str(v)


def _selected() -> tuple[tuple[int, ...] | None, tuple[str, ...]]:
    sizes = os.environ.get("SLAMCLI_SCALE_SIZES")
    rows = os.environ.get("SLAMCLI_SCALE_ROWS")
    return (tuple(int(s) for s in sizes.split(",")) if sizes else None,
            tuple(r.strip() for r in rows.split(",")) if rows else ROWS)


def run(quick: bool = False, sizes: tuple[int, ...] | None = None, rows_sel: tuple[str, ...] | None = None,
        on_row=None) -> list[dict]:
    """The table's rows; ``on_row(rows)`` is called after each measured pair (for incremental saving)."""
    rows = _Rows(on_row)
    _run(rows, quick, sizes, rows_sel)
    return list(rows)


class _Rows(list):
    """A list that reports every append/extend to ``on_row`` (the standalone runner saves the CSV)."""

    def __init__(self, on_row):
        super().__init__()
        self.on_row = on_row

    def append(self, item):
        super().append(item)
        if self.on_row:
            self.on_row(list(self))

    def __iadd__(self, items):
        super().extend(items)
        if self.on_row:
            self.on_row(list(self))
        return self


def _run(rows: list[dict], quick: bool, sizes, rows_sel) -> None:
    env_sizes, env_rows = _selected()
    sizes = sizes or env_sizes or (QUICK_SIZES if quick else SIZES)
    rows_sel = rows_sel or env_rows
    unknown = set(rows_sel) - set(ROWS)
    if unknown:
        raise SystemExit(f"unknown rows {sorted(unknown)}; known: {', '.join(ROWS)}")
    for n in sizes:  # simulate + cache the worlds first (in a child: the parent stays light)
        if any(r in rows_sel for r in ("startup", "hdf5", "graph", "icm")) and not dataset_path_exists(n):
            m = measure({"kind": "simulate-cache", "size": n})
            if m.get("status") != "ok":
                raise SystemExit(f"could not simulate the {n}-pose world: {m.get('status')}")
    if "startup" in rows_sel:
        info_file = dataset_path(min(sizes))
        reps = 3 if quick else 7
        floor = _startup_floor(reps)
        rows.append(_row("startup", 0, "python -c pass", floor))
        _progress(rows[-1])
        for name, args in (("--help", ["--help"]), ("solvers", ["solvers"]), ("info", ["info", str(info_file)])):
            m = _startup_cmd(args, reps)
            rows.append(_row("startup", 0, f"slamcli {name}", m, "< 0.5 s"))
            _progress(rows[-1])
    for n in sizes:
        if "simulate" in rows_sel:
            _pair(rows, "simulate", n, measure({"kind": "simulate", "size": n}),
                  measure({"kind": "simulate-allpairs", "size": n}), "all-pairs sensor (before)", "~linear in T")
        if "hdf5" in rows_sel:
            _pair(rows, "hdf5-write", n, measure({"kind": "hdf5-write", "size": n}), measure({"kind": "savez", "size": n}),
                  "np.savez", "documented trade-off")
            _pair(rows, "hdf5-read", n, measure({"kind": "hdf5-read", "size": n}), measure({"kind": "npload", "size": n}),
                  "np.load", "documented trade-off")
        if "graph" in rows_sel:
            _pair(rows, "graph+marginals", n, measure({"kind": "graph", "size": n}),
                  measure({"kind": "gtsam-marginals", "size": n}), "gtsam LM + Marginals",
                  "< 4 GB at 100k, ≤ 1.5× GTSAM")
        if "icm" in rows_sel:
            _pair(rows, "icm-joint", n, measure({"kind": "icm", "size": n}), measure({"kind": "gtsam-lm", "size": n}),
                  "gtsam LM", "< 4 GB at 100k")
    if "ekf" in rows_sel:
        for n in EKF_N:
            steps = (30 if quick else 150) if n > 1000 else (100 if quick else 400)
            task = {"size": n, "steps": steps}
            _pair(rows, "ekf", n, measure({"kind": "ekf", **task}), measure({"kind": "ekf-reference", **task}),
                  "in-place BLAS EKF", "≤ 1.2× reference, O(n²)")


def dataset_path_exists(n: int) -> bool:
    return (DATA / f"grid-city-{n}.h5").exists()


def _startup_floor(reps: int) -> dict:
    """The interpreter's own start-up (``python -c pass``), the floor under every CLI command."""
    runs = []
    for _ in range(reps):
        t0 = time.perf_counter()
        subprocess.run([sys.executable, "-c", "pass"], check=True)
        runs.append(time.perf_counter() - t0)
    return {"status": "ok", "wall_s": statistics.median(runs), "wall_min_s": min(runs)}


def main(argv: list[str] | None = None) -> int:
    import argparse

    ap = argparse.ArgumentParser(prog="python -m benchmarks.bench_scale")
    ap.add_argument("--quick", action="store_true")
    ap.add_argument("--sizes", help="comma-separated pose counts (default 10001,50001,100001)")
    ap.add_argument("--rows", help=f"comma-separated rows out of {','.join(ROWS)}")
    ap.add_argument("--out", default="scale", help="CSV name under benchmarks/results/ (default scale)")
    ap.add_argument("--worker", help=argparse.SUPPRESS)
    args = ap.parse_args(argv)
    if args.worker:
        task = json.loads(args.worker)
        if task["kind"] == "simulate-cache":
            dataset_path(int(task["size"]))
            print(json.dumps({"status": "ok"}))
            return 0
        t0 = time.perf_counter()
        try:
            out = _task(task)
        except Exception as exc:  # noqa: BLE001 - a failed measurement is a row, with the memory it reached
            first = (str(exc).strip().splitlines() or [""])[0][:160]
            out = {"status": f"failed: {type(exc).__name__}: {first}", "wall_s": time.perf_counter() - t0,
                   "peak_rss_mb": _rss_mb()}
        print(json.dumps(out, default=str))
        return 0
    from benchmarks.__main__ import write_rows

    rows = run(quick=args.quick, sizes=tuple(int(s) for s in args.sizes.split(",")) if args.sizes else None,
               rows_sel=tuple(args.rows.split(",")) if args.rows else None,
               on_row=lambda rows: write_rows(args.out, rows))  # saved after every row: a long run keeps its rows
    print(write_rows(args.out, rows))
    return 0


if __name__ == "__main__":
    sys.exit(main())
