"""FastSLAM 1.0 / 2.0: the landmark EKF and the 2.0 proposal against hand-written algebra, particle-copy
independence, association, landmark removal, determinism, and accuracy vs the EKF.

Worlds come from ``conftest.drive_world``; the truth stays in the test, never goes to the solver.
"""

from __future__ import annotations

import numpy as np
import pytest
from conftest import drive_world
from scipy import stats

from slamcli.errors import ConfigError, SolverError
from slamcli.models import motion, observation, se2
from slamcli.params import build_params
from slamcli.solvers.fastslam import (
    FastSlam,
    FastSlamParams,
    ParticleSet,
    init_landmark,
    landmark_ekf_update,
    moment_matched_landmarks,
)
from slamcli.types import NoiseSpec, Observations, SlamInputs, Status


# ------------------------------------------------------------------------------------------------ world
def make_world(seed: int, *, T: int = 150, v: float = 1.0, omega: float = 0.2, n_landmarks: int = 12, **noise):
    """A robot circling (radius v/ω) among landmarks on two rings (:func:`conftest.drive_world`; ``noise`` its
    keywords); returns ``(inputs, truth_poses, truth_landmarks, obs_label)``."""
    R0 = v / omega
    ang = np.linspace(0, 2 * np.pi, n_landmarks, endpoint=False)
    rad = np.where(np.arange(n_landmarks) % 2 == 0, R0 - 2.0, R0 + 2.0)
    lms = np.column_stack([rad * np.sin(ang), R0 - rad * np.cos(ang)])
    ds = drive_world(seed, lms, T=T, v=v, omega=omega, **noise)
    return ds.inputs, ds.truth.poses_xyt, ds.truth.landmarks_xy, ds.truth.obs_landmark


def landmark_rmse(est_xy, assoc, obs_label, truth_xy):
    """RMSE between each estimated landmark and the true landmark its observations came from (majority)."""
    err = []
    for row in range(len(est_xy)):
        labs = obs_label[(assoc == row) & (obs_label >= 0)]
        if labs.size:
            j = np.bincount(labs).argmax()
            err.append(np.sum((est_xy[row] - truth_xy[j]) ** 2))
    return float(np.sqrt(np.mean(err)))


def pose_rmse(est, truth):
    return float(np.sqrt(np.mean(np.sum((est[:, :2] - truth[:, :2]) ** 2, axis=1))))


def solve(inputs, seed=0, **kw):
    return FastSlam(FastSlamParams(**kw)).solve(inputs, rng=np.random.default_rng(seed))


# ------------------------------------------------------------------------------------------------ EKF core
def test_landmark_ekf_update_matches_hand_computed():
    x = np.array([1.0, 2.0, 0.3])
    mu = np.array([4.0, 6.0])  # dx=3, dy=4: r=5, q=25
    sig = np.array([[0.5, 0.1], [0.1, 0.2]])
    Q = np.diag([0.01, 0.0004])
    z = np.array([5.2, np.arctan2(4.0, 3.0) - 0.3 + 0.05])
    H = np.array([[3 / 5, 4 / 5], [-4 / 25, 3 / 25]])  # ∂[r, b]/∂m by hand
    nu = z - np.array([5.0, np.arctan2(4.0, 3.0) - 0.3])
    S = H @ sig @ H.T + Q
    K = sig @ H.T @ np.linalg.inv(S)
    mu_ref = mu + K @ nu
    sig_ref = (np.eye(2) - K @ H) @ sig
    ll_ref = stats.multivariate_normal(mean=np.zeros(2), cov=S).logpdf(nu)

    mu_new, sig_new, ll = landmark_ekf_update(x, mu, sig, z, Q)
    np.testing.assert_allclose(mu_new, mu_ref, rtol=1e-12)
    np.testing.assert_allclose(sig_new, sig_ref, rtol=1e-10, atol=1e-14)
    assert ll == pytest.approx(ll_ref, rel=1e-12)

    # vectorised over particles: the same answer row by row
    xs = x + np.array([[0, 0, 0], [0.1, -0.2, 0.05], [-0.3, 0.1, -0.1]])
    mus = np.stack([mu, mu + 0.2, mu - [0.5, 0.1]])
    sigs = np.stack([sig, 2 * sig, sig + 0.05 * np.eye(2)])
    mb, sb, lb = landmark_ekf_update(xs, mus, sigs, z, Q)
    for k in range(3):
        m1, s1, l1 = landmark_ekf_update(xs[k], mus[k], sigs[k], z, Q)
        np.testing.assert_allclose(mb[k], m1, rtol=1e-12)
        np.testing.assert_allclose(sb[k], s1, rtol=1e-12)
        assert lb[k] == pytest.approx(float(l1), rel=1e-12)


def test_bearing_innovation_is_wrapped():
    """A landmark right behind the robot, measured across the ±π cut, gives a tiny innovation."""
    x = np.array([0.0, 0.0, 0.0])
    mu = np.array([-5.0, 0.01])  # predicted bearing just below +π
    sig = 0.01 * np.eye(2)
    Q = np.diag([0.01, 0.0001])
    z = np.array([5.0, -np.pi + 0.001])  # measured just above −π
    mu_new, _, ll = landmark_ekf_update(x, mu, sig, z, Q)
    assert np.linalg.norm(mu_new - mu) < 0.02
    assert ll > -5.0


def test_init_landmark_is_inverse_model():
    x = np.array([1.0, -1.0, 0.7])
    z = np.array([3.0, -0.4])
    Q = np.diag([0.04, 0.0009])
    mu, sig = init_landmark(x, z, Q)
    np.testing.assert_allclose(observation.range_bearing(x, mu), z, atol=1e-12)
    a = 0.7 - 0.4
    Mz = np.array([[np.cos(a), -3 * np.sin(a)], [np.sin(a), 3 * np.cos(a)]])
    np.testing.assert_allclose(sig, Mz @ Q @ Mz.T, rtol=1e-12)


def test_moment_matched_landmarks_hand_values():
    mu = np.array([[[0.0, 0.0]], [[2.0, 0.0]]])  # 2 particles, 1 landmark
    sig = np.array([[[[1.0, 0.0], [0.0, 1.0]]], [[[3.0, 0.0], [0.0, 1.0]]]])
    w = np.array([0.75, 0.25])
    mean, cov = moment_matched_landmarks(mu, sig, w)
    np.testing.assert_allclose(mean, [[0.5, 0.0]])
    # Σw Σ = diag(1.5, 1); spread: 0.75·0.25 + 0.25·2.25 = 0.75
    np.testing.assert_allclose(cov, [[[2.25, 0.0], [0.0, 1.0]]])


# ------------------------------------------------------------------------------------------------ particles
def test_resampled_particles_do_not_share_landmark_arrays():
    ps = ParticleSet.create(np.zeros(3), n_particles=3, capacity=4)
    ps.mu[:] = np.arange(3)[:, None, None]
    ps.sig[:] = np.eye(2)
    ps.exists[:, :2] = True
    new = ps.take(np.array([0, 0, 2]))
    for a in ("x", "mu", "sig", "count", "exists", "n_slots"):
        assert not np.shares_memory(getattr(new, a), getattr(ps, a))
    new.mu[0, 1] = [42.0, 42.0]
    new.sig[0, 1] = 7.0
    new.exists[0, 3] = True
    new.x[0] = 9.0
    # the other copy of ancestor 0 and the ancestor itself are intact
    np.testing.assert_array_equal(new.mu[1], np.zeros((4, 2)))
    np.testing.assert_array_equal(new.sig[1, 1], np.eye(2))
    assert not new.exists[1, 3] and not ps.exists[0, 3]
    np.testing.assert_array_equal(ps.mu[0], np.zeros((4, 2)))
    np.testing.assert_array_equal(new.x[1], np.zeros(3))
    np.testing.assert_array_equal(new.log_w, np.zeros(3))


# ------------------------------------------------------------------------------------------------ proposals
def _one_step_inputs(z_rows, motion_std=(0.1, 0.05), odometry_std=(0.05, 0.03, 0.02)):
    """Pose 0 at the origin, one step; ``z_rows`` = [(t, r, b, id)]."""
    dt = 0.5
    x0 = np.zeros(3)
    controls = np.array([[1.0, 0.2]])
    odo = np.array([[0.0, 0.0, 0.0], [0.5, 0.02, 0.1]])
    zr = np.asarray(z_rows, float).reshape(-1, 4)
    step = zr[:, 0].astype(np.int64)
    obs = Observations(
        step=step,
        range_m=zr[:, 1].copy(),
        bearing_rad=zr[:, 2].copy(),
        sensor=np.zeros(len(step), np.int16),
        reported_id=zr[:, 3].astype(np.int64),
        offsets=Observations.offsets_from_steps(step, 2),
    )
    return SlamInputs(
        dt=dt,
        timestamps=np.array([0.0, dt]),
        x0=x0,
        controls=controls,
        odometry_xyt=odo,
        observations=obs,
        noise=NoiseSpec(
            motion_std=np.array(motion_std),
            odometry_std=np.array(odometry_std),
            range_std=0.05,
            bearing_std=0.02,
        ),
    )


def test_v2_motion_prior_is_ddmr_step_and_gu_m_gut():
    """The fused 2.0 prior: ``x̂ = g(x, u)`` and ``R = G_u M G_uᵀ`` (models.motion Jacobians), per particle."""
    from slamcli.solvers.fastslam import _predict_controls

    rng = np.random.default_rng(0)
    x = np.column_stack([rng.normal(size=5), rng.normal(size=5), rng.uniform(-np.pi, np.pi, 5)])
    x[0, 2] = np.pi - 1e-3  # the heading wraps
    u, dt, std = np.array([0.8, 0.5]), 0.1, np.array([0.05, 0.02])
    R_buf = np.zeros((3, 3, 5))
    x_hat, R = _predict_controls(x, u, dt, std[0], std[1], R_buf)
    np.testing.assert_allclose(x_hat, motion.ddmr_step(x, u, dt), rtol=1e-14, atol=1e-15)
    _, G_u = motion.ddmr_jacobians(x, u, dt)
    R_ref = G_u @ np.diag(std**2) @ np.swapaxes(G_u, 1, 2)
    np.testing.assert_allclose(np.moveaxis(R, 2, 0), R_ref, rtol=1e-12, atol=1e-18)


def test_v1_samples_the_motion_model():
    """No observations: particles of step 1 are g(x0, u + ε) — mean g(x0, u), covariance G_u M G_uᵀ."""
    inputs = _one_step_inputs(np.zeros((0, 4)))
    r = solve(inputs, seed=3, version=1, n_particles=40000)
    x1 = motion.ddmr_step(np.zeros(3), inputs.controls[0], inputs.dt)
    _, G_u = motion.ddmr_jacobians(np.zeros(3), inputs.controls[0], inputs.dt)
    R = G_u @ np.diag(inputs.noise.motion_std**2) @ G_u.T
    np.testing.assert_allclose(r.poses_xyt[1], x1, atol=4 * np.sqrt(np.diag(R).max() / 40000))
    np.testing.assert_allclose(r.pose_cov[1], R, rtol=0.05, atol=4 * np.sqrt(R[0, 0] * R[2, 2] / 40000))
    np.testing.assert_array_equal(r.pose_cov[0], np.zeros((3, 3)))


def test_v2_samples_the_observation_improved_proposal():
    """One landmark seen at poses 0 and 1 (odometry motion, full-rank R): the particles of step 1 are draws
    from N(μ_p, Σ_p) with Σ_p = (H_xᵀ Q_n⁻¹ H_x + R⁻¹)⁻¹ and μ_p = x̂ + Σ_p H_xᵀ Q_n⁻¹ ν (information form,
    computed independently of the solver's Kalman form). Weights are equal (all particles share x0), so the
    reported mean / covariance are the sample moments."""
    lm = np.array([3.0, 1.0])
    z0 = observation.range_bearing(np.zeros(3), lm)
    x_true = np.array([0.55, 0.0, 0.08])
    z1 = observation.range_bearing(x_true, lm) + [0.03, -0.01]
    inputs = _one_step_inputs([(0, *z0, 7), (1, *z1, 7)])
    P = 40000
    r = solve(inputs, seed=5, version=2, motion_source="odometry", n_particles=P)

    Q = inputs.noise.obs_cov
    d = se2.between(inputs.odometry_xyt[0], inputs.odometry_xyt[1])
    x_hat = se2.compose(np.zeros(3), d)
    R = np.diag(inputs.noise.odometry_std**2)  # θ0 = 0: ∂(x0 ⊕ d)/∂d = I
    mu0 = observation.inverse_range_bearing(np.zeros(3), z0)
    _, Mz = observation.inverse_range_bearing_jacobians(np.zeros(3), z0)
    sig0 = Mz @ Q @ Mz.T
    Hx, Hm = observation.range_bearing_jacobians(x_hat, mu0)
    Qn = Hm @ sig0 @ Hm.T + Q
    Sp = np.linalg.inv(Hx.T @ np.linalg.inv(Qn) @ Hx + np.linalg.inv(R))
    nu = observation.measurement_residual(z1, observation.range_bearing(x_hat, mu0))
    mp = x_hat + Sp @ Hx.T @ np.linalg.inv(Qn) @ nu

    assert np.trace(Sp) < 0.8 * np.trace(R)  # the observation really sharpens the proposal
    np.testing.assert_allclose(r.poses_xyt[1], mp, atol=4 * np.sqrt(np.diag(Sp).max() / P))
    np.testing.assert_allclose(
        r.pose_cov[1], Sp, rtol=0.05, atol=0.03 * np.sqrt(np.outer(np.diag(Sp), np.diag(Sp))).max()
    )
    assert r.extra["best_particle_weight"] == pytest.approx(1.0 / P)  # uniform: all share x0


def _single_landmark_inputs(seed: int, T: int = 6):
    """Robot on a gentle arc (dt 0.5 s) seeing one landmark at every pose, ids reported."""
    rng = np.random.default_rng(seed)
    dt, x0 = 0.5, np.zeros(3)
    controls = np.tile([1.0, 0.1], (T, 1))
    motion_std, range_std, bearing_std = np.array([0.1, 0.05]), 0.05, 0.02
    poses = motion.integrate(x0, controls + rng.standard_normal((T, 2)) * motion_std, dt)
    lm = np.array([4.0, 2.0])
    z = observation.range_bearing(poses, lm) + rng.standard_normal((T + 1, 2)) * [range_std, bearing_std]
    step = np.arange(T + 1)
    obs = Observations(
        step=step,
        range_m=z[:, 0].copy(),
        bearing_rad=observation.wrap_angle(z[:, 1]),
        sensor=np.zeros(T + 1, np.int16),
        reported_id=np.zeros(T + 1, np.int64),
        offsets=Observations.offsets_from_steps(step, T + 1),
    )
    return SlamInputs(
        dt=dt,
        timestamps=np.arange(T + 1) * dt,
        x0=x0,
        controls=controls,
        odometry_xyt=motion.integrate(x0, controls, dt),
        observations=obs,
        noise=NoiseSpec(
            motion_std=motion_std,
            odometry_std=np.array([0.05, 0.05, 0.02]),
            range_std=range_std,
            bearing_std=bearing_std,
        ),
    )


@pytest.mark.parametrize("world_seed", [0, 1, 2])
@pytest.mark.slow
def test_v2_single_landmark_many_particles_matches_ekf(world_seed):
    """One landmark, 6 steps, 20 000 particles: the FastSLAM 2.0 posterior (moment-matched landmark, weighted
    final pose) equals EKF-SLAM's joint Gaussian to a few % — a check of the proposal (motion noise R from
    ``noise.motion_std``, the simulator's actuation noise), the predictive weights, the landmark
    initialisation ``Σ = H_m⁻¹ Q H_m⁻ᵀ`` and the moment matching together.

    Measured: covariance entries within 0.4-2.5 % (of the largest diagonal), means within 0.07 σ. A proposal
    without the motion noise, weights without ``H_x R H_xᵀ`` or an initial ``Σ = Q`` miss by far more. Both
    filters linearise, so a longer run (or resampling, which starts after ~8 steps here) widens the gap.
    """
    from slamcli.solvers.ekf import EkfParams, EkfSlam

    inputs = _single_landmark_inputs(world_seed)
    e = EkfSlam(EkfParams()).solve(inputs, rng=np.random.default_rng(0))
    r = solve(inputs, seed=world_seed, version=2, n_particles=20000)
    assert r.extra["n_resamples"] == 0

    def rel_cov(ref, got):
        return np.abs(got - ref).max() / np.diag(ref).max()

    def maha(ref_mean, got_mean, ref_cov):
        d = got_mean - ref_mean
        return float(np.sqrt(d @ np.linalg.solve(ref_cov, d)))

    assert rel_cov(e.landmark_cov[0], r.landmark_cov[0]) < 0.05
    assert rel_cov(e.pose_cov[-1], r.pose_cov[-1]) < 0.05
    assert maha(e.landmarks_xy[0], r.landmarks_xy[0], e.landmark_cov[0]) < 0.1
    assert maha(e.poses_xyt[-1], r.poses_xyt[-1], e.pose_cov[-1]) < 0.1


# ------------------------------------------------------------------------------------------------ solver
@pytest.mark.slow
def test_known_association_on_loop_close_to_ekf_and_records_it():
    """``loop`` scenario, sensor-reported ids, 100 particles: landmark RMSE (vs truth, mean over 6 seeds)
    within a factor 2 of EKF-SLAM's on the same data.

    Why not 1.5: after repeated resampling all particles share one early path (path depletion), so the map
    FastSLAM returns behaves like one posterior *sample* of the early trajectory rather than its mean, whose
    expected squared error is twice the MMSE one (ratio ≈ √2). The filter itself matches the EKF where no
    depletion happens (``test_v2_single_landmark_many_particles_matches_ekf``). Measured (fastslam2 session):
    with 100 particles the moment-matched landmark covariance is ~6× too small in σ (landmark NEES 280-490 on
    seed 6, 2-4 with 5000 particles, where the error equals the EKF's posterior σ); mean ratio over 20 seeds
    (benchmarks/bench_fastslam.py) 1.52 / 1.78 / 1.91 with 50 / 100 / 200 particles, and these 6 seeds with 12
    different filter seeds give 0.84-2.09 (100 particles) and 1.02-1.80 (200): the bound cannot be tightened
    without the test hanging on the random stream. These 6 seeds with seed = data seed: 1.79.
    """
    from slamcli.sim import simulate_scenario
    from slamcli.solvers.ekf import EkfParams, EkfSlam

    err_fs, err_ekf, pos_fs, pos_ekf = [], [], [], []
    for seed in range(6):
        d = simulate_scenario("loop", seed=seed, overrides={"sensor.report_ids": True})
        inputs, poses, lms, lab = d.inputs, d.truth.poses_xyt, d.truth.landmarks_xy, d.truth.obs_landmark
        r = solve(inputs, seed=seed, n_particles=100)
        e = EkfSlam(EkfParams()).solve(inputs, rng=np.random.default_rng(seed))
        err_fs.append(landmark_rmse(r.landmarks_xy, r.assoc, lab, lms))
        err_ekf.append(landmark_rmse(e.landmarks_xy, e.assoc, lab, lms))
        pos_fs.append(pose_rmse(r.poses_xyt, poses))
        pos_ekf.append(pose_rmse(e.poses_xyt, poses))
        assert r.status is Status.COMPLETED
        assert r.extra["association"] == "known"
        n_seen = len(np.unique(inputs.observations.reported_id[inputs.observations.reported_id >= 0]))
        assert r.landmarks_xy.shape == (n_seen, 2) and r.landmark_cov.shape == (n_seen, 2, 2)
        assert r.pose_cov.shape == (inputs.n_poses, 3, 3)
        # rows follow the sorted reported ids
        ids = np.unique(inputs.observations.reported_id)
        np.testing.assert_array_equal(ids[r.assoc], inputs.observations.reported_id)
        # moment-matched covariances: symmetric, positive definite, full 3×3 for the pose
        assert np.allclose(r.pose_cov, np.swapaxes(r.pose_cov, 1, 2))
        assert np.all(np.linalg.eigvalsh(r.landmark_cov) > 0)
        assert np.all(np.linalg.eigvalsh(r.pose_cov[50:]) > 0)
        assert np.abs(r.pose_cov[50:, 0, 2]).max() > 0  # x–θ cross terms are kept
        # NIS of the 2.0 predictive innovations ~ χ²(2): mean near 2 (measured 2.3-2.5 on loop)
        assert 1.6 < r.extra["mean_nis"] < 3.2, r.extra["mean_nis"]
    print(f"landmark RMSE FastSLAM {np.mean(err_fs):.4f} m vs EKF {np.mean(err_ekf):.4f} m; pose RMSE "
          f"{np.mean(pos_fs):.4f} vs {np.mean(pos_ekf):.4f}")  # fmt: skip
    assert np.mean(err_fs) < 2.0 * np.mean(err_ekf), (err_fs, err_ekf)
    assert np.mean(pos_fs) < 2.0 * np.mean(pos_ekf), (pos_fs, pos_ekf)


@pytest.mark.slow
def test_fastslam2_needs_fewer_particles_than_1():
    """Accurate sensor, noisy motion: the 1.0 proposal (motion model) is much wider than the likelihood and
    degenerates; 2.0 samples where the measurements point. 2.0 with 5 particles beats 1.0 with 25."""
    err = {}
    for version, P in ((1, 5), (1, 25), (2, 5)):
        e = []
        for seed in range(4):
            inputs, _, lms, lab = make_world(
                100 + seed, T=200, motion_std=(0.3, 0.15), range_std=0.01, bearing_std=0.002
            )
            r = solve(inputs, seed=seed, version=version, n_particles=P)
            e.append(landmark_rmse(r.landmarks_xy, r.assoc, lab, lms))
        err[(version, P)] = float(np.mean(e))
    assert err[(2, 5)] < err[(1, 25)] < err[(1, 5)], err
    assert err[(2, 5)] < 0.5 * err[(1, 5)], err


@pytest.mark.parametrize("version", [1, 2])
@pytest.mark.slow
def test_ml_association_recovers_the_map(version):
    inputs, _, lms, lab = make_world(21, T=250, report_ids=False)
    # This run has one 4.3σ range outlier (row 681): with the default p0 (Mahalanobis² 18.4) it rightly starts
    # a landmark of its own; a p0 at Mahalanobis² 30 keeps the map exact.
    p0 = np.exp(-0.5 * 30.0) / (2 * np.pi * inputs.noise.range_std * inputs.noise.bearing_std)
    r = solve(inputs, seed=2, version=version, association="ml", n_particles=30, p0=p0)
    assert r.extra["association"] == "ml"
    assert len(r.landmarks_xy) == len(lms)
    # every estimated landmark collects the observations of exactly one true landmark, and vice versa
    pairs = {(a, b) for a, b in zip(r.assoc, lab)}
    assert len(pairs) == len(lms)
    assert landmark_rmse(r.landmarks_xy, r.assoc, lab, lms) < 0.1


@pytest.mark.slow
def test_negative_evidence_removes_clutter_landmarks():
    inputs, _, lms, lab = make_world(31, T=250, report_ids=False, clutter_per_step=0.3)
    keep = solve(inputs, seed=4, association="ml", n_particles=20)
    drop = solve(inputs, seed=4, association="ml", n_particles=20, remove_unsupported=True)
    assert len(keep.landmarks_xy) > len(lms) + 10  # clutter starts landmarks...
    assert len(drop.landmarks_xy) < len(lms) + 5  # ...which negative evidence removes
    # all true landmarks survive, near the truth
    d = np.linalg.norm(lms[:, None] - drop.landmarks_xy[None], axis=2).min(axis=1)
    assert d.max() < 0.3
    assert (drop.assoc[lab == -1] == -1).mean() > 0.8  # clutter rows end up unassigned
    assert (drop.assoc[lab >= 0] >= 0).mean() > 0.99


@pytest.mark.slow
def test_same_seed_same_result_and_best_path_output():
    inputs, poses, _, _ = make_world(41, T=80)
    a = solve(inputs, seed=9, n_particles=30)
    b = solve(inputs, seed=9, n_particles=30)
    c = solve(inputs, seed=10, n_particles=30)
    np.testing.assert_array_equal(a.poses_xyt, b.poses_xyt)
    np.testing.assert_array_equal(a.landmarks_xy, b.landmarks_xy)
    assert not np.array_equal(a.poses_xyt, c.poses_xyt)
    best = solve(inputs, seed=9, n_particles=30, output="best")
    np.testing.assert_array_equal(best.poses_xyt[0], inputs.x0)
    np.testing.assert_array_equal(best.landmarks_xy, a.landmarks_xy)  # same draws, only the output differs
    assert not np.array_equal(best.poses_xyt, a.poses_xyt)
    assert pose_rmse(best.poses_xyt, poses) < 0.5


def test_bad_inputs_and_params():
    inputs, *_ = make_world(1, T=20, report_ids=False)
    with pytest.raises(SolverError, match="reported_id"):
        solve(inputs, association="known")
    with pytest.raises(ConfigError, match="version"):
        build_params(FastSlamParams, ["version=3"])
    with pytest.raises(ConfigError, match="n_particles"):
        build_params(FastSlamParams, ["n_particles=0"])
    p = build_params(FastSlamParams, ["version=1", "association=ml", "p0=0.01", "resampling=multinomial"])
    assert p.version == 1 and p.association == "ml" and p.p0 == 0.01


def test_registered_as_fastslam():
    from slamcli.solvers import registry

    assert registry.load("fastslam") is FastSlam


def test_solve_dataset_by_name_with_string_params():
    """The ``--method fastslam -p k=v`` path: registry lookup, string overrides, result contract."""
    from slamcli.api.solve import solve_dataset

    inputs, poses, _, lab = make_world(51, T=60)
    r = solve_dataset(inputs, "fastslam", ["n_particles=20", "version=1", "output=best"], seed=3)
    assert r.solver == "fastslam" and r.status is Status.COMPLETED
    assert r.params["n_particles"] == 20 and r.params["version"] == 1 and r.params["output"] == "best"
    assert r.poses_xyt.shape == poses.shape and r.assoc.shape == lab.shape
    r2 = solve_dataset(inputs, "fastslam", ["n_particles=20", "version=1", "output=best"], seed=3)
    np.testing.assert_array_equal(r.poses_xyt, r2.poses_xyt)
