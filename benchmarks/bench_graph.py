"""``graph`` vs GTSAM Levenberg-Marquardt on the same factor graph, in one run.

Problem (full mode): a robot drives 2000 poses on a lap-like path through a field of ~50 landmarks, range-
bearing sensor with known identities, ~20k observations; built directly with :mod:`slamcli.models`.
Both optimisers start from the chained odometry and the mean inverse observations and use the same
factors (PriorFactorPose2 on x_0, BetweenFactorPose2 odometry, BearingRangeFactor2D). Reported per row:
wall time of each optimiser (best of ``repeats``), ratio graph/GTSAM (goal ≤ 1.5), final cost of both
evaluated by GTSAM's ``graph.error`` and by ours, iterations, and the time of all pose and landmark
marginal covariances by ours and by ``gtsam.Marginals`` (not part of the optimiser timing).
"""

from __future__ import annotations

import time

import numpy as np

from slamcli.models import motion, observation
from slamcli.types import NoiseSpec, Observations, SlamInputs


def make_problem(n_poses: int = 2001, n_landmarks: int = 50, seed: int = 0, max_range: float = 7.5):
    """A ``SlamInputs`` with reported landmark identities (a lap around a rounded rectangle).

    Returns
    -------
    inputs : SlamInputs;  truth_poses : ndarray (T+1, 3);  landmarks : ndarray (L, 2)
    """
    rng = np.random.default_rng(seed)
    T = n_poses - 1
    dt = 0.1
    # circle of radius ~12 m driven ~1.6 times: v = 1 m/s, ω = v / 12
    controls = np.column_stack([np.full(T, 1.0), np.full(T, 1.0 / 12.0)])
    motion_std = np.array([0.05, 0.02])
    executed = controls + rng.normal(0.0, 1.0, controls.shape) * motion_std
    x0 = np.array([0.0, -12.0, 0.0])
    truth = motion.integrate(x0, executed, dt)
    odo_std = np.array([0.01, 0.01, 0.005])
    inc = motion.odometry_increments(truth) + rng.normal(0.0, 1.0, (T, 3)) * odo_std
    odometry = motion.chain_increments(x0, inc)
    ang = rng.uniform(0, 2 * np.pi, n_landmarks)
    rad = 12.0 + rng.uniform(-4.0, 4.0, n_landmarks)
    landmarks = np.column_stack([rad * np.cos(ang), rad * np.sin(ang)])
    range_std, bearing_std = 0.05, 0.02
    z = observation.range_bearing(truth[:, None, :], landmarks[None, :, :])  # (T+1, L, 2)
    t_idx, l_idx = np.nonzero(z[..., 0] <= max_range)
    zz = z[t_idx, l_idx] + rng.normal(0.0, 1.0, (t_idx.size, 2)) * [range_std, bearing_std]
    obs = Observations.from_rows(t_idx, zz, T + 1, reported_id=l_idx)
    inputs = SlamInputs(
        dt=dt,
        timestamps=np.arange(T + 1) * dt,
        x0=x0,
        controls=controls,
        odometry_xyt=odometry,
        observations=obs,
        noise=NoiseSpec(
            motion_std=motion_std, odometry_std=odo_std, range_std=range_std, bearing_std=bearing_std
        ),
        max_range=max_range,
    )
    return inputs, truth, landmarks


def gtsam_graph(inputs: SlamInputs, assoc: np.ndarray, prior_std, init_poses, init_landmarks):
    """The same factor graph and initial values in GTSAM (symbols x_t, l_j)."""
    import gtsam
    from gtsam.symbol_shorthand import L, X

    graph = gtsam.NonlinearFactorGraph()
    graph.add(
        gtsam.PriorFactorPose2(
            X(0), gtsam.Pose2(*inputs.x0), gtsam.noiseModel.Diagonal.Sigmas(np.asarray(prior_std, float))
        )
    )
    odo_noise = gtsam.noiseModel.Diagonal.Sigmas(np.asarray(inputs.noise.odometry_std, float))
    d = motion.odometry_increments(inputs.odometry_xyt)
    for t in range(d.shape[0]):
        graph.add(gtsam.BetweenFactorPose2(X(t), X(t + 1), gtsam.Pose2(*d[t]), odo_noise))
    cov = inputs.noise.obs_cov  # [range, bearing] → GTSAM's [bearing, range]
    br_noise = gtsam.noiseModel.Gaussian.Covariance(cov[::-1, ::-1].copy())
    obs = inputs.observations
    for k in np.flatnonzero(assoc >= 0):
        graph.add(
            gtsam.BearingRangeFactor2D(
                X(int(obs.step[k])),
                L(int(assoc[k])),
                gtsam.Rot2(float(obs.bearing_rad[k])),
                float(obs.range_m[k]),
                br_noise,
            )
        )
    values = gtsam.Values()
    for t, p in enumerate(init_poses):
        values.insert(X(t), gtsam.Pose2(*p))
    for j, m in enumerate(init_landmarks):
        values.insert(L(j), np.asarray(m, float))
    return graph, values


def gtsam_poses(values, n_poses: int) -> np.ndarray:
    from gtsam.symbol_shorthand import X

    out = np.empty((n_poses, 3))
    for t in range(n_poses):
        p = values.atPose2(X(t))
        out[t] = (p.x(), p.y(), p.theta())
    return out


def run(quick: bool = False) -> list[dict]:
    """One row per BLAS threading setting, each measured in a fresh child process.

    OpenBLAS's thread pool is set when numpy loads, so the setting needs its own process. On a loaded
    machine multi-threaded OpenBLAS can make a 6000×100 GEMM ~100× slower than single-threaded; GTSAM is
    unaffected by this variable (Eigen + TBB), so the ``blas_threads=1`` row is the like-for-like one.
    """
    import json
    import os
    import subprocess
    import sys
    from pathlib import Path

    rows = []
    for threads in ("1", "default"):
        env = dict(os.environ)
        if threads == "1":
            env.update(OPENBLAS_NUM_THREADS="1", OMP_NUM_THREADS="1", MKL_NUM_THREADS="1")
        cmd = [sys.executable, "-m", "benchmarks.bench_graph"] + (["--quick"] if quick else [])
        out = subprocess.run(
            cmd,
            env=env,
            cwd=Path(__file__).resolve().parent.parent,
            capture_output=True,
            text=True,
            check=True,
        )
        for line in out.stdout.splitlines():
            if line.startswith("{"):
                row = json.loads(line)
                rows.append({"blas_threads": threads, **row})
    return rows


def run_here(quick: bool = False) -> list[dict]:
    """The measurement itself, in this process."""
    import gtsam

    from slamcli.solvers import frontend, graph, nls

    rows = []
    sizes = [(301, 20)] if quick else [(2001, 50)]
    repeats = 1 if quick else 3
    for n_poses, n_lm in sizes:
        inputs, _, _ = make_problem(n_poses, n_lm)
        params = graph.GraphParams(rel_cost_tol=1e-10, step_tol=1e-10)
        assoc = frontend.associate_reported(inputs.observations)
        L = int(assoc.max()) + 1
        poses0 = graph.odometry_initial_poses(inputs)
        lm0 = frontend.landmarks_from_observations(poses0, inputs.observations, assoc, L)
        gp = graph.build_gtsam_problem(inputs, assoc, poses0, lm0, params)
        npar = nls.NlsParams(rel_cost_tol=1e-10, step_tol=1e-10)

        t_ours = np.inf
        for _ in range(repeats):
            t0 = time.perf_counter()
            res = nls.solve(gp.problem, gp.x0, npar)
            t_ours = min(t_ours, time.perf_counter() - t0)
        t0 = time.perf_counter()
        graph.laplace_marginals(gp, res.information)
        t_cov = time.perf_counter() - t0

        g, v0 = gtsam_graph(inputs, assoc, params.prior_std, poses0, lm0)
        lmp = gtsam.LevenbergMarquardtParams()
        lmp.setRelativeErrorTol(1e-10)
        lmp.setAbsoluteErrorTol(0.0)
        lmp.setMaxIterations(100)
        t_gt = np.inf
        for _ in range(repeats):
            t0 = time.perf_counter()
            opt = gtsam.LevenbergMarquardtOptimizer(g, v0, lmp)
            vg = opt.optimize()
            t_gt = min(t_gt, time.perf_counter() - t0)
        t0 = time.perf_counter()
        marg = gtsam.Marginals(g, vg)
        for t in range(n_poses):
            marg.marginalCovariance(gtsam.symbol("x", t))
        for j in range(L):
            marg.marginalCovariance(gtsam.symbol("l", j))
        t_gt_cov = time.perf_counter() - t0
        poses_ours, lms_ours = gp.unpack(res.x)
        _, v_ours = gtsam_graph(inputs, assoc, params.prior_std, poses_ours, lms_ours)
        gt_poses = gtsam_poses(vg, n_poses)
        vg_as_ours = graph.pack_state(
            gt_poses, np.array([vg.atPoint2(gtsam.symbol("l", j)) for j in range(L)])
        )
        rows.append(
            {
                "problem": f"{n_poses} poses / {L} landmarks / {int((assoc >= 0).sum())} obs",
                "graph_s": round(t_ours, 4),
                "gtsam_lm_s": round(t_gt, 4),
                "ratio": round(t_ours / t_gt, 3),
                "goal_ratio": 1.5,
                "graph_iterations": int(res.iterations),
                "gtsam_iterations": int(opt.iterations()),
                "cost_graph_by_gtsam": float(g.error(v_ours)),
                "cost_gtsam_by_gtsam": float(g.error(vg)),
                "cost_graph_by_ours": float(res.cost),
                "cost_gtsam_by_ours": float(nls.evaluate_cost(gp.problem, vg_as_ours)),
                "max_pose_diff": float(np.max(np.abs(poses_ours - gt_poses))),
                "marginals_s": round(t_cov, 4),
                "gtsam_marginals_s": round(t_gt_cov, 4),
            }
        )
    return rows


if __name__ == "__main__":  # pragma: no cover
    import json
    import sys

    for row in run_here(quick="--quick" in sys.argv):
        print(json.dumps(row))
