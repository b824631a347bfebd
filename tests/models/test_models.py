"""Shared models: Jacobians against central finite differences, wrap edge cases, inverse ∘ forward."""

from decimal import Decimal, localcontext

import numpy as np
import pytest

from slamcli.models import motion, observation, potentials, se2
from slamcli.models.angles import angle_diff, circular_mean, wrap_angle, wrap_pose_error

RNG = np.random.default_rng(12345)
DT = 0.1


def numeric_jacobian(f, x, eps=1e-6, wrap_rows=()):
    """Central differences of f at x; rows in ``wrap_rows`` are angle outputs (differences wrapped)."""
    x = np.asarray(x, float)
    f0 = np.asarray(f(x), float)
    J = np.zeros((f0.size, x.size))
    for k in range(x.size):
        d = np.zeros_like(x)
        d[k] = eps
        df = np.asarray(f(x + d), float) - np.asarray(f(x - d), float)
        for r in wrap_rows:
            df[r] = wrap_angle(df[r])
        J[:, k] = df / (2 * eps)
    return J


def random_pose():
    return np.array([RNG.uniform(-5, 5), RNG.uniform(-5, 5), RNG.uniform(-np.pi, np.pi)])


# ---------------------------------------------------------------- angles
@pytest.mark.parametrize(
    "a, expected",
    [
        (0.0, 0.0),
        (np.pi, -np.pi),  # half-open interval [-pi, pi)
        (-np.pi, -np.pi),
        (3 * np.pi, -np.pi),
        (2 * np.pi, 0.0),
        (-2 * np.pi, 0.0),
        (np.pi / 2 + 4 * np.pi, np.pi / 2),
        (-3 * np.pi / 2, np.pi / 2),
        (1e-17, 1e-17),
    ],
)
def test_wrap_angle_edge_cases(a, expected):
    assert wrap_angle(a) == pytest.approx(expected, abs=1e-12)


def test_wrap_angle_range_and_vectorised():
    a = RNG.uniform(-100, 100, 10_000)
    w = wrap_angle(a)
    assert w.shape == a.shape
    assert np.all(w >= -np.pi) and np.all(w < np.pi)
    # wrapping preserves the angle on the circle
    np.testing.assert_allclose(np.cos(w), np.cos(a), atol=1e-9)
    np.testing.assert_allclose(np.sin(w), np.sin(a), atol=1e-9)
    # nextafter(pi) just below pi stays, just above goes to -pi side
    assert wrap_angle(np.nextafter(np.pi, 0)) < np.pi
    assert wrap_angle(np.nextafter(np.pi, 4)) < -np.pi + 1e-12


def test_angle_diff_across_the_cut():
    assert angle_diff(np.pi - 0.1, -np.pi + 0.1) == pytest.approx(-0.2)
    assert angle_diff(-np.pi + 0.1, np.pi - 0.1) == pytest.approx(0.2)
    e = wrap_pose_error(np.array([[1.0, 2.0, 2 * np.pi + 0.5]]))
    np.testing.assert_allclose(e, [[1.0, 2.0, 0.5]])


def test_circular_mean_across_the_cut():
    assert abs(angle_diff(circular_mean([np.pi - 0.1, -np.pi + 0.1]), np.pi)) < 1e-12
    assert circular_mean([0.1, 0.3], weights=[3, 1]) == pytest.approx(np.arctan2(3 * np.sin(0.1) + np.sin(0.3), 3 * np.cos(0.1) + np.cos(0.3)))


# ---------------------------------------------------------------- SE(2)
def test_se2_compose_inverse_between_identities():
    for _ in range(50):
        a, b = random_pose(), random_pose()
        np.testing.assert_allclose(se2.compose(a, se2.inverse(a)), [0, 0, 0], atol=1e-12)
        np.testing.assert_allclose(wrap_pose_error(se2.compose(a, se2.between(a, b)) - b), 0, atol=1e-12)
        # between's translation is tau(theta_a)(p_b - p_a) of paper eq. (16)
        tau = np.array([[np.cos(a[2]), np.sin(a[2])], [-np.sin(a[2]), np.cos(a[2])]])
        np.testing.assert_allclose(se2.between(a, b)[:2], tau @ (b[:2] - a[:2]), atol=1e-12)


def test_se2_exp_log_round_trip_and_small_angle():
    for _ in range(50):
        xi = np.array([RNG.normal(), RNG.normal(), RNG.uniform(-3, 3)])
        np.testing.assert_allclose(se2.log(se2.exp(xi)), xi, atol=1e-10)
    xi = np.array([0.3, -0.2, 1e-9])
    np.testing.assert_allclose(se2.exp(xi), [0.3, -0.2, 1e-9], atol=1e-9)
    # pure rotation then translation along the arc: exp([v,0,w]) is the arc end point
    p = se2.exp(np.array([np.pi / 2, 0.0, np.pi / 2]))
    np.testing.assert_allclose(p, [1.0, 1.0, np.pi / 2], atol=1e-12)


def test_between_jacobians_match_finite_differences():
    for _ in range(20):
        a, b = random_pose(), random_pose()
        J_a, J_b = se2.between_jacobians(a, b)
        np.testing.assert_allclose(J_a, numeric_jacobian(lambda x: se2.between(x, b), a, wrap_rows=(2,)), atol=1e-7)
        np.testing.assert_allclose(J_b, numeric_jacobian(lambda x: se2.between(a, x), b, wrap_rows=(2,)), atol=1e-7)


def _sin_cos_60(w: float):
    """``sin w, cos w`` to 60 digits by their power series in :mod:`decimal` (the exact binary ``w``): the
    independent reference of the SE(2) terms below, free of the float cancellations near ``w = 0``."""
    with localcontext() as ctx:
        ctx.prec = 60
        x = Decimal(w)
        s = c = Decimal(0)
        term, k = Decimal(1), 0  # x^k / k!
        while k < 80:
            if k % 4 == 0:
                c += term
            elif k % 4 == 1:
                s += term
            elif k % 4 == 2:
                c -= term
            else:
                s -= term
            k += 1
            term = term * x / k
        return s, c


def _se2_terms_reference(w: float):
    """``(A, B, α, α')`` of :func:`se2._sinc_terms` / :func:`se2.log_terms` at ``w`` from :func:`_sin_cos_60`
    (their limits 1, 0, 1, 0 at ``w = 0``)."""
    if w == 0.0:
        return 1.0, 0.0, 1.0, 0.0
    s, c = _sin_cos_60(w)
    sh, ch = _sin_cos_60(w / 2)  # w/2 is exact in binary
    with localcontext() as ctx:
        ctx.prec = 60
        x, h = Decimal(w), Decimal(w) / 2
        cot = ch / sh
        return float(s / x), float((1 - c) / x), float(h * cot), float(cot / 2 - h / (2 * sh * sh))


SE2_ANGLES = np.concatenate([[0.0, 1e-9, 5e-7, 9.99e-7, 1.001e-6, 3e-5, 9.99e-5, 1.001e-4, 1e-3, 0.3, 1.0, 2.5, 3.1]])
SE2_ANGLES = np.concatenate([SE2_ANGLES, -SE2_ANGLES[1:]])


def test_se2_series_terms_against_60_digit_reference():
    """``A = sin w / w``, ``B = (1 − cos w)/w``, ``α = (w/2) cot(w/2)``, ``α'`` on both sides of their series
    thresholds (1e-6, 1e-4), against :func:`_se2_terms_reference`. The tolerances are the float closed forms'
    cancellation just above a threshold (``B``: 1 − cos w ≈ 5e-13 at 1e-6; ``α'``: two terms ≈ 1e4 at 1e-4)."""
    ref = np.array([_se2_terms_reference(float(w)) for w in SE2_ANGLES])
    A, B = se2._sinc_terms(SE2_ANGLES)
    alpha, dalpha = se2.log_terms(SE2_ANGLES)
    np.testing.assert_allclose(A, ref[:, 0], rtol=1e-15, atol=0)
    np.testing.assert_allclose(B, ref[:, 1], rtol=1e-12, atol=1e-10)
    np.testing.assert_allclose(alpha, ref[:, 2], rtol=1e-15, atol=0)
    np.testing.assert_allclose(dalpha, ref[:, 3], rtol=1e-12, atol=5e-12)


def test_se2_series_terms_keep_the_input_shape():
    """A 0-d angle gives 0-d terms equal to the same angle's entry of a vector call; a 2-d one keeps its shape."""
    for f in (se2._sinc_terms, se2.log_terms):
        vec = f(SE2_ANGLES)
        for i, w in enumerate(SE2_ANGLES):
            for v, s in zip(vec, f(w)):
                assert np.shape(s) == () and s == v[i]
        grid = f(SE2_ANGLES[1:].reshape(4, -1))
        for v, g in zip(vec, grid):
            assert g.shape == (4, 6) and np.array_equal(g.ravel(), v[1:])


# ---------------------------------------------------------------- motion
def test_ddmr_step_hand_computed():
    x = np.array([1.0, 2.0, np.pi / 2])
    u = np.array([2.0, 0.5])
    np.testing.assert_allclose(motion.ddmr_step(x, u, DT), [1.0, 2.2, np.pi / 2 + 0.05], atol=1e-12)


def test_ddmr_jacobians_match_finite_differences():
    for _ in range(20):
        x = random_pose()
        u = np.array([RNG.uniform(-1, 2), RNG.uniform(-1, 1)])
        G_x, G_u = motion.ddmr_jacobians(x, u, DT)
        np.testing.assert_allclose(G_x, numeric_jacobian(lambda s: motion.ddmr_step(s, u, DT), x, wrap_rows=(2,)), atol=1e-8)
        np.testing.assert_allclose(G_u, numeric_jacobian(lambda c: motion.ddmr_step(x, c, DT), u, wrap_rows=(2,)), atol=1e-8)


def test_ddmr_vectorised_equals_loop():
    X = np.stack([random_pose() for _ in range(7)])
    U = RNG.normal(size=(7, 2))
    batch = motion.ddmr_step(X, U, DT)
    for k in range(7):
        np.testing.assert_allclose(batch[k], motion.ddmr_step(X[k], U[k], DT), atol=1e-15)
    Gx, Gu = motion.ddmr_jacobians(X, U, DT)
    assert Gx.shape == (7, 3, 3) and Gu.shape == (7, 3, 2)


def test_integrate_and_increments_round_trip():
    controls = np.column_stack([RNG.uniform(0.2, 1.0, 200), RNG.uniform(-0.5, 0.5, 200)])
    x0 = np.array([0.5, -1.0, 3.0])
    poses = motion.integrate(x0, controls, DT)
    assert poses.shape == (201, 3)
    np.testing.assert_allclose(poses[1], motion.ddmr_step(x0, controls[0], DT))
    inc = motion.odometry_increments(poses)
    assert inc.shape == (200, 3)
    rebuilt = motion.chain_increments(x0, inc)
    np.testing.assert_allclose(wrap_pose_error(rebuilt - poses), 0, atol=1e-9)
    # the increment is frame independent: a rigid motion of the whole path leaves it unchanged
    moved = se2.compose(np.array([3.0, -2.0, 1.1]), poses)
    np.testing.assert_allclose(wrap_pose_error(motion.odometry_increments(moved) - inc), 0, atol=1e-10)


# ---------------------------------------------------------------- observation
def test_range_bearing_hand_computed():
    x = np.array([1.0, 1.0, np.pi / 2])
    np.testing.assert_allclose(observation.range_bearing(x, [1.0, 3.0]), [2.0, 0.0], atol=1e-12)
    np.testing.assert_allclose(observation.range_bearing(x, [0.0, 1.0]), [1.0, np.pi / 2], atol=1e-12)
    np.testing.assert_allclose(observation.range_bearing(x, [2.0, 1.0]), [1.0, -np.pi / 2], atol=1e-12)


def test_inverse_after_forward_is_identity_and_vice_versa():
    for _ in range(50):
        x = random_pose()
        m = RNG.uniform(-10, 10, 2)
        z = observation.range_bearing(x, m)
        np.testing.assert_allclose(observation.inverse_range_bearing(x, z), m, atol=1e-10)
        z2 = np.array([RNG.uniform(0.1, 20), RNG.uniform(-np.pi, np.pi)])
        np.testing.assert_allclose(
            observation.measurement_residual(observation.range_bearing(x, observation.inverse_range_bearing(x, z2)), z2),
            0,
            atol=1e-10,
        )


def test_observation_jacobians_match_finite_differences():
    for _ in range(20):
        x = random_pose()
        m = x[:2] + RNG.uniform(1, 8, 2) * RNG.choice([-1, 1], 2)
        H_x, H_m = observation.range_bearing_jacobians(x, m)
        np.testing.assert_allclose(H_x, numeric_jacobian(lambda s: observation.range_bearing(s, m), x, wrap_rows=(1,)), atol=1e-7)
        np.testing.assert_allclose(H_m, numeric_jacobian(lambda q: observation.range_bearing(x, q), m, wrap_rows=(1,)), atol=1e-7)
        z = observation.range_bearing(x, m)
        M_x, M_z = observation.inverse_range_bearing_jacobians(x, z)
        np.testing.assert_allclose(M_x, numeric_jacobian(lambda s: observation.inverse_range_bearing(s, z), x), atol=1e-7)
        np.testing.assert_allclose(M_z, numeric_jacobian(lambda q: observation.inverse_range_bearing(x, q), z), atol=1e-7)


def test_paper_bearing_convention():
    # paper 000: 0 = robot's right side, pi = its left side; slamcli: 0 = straight ahead
    assert observation.to_paper_bearing(0.0) == pytest.approx(np.pi / 2)
    assert observation.to_paper_bearing(-np.pi / 2) == pytest.approx(0.0)
    assert observation.from_paper_bearing(observation.to_paper_bearing(0.7)) == pytest.approx(0.7)
    # the paper's inverse model m = p + d [cos(b_p + theta - pi/2), sin(...)] equals ours
    x = np.array([1.0, -2.0, 0.4])
    r, b = 3.0, 0.3
    bp = observation.to_paper_bearing(b)
    paper = x[:2] + r * np.array([np.cos(bp + x[2] - np.pi / 2), np.sin(bp + x[2] - np.pi / 2)])
    np.testing.assert_allclose(observation.inverse_range_bearing(x, [r, b]), paper, atol=1e-12)


# ---------------------------------------------------------------- ICM potentials
def test_potential_jacobians_match_finite_differences():
    for _ in range(10):
        xp, x = random_pose(), random_pose()
        u = RNG.normal(size=2)
        A, B = potentials.motion_residual_jacobians(xp, u, x, DT)
        np.testing.assert_allclose(A, numeric_jacobian(lambda s: potentials.motion_residual(s, u, x, DT), xp, wrap_rows=(2,)), atol=1e-7)
        np.testing.assert_allclose(B, numeric_jacobian(lambda s: potentials.motion_residual(xp, u, s, DT), x, wrap_rows=(2,)), atol=1e-7)
        op, o = random_pose(), random_pose()
        A, B = potentials.odometry_residual_jacobians(xp, x)
        np.testing.assert_allclose(A, numeric_jacobian(lambda s: potentials.odometry_residual(s, x, op, o), xp, wrap_rows=(2,)), atol=1e-7)
        np.testing.assert_allclose(B, numeric_jacobian(lambda s: potentials.odometry_residual(xp, s, op, o), x, wrap_rows=(2,)), atol=1e-7)
        z = np.array([RNG.uniform(1, 10), RNG.uniform(-3, 3)])
        m = RNG.normal(size=2)
        Mx, Mm = potentials.observation_residual_jacobians(x, z)
        np.testing.assert_allclose(Mx, numeric_jacobian(lambda s: potentials.observation_residual(s, z, m), x), atol=1e-7)
        np.testing.assert_allclose(Mm, numeric_jacobian(lambda q: potentials.observation_residual(x, z, q), m), atol=1e-7)


def test_potentials_vanish_on_consistent_data():
    controls = np.column_stack([np.full(30, 0.8), np.linspace(-0.3, 0.3, 30)])
    poses = motion.integrate(np.zeros(3), controls, DT)
    np.testing.assert_allclose(potentials.motion_residual(poses[:-1], controls, poses[1:], DT), 0, atol=1e-12)
    np.testing.assert_allclose(potentials.odometry_residual(poses[:-1], poses[1:], poses[:-1], poses[1:]), 0, atol=1e-12)
    m = np.array([4.0, 1.0])
    z = observation.range_bearing(poses, m)
    np.testing.assert_allclose(potentials.observation_residual(poses, z, m), 0, atol=1e-10)
    r = np.array([[1.0, 2.0]])
    assert potentials.weighted_sq(r, np.diag([2.0, 3.0])) == pytest.approx(2 * 1 + 3 * 4)
