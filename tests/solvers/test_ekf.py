"""EKF-SLAM: the pure-function core against hand-written Kalman algebra, and the solver's association logic.

Worlds come from ``conftest.drive_world`` (truth is kept by the test, never passed to the solver).
"""

from __future__ import annotations

import numpy as np
import pytest
from conftest import drive_world

from slamcli.errors import SolverError
from slamcli.models import motion, observation, se2
from slamcli.models.angles import wrap_angle
from slamcli.solvers.ekf import (
    EkfParams,
    EkfSlam,
    compose_jacobians,
    innovation_stats,
    landmark_init,
    predict,
    update,
)
from slamcli.types import Observations, Status


# ------------------------------------------------------------------------------------------------ world
def make_world(seed: int, *, T: int = 200, v: float = 1.0, radius: float = 5.0, landmarks_xy=None, **noise):
    """A robot driving a circle of ``radius`` around a ring of landmarks (:func:`conftest.drive_world`; ``noise``
    its keywords). Returns ``(inputs, truth)`` where ``truth = dict(poses, landmarks, obs_landmark)``; clutter rows
    have true landmark −1 and reported id −1.
    """
    if landmarks_xy is None:
        ang = np.linspace(0, 2 * np.pi, 12, endpoint=False)
        landmarks_xy = np.stack([np.r_[1.4 * radius * np.cos(ang), 0.5 * radius * np.cos(ang + 0.3)],
                                 np.r_[1.4 * radius * np.sin(ang), 0.5 * radius * np.sin(ang + 0.3)]], -1)
        landmarks_xy = landmarks_xy + np.array([0.0, radius])
    ds = drive_world(seed, landmarks_xy, T=T, v=v, omega=v / radius, **noise)
    truth = {"poses": ds.truth.poses_xyt, "landmarks": ds.truth.landmarks_xy, "obs_landmark": ds.truth.obs_landmark}
    return ds.inputs, truth


def association_accuracy(assoc, true_lm):
    """Fraction of real-landmark rows whose label maps consistently to their true landmark.

    Each estimated label is mapped to the true landmark most of its rows belong to; a row counts as correct
    when its label is ≥ 0 and maps to its own true landmark (discarded rows count as wrong).
    """
    real = true_lm >= 0
    label_to_true = {}
    for lab in np.unique(assoc[assoc >= 0]):
        t = true_lm[assoc == lab]
        t = t[t >= 0]
        if t.size:
            label_to_true[lab] = np.bincount(t).argmax()
    ok = np.array([a >= 0 and label_to_true.get(a, -2) == t for a, t in zip(assoc[real], true_lm[real])])
    return float(ok.mean())


def random_spd(rng, n):
    A = rng.normal(size=(n, n))
    return A @ A.T + n * np.eye(n) * 0.1


# ------------------------------------------------------------------------------------------------ core
def test_predict_matches_full_FPFt_plus_Q():
    rng = np.random.default_rng(0)
    n = 3 + 2 * 4
    x = rng.normal(size=n)
    P = random_spd(rng, n)
    u, dt = np.array([0.8, 0.3]), 0.1
    F, G_u = motion.ddmr_jacobians(x[:3], u, dt)
    M = np.diag([0.1**2, 0.05**2])
    Q = G_u @ M @ G_u.T
    x_new, P_new = predict(x, P, motion.ddmr_step(x[:3], u, dt), F, Q)
    # hand computation with the full (n, n) block-diagonal F̄ and Q̄
    Fb = np.eye(n)
    Fb[:3, :3] = F
    Qb = np.zeros((n, n))
    Qb[:3, :3] = Q
    np.testing.assert_allclose(P_new, Fb @ P @ Fb.T + Qb, rtol=0, atol=1e-12)
    # and the pose mean is g(x, u) written out: x + dt [v cos θ, v sin θ, ω]
    th = x[2]
    np.testing.assert_allclose(x_new[:2], x[:2] + dt * u[0] * np.array([np.cos(th), np.sin(th)]), atol=1e-14)
    np.testing.assert_allclose(x_new[3:], x[3:])
    # the input was not modified (pure function)
    assert not np.shares_memory(P_new, P)


def test_compose_jacobians_finite_difference():
    a, b = np.array([0.3, -1.0, 2.5]), np.array([0.4, 0.1, 0.2])
    J_a, J_b = compose_jacobians(a, b)
    eps = 1e-6
    for J, which in ((J_a, 0), (J_b, 1)):
        num = np.zeros((3, 3))
        for k in range(3):
            d = np.zeros(3)
            d[k] = eps
            args_p = (a + d, b) if which == 0 else (a, b + d)
            args_m = (a - d, b) if which == 0 else (a, b - d)
            diff = se2.compose(*args_p) - se2.compose(*args_m)
            num[:, k] = diff / (2 * eps)
        np.testing.assert_allclose(J, num, atol=1e-8)


def test_update_one_landmark_matches_dense_kalman_update():
    rng = np.random.default_rng(1)
    L, j = 3, 1
    n = 3 + 2 * L
    x = np.r_[0.5, -0.2, 0.3, rng.uniform(2, 6, size=2 * L)]
    P = random_spd(rng, n) * 0.01
    R = np.diag([0.1**2, 0.02**2])
    k = 3 + 2 * j
    z = observation.range_bearing(x[:3], x[k : k + 2]) + np.array([0.05, -0.01])
    x_new, P_new, y, S = update(x, P, z, j, R)
    # dense hand-written Kalman update with the full (2, n) H
    H_r, H_m = observation.range_bearing_jacobians(x[:3], x[k : k + 2])
    H = np.zeros((2, n))
    H[:, :3] = H_r
    H[:, k : k + 2] = H_m
    y_ref = z - observation.range_bearing(x[:3], x[k : k + 2])
    S_ref = H @ P @ H.T + R
    K = P @ H.T @ np.linalg.inv(S_ref)
    x_ref = x + K @ y_ref
    P_ref = (np.eye(n) - K @ H) @ P  # optimal K: Joseph form equals the short form
    np.testing.assert_allclose(y, y_ref, atol=1e-14)
    np.testing.assert_allclose(S, S_ref, rtol=1e-12)
    np.testing.assert_allclose(x_new, x_ref, atol=1e-12)
    np.testing.assert_allclose(P_new, P_ref, atol=1e-12)


def test_update_wraps_bearing_innovation():
    # landmark straight behind the robot: predicted bearing −π, measured +π−0.01 ⇒ innovation −0.01... wrapped
    x = np.array([0.0, 0.0, 0.0, -3.0, 1e-9])
    P = np.diag([1e-2, 1e-2, 1e-3, 1e-2, 1e-2])
    z = np.array([3.0, np.pi - 0.01])
    _, _, y, _ = update(x, P, z, 0, np.diag([0.01, 1e-4]))
    assert abs(y[1]) < 0.02


def test_joseph_form_keeps_P_symmetric_psd_over_many_updates():
    inputs, _ = make_world(3, T=300, range_std=1e-3, bearing_std=1e-4)  # tiny R: ill-conditioned updates
    res = EkfSlam(EkfParams()).solve(inputs, rng=np.random.default_rng(0))
    # rebuild the final full P through the core to check it directly
    for C in list(res.pose_cov) + list(res.landmark_cov):
        np.testing.assert_array_equal(C, C.T)
        assert np.linalg.eigvalsh(C).min() > -1e-12
    # also the full state covariance of a hand-driven filter
    rng = np.random.default_rng(2)
    x = np.r_[0.0, 0.0, 0.1, 3.0, 1.0, 2.0, -2.0]
    P = random_spd(rng, 7) * 1e-2
    R = np.diag([1e-6, 1e-8])
    for _ in range(200):
        for j in range(2):
            z = observation.range_bearing(x[:3], x[3 + 2 * j : 5 + 2 * j]) + rng.normal(0, [1e-3, 1e-4])
            x, P, _, _ = update(x, P, z, j, R)
    np.testing.assert_array_equal(P, P.T)
    assert np.linalg.eigvalsh(P).min() > -1e-15


def test_landmark_init_matches_linearised_augmentation():
    rng = np.random.default_rng(4)
    x = np.r_[1.0, 2.0, 0.7, 4.0, 4.0]
    P = random_spd(rng, 5) * 0.01
    z = np.array([2.0, 0.4])
    R = np.diag([0.1**2, 0.05**2])
    m, P_mx, P_mm = landmark_init(x, P, z, R)
    M_x, M_z = observation.inverse_range_bearing_jacobians(x[:3], z)
    J = np.zeros((2, 5))
    J[:, :3] = M_x
    np.testing.assert_allclose(m, observation.inverse_range_bearing(x[:3], z))
    np.testing.assert_allclose(P_mx, J @ P, atol=1e-15)
    np.testing.assert_allclose(P_mm, M_x @ P[:3, :3] @ M_x.T + M_z @ R @ M_z.T, atol=1e-15)


def test_innovation_stats_matches_per_landmark_loop():
    rng = np.random.default_rng(5)
    L = 4
    x = np.r_[0.2, 0.1, -0.4, rng.uniform(-5, 5, size=2 * L)]
    P = random_spd(rng, 3 + 2 * L) * 0.05
    R = np.diag([0.2**2, 0.03**2])
    z = np.array([3.0, 0.5])
    d2 = innovation_stats(x, P, z, R)
    for k in range(L):
        H_r, H_m = observation.range_bearing_jacobians(x[:3], x[3 + 2 * k : 5 + 2 * k])
        H = np.zeros((2, 3 + 2 * L))
        H[:, :3], H[:, 3 + 2 * k : 5 + 2 * k] = H_r, H_m
        y = observation.measurement_residual(z, observation.range_bearing(x[:3], x[3 + 2 * k : 5 + 2 * k]))
        S = H @ P @ H.T + R
        assert d2[k] == pytest.approx(float(y @ np.linalg.solve(S, y)), rel=1e-10)


# ------------------------------------------------------------------------------------------------ solver
def test_solver_shapes_status_and_determinism():
    inputs, truth = make_world(7, T=150)
    a = EkfSlam(EkfParams()).solve(inputs, rng=np.random.default_rng(0))
    b = EkfSlam(EkfParams()).solve(inputs, rng=np.random.default_rng(99))
    T1, N = inputs.n_poses, len(inputs.observations)
    L = a.landmarks_xy.shape[0]
    assert a.status is Status.COMPLETED
    assert a.poses_xyt.shape == (T1, 3) and a.pose_cov.shape == (T1, 3, 3)
    assert a.assoc.shape == (N,) and a.landmark_cov.shape == (L, 2, 2)
    assert L == len(np.unique(truth["obs_landmark"]))
    np.testing.assert_array_equal(a.poses_xyt, b.poses_xyt)
    assert np.isfinite(a.extra["mean_nis"])
    # filtered estimate is much better than dead reckoning on the commanded controls
    dr = motion.integrate(inputs.x0, inputs.controls, inputs.dt)
    err_ekf = np.linalg.norm(a.poses_xyt[:, :2] - truth["poses"][:, :2], axis=1).mean()
    err_dr = np.linalg.norm(dr[:, :2] - truth["poses"][:, :2], axis=1).mean()
    assert err_ekf < 0.5 * err_dr


def test_known_association_requires_reported_ids():
    inputs, _ = make_world(8, T=20, report_ids=False)
    with pytest.raises(SolverError, match="reported_id"):
        EkfSlam(EkfParams(association="known")).solve(inputs, rng=np.random.default_rng(0))


def test_bad_params_rejected():
    with pytest.raises(ValueError, match="new_landmark_prob"):
        EkfParams(gate_prob=0.99, new_landmark_prob=0.9)


@pytest.mark.parametrize("motion_input", ["controls", "odometry"])
def test_known_and_ml_agree_when_landmarks_far_apart_and_noise_small(motion_input):
    ang = np.linspace(0, 2 * np.pi, 8, endpoint=False)
    lms = np.stack([9.0 * np.cos(ang), 5.0 + 9.0 * np.sin(ang)], -1)  # ≥ 6.9 m apart
    inputs, _ = make_world(
        9, T=250, landmarks_xy=lms, max_range=8.0, motion_std=(0.01, 0.005), odometry_std=(0.005, 0.005, 0.002),
        range_std=0.01, bearing_std=0.002,
    )
    known = EkfSlam(EkfParams(association="known", motion_input=motion_input)).solve(inputs, rng=np.random.default_rng(0))
    # a wide gate: with a 0.99 gate ~1 % of the true associations would (correctly) be rejected; far-apart
    # landmarks keep wrong matches at d² ≫ 50 so a 1−1e-9 gate (d² ≤ 41.4) is still unambiguous
    ml_params = EkfParams(association="ml", motion_input=motion_input, gate_prob=1 - 1e-9, new_landmark_prob=1 - 1e-12)
    ml = EkfSlam(ml_params).solve(inputs, rng=np.random.default_rng(0))
    # same partition of the rows (labels may be permuted only by creation order, which is the same here)
    np.testing.assert_array_equal(ml.assoc, known.assoc)
    np.testing.assert_allclose(ml.poses_xyt, known.poses_xyt, atol=1e-12)
    np.testing.assert_allclose(ml.landmarks_xy, known.landmarks_xy, atol=1e-12)
    np.testing.assert_allclose(ml.pose_cov, known.pose_cov, atol=1e-15)


@pytest.mark.slow
def test_ml_association_accuracy_on_loop_world():
    inputs, truth = make_world(10, T=400, report_ids=False)
    res = EkfSlam(EkfParams(association="ml", provisional=False)).solve(inputs, rng=np.random.default_rng(0))
    acc = association_accuracy(res.assoc, truth["obs_landmark"])
    assert acc >= 0.95, acc
    # and the map has (close to) one landmark per true landmark
    assert abs(res.landmarks_xy.shape[0] - truth["landmarks"].shape[0]) <= 2


def n_spurious(assoc, true_lm, n_landmarks):
    """Estimated landmarks whose rows are mostly clutter (true id −1), or that have no row at all."""
    out = 0
    for lab in range(n_landmarks):
        t = true_lm[assoc == lab]
        out += int(t.size == 0 or np.mean(t < 0) > 0.5)
    return out


@pytest.mark.slow
def test_provisional_list_reduces_spurious_landmarks_under_clutter():
    inputs, truth = make_world(11, T=200, report_ids=False, clutter_per_step=0.3)
    true_lm = truth["obs_landmark"]
    off = EkfSlam(EkfParams(association="ml", provisional=False)).solve(inputs, rng=np.random.default_rng(0))
    on = EkfSlam(EkfParams(association="ml", provisional=True, provisional_min_hits=3, provisional_window=10)).solve(
        inputs, rng=np.random.default_rng(0)
    )
    spurious_off = n_spurious(off.assoc, true_lm, off.landmarks_xy.shape[0])
    spurious_on = n_spurious(on.assoc, true_lm, on.landmarks_xy.shape[0])
    assert spurious_off > 30  # without the list every clutter row that gates nowhere becomes a landmark
    assert spurious_on < 0.2 * spurious_off, (spurious_on, spurious_off)
    assert on.extra["n_provisional_dropped"] > 30
    # the real landmarks are still found and associated
    assert association_accuracy(on.assoc, true_lm) >= 0.95


def test_stabilising_noise_inflates_covariance():
    inputs, _ = make_world(12, T=100)
    base = EkfSlam(EkfParams()).solve(inputs, rng=np.random.default_rng(0))
    infl = EkfSlam(EkfParams(obs_std_scale=10.0, stabilising_pose_std=(0.01, 0.01, 0.005))).solve(
        inputs, rng=np.random.default_rng(0)
    )
    tr_b = np.trace(base.pose_cov[1:], axis1=1, axis2=2)
    tr_i = np.trace(infl.pose_cov[1:], axis1=1, axis2=2)
    assert np.all(tr_i > tr_b)


def test_growing_state_many_landmarks_and_progress():
    # 60 landmarks force several buffer reallocations; progress is reported up to completion
    ang = np.linspace(0, 2 * np.pi, 60, endpoint=False)
    lms = np.stack([6.5 * np.cos(ang), 5.0 + 6.5 * np.sin(ang)], -1)
    inputs, truth = make_world(13, T=320, landmarks_xy=lms, max_range=4.0)
    calls = []
    res = EkfSlam(EkfParams()).solve(inputs, rng=np.random.default_rng(0), progress=lambda d, t: calls.append((d, t)))
    seen = np.unique(truth["obs_landmark"])
    assert res.landmarks_xy.shape[0] == seen.size
    assert calls[-1] == (inputs.n_poses, inputs.n_poses)
    # landmark rows follow creation order: label of the first row of each id
    err = np.linalg.norm(res.landmarks_xy[res.assoc] - truth["landmarks"][truth["obs_landmark"]], axis=1)
    assert np.median(err) < 0.2


def test_scalar_hot_loop_twins_match_the_models():
    from slamcli.solvers.ekf import _ddmr_predict, _innovation_and_jacobian, _wrap

    rng = np.random.default_rng(14)
    for _ in range(50):
        x = np.r_[rng.uniform(-5, 5, 2), rng.uniform(-np.pi, np.pi)]
        m = rng.uniform(-5, 5, 2)
        z = np.array([rng.uniform(0.5, 8), rng.uniform(-np.pi, np.pi)])
        y, Hs = _innovation_and_jacobian(*x, *m, *z)
        H_r, H_m = observation.range_bearing_jacobians(x, m)
        np.testing.assert_allclose(y, observation.measurement_residual(z, observation.range_bearing(x, m)), atol=1e-12)
        np.testing.assert_allclose(Hs, np.hstack([H_r, H_m]), atol=1e-12)
        u = rng.normal(size=2)
        pose, F, G_u = _ddmr_predict(x, u, 0.1)
        F_ref, G_ref = motion.ddmr_jacobians(x, u, 0.1)
        np.testing.assert_allclose(pose, motion.ddmr_step(x, u, 0.1), atol=1e-12)
        np.testing.assert_allclose(F, F_ref, atol=1e-15)
        np.testing.assert_allclose(G_u, G_ref, atol=1e-15)
    for a in (np.pi, -np.pi, 3 * np.pi, 2 * np.pi, 1e-17, -7.5):
        assert _wrap(a) == pytest.approx(float(wrap_angle(a)), abs=1e-15)


def test_scalar_odometry_prediction_matches_compose_and_finite_differences():
    """The odometry predict's twin: ``x ⊕ d`` against se2.compose, its Jacobians against central differences."""
    from slamcli.models import se2
    from slamcli.solvers.ekf import _odometry_predict

    rng = np.random.default_rng(15)
    h = 1e-6
    for _ in range(20):
        x = np.r_[rng.uniform(-5, 5, 2), rng.uniform(-3, 3)]
        d = np.r_[rng.normal(size=2), rng.uniform(-0.5, 0.5)]
        pose, F, G = _odometry_predict(x, d)
        ref = se2.compose(x, d)
        np.testing.assert_allclose(pose[:2], ref[:2], atol=1e-12)
        assert float(wrap_angle(pose[2] - ref[2])) == pytest.approx(0.0, abs=1e-12)
        for k in range(3):
            e = np.zeros(3)
            e[k] = h
            fd_a = (se2.compose(x + e, d) - se2.compose(x - e, d)) / (2 * h)
            fd_b = (se2.compose(x, d + e) - se2.compose(x, d - e)) / (2 * h)
            fd_a[2], fd_b[2] = float(wrap_angle(fd_a[2] * 2 * h)) / (2 * h), float(wrap_angle(fd_b[2] * 2 * h)) / (2 * h)
            np.testing.assert_allclose(F[:, k], fd_a, atol=1e-7)
            np.testing.assert_allclose(G[:, k], fd_b, atol=1e-7)


def test_noise_free_sensor_is_a_clear_error():
    import dataclasses

    inputs, _ = make_world(15, T=10)
    bad = dataclasses.replace(inputs, noise=dataclasses.replace(inputs.noise, bearing_std=0.0))
    with pytest.raises(SolverError, match="bearing_std=0.0"):
        EkfSlam(EkfParams()).solve(bad, rng=np.random.default_rng(0))


def test_ml_handles_several_returns_per_landmark_per_step():
    # a laser sees one post on adjacent beams: duplicate rows of the same landmark in one step must fuse into
    # one landmark (exclusive_per_step=False, the default), not spawn duplicates
    inputs, truth = make_world(16, T=150, report_ids=False)
    o = inputs.observations
    rep = np.repeat(np.arange(len(o)), 2)
    rng = np.random.default_rng(0)
    # a second, independent return per row: noise-free measurement from the truth + fresh noise
    z_true = observation.range_bearing(truth["poses"][o.step], truth["landmarks"][truth["obs_landmark"]])
    z = z_true[rep] + rng.normal(0, [inputs.noise.range_std, inputs.noise.bearing_std], size=(rep.size, 2))
    import dataclasses

    obs2 = dataclasses.replace(
        o, step=o.step[rep], range_m=z[:, 0], bearing_rad=observation.wrap_angle(z[:, 1]),
        sensor=o.sensor[rep], reported_id=o.reported_id[rep],
        offsets=Observations.offsets_from_steps(o.step[rep], inputs.n_poses),
    )
    res = EkfSlam(EkfParams(association="ml", provisional=False)).solve(dataclasses.replace(inputs, observations=obs2),
                                                      rng=np.random.default_rng(0))
    n_seen = np.unique(truth["obs_landmark"]).size
    assert res.landmarks_xy.shape[0] <= n_seen + 1
    assert association_accuracy(res.assoc, truth["obs_landmark"][rep]) >= 0.95


def test_gps_update_matches_dense_kalman_update_and_is_used():
    from slamcli.solvers.ekf import update_position

    rng = np.random.default_rng(17)
    n = 3 + 2 * 3
    x = rng.normal(size=n)
    P = random_spd(rng, n) * 0.1
    R = 0.3**2 * np.eye(2)
    z = x[:2] + np.array([0.2, -0.1])
    H = np.zeros((2, n))
    H[0, 0] = H[1, 1] = 1.0
    K = P @ H.T @ np.linalg.inv(H @ P @ H.T + R)
    I_KH = np.eye(n) - K @ H
    x_new, P_new = update_position(x, P, z, R)
    np.testing.assert_allclose(x_new, x + K @ (z - x[:2]), atol=1e-12)
    np.testing.assert_allclose(P_new, I_KH @ P @ I_KH.T + K @ R @ K.T, atol=1e-12)
    # in the solver: fixes shrink the position covariance at their steps
    import dataclasses

    inputs, truth = make_world(18, T=60)
    steps = np.arange(0, 61, 10)
    with_gps = dataclasses.replace(inputs, gps_step=steps, gps_xy=truth["poses"][steps, :2], gps_std=0.05)
    a = EkfSlam(EkfParams()).solve(with_gps, rng=np.random.default_rng(0))
    b = EkfSlam(EkfParams(use_gps=False)).solve(with_gps, rng=np.random.default_rng(0))
    tr = lambda r: np.trace(r.pose_cov[steps[1:], :2, :2], axis1=1, axis2=2)
    assert np.all(tr(a) < tr(b))


def test_provisional_list_is_ignored_with_known_ids():
    inputs, _ = make_world(3, T=60, report_ids=True)
    a = EkfSlam(EkfParams(association="known", provisional=True)).solve(inputs, rng=np.random.default_rng(0))
    b = EkfSlam(EkfParams(association="known", provisional=False)).solve(inputs, rng=np.random.default_rng(0))
    np.testing.assert_array_equal(a.poses_xyt, b.poses_xyt)
    np.testing.assert_array_equal(a.assoc, b.assoc)


def test_auto_with_reported_ids_stays_known_under_the_default_provisional_list():
    inputs, _ = make_world(3, T=60, report_ids=True)
    assert EkfSlam(EkfParams()).solve(inputs, rng=np.random.default_rng(0)).extra["association"] == "known"


# ------------------------------------------------------------------------------------------------ sim scenario
@pytest.mark.slow
def test_ml_association_accuracy_on_sim_loop_scenario():
    from slamcli.sim import simulate_scenario

    for seed in (0, 1, 2):
        ds = simulate_scenario("loop", seed=seed)  # clutter off, no reported ids
        assert np.all(ds.inputs.observations.reported_id < 0)
        res = EkfSlam(EkfParams(association="ml", provisional=False)).solve(ds.inputs, rng=np.random.default_rng(0))
        acc = association_accuracy(res.assoc, ds.truth.obs_landmark)  # measured 0.990, 0.990, 0.991
        assert acc >= 0.95, (seed, acc)
        assert res.landmarks_xy.shape[0] == np.unique(ds.truth.obs_landmark).size


@pytest.mark.slow
def test_provisional_list_on_sim_loop_with_clutter():
    from slamcli.sim import simulate_scenario

    ds = simulate_scenario("loop", seed=0, overrides={"clutter.rate": 0.3, "n_steps": 200})
    true_lm = ds.truth.obs_landmark
    off = EkfSlam(EkfParams(association="ml", provisional=False)).solve(ds.inputs, rng=np.random.default_rng(0))
    on = EkfSlam(EkfParams(association="ml", provisional=True)).solve(ds.inputs, rng=np.random.default_rng(0))
    s_off = n_spurious(off.assoc, true_lm, off.landmarks_xy.shape[0])  # measured 83
    s_on = n_spurious(on.assoc, true_lm, on.landmarks_xy.shape[0])  # measured 0
    assert s_off > 30 and s_on <= 0.1 * s_off, (s_on, s_off)
    assert association_accuracy(on.assoc, true_lm) >= 0.95


def _duplicated_returns(seed):
    """The make_world data with every row observed twice (two independent returns of the same landmark)."""
    import dataclasses

    inputs, truth = make_world(seed, T=120)
    o = inputs.observations
    rep = np.repeat(np.arange(len(o)), 2)
    rng = np.random.default_rng(seed + 100)
    z_true = observation.range_bearing(truth["poses"][o.step], truth["landmarks"][truth["obs_landmark"]])
    z = z_true[rep] + rng.normal(0, [inputs.noise.range_std, inputs.noise.bearing_std], size=(rep.size, 2))
    z[:, 1] = wrap_angle(z[:, 1])
    obs2 = dataclasses.replace(
        o, step=o.step[rep], range_m=z[:, 0], bearing_rad=z[:, 1], sensor=o.sensor[rep],
        reported_id=o.reported_id[rep], offsets=Observations.offsets_from_steps(o.step[rep], inputs.n_poses),
    )
    # the same data pre-averaged by hand: mean range, circular-mean bearing of each pair, + range offset
    zp = z.reshape(-1, 2, 2)
    z_avg = np.stack([zp[:, :, 0].mean(1), np.arctan2(np.sin(zp[:, :, 1]).sum(1), np.cos(zp[:, :, 1]).sum(1))], -1)
    obs_avg = dataclasses.replace(o, range_m=z_avg[:, 0] + 0.1, bearing_rad=z_avg[:, 1])
    return dataclasses.replace(inputs, observations=obs2), dataclasses.replace(inputs, observations=obs_avg), rep


@pytest.mark.parametrize("association", ["known", "ml"])
@pytest.mark.slow
def test_group_returns_equals_filtering_the_averaged_measurements(association):
    dup, avg, rep = _duplicated_returns(19)
    grouped = EkfSlam(EkfParams(association=association, group_returns=True, range_offset=0.1)).solve(
        dup, rng=np.random.default_rng(0)
    )
    ref = EkfSlam(EkfParams(association=association)).solve(avg, rng=np.random.default_rng(0))
    np.testing.assert_allclose(grouped.poses_xyt, ref.poses_xyt, atol=1e-12)
    np.testing.assert_allclose(grouped.pose_cov, ref.pose_cov, atol=1e-15)
    np.testing.assert_allclose(grouped.landmarks_xy, ref.landmarks_xy, atol=1e-12)
    np.testing.assert_array_equal(grouped.assoc, ref.assoc[rep])  # both rows of a pair get the pair's label


def test_the_covariance_a_dataset_makes_the_ekf_grow_to_is_checked_before_it_is_allocated(monkeypatch):
    """The joint covariance grows with the landmarks the data create: each growth goes through
    check_allocation, so a file that makes millions of landmarks is one line, not a 2 PiB request."""
    from conftest import tiny_dataset

    from slamcli.errors import ConfigError

    ds = tiny_dataset(T=30, n_landmarks=6, seed=2)
    monkeypatch.setenv("SLAMCLI_MEMORY_LIMIT_MB", "0.0005")  # 524 bytes: the first 11×11 block (968 B) is over
    with pytest.raises(ConfigError, match=r"landmarks=4: needs about 9.68e-07 GB for the EKF's joint covariance"):
        EkfSlam(EkfParams()).solve(ds.inputs, rng=np.random.default_rng(0))
    monkeypatch.setenv("SLAMCLI_MEMORY_LIMIT_MB", "1")
    assert EkfSlam(EkfParams()).solve(ds.inputs, rng=np.random.default_rng(0)).status is not Status.FAILED
