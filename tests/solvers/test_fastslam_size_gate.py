"""FastSLAM's size gate (EKF's ``size_gate``, per particle) and the shared declared-size test of
``slamcli.solvers.frontend``.

Expectations are geometric, built here: two returns on the surface of one post of declared diameter d lie
closer than d to each other, so with the gate only the first starts a landmark; two posts farther apart than
d are two landmarks either way. The declared-size test is checked against a brute-force double loop.
"""

from __future__ import annotations

import numpy as np
import pytest

from slamcli.models import observation
from slamcli.solvers.fastslam import FastSlam, FastSlamParams
from slamcli.solvers.frontend import inside_declared_size
from slamcli.types import NoiseSpec, Observations, SlamInputs

RANGE_STD, BEARING_STD = 0.01, 0.005
CHI2_2DOF_9999 = -2.0 * np.log(1e-4)  # the default new-landmark threshold p0 (Mahalanobis², 2 DoF)


def _inputs(points_xy, diameter, step: int = 1):
    """Two poses (x0 = origin, one step straight ahead at 0.5 m/s × 0.5 s); noise-free returns of the points
    ``points_xy (k, 2)`` seen from the TRUE pose of ``step``, every row declaring ``diameter`` (m)."""
    dt = 0.5
    poses = np.array([[0.0, 0.0, 0.0], [0.25, 0.0, 0.0]])
    z = observation.range_bearing(poses[step][None, :], np.asarray(points_xy, float))
    k = z.shape[0]
    steps = np.full(k, step, np.int64)
    obs = Observations(
        step=steps,
        range_m=z[:, 0].copy(),
        bearing_rad=z[:, 1].copy(),
        sensor=np.zeros(k, np.int16),
        reported_id=np.full(k, -1, np.int64),
        offsets=Observations.offsets_from_steps(steps, 2),
        diameter_m=np.full(k, float(diameter)),
    )
    return SlamInputs(
        dt=dt, timestamps=np.array([0.0, dt]), x0=poses[0], controls=np.array([[0.5, 0.0]]), odometry_xyt=poses,
        observations=obs,
        noise=NoiseSpec(motion_std=np.array([1e-3, 1e-3]), odometry_std=np.array([1e-3, 1e-3, 1e-3]),
                        range_std=RANGE_STD, bearing_std=BEARING_STD),
    )


def _surface_points(centre, rho, lateral):
    """Points on the near face of a post of radius ``rho`` at ``centre`` seen along +x, at lateral offsets."""
    s = np.asarray(lateral, float)
    return np.column_stack([centre[0] - np.sqrt(rho**2 - s**2), centre[1] + s])


def _solve(inputs, **kw):
    p = FastSlamParams(**{"n_particles": 20, "association": "ml", "group_returns": False, **kw})
    return FastSlam(p).solve(inputs, rng=np.random.default_rng(3))


@pytest.mark.parametrize("hide", [True, False])
@pytest.mark.parametrize("version", [1, 2])
def test_two_returns_of_one_post_make_one_landmark_with_the_gate(version, hide):
    d = 0.5
    pts = _surface_points((2.25, 0.0), d / 2, [-0.18, 0.18])  # one post, its left and right edges
    sep = np.linalg.norm(pts[0] - pts[1])
    assert sep < d  # both returns within one declared diameter of each other
    # ... and far outside the new-landmark threshold of one another: the lateral σ at 2 m is r·σ_b ≈ 0.01 m, the
    # predictive covariance of a just-initialised landmark is twice one return's, so d² ≥ sep² / (2·σ_max²)
    sigma_max = 2.1 * max(RANGE_STD, BEARING_STD)
    assert sep**2 / (2 * sigma_max**2) > CHI2_2DOF_9999
    inputs = _inputs(pts, d)
    off = _solve(inputs, version=version, size_gate=False)
    on = _solve(inputs, version=version, size_gate=True, size_gate_hide=hide)
    assert off.landmarks_xy.shape == (2, 2)
    assert on.landmarks_xy.shape == (1, 2)
    assert on.extra["n_size_gated"] == 20  # every particle dropped the second one
    np.testing.assert_array_equal(on.assoc, [0, -1])  # the cut view stays unassociated
    np.testing.assert_allclose(on.landmarks_xy[0], pts[0], atol=0.05)  # the landmark is the first return's point


def test_two_posts_farther_apart_than_a_diameter_stay_two():
    d = 0.5
    pts = np.array([[2.25, -0.3], [2.25, 0.3]])  # 0.6 m apart > d
    on = _solve(_inputs(pts, d), version=2, size_gate=True)
    assert on.landmarks_xy.shape == (2, 2)
    assert on.extra["n_size_gated"] == 0
    np.testing.assert_allclose(np.sort(on.landmarks_xy[:, 1]), [-0.3, 0.3], atol=0.05)


def test_gate_without_declared_sizes_changes_nothing():
    pts = _surface_points((2.25, 0.0), 0.25, [-0.18, 0.18])
    inputs = _inputs(pts, 0.5)
    inputs = SlamInputs(**{**inputs.__dict__, "observations": Observations(
        **{**inputs.observations.__dict__, "diameter_m": None})})
    a, b = _solve(inputs, size_gate=True), _solve(inputs, size_gate=False)
    np.testing.assert_array_equal(a.landmarks_xy, b.landmarks_xy)
    np.testing.assert_array_equal(a.assoc, b.assoc)


def test_gated_slot_is_reused_and_later_landmarks_keep_their_rows():
    """A gated landmark's slot is given back at the end of its step: the post seen next gets slot 1."""
    d = 0.5
    pts = _surface_points((2.25, 0.0), d / 2, [-0.18, 0.18])
    far = np.array([[2.0, 2.0]])
    a = _inputs(pts, d, step=0)
    b = _inputs(far, d, step=1)
    obs = Observations(
        step=np.r_[a.observations.step, b.observations.step],
        range_m=np.r_[a.observations.range_m, b.observations.range_m],
        bearing_rad=np.r_[a.observations.bearing_rad, b.observations.bearing_rad],
        sensor=np.zeros(3, np.int16), reported_id=np.full(3, -1, np.int64),
        offsets=Observations.offsets_from_steps(np.array([0, 0, 1]), 2), diameter_m=np.full(3, d),
    )
    inputs = SlamInputs(**{**a.__dict__, "observations": obs})
    res = _solve(inputs, version=2, size_gate=True, size_gate_hide=False)
    # the gated row stays unassociated (not relabelled to the landmark that reuses its slot)
    np.testing.assert_array_equal(res.assoc, [0, -1, 1])
    assert res.landmarks_xy.shape == (2, 2)
    from slamcli.solvers.fastslam import _Run, _setup

    p = FastSlamParams(n_particles=20, association="ml", group_returns=False, size_gate=True, size_gate_hide=False)
    run = _Run(_setup(inputs, p), inputs, np.random.default_rng(3))
    run.step(0)
    np.testing.assert_array_equal(run.ps.n_slots, 1)  # slot 1 given back after step 0
    run.step(1)
    np.testing.assert_array_equal(run.ps.n_slots, 2)
    assert run.ps.exists[:, :2].all() and not run.ps.exists[:, 2:].any()


def test_inside_declared_size_matches_brute_force():
    rng = np.random.default_rng(7)
    P, L = 6, 9
    lm = rng.uniform(-2, 2, (P, L, 2))
    live = rng.random((P, L)) < 0.7
    pts = rng.uniform(-2, 2, (P, 2))
    for sep in (0.0, 0.5, 1.3):
        got = inside_declared_size(lm, pts, sep, live=live)
        want = [any(live[k, j] and np.hypot(*(lm[k, j] - pts[k])) < sep for j in range(L)) for k in range(P)]
        np.testing.assert_array_equal(got, want)
    # one map (EKF), no live mask; an empty map
    assert inside_declared_size(lm[0], lm[0, 3] + [0.1, 0.0], 0.2)
    assert not inside_declared_size(np.zeros((0, 2)), np.zeros(2), 1.0)


def test_size_gate_param_is_validated():
    with pytest.raises(ValueError, match="size_gate"):
        FastSlamParams(size_gate="yes")
    with pytest.raises(ValueError, match="size_gate_hide"):
        FastSlamParams(size_gate_hide=1)


@pytest.mark.slow
def test_hidden_landmarks_leave_the_filter_unchanged():
    """size_gate_hide: the particles run exactly as without the gate (same path, same draws); the reported map
    is the ungated one without the landmarks born within 2ρ of another (each within 2ρ of one reported)."""
    from slamcli.sim import simulate_scenario

    ds = simulate_scenario("paper-sim1", seed=0, overrides={"n_steps": 400})
    off = FastSlam(FastSlamParams(size_gate=False)).solve(ds.inputs, rng=np.random.default_rng(0))
    on = FastSlam(FastSlamParams(size_gate=True)).solve(ds.inputs, rng=np.random.default_rng(0))
    np.testing.assert_array_equal(on.poses_xyt, off.poses_xyt)
    assert 0 < on.landmarks_xy.shape[0] < off.landmarks_xy.shape[0]
    kept = [np.flatnonzero(np.all(off.landmarks_xy == m, axis=1)) for m in on.landmarks_xy]
    assert all(k.size == 1 for k in kept)  # the reported map is a subset of the ungated one
    hidden = np.setdiff1d(np.arange(off.landmarks_xy.shape[0]), np.concatenate(kept))
    two_rho = float(np.max(ds.inputs.observations.diameter_m))
    d = np.linalg.norm(off.landmarks_xy[hidden, None] - on.landmarks_xy[None], axis=-1)
    assert np.all(d.min(axis=1) < two_rho)  # every hidden one shadows a reported landmark
