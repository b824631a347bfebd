"""ICM at the speed of its arithmetic (issue 25 item 5): the fast paths equal plain references.

1. The on-line init's grid hash (:class:`~slamcli.solvers.icm.common.MeanGrid`) returns the label a scan of every
   running mean returns: nearest, ties to the lowest label, none beyond ϑ — also for points at exactly ϑ.
2. :func:`~slamcli.solvers.icm.common.online_init` equals a brute-force init written here from Algorithm 2
   step 1 (every sighting compared with every mean), label for label and bit for bit.
3. Its scalar helpers equal the library functions they stand in for, bit for bit; the pose conditional of a
   last pose (float ``hn = 0``, which skips its t+1 terms) equals the array path, which computes them.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from slamcli.models import motion, observation
from slamcli.models.angles import wrap_angle
from slamcli.solvers.icm import common
from slamcli.solvers.icm import energy as en
from slamcli.types import NoiseSpec, Observations, SlamInputs


def _scan_nearest(means, p, r2):
    """Reference of eqs. 9-10 for one point: the first label of least squared distance, if within ϑ."""
    d2 = [(float(p[0]) - m[0]) ** 2 + (float(p[1]) - m[1]) ** 2 for m in means]
    if not d2:
        return -1
    j = min(range(len(d2)), key=lambda k: (d2[k], k))
    return j if d2[j] <= r2 else -1


@pytest.mark.parametrize("radius", [0.5, 1.0, 3.0, math.inf])
def test_grid_nearest_equals_full_scan(radius):
    rng = np.random.default_rng(1)
    grid = common.MeanGrid(4000, radius)
    sums: list[list[float]] = []
    for _ in range(60):  # means move as points are added, and cross cell borders
        pts = rng.uniform(-6, 6, (12, 2))
        if rng.random() < 0.3:  # integer points: exact ties and distances of exactly ϑ
            pts = np.round(pts)
        means = [(s[0] / s[2], s[1] / s[2]) for s in sums]
        got = grid.nearest(pts)
        want = [_scan_nearest(means, p, radius * radius) for p in pts]
        assert got.tolist() == want
        lab = np.array([w if w >= 0 else len(sums) + k for k, w in enumerate(want)], np.int64)
        fresh = lab >= len(sums)
        lab[fresh] = len(sums) + np.arange(fresh.sum())
        sums += [[0.0, 0.0, 0.0] for _ in range(int(fresh.sum()))]
        grid.L = len(sums)
        grid.add(lab, pts)
        for j, p in zip(lab.tolist(), pts):
            sums[j][0] += p[0]
            sums[j][1] += p[1]
            sums[j][2] += 1.0


def test_grid_tie_goes_to_lowest_label_and_radius_is_inclusive():
    grid = common.MeanGrid(8, 1.0)
    grid.L = 3
    grid.add(np.array([0, 1, 2]), np.array([[2.0, 0.0], [0.0, 0.0], [5.0, 5.0]]))
    # (1, 0) is at exactly ϑ = 1 from labels 0 and 1: label 0 wins the tie; (3.5, 5) is 1.5 from label 2
    assert grid.nearest(np.array([[1.0, 0.0], [3.5, 5.0], [0.5, 0.0]])).tolist() == [0, -1, 1]


def _street(T=400, seed=0, spacing=2.5, clutter=0.0):
    """A drive among landmarks on a jittered grid, unknown association, some spurious sightings."""
    rng = np.random.default_rng(seed)
    dt = 0.5
    u = np.column_stack([np.full(T, 1.0), rng.normal(0.0, 0.2, T)])
    x0 = np.zeros(3)
    truth = motion.integrate(x0, u, dt)
    lo, hi = truth[:, :2].min(0) - 6, truth[:, :2].max(0) + 6
    gx, gy = np.meshgrid(np.arange(lo[0], hi[0], spacing), np.arange(lo[1], hi[1], spacing))
    lm = np.column_stack([gx.ravel(), gy.ravel()]) + rng.normal(0, 0.3, (gx.size, 2))
    steps, zs = [], []
    for t in range(T + 1):
        z = observation.range_bearing(truth[t][None, :], lm)
        vis = np.flatnonzero(z[:, 0] < 5.0)
        steps += [t] * len(vis)
        zs.append(z[vis] + rng.normal(0, [0.05, 0.02], (len(vis), 2)))
    z = np.concatenate(zs)
    if clutter:
        z[rng.random(len(z)) < clutter, 0] += rng.uniform(-1.5, 1.5)
    obs = Observations.from_rows(np.array(steps, np.int64), z, T + 1)
    u_meas = u + rng.normal(0, [0.03, 0.02], u.shape)
    noise = NoiseSpec(np.array([0.03, 0.02]), np.array([0.01, 0.01, 0.005]), 0.05, 0.02)
    return SlamInputs(dt=dt, timestamps=dt * np.arange(T + 1), x0=x0, controls=u_meas,
                      odometry_xyt=motion.integrate(x0, u_meas, dt), observations=obs, noise=noise)


def _reference_init(prob, W, radius, kinematic, iters):
    """Algorithm 2 step 1 with a full scan of the running means (the O(n·L) form the grid replaces)."""
    T, r2 = prob.T, radius * radius
    poses = np.empty((T + 1, 3))
    poses[0] = prob.x0
    kin = prob.kinematic_poses()
    labels = np.full(prob.n_obs, -1, np.int64)
    msum, mcnt = np.zeros((prob.n_obs, 2)), np.zeros(prob.n_obs)
    for t in range(T + 1):
        a, b = int(prob.offsets[t]), int(prob.offsets[t + 1])
        if t == 0 or kinematic:
            xh = kin[t].copy()
        else:
            px, py, pth = poses[t - 1]
            (v, w), lat, dt = prob.controls[t - 1], prob.lat[t - 1], prob.dt
            xh = np.array([px + dt * v * math.cos(pth) - dt * lat * math.sin(pth),
                           py + dt * v * math.sin(pth) + dt * lat * math.cos(pth), wrap_angle(pth + dt * w)])
        L = int((mcnt > 0).sum())
        pts = observation.inverse_range_bearing(xh, prob.z[a:b])
        match = np.array([_scan_nearest(msum[:L] / mcnt[:L, None], p, r2) for p in pts], np.int64)
        x = xh
        if t > 0 and not kinematic:
            ok = match >= 0
            v, m = prob.v_body[a:b][ok], msum[match[ok]] / mcnt[match[ok], None]
            st = (len(v), v[:, 0].sum(), v[:, 1].sum(), m[:, 0].sum(), m[:, 1].sum()) if len(v) else (0.0,) * 5
            st += tuple(v[:, i] @ w[:, j] for v, w, i, j in [(v, v, 0, 0), (v, v, 0, 1), (v, v, 1, 1), (v, m, 0, 0),
                        (v, m, 0, 1), (v, m, 1, 0), (v, m, 1, 1), (m, m, 0, 0), (m, m, 1, 1)])
            st = tuple(float(q) for q in st)
            px, py, pth = poses[t - 1]
            d = prob.odo_inc[t - 1]
            ctx = (px, py, pth, xh[0], xh[1], pth + prob.dt * prob.controls[t - 1, 1], *d) + (0.0,) * 10
            x = np.array(en.cond_minimise_scalar(*xh, ctx, st, W.flat, prob.dt, iters, 1e-10))
        poses[t] = x
        pts = observation.inverse_range_bearing(x, prob.z[a:b])
        for i in np.argsort(match < 0, kind="stable"):  # matched sightings first, then new ones in order
            if match[i] < 0:
                L = int((mcnt > 0).sum())
                j = _scan_nearest(msum[:L] / mcnt[:L, None], pts[i], r2)
                match[i] = j if j >= 0 else L
            msum[match[i]] += pts[i]
            mcnt[match[i]] += 1.0
        labels[a:b] = match
    L = int((mcnt > 0).sum())
    return poses, labels, msum[:L] / mcnt[:L, None]


@pytest.mark.parametrize(
    "radius, kinematic, clutter", [(1.0, False, 0.0), (0.4, False, 0.1), (2.0, False, 0.0), (1.0, True, 0.1)]
)
@pytest.mark.slow
def test_online_init_equals_brute_force(radius, kinematic, clutter):
    prob = en.Problem.from_inputs(_street(clutter=clutter))
    W = en.Weights.from_params((2.0, 2.0, 1.0), (0.5, 0.5, 0.2), 1.0)
    poses, labels, landmarks, _ = common.online_init(prob, W, radius=radius, kinematic=kinematic)
    ref_poses, ref_labels, ref_lm = _reference_init(prob, W, radius, kinematic, iters=5)
    assert landmarks.shape[0] > 40  # many map points: a scan and a grid lookup differ in what they visit
    np.testing.assert_array_equal(labels, ref_labels)
    np.testing.assert_array_equal(poses, ref_poses)
    np.testing.assert_array_equal(landmarks, ref_lm)


def test_scalar_helpers_equal_library_functions():
    rng = np.random.default_rng(3)
    a = np.concatenate([rng.uniform(-30, 30, 2000), [math.pi, -math.pi, 3 * math.pi, 0.0, -0.0, 1e-300]])
    assert [common._wrap_float(v) for v in a.tolist()] == wrap_angle(a).tolist()
    x = (1.5, -2.25, 0.7)
    z = np.column_stack([rng.uniform(0, 20, 50), rng.uniform(-4, 4, 50)])
    np.testing.assert_array_equal(common._points(x, z[:, 0].copy(), z[:, 1].copy()),
                                  observation.inverse_range_bearing(np.array(x), z))
    prev, u, lat = (0.3, -1.0, 2.9), (1.2, -0.4), 0.05
    want = en._motion(np.array([prev]), np.array([u]), 0.1, np.array([lat]))[0]
    got = common._predict(0.1, prev, u, lat)
    np.testing.assert_allclose(got[:2], want[:2], rtol=0, atol=1e-15)
    assert got[2] == wrap_angle(want[2])


def test_last_pose_conditional_skips_nothing_that_counts():
    """Float ``hn = 0`` skips the t+1 terms; the array path computes them times 0: same cost, same step."""
    rng = np.random.default_rng(4)
    Wf = (2.0, 1.5, 3.0, 0.7, 1.1, 0.4, 1.3, 0.8)
    for _ in range(50):
        ctx = tuple(rng.normal(size=9).tolist()) + (0.0,) + tuple(rng.normal(size=9).tolist())
        st = tuple(np.abs(rng.normal(size=14)).tolist())
        x, y, th = rng.normal(size=3).tolist()
        arr = tuple(np.array([v]) for v in ctx)
        for fn in (en.cond_cost, en.cond_step):
            scalar = np.atleast_1d(fn(x, y, th, ctx, st, Wf, 0.1, math.cos, math.sin))
            vector = np.ravel(fn(np.array([x]), np.array([y]), np.array([th]), arr, st, Wf, 0.1, np.cos, np.sin))
            np.testing.assert_allclose(scalar, vector, rtol=1e-13, atol=1e-13)


@pytest.mark.slow
def test_compiled_kernels_equal_python_kernels(monkeypatch):
    """numba's copies of the pose kernels (optional extra ``fast``) give the Python kernels' floats, bit for bit:
    the sequential sweep (Algorithm 2's visit order) and the on-line init."""
    pytest.importorskip("numba")
    monkeypatch.delenv(en.NO_JIT_ENV, raising=False)
    assert en.compiled_kernels() is not None
    prob = en.Problem.from_inputs(_street(T=300, clutter=0.05))
    W = en.Weights.from_params((2.0, 2.0, 1.0), (0.5, 0.5, 0.2), 1.0)
    runs = {}
    for jit_from in (10**9, 0):  # Python kernels, then the compiled ones
        monkeypatch.setattr(en, "JIT_MIN_POSES", jit_from)
        poses, labels, landmarks, _ = common.online_init(prob, W, radius=1.0)
        stats = en.step_stats(prob, labels, landmarks)
        swept = en.sweep_poses_sequential(prob, W, poses.copy(), stats, iters=3)
        runs[jit_from] = (poses, labels, swept)
    for a, b in zip(runs[10**9], runs[0]):
        np.testing.assert_array_equal(a, b)
    assert np.abs(runs[0][2] - runs[0][0]).max() > 1e-6  # the sweep moved the poses


def test_no_jit_switch_keeps_python_kernels(monkeypatch):
    monkeypatch.setenv(en.NO_JIT_ENV, "1")
    assert en.compiled_kernels() is None
