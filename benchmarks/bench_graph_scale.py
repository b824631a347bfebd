"""``graph`` at scale vs GTSAM (issue 17, the two ``graph`` rows): Laplace marginals and Gauss-Newton
per-iteration cost on grid-city worlds of 10k / 50k / 100k poses, time and peak memory.

World: a Manhattan grid of 22 × 22 intersections 10 m apart with four landmarks around each (2 m off both
street axes; 1936 landmarks), a robot that drives 1 m per step along the streets and turns at random at
intersections, a range-bearing sensor with 9 m range and known ids (≈ 10 observations per pose), odometry
noise as in ``bench_graph``. All draws from ``numpy.random.default_rng(seed)``.

Each (size, side) is measured in its own child process with single-threaded BLAS, so that its peak RSS
(``resource.getrusage``, KiB → MB) belongs to that measurement only. Wall and CPU time (``process_time``,
all threads) are both reported: on a shared, overloaded machine the CPU-time ratio is the like-for-like one.

* ``marginals``: ours = :func:`slamcli.solvers.graph.laplace_marginals` (every pose and landmark block);
  GTSAM = ``gtsam.Marginals`` + ``marginalCovariance`` of every variable — both at the same values (the
  true poses/landmarks; a marginal's cost does not depend on where it is evaluated). Goal: < 4 GB at 100k
  and ≤ 1.5× GTSAM's time; the largest pose-block difference to GTSAM's (converted to world frame) is
  reported as a check.
* ``gn_iter``: Gauss-Newton iterations from the same perturbed values; ours ``nls.solve(method="gn")`` with
  no convergence test, GTSAM ``GaussNewtonOptimizer.iterate()`` called n times (its ``optimize`` stops after
  one iteration here); n = 1 and n = 4, per iteration = (T₄ − T₁)/3, so that the one-off set-up of either
  side (our structure analysis, GTSAM's ordering) is not counted (goal ≤ 1.0× GTSAM's).

Run: ``python -m benchmarks graph_scale [--quick]`` (``--quick``: 5k poses only).
"""

from __future__ import annotations

import json
import os
import resource
import subprocess
import sys
import time
from pathlib import Path

import numpy as np


def make_city(n_poses: int, seed: int = 0, n_grid: int = 22, spacing: float = 10.0, max_range: float = 9.0):
    """Grid-city ``SlamInputs`` with known ids; returns ``(inputs, truth_poses (T+1, 3), landmarks (L, 2))``."""
    from scipy.spatial import cKDTree

    from slamcli.models import motion, observation
    from slamcli.types import NoiseSpec, Observations, SlamInputs

    rng = np.random.default_rng(seed)
    T = n_poses - 1
    g = np.arange(n_grid) * spacing
    cx, cy = np.meshgrid(g, g, indexing="ij")
    off = np.array([[2.0, 2.0], [2.0, -2.0], [-2.0, 2.0], [-2.0, -2.0]])
    landmarks = (np.stack([cx.ravel(), cy.ravel()], -1)[:, None, :] + off[None]).reshape(-1, 2)
    # drive the streets: 1 m steps, turn (left/straight/right) at intersections, never leave the grid
    pos = np.array([g[n_grid // 2], g[n_grid // 2]])
    heading = 0  # 0:+x 1:+y 2:-x 3:-y
    dirs = np.array([[1, 0], [0, 1], [-1, 0], [0, -1]], float)
    xy = np.empty((n_poses, 2))
    th = np.empty(n_poses)
    steps_per_block = int(spacing)
    k = 0
    while k < n_poses:
        for _ in range(steps_per_block):
            if k >= n_poses:
                break
            xy[k], th[k] = pos, heading * np.pi / 2
            pos = pos + dirs[heading]
            k += 1
        choices = [(heading + d) % 4 for d in (-1, 0, 1)]
        ok = [
            c
            for c in choices
            if 0 <= (pos + spacing * dirs[c])[0] <= g[-1] and 0 <= (pos + spacing * dirs[c])[1] <= g[-1]
        ]
        heading = int(rng.choice(ok if ok else [(heading + 2) % 4]))
    truth = np.column_stack([xy, np.unwrap(th)])
    truth[:, 2] = np.arctan2(np.sin(truth[:, 2]), np.cos(truth[:, 2]))
    odo_std = np.array([0.01, 0.01, 0.005])
    inc = motion.odometry_increments(truth) + rng.normal(0.0, 1.0, (T, 3)) * odo_std
    odometry = motion.chain_increments(truth[0], inc)
    tree = cKDTree(landmarks)
    lists = tree.query_ball_point(truth[:, :2], max_range)
    t_idx = np.repeat(np.arange(n_poses), [len(v) for v in lists])
    l_idx = np.concatenate([np.asarray(v, np.int64) for v in lists])
    range_std, bearing_std = 0.05, 0.02
    z = observation.range_bearing(truth[t_idx], landmarks[l_idx])
    z = z + rng.normal(0.0, 1.0, z.shape) * [range_std, bearing_std]
    obs = Observations.from_rows(t_idx, z, n_poses, reported_id=l_idx)
    dt = 1.0
    controls = np.column_stack([np.linalg.norm(inc[:, :2], axis=1), inc[:, 2]]) / dt
    inputs = SlamInputs(
        dt=dt,
        timestamps=np.arange(n_poses) * dt,
        x0=truth[0].copy(),
        controls=controls,
        odometry_xyt=odometry,
        observations=obs,
        noise=NoiseSpec(
            motion_std=np.array([0.05, 0.02]),
            odometry_std=odo_std,
            range_std=range_std,
            bearing_std=bearing_std,
        ),
        max_range=max_range,
    )
    return inputs, truth, landmarks


def _problem(n_poses: int):
    from slamcli.solvers import frontend, graph

    inputs, truth, landmarks = make_city(n_poses)
    assoc, old_of_new = frontend.compact_labels(frontend.associate_reported(inputs.observations), 1)
    gp = graph.build_gtsam_problem(inputs, assoc, truth, landmarks[old_of_new], graph.GraphParams())
    return inputs, assoc, gp


def _gtsam(inputs, assoc, gp, x):
    import gtsam
    from gtsam.symbol_shorthand import L, X

    from benchmarks.bench_graph_real import to_values
    from slamcli.models import motion
    from slamcli.solvers import graph

    g = gtsam.NonlinearFactorGraph()
    g.add(
        gtsam.PriorFactorPose2(
            X(0), gtsam.Pose2(*inputs.x0), gtsam.noiseModel.Diagonal.Sigmas(np.full(3, 1e-4))
        )
    )
    odo = gtsam.noiseModel.Diagonal.Sigmas(np.asarray(inputs.noise.odometry_std, float))
    d = motion.odometry_increments(inputs.odometry_xyt)
    for t in range(d.shape[0]):
        g.add(gtsam.BetweenFactorPose2(X(t), X(t + 1), gtsam.Pose2(*d[t]), odo))
    obs = inputs.observations
    rows = np.flatnonzero(assoc >= 0)
    steps, labels, z = graph.group_returns(
        np.asarray(obs.step)[rows], assoc[rows], obs.z[rows], gp.n_landmarks
    )
    br = gtsam.noiseModel.Gaussian.Covariance(inputs.noise.obs_cov[::-1, ::-1].copy())
    for s, j, (r, b) in zip(steps, labels, z):
        g.add(gtsam.BearingRangeFactor2D(X(int(s)), L(int(j)), gtsam.Rot2(float(b)), float(r), br))
    return g, to_values(gp, x)


def measure(n_poses: int, side: str, what: str) -> dict:
    """One measurement in this process (called in a child)."""
    from slamcli.solvers import graph, nls

    inputs, assoc, gp = _problem(n_poses)
    out = {"poses": gp.n_poses, "landmarks": gp.n_landmarks, "side": side, "what": what}
    if what == "marginals":
        x = gp.x0
        if side == "ours":
            H = nls.solve(gp.problem, x, nls.NlsParams(method="gn", max_iterations=1)).information
            asm_H = H  # H at the truth + one GN step: the marginals of that H are what is timed
            t0, c0 = time.perf_counter(), time.process_time()
            pose_cov, lm_cov = graph.laplace_marginals(gp, asm_H)
            out["seconds"], out["cpu_s"] = time.perf_counter() - t0, time.process_time() - c0
            out["pose_cov_0"] = pose_cov[len(pose_cov) // 2].tolist()
        else:
            import gtsam
            from gtsam.symbol_shorthand import L, X

            xs = nls.solve(gp.problem, x, nls.NlsParams(method="gn", max_iterations=1)).x
            g, v = _gtsam(inputs, assoc, gp, xs)
            t0, c0 = time.perf_counter(), time.process_time()
            m = gtsam.Marginals(g, v)
            covs = [m.marginalCovariance(X(t)) for t in range(gp.n_poses)]
            for j in range(gp.n_landmarks):
                m.marginalCovariance(L(j))
            out["seconds"], out["cpu_s"] = time.perf_counter() - t0, time.process_time() - c0
            t = gp.n_poses // 2
            th = v.atPose2(X(t)).theta()
            R = np.eye(3)
            R[:2, :2] = [[np.cos(th), -np.sin(th)], [np.sin(th), np.cos(th)]]
            out["pose_cov_0"] = (R @ covs[t] @ R.T).tolist()  # body → world frame
    else:
        rng = np.random.default_rng(1)
        P = 3 * gp.n_poses
        x = gp.x0.copy()
        x[:P] += rng.normal(0.0, 0.02, P)
        if side == "ours":

            def run_n(n):
                nls.solve(gp.problem, x, nls.NlsParams(method="gn", max_iterations=n, rel_cost_tol=-1.0))

        else:
            import gtsam

            g, v = _gtsam(inputs, assoc, gp, x)

            def run_n(n):
                opt = gtsam.GaussNewtonOptimizer(g, v, gtsam.GaussNewtonParams())
                for _ in range(n):  # exactly n linearise + solve + update steps, no convergence test
                    opt.iterate()

        meas = {}
        for n in (1, 4):
            t0, c0 = time.perf_counter(), time.process_time()
            run_n(n)
            meas[n] = (time.perf_counter() - t0, time.process_time() - c0)
        out["seconds"], out["cpu_s"] = meas[4]
        out["iterations"] = 4
        # per iteration without the one-off set-up (our structure analysis, GTSAM's ordering): (T₄ − T₁) / 3
        out["s_per_iter"] = (meas[4][0] - meas[1][0]) / 3.0
        out["cpu_per_iter"] = (meas[4][1] - meas[1][1]) / 3.0
    out["peak_rss_mb"] = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0
    return out


def _child(n: int, side: str, what: str) -> dict:
    env = dict(os.environ, OPENBLAS_NUM_THREADS="1", OMP_NUM_THREADS="1", MKL_NUM_THREADS="1")
    cmd = [sys.executable, "-m", "benchmarks.bench_graph_scale", "--one", str(n), side, what]
    r = subprocess.run(
        cmd, env=env, cwd=Path(__file__).resolve().parent.parent, capture_output=True, text=True
    )
    lines = [ln for ln in r.stdout.splitlines() if ln.startswith("{")]
    if r.returncode != 0 or not lines:
        tail = (r.stderr.strip().splitlines() or ["no output"])[-1]
        return {"side": side, "what": what, "error": f"exit {r.returncode}: {tail}"}
    return json.loads(lines[-1])


def run(quick: bool = False) -> list[dict]:
    sizes = [5000] if quick else [10000, 50000, 100000]
    rows = []
    for n in sizes:
        for what in ("marginals", "gn_iter"):
            a, b = _child(n, "ours", what), _child(n, "gtsam", what)
            row = {"poses": a.get("poses", n), "landmarks": a.get("landmarks", ""), "what": what}
            row["graph_s"] = round(a["seconds"], 3) if "seconds" in a else a.get("error")
            row["gtsam_s"] = round(b["seconds"], 3) if "seconds" in b else b.get("error")
            row["graph_cpu_s"] = round(a["cpu_s"], 3) if "cpu_s" in a else ""
            row["gtsam_cpu_s"] = round(b["cpu_s"], 3) if "cpu_s" in b else ""
            row["graph_peak_rss_mb"] = round(a.get("peak_rss_mb", np.nan), 1)
            row["gtsam_peak_rss_mb"] = round(b.get("peak_rss_mb", np.nan), 1)
            if "seconds" in a and "seconds" in b:
                if what == "marginals":
                    row["ratio"] = round(a["seconds"] / b["seconds"], 3)
                    row["cpu_ratio"] = round(a["cpu_s"] / b["cpu_s"], 3)
                    row["goal_ratio"] = 1.5
                    row["goal_peak_rss_mb"] = 4096
                    row["max_pose_cov_diff"] = float(
                        np.max(np.abs(np.array(a["pose_cov_0"]) - np.array(b["pose_cov_0"])))
                    )
                else:
                    pa, pb = a["s_per_iter"], b["s_per_iter"]
                    row["graph_cpu_per_iter"] = round(a["cpu_per_iter"], 4)
                    row["gtsam_cpu_per_iter"] = round(b["cpu_per_iter"], 4)
                    row["cpu_per_iter_ratio"] = round(a["cpu_per_iter"] / b["cpu_per_iter"], 3)
                    row.update(
                        graph_iterations=a["iterations"],
                        gtsam_iterations=b["iterations"],
                        graph_s_per_iter=round(pa, 4),
                        gtsam_s_per_iter=round(pb, 4),
                        per_iter_ratio=round(pa / pb, 3),
                        goal_per_iter_ratio=1.0,
                        linear_solver=a.get("linear_solver", ""),
                    )
            rows.append(row)
    return rows


if __name__ == "__main__":  # pragma: no cover
    if "--one" in sys.argv:
        i = sys.argv.index("--one")
        print(json.dumps(measure(int(sys.argv[i + 1]), sys.argv[i + 2], sys.argv[i + 3])), flush=True)
    else:
        for row in run(quick="--quick" in sys.argv):
            print(json.dumps(row), flush=True)
