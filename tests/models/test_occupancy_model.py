"""Grid traversal and the discretised range-sensor model of paper 001 (eqs. 32-34) against brute force."""

import itertools
import math

import numpy as np
import pytest
from scipy.special import ndtr

from slamcli.models.occupancy import (
    GridSpec,
    RaySegments,
    band_for,
    gamma,
    observation_probs,
    rasterise_segments,
    ray_products,
    tail_prob,
    traverse,
)


def _brute_cells(spec, o, a, L, n=20000):
    ts = np.linspace(0, L, n)[1:-1]
    px, py = o[0] + ts * math.cos(a), o[1] + ts * math.sin(a)
    x0, y0 = spec.origin_xy
    H, W = spec.shape
    c = np.floor((px - x0) / spec.resolution).astype(int)
    r = np.floor((py - y0) / spec.resolution).astype(int)
    ok = (c >= 0) & (c < W) & (r >= 0) & (r < H)
    cells = (r * W + c)[ok]
    return [int(cells[0])] + [int(x) for i, x in enumerate(cells[1:]) if x != cells[i]] if len(cells) else []


def test_traverse_matches_dense_sampling():
    rng = np.random.default_rng(1)
    spec = GridSpec((-10.25, -10.25), 0.5, (60, 60))
    o = rng.uniform(-5, 5, (300, 2))
    a = rng.uniform(-math.pi, math.pi, 300)
    a[:4] = [0.0, math.pi / 2, -math.pi, -math.pi / 2]  # axis-aligned rays
    o[4], a[4] = (0.1, 0.1), math.pi / 4  # diagonal through grid corners (a tie of the two line families)
    L = rng.uniform(0.5, 12, 300)
    cell, t_in, t_out = traverse(spec, o, a, L, 12.0)
    for r in range(0, 300, 7):
        assert [int(x) for x in cell[r] if x >= 0] == _brute_cells(spec, o[r], a[r], L[r]), r
    # intervals tile [0, L] along every ray that stays inside the grid
    valid = cell >= 0
    lengths = np.where(valid, t_out - t_in, 0).sum(axis=1)
    inside = np.all(np.abs(o + L[:, None] * np.column_stack([np.cos(a), np.sin(a)])) < 10, axis=1)
    np.testing.assert_allclose(lengths[inside], L[inside], atol=1e-6)


def test_rasterise_walls_on_cell_centres():
    spec = GridSpec((-0.25, -0.25), 0.5, (10, 10))  # cell centres at multiples of 0.5
    occ = rasterise_segments(spec, np.array([[1.0, 1.0, 3.0, 1.0], [1.0, 1.0, 1.0, 2.0]]))
    rows, cols = np.nonzero(occ)
    expect = {(2, c) for c in range(2, 7)} | {(r, 2) for r in range(2, 5)}
    assert set(zip(rows.tolist(), cols.tolist())) == expect


def _gamma_numeric(ak, bk, aj, bj, s, n=40001):
    x = np.linspace(aj, bj, n)
    vals = ndtr((bk - x) / s) - ndtr((ak - x) / s)
    return float(np.trapezoid(vals, x) / (bj - aj))


def test_gamma_and_tail_closed_forms():
    for (ak, bk, aj, bj, s) in [(0.5, 0.9, 0.0, 0.5, 0.2), (0.0, 0.5, 0.0, 0.5, 0.01), (1.0, 1.7, 0.2, 0.9, 0.3),
                                 (0.0, 0.3, 0.5, 0.55, 0.1)]:
        assert float(gamma(ak, bk, aj, bj, s)) == pytest.approx(_gamma_numeric(ak, bk, aj, bj, s), abs=1e-6)
        x = np.linspace(aj, bj, 4001)
        q = float(np.trapezoid(ndtr((x - ak) / s), x) / (bj - aj))
        assert float(tail_prob(ak, aj, bj, s)) == pytest.approx(q, abs=1e-6)


def _enumerate(P, a, b, s):
    """Brute force over the 2^4 cell states: P(q̂_k = O | q_k), P(reached k | q_k) for every k."""
    n = len(P)
    G = np.array([[_gamma_numeric(a[k], b[k], a[j], b[j], s) for j in range(n)] for k in range(n)])
    Q = np.array([[float(np.trapezoid(ndtr((np.linspace(a[j], b[j], 4001) - a[k]) / s), np.linspace(a[j], b[j], 4001))
                         / (b[j] - a[j])) for j in range(n)] for k in range(n)])
    out = np.zeros((n, 2, 2))  # [k, state of k (O=0, E=1), (P(q̂=O, ·), P(observed, ·))]
    for states in itertools.product((1, 0), repeat=n):
        for k in range(n):
            pr = np.prod([P[i] if states[i] else 1 - P[i] for i in range(n) if i != k])
            first = next((j for j in range(n) if states[j]), None)
            hat_o = 0.0 if first is None else G[k, first]
            reached = 1.0 if first is None else Q[k, first]
            out[k, 1 - states[k]] += pr * np.array([hat_o, reached])
    return out


@pytest.mark.parametrize("sigma", [0.2, 0.05])
def test_eqs_33_34_against_enumeration_on_a_4_cell_ray(sigma):
    P = np.array([0.3, 0.6, 0.2, 0.7])
    a = np.array([0.0, 0.5, 0.8, 1.5])
    b = np.array([0.5, 0.8, 1.5, 2.0])
    rs = RaySegments(np.zeros(4, np.int64), np.arange(4), a, b, np.zeros(4, np.int64), 1)
    brute = _enumerate(P, a, b, sigma)
    sig = np.full(4, sigma)
    a_oo, a_oe = observation_probs(P, rs, sig, band=3, conditional=False)
    np.testing.assert_allclose(a_oo, brute[:, 0, 0], atol=1e-6)  # eq. (33)
    np.testing.assert_allclose(a_oe, brute[:, 1, 0], atol=1e-6)  # eq. (34)
    c_oo, c_oe = observation_probs(P, rs, sig, band=3, conditional=True)
    np.testing.assert_allclose(c_oo, brute[:, 0, 0] / brute[:, 0, 1], atol=1e-6)
    np.testing.assert_allclose(c_oe, brute[:, 1, 0] / brute[:, 1, 1], atol=1e-6)


def test_ray_products_and_band():
    P = np.array([0.5, 0.2, 0.9, 0.1, 0.3])
    rs = RaySegments(np.array([0, 0, 0, 1, 1]), np.arange(5), np.zeros(5), np.ones(5), np.array([0, 0, 0, 3, 3]), 2)
    U, pi, miss = ray_products(P, rs)
    np.testing.assert_allclose(U, [1, 0.5, 0.4, 1, 0.9])
    np.testing.assert_allclose(pi, [0.5, 0.1, 0.36, 0.1, 0.27])
    np.testing.assert_allclose(miss, [0.04, 0.63])
    assert band_for(0.2, 0.5) == 6 and band_for(0.01, 0.5) == 2
