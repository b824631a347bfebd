"""Pose-graph benchmarks with loop closures: ``graph`` vs GTSAM (LM, Dogleg, ISAM2) from the same initial values.

Data: ``shared/datasets/pose_graphs`` (Intel, MIT, CSAIL, Manhattan M3500, City10000, KITTI 00; see its
PROVENANCE.txt), imported with :func:`slamcli.datasets.g2o.import_graph` (odometry chain + between-factors with
every edge's information matrix). For each dataset and each initialisation (``odometry``: the chained
odometry; ``chordal``: chordal relaxation of the rotations + linear translations,
:mod:`slamcli.solvers.graph.init`) both optimisers get the same factor graph (PriorFactorPose2 on x_0 with
σ = 1e-4, BetweenFactorPose2 with ``noiseModel.Gaussian.Information``) and the same initial values, the same
relative-decrease tolerance (1e-10) and iteration budget (100).

Columns: final cost ``½ Σ eᵀΛe`` of every optimiser evaluated by GTSAM's ``graph.error`` (one referee),
``rel_cost_diff = |cost_graph − cost_gtsam_lm| / cost_gtsam_lm`` (goal ≤ 1e-6 where both converge), wall
time of the optimisation alone (initialisation timed separately as ``init_s``), ``ratio = graph_s /
gtsam_lm_s`` (goal ≤ 1.5), iterations. ISAM2 runs one batch update with every factor and then further
``update()`` calls (relinearisation, threshold 0.01) until the cost changes by < 1e-10 relative (≤ 50).
``--quick`` runs MIT and Intel only.
"""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np

DATA = Path(__file__).resolve().parent.parent.parent.parent / "shared" / "datasets" / "pose_graphs"
if not DATA.is_dir():  # a clone outside /work/clones
    DATA = Path("/work/shared/datasets/pose_graphs")
NAMES = ("intel", "MIT", "CSAIL", "manhattan", "city10000", "kitti_00")
QUICK = ("MIT", "intel")
TOL = 1e-10
MAX_IT = 100


def gtsam_pose_graph(inputs, prior_std, init_poses):
    """GTSAM factor graph (prior, odometry and loop-closure BetweenFactorPose2) + initial values of a dataset."""
    import gtsam

    from slamcli.solvers.graph import pose_graph_edges

    graph = gtsam.NonlinearFactorGraph()
    graph.add(
        gtsam.PriorFactorPose2(
            0, gtsam.Pose2(*inputs.x0), gtsam.noiseModel.Diagonal.Sigmas(np.asarray(prior_std, float))
        )
    )
    ij, xyt, info = pose_graph_edges(inputs)
    for (i, j), d, m in zip(ij, xyt, info):
        graph.add(
            gtsam.BetweenFactorPose2(int(i), int(j), gtsam.Pose2(*d), gtsam.noiseModel.Gaussian.Information(m))
        )
    values = gtsam.Values()
    for t, p in enumerate(init_poses):
        values.insert(t, gtsam.Pose2(*p))
    return graph, values


def _poses(values, n: int) -> np.ndarray:
    return np.array([[values.atPose2(t).x(), values.atPose2(t).y(), values.atPose2(t).theta()] for t in range(n)])


def run_one(name: str, init: str) -> dict:
    import gtsam

    from slamcli.datasets.g2o import import_graph
    from slamcli.solvers import graph, nls

    ds = import_graph(DATA / f"{name}.g2o")
    inp = ds.inputs
    n = inp.n_poses
    params = graph.GraphParams(rel_cost_tol=TOL, step_tol=TOL, max_iterations=MAX_IT)
    t0 = time.perf_counter()
    poses0 = graph.initial_poses(inp, init)
    t_init = time.perf_counter() - t0
    gp = graph.build_gtsam_problem(inp, np.full(len(inp.observations), -1, np.int64), poses0, np.zeros((0, 2)), params)
    npar = nls.NlsParams(rel_cost_tol=TOL, step_tol=TOL, max_iterations=MAX_IT)
    t0 = time.perf_counter()
    res = nls.solve(gp.problem, gp.x0, npar)
    t_ours = time.perf_counter() - t0

    g, v0 = gtsam_pose_graph(inp, params.prior_std, poses0)
    lmp = gtsam.LevenbergMarquardtParams()
    lmp.setRelativeErrorTol(TOL)
    lmp.setAbsoluteErrorTol(0.0)
    lmp.setMaxIterations(MAX_IT)
    t0 = time.perf_counter()
    lm = gtsam.LevenbergMarquardtOptimizer(g, v0, lmp)
    v_lm = lm.optimize()
    t_lm = time.perf_counter() - t0

    dlp = gtsam.DoglegParams()
    dlp.setRelativeErrorTol(TOL)
    dlp.setAbsoluteErrorTol(0.0)
    dlp.setMaxIterations(MAX_IT)
    t0 = time.perf_counter()
    dl_iters, c_dl = "", "failed"
    try:  # GTSAM's dogleg solves the undamped GN system, which can be indeterminate far from the optimum
        dl = gtsam.DoglegOptimizer(g, v0, dlp)
        c_dl = float(g.error(dl.optimize()))
        dl_iters = int(dl.iterations())
    except RuntimeError as exc:
        c_dl = "failed: " + str(exc).strip().splitlines()[0]
    t_dl = time.perf_counter() - t0

    ip = gtsam.ISAM2Params()
    ip.setRelinearizeThreshold(0.01)
    ip.relinearizeSkip = 1
    t0 = time.perf_counter()
    n_upd, c_is = 0, "failed"
    try:
        isam = gtsam.ISAM2(ip)
        isam.update(g, v0)
        n_upd = 1
        prev = g.error(isam.calculateEstimate())
        for _ in range(49):
            isam.update()
            n_upd += 1
            cur = g.error(isam.calculateEstimate())
            if abs(prev - cur) <= TOL * max(prev, 1e-300):
                break
            prev = cur
        c_is = float(cur if n_upd > 1 else prev)
    except RuntimeError as exc:
        c_is = "failed: " + str(exc).strip().splitlines()[0]
    t_is = time.perf_counter() - t0

    poses_ours = gp.unpack(res.x)[0]
    _, v_ours = gtsam_pose_graph(inp, params.prior_std, poses_ours)
    c_ours = float(g.error(v_ours))
    c_lm = float(g.error(v_lm))
    return {
        "dataset": name,
        "poses": n,
        "odometry_edges": n - 1,
        "loop_closures": int(inp.constraints.n_between),
        "init": init,
        "init_cost": float(g.error(v0)),
        "init_s": round(t_init, 4),
        "graph_status": res.status.value,
        "graph_iterations": int(res.iterations),
        "graph_s": round(t_ours, 3),
        "cost_graph": c_ours,
        "cost_graph_by_ours": float(res.cost),
        "gtsam_lm_iterations": int(lm.iterations()),
        "gtsam_lm_s": round(t_lm, 3),
        "cost_gtsam_lm": c_lm,
        "rel_cost_diff": abs(c_ours - c_lm) / c_lm,
        "max_pose_diff": float(np.max(np.abs(poses_ours[:, :2] - _poses(v_lm, n)[:, :2]))),
        "ratio_graph_gtsam_lm": round(t_ours / t_lm, 3),
        "gtsam_dogleg_iterations": dl_iters,
        "gtsam_dogleg_s": round(t_dl, 3),
        "cost_gtsam_dogleg": c_dl,
        "isam2_updates": n_upd,
        "isam2_s": round(t_is, 3),
        "cost_isam2": c_is,
    }


def run(quick: bool = False) -> list[dict]:
    """One child process per dataset with single-threaded BLAS (like-for-like with GTSAM's Eigen, and
    OpenBLAS's thread pool is fixed when numpy loads; see bench_graph)."""
    import json
    import os
    import subprocess
    import sys

    env = dict(os.environ, OPENBLAS_NUM_THREADS="1", OMP_NUM_THREADS="1", MKL_NUM_THREADS="1")
    rows = []
    for name in QUICK if quick else NAMES:
        out = subprocess.run(
            [sys.executable, "-m", "benchmarks.bench_posegraph", name],
            env=env,
            cwd=Path(__file__).resolve().parent.parent,
            capture_output=True,
            text=True,
            check=True,
        )
        rows += [json.loads(ln) for ln in out.stdout.splitlines() if ln.startswith("{")]
    return rows


if __name__ == "__main__":  # pragma: no cover
    import json
    import sys

    names = [a for a in sys.argv[1:] if not a.startswith("-")] or list(QUICK if "--quick" in sys.argv else NAMES)
    for nm in names:
        for ini in ("odometry", "chordal"):
            print(json.dumps(run_one(nm, ini)))
