"""FastSLAM 1.0 batched over particles and landmarks (issue 25 item 5) and re-entrant (issue 21).

The batched known-association filter is checked against an independent per-particle Python loop of the
textbook algorithm (Thrun et al. Table 13.1: sample, per-landmark EKF, weight by N(z; ẑ, S), systematic
resampling) that consumes the same random stream, so the two must agree to round-off; a step in which one
landmark is seen twice checks the rounds. Re-entrancy: two threads solving with one solver instance give
the solo results, and ``solve`` leaves no attribute on the instance.
"""

from __future__ import annotations

import math
import threading

import numpy as np

from slamcli.sim import simulate_scenario
from slamcli.solvers.fastslam import FastSlam, FastSlamParams

POSE_TOL = 1e-9  # round-off only: the batched sums add the same terms in another order


def per_particle_fastslam1(inputs, P: int, rng) -> np.ndarray:
    """Textbook FastSLAM 1.0 with known ids, one particle and one row at a time; weighted-mean positions."""
    obs = inputs.observations
    sr, sb = inputs.noise.range_std, inputs.noise.bearing_std
    Q = np.diag([sr * sr, sb * sb])
    M = np.asarray(inputs.noise.motion_std, float)
    x = np.tile(np.asarray(inputs.x0, float), (P, 1))
    maps: list[dict] = [{} for _ in range(P)]
    logw = np.zeros(P)
    T = inputs.n_poses - 1
    out = np.empty((T + 1, 2))
    for t in range(T + 1):
        if t > 0:
            eps = rng.standard_normal((P, 2))
            for k in range(P):
                v, w = inputs.controls[t - 1] + M * eps[k]
                th = x[k, 2]
                x[k] = [x[k, 0] + inputs.dt * v * math.cos(th), x[k, 1] + inputs.dt * v * math.sin(th),
                        (th + inputs.dt * w + math.pi) % (2 * math.pi) - math.pi]
        for i in range(int(obs.offsets[t]), int(obs.offsets[t + 1])):
            lid, z = int(obs.reported_id[i]), obs.z[i]
            for k in range(P):
                px, py, th = x[k]
                if lid not in maps[k]:
                    phi = th + z[1]
                    Mz = np.array([[math.cos(phi), -z[0] * math.sin(phi)], [math.sin(phi), z[0] * math.cos(phi)]])
                    maps[k][lid] = (np.array([px + z[0] * math.cos(phi), py + z[0] * math.sin(phi)]), Mz @ Q @ Mz.T)
                    continue
                m, S = maps[k][lid]
                d = m - [px, py]
                q = float(d @ d)
                H = np.array([[d[0], d[1]], [-d[1] / math.sqrt(q), d[0] / math.sqrt(q)]]) / math.sqrt(q)
                nu = z - [math.sqrt(q), math.atan2(d[1], d[0]) - th]
                nu[1] = (nu[1] + math.pi) % (2 * math.pi) - math.pi
                Sn = H @ S @ H.T + Q
                K = S @ H.T @ np.linalg.inv(Sn)
                maps[k][lid] = (m + K @ nu, (np.eye(2) - K @ H) @ S)
                logw[k] += -0.5 * nu @ np.linalg.solve(Sn, nu) - 0.5 * math.log(np.linalg.det(2 * math.pi * Sn))
        w = np.exp(logw - logw.max())
        w /= w.sum()
        out[t] = w @ x[:, :2]
        if t < T and 1.0 / np.sum(w * w) < 0.5 * P:
            cdf = np.cumsum(w)
            cdf[-1] = 1.0
            idx = np.minimum(np.searchsorted(cdf, (rng.random() + np.arange(P)) / P, side="right"), P - 1)
            x, maps, logw = x[idx], [dict(maps[j]) for j in idx], np.zeros(P)
    return out


def _known_loop(n_steps: int, seed: int = 0):
    return simulate_scenario("loop", seed=seed, overrides={"sensor.report_ids": True, "n_steps": n_steps})


def test_batched_v1_equals_per_particle_reference():
    d = _known_loop(80)
    P = 40
    ref = per_particle_fastslam1(d.inputs, P, np.random.default_rng(5))
    res = FastSlam(FastSlamParams(version=1, n_particles=P, association="known", group_returns=False)).solve(
        d.inputs, rng=np.random.default_rng(5))
    assert np.abs(res.poses_xyt[:, :2] - ref).max() < POSE_TOL


def test_batched_v1_landmark_seen_twice_in_a_step():
    d = _known_loop(40, seed=2)
    obs = d.inputs.observations
    t = int(np.argmax(np.diff(obs.offsets) > 0))  # first step with a sighting: duplicate its first row
    i = int(obs.offsets[t])
    keep = np.r_[np.arange(i + 1), i, np.arange(i + 1, len(obs))]
    from dataclasses import replace

    from slamcli.types import Observations

    dup = Observations.from_rows(np.asarray(obs.step)[keep], obs.z[keep], d.inputs.n_poses,
                                 reported_id=np.asarray(obs.reported_id)[keep])
    inputs = replace(d.inputs, observations=dup)
    ref = per_particle_fastslam1(inputs, 20, np.random.default_rng(1))
    res = FastSlam(FastSlamParams(version=1, n_particles=20, association="known", group_returns=False)).solve(
        inputs, rng=np.random.default_rng(1))
    assert np.abs(res.poses_xyt[:, :2] - ref).max() < POSE_TOL


def test_solve_is_reentrant():
    solver = FastSlam(FastSlamParams(n_particles=30))
    data = [_known_loop(60, seed=s) for s in (0, 1)]
    solo = [solver.solve(d.inputs, rng=np.random.default_rng(9)) for d in data]
    before = dict(vars(solver))
    out: list = [None, None]

    def work(k):
        out[k] = solver.solve(data[k].inputs, rng=np.random.default_rng(9))

    threads = [threading.Thread(target=work, args=(k,)) for k in (0, 1)]
    for th in threads:
        th.start()
    for th in threads:
        th.join()
    for a, b in zip(solo, out):
        np.testing.assert_array_equal(a.poses_xyt, b.poses_xyt)
        np.testing.assert_array_equal(a.landmarks_xy, b.landmarks_xy)
    assert vars(solver) == before


def test_known_detections_equal_step_by_step_grouping():
    """The detections built once for known association (fastslam._known_detections) equal the frontend's
    step-by-step grouping, on a laser world (several returns per post) with rows without an id mixed in."""
    from slamcli.solvers.fastslam import _known_detections, _setup
    from slamcli.solvers.frontend import group_detections

    d = simulate_scenario("paper-sim1", seed=1, overrides={"sensor.report_ids": True, "n_steps": 60})
    obs = d.inputs.observations
    rid = np.asarray(obs.reported_id).copy()
    rid[::7] = -1  # rows the sensor reports no id for stay single detections with slot −1
    from dataclasses import replace

    obs = replace(obs, reported_id=rid)
    inputs = replace(d.inputs, observations=obs)
    slot_of_obs = _setup(inputs, FastSlamParams(association="known")).slot_of_obs
    z_all = obs.z
    z, slots, offsets = _known_detections(obs, z_all, slot_of_obs, group=True)
    n_merged = 0
    for t in range(inputs.n_poses):
        lo, hi = int(obs.offsets[t]), int(obs.offsets[t + 1])
        dets = group_detections(z_all, np.asarray(obs.sensor), rid, lo, hi, None, group=True, association="known",
                                group_dist=0.5)
        a, b = int(offsets[t]), int(offsets[t + 1])
        assert b - a == len(dets)
        n_merged += (hi - lo) - len(dets)
        for k, (zd, rows) in enumerate(dets):
            assert np.array_equal(z[a + k], zd)
            assert slots[a + k] == slot_of_obs[rows[0]]
    assert n_merged > 0  # the world does merge returns: the grouped branch was exercised
    z1, s1, o1 = _known_detections(obs, z_all, slot_of_obs, group=False)
    assert z1 is z_all and s1 is slot_of_obs and np.array_equal(o1, obs.offsets)
