"""Surface-aware observation model (slamcli.models.observation): a beam hitting a disc landmark of radius ρ.

References: a brute-force march along the beam (the first sample inside the disc, refined by bisection),
central finite differences for every Jacobian, and quadrature for the mean centre offset π/4·ρ."""

import numpy as np
import pytest

from slamcli.models import observation as ob

FD_STEP = 1e-6
FD_TOL = 1e-6
BRUTE_TOL = 1e-9


def _brute_range(x, m, bearing, rho):
    """First point of the beam inside the disc: a coarse march, then bisection on ‖p + t u − m‖ − ρ."""
    p = np.asarray(x[:2], float)
    u = np.array([np.cos(x[2] + bearing), np.sin(x[2] + bearing)])
    f = lambda t: np.linalg.norm(p + t * u - m) - rho
    ts = np.linspace(0.0, 60.0, 600001)
    inside = np.flatnonzero(np.linalg.norm(p + ts[:, None] * u - m, axis=1) <= rho)
    if not inside.size:
        return np.nan
    lo, hi = ts[max(inside[0] - 1, 0)], ts[inside[0]]
    for _ in range(80):
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if f(mid) > 0 else (lo, mid)
    return 0.5 * (lo + hi)


def _cases(rng, n=12):
    """Poses, centres, beam bearings that hit the disc (lateral offset inside ±0.9 ρ), radii."""
    out = []
    for _ in range(n):
        x = np.array([rng.uniform(-5, 5), rng.uniform(-5, 5), rng.uniform(-np.pi, np.pi)])
        rho = rng.uniform(0.05, 0.5)
        d = rng.uniform(2.0, 25.0)
        b_c = rng.uniform(-1.5, 1.5)  # bearing of the centre
        m = x[:2] + d * np.array([np.cos(x[2] + b_c), np.sin(x[2] + b_c)])
        s = rng.uniform(-0.9, 0.9) * rho  # the beam passes the centre at lateral distance s
        b = b_c - np.arcsin(s / d)
        out.append((x, m, b, rho))
    return out


@pytest.mark.slow
def test_surface_range_matches_brute_force_ray_march():
    for x, m, b, rho in _cases(np.random.default_rng(3)):
        assert ob.surface_range(x, m, b, rho) == pytest.approx(_brute_range(x, m, b, rho), abs=BRUTE_TOL)


def test_beam_through_centre_is_distance_minus_radius_and_miss_is_nan():
    x = np.array([1.0, 2.0, 0.3])
    m = x[:2] + 7.0 * np.array([np.cos(0.8), np.sin(0.8)])
    assert ob.surface_range(x, m, 0.5, 0.25) == pytest.approx(7.0 - 0.25, abs=1e-12)
    np.testing.assert_allclose(ob.surface_range_bearing(x, m, 0.25), [6.75, 0.5], atol=1e-12)
    np.testing.assert_allclose(ob.inverse_surface_range_bearing(x, [6.75, 0.5], 0.25), m, atol=1e-12)
    assert np.isnan(ob.surface_range(x, m, 0.5 + 0.2, 0.25))  # 7 m · sin 0.2 ≈ 1.4 m off the centre
    assert ob.surface_centre_offset(x, m, 0.7, 0.25) == 0.0


def test_surface_range_jacobians_match_finite_differences():
    for x, m, b, rho in _cases(np.random.default_rng(5)):
        H_x, H_m, H_rho = ob.surface_range_jacobians(x, m, b, rho)
        for k in range(3):
            e = np.zeros(3)
            e[k] = FD_STEP
            fd = (ob.surface_range(x + e, m, b, rho) - ob.surface_range(x - e, m, b, rho)) / (2 * FD_STEP)
            assert H_x[k] == pytest.approx(fd, rel=FD_TOL, abs=FD_TOL)
        for k in range(2):
            e = np.zeros(2)
            e[k] = FD_STEP
            fd = (ob.surface_range(x, m + e, b, rho) - ob.surface_range(x, m - e, b, rho)) / (2 * FD_STEP)
            assert H_m[k] == pytest.approx(fd, rel=FD_TOL, abs=FD_TOL)
        fd = (ob.surface_range(x, m, b, rho + FD_STEP) - ob.surface_range(x, m, b, rho - FD_STEP)) / (2 * FD_STEP)
        assert H_rho == pytest.approx(fd, rel=FD_TOL, abs=FD_TOL)


def test_vectorised_jacobians_equal_the_one_at_a_time_ones():
    cases = _cases(np.random.default_rng(9), 6)
    X, M, B, P = (np.array([c[i] for c in cases]) for i in range(4))
    H_x, H_m, H_rho = ob.surface_range_jacobians(X, M, B, P)
    for i, (x, m, b, rho) in enumerate(cases):
        hx, hm, hr = ob.surface_range_jacobians(x, m, b, rho)
        np.testing.assert_allclose(H_x[i], hx, atol=1e-14)
        np.testing.assert_allclose(H_m[i], hm, atol=1e-14)
        assert H_rho[i] == pytest.approx(float(hr), abs=1e-14)


def test_offset_plus_range_reaches_the_foot_of_the_centre_and_mean_is_pi_over_4():
    for x, m, b, rho in _cases(np.random.default_rng(11)):
        r = ob.surface_range(x, m, b, rho)
        foot = ob.inverse_range_bearing(x, [r + ob.surface_centre_offset(x, m, b, rho), b])
        u_perp = np.array([-np.sin(x[2] + b), np.cos(x[2] + b)])
        np.testing.assert_allclose(foot, m - (u_perp @ (m - x[:2])) * u_perp, atol=1e-9)
    s = np.linspace(-1.0, 1.0, 200001)  # quadrature of √(1 − s²) over s uniform on [−1, 1]
    assert ob.mean_surface_offset(0.25) == pytest.approx(0.25 * np.trapezoid(np.sqrt(1 - s * s), s) / 2.0, rel=1e-6)
