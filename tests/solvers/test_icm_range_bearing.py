"""ICM's range-bearing observation potential under the Cauchy kernel (``observation=range_bearing``, preset=real
with sensor ids): its energy against an independently written one, the polish's kernel scale and gradient
against that energy and finite differences, and the optimum a solve stops at against scipy's
``least_squares`` on the independent energy.

scipy's ``loss="cauchy"`` (``ρ(z) = ln(1 + z)``, ``z = f²/C²``, cost ``½ Σ C² ρ``) acts on each scalar residual,
whereas the potential's kernel acts on the whitened 2-vector of a sighting (``k² log(1 + s²/k²)``, s² the sum of
both squared components). The reference therefore passes one scalar residual per sighting,
``f = √(k² log(1 + s²/k²))``, with the linear loss: ``½ Σ f²`` is half the potential, as ``½ Σ (w e)²`` is half
the odometry potential.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from conftest import tiny_dataset
from scipy.optimize import least_squares

from slamcli.errors import ConfigError
from slamcli.models import potentials
from slamcli.solvers import nls
from slamcli.solvers.icm import IcmSlam
from slamcli.solvers.icm import energy as en
from slamcli.solvers.icm import polish as pl
from slamcli.solvers.icm.common import reported_labels
from slamcli.solvers.icm.params import IcmParams

CAUCHY_K = 2.3849  # graph's default scale, the preset's cauchy_k
SUM_RTOL = 1e-10  # two evaluations of one sum in a different order
FD_STEP = 1e-6  # central differences
FD_GRAD_RTOL = 1e-5  # relative to the gradient's largest component
FD_JAC_ATOL = 1e-6
OPT_ENERGY_RTOL = 1e-6  # the optimum's energy, ICM against scipy
OPT_POSE_ATOL_M = 1e-3  # and its poses / map points
MISREAD_M = 1.5  # added to a few ranges: 30 σ_r, far beyond the noise


def _world(seed: int = 0, n_bad: int = 3):
    """tiny_dataset with sensor ids, ``n_bad`` id'd ranges misread by :data:`MISREAD_M`."""
    inp = tiny_dataset(T=60, seed=seed, report_ids=True).inputs
    obs = inp.observations
    bad = np.random.default_rng(seed).choice(np.flatnonzero(obs.reported_id >= 0), n_bad, replace=False)
    r = obs.range_m.copy()
    r[bad] += MISREAD_M
    return dataclasses.replace(inp, observations=dataclasses.replace(obs, range_m=r))


def _wrap(a):
    return (np.asarray(a) + np.pi) % (2.0 * np.pi) - np.pi


def _body_increments(a, b):
    """``[R(θ_a)ᵀ (p_b − p_a), wrap(θ_b − θ_a)]`` row by row."""
    d = b[:, :2] - a[:, :2]
    c, s = np.cos(a[:, 2]), np.sin(a[:, 2])
    return np.column_stack([c * d[:, 0] + s * d[:, 1], -s * d[:, 0] + c * d[:, 1], _wrap(b[:, 2] - a[:, 2])])


def _reference_residuals(inp, poses, landmarks, labels):
    """Independent residuals: the odometry's, whitened by its σ (an (T, 3) array), and the squared whitened
    range-bearing error ``s² (n,)`` of every sighting with a label."""
    od = inp.odometry_xyt
    e = _body_increments(poses[:-1], poses[1:]) - _body_increments(od[:-1], od[1:])
    e[:, 2] = _wrap(e[:, 2])
    obs, ok = inp.observations, labels >= 0
    x, m = poses[obs.step[ok]], landmarks[labels[ok]]
    dx, dy = m[:, 0] - x[:, 0], m[:, 1] - x[:, 1]
    er = np.hypot(dx, dy) - obs.range_m[ok]
    eb = _wrap(np.arctan2(dy, dx) - x[:, 2] - obs.bearing_rad[ok])
    s2 = (er / inp.noise.range_std) ** 2 + (eb / inp.noise.bearing_std) ** 2
    return e / np.asarray(inp.noise.odometry_std, float), s2


def _reference_energy(inp, poses, landmarks, labels) -> float:
    w_odo, s2 = _reference_residuals(inp, poses, landmarks, labels)
    return float(np.sum(w_odo**2) + np.sum(CAUCHY_K**2 * np.log1p(s2 / CAUCHY_K**2)))


def _setup(inp):
    p = IcmParams.resolve({"preset": "real"}, inp)
    W = p.weights_for(inp)
    prob = en.Problem.from_inputs(inp)
    return p, W, prob, reported_labels(inp.observations.reported_id)


def _perturbed_state(inp, seed: int = 3):
    """The true poses and landmarks, each moved by a few cm / mrad (x_0 kept)."""
    truth = tiny_dataset(T=60, seed=0, report_ids=True).truth
    rng = np.random.default_rng(seed)
    poses = truth.poses_xyt + rng.normal(0.0, [0.05, 0.05, 0.01], truth.poses_xyt.shape)
    poses[0] = inp.x0
    return poses, truth.landmarks_xy + rng.normal(0.0, 0.05, truth.landmarks_xy.shape)


def test_preset_real_with_ids_resolves_graphs_energy():
    inp = _world()
    p, W, _, _ = _setup(inp)
    assert (p.observation, p.odometry_only, p.cauchy_k) == ("range_bearing", True, CAUCHY_K)
    assert W.range_bearing and W.R == (0.0, 0.0, 0.0) and W.obs_sigma == (inp.noise.range_std, inp.noise.bearing_std)
    assert IcmParams().observation == "cartesian" and not IcmParams().odometry_only  # paper: unchanged


def test_energy_matches_an_independent_evaluation():
    inp = _world()
    _, W, prob, labels = _setup(inp)
    poses, lm = _perturbed_state(inp)
    H = en.energy(prob, W, poses, lm, labels)
    assert H == pytest.approx(_reference_energy(inp, poses, lm, labels), rel=SUM_RTOL)
    # the polish's least-squares cost (the engine's ½ k'² log(1 + s'²/k'²) on √2-whitened residuals) is H
    problem = pl.nls_problem(prob, W, lm.shape[0], labels)
    x = np.concatenate([poses.ravel(), lm.ravel()])
    assert nls.evaluate_cost(problem, x, pl._nls_params(W, 1)) == pytest.approx(H, rel=SUM_RTOL)


def test_range_bearing_jacobians_by_finite_differences():
    rng = np.random.default_rng(1)
    x = rng.normal(0.0, 1.0, (5, 3))
    m = x[:, :2] + rng.uniform(1.0, 4.0, (5, 2))
    z = rng.normal(0.0, 1.0, (5, 2))
    Jx, Jm = potentials.range_bearing_residual_jacobians(x, m)
    for J, which in ((Jx, 0), (Jm, 1)):
        base = (x, m)[which]
        for c in range(base.shape[1]):
            d = np.zeros_like(base)
            d[:, c] = FD_STEP
            args_p = (x + d, m) if which == 0 else (x, m + d)
            args_m = (x - d, m) if which == 0 else (x, m - d)
            num = (potentials.range_bearing_residual(args_p[0], z, args_p[1])
                   - potentials.range_bearing_residual(args_m[0], z, args_m[1])) / (2 * FD_STEP)
            np.testing.assert_allclose(J[:, :, c], num, atol=FD_JAC_ATOL)


def test_gradient_of_the_energy_by_finite_differences():
    """``optimality``'s gradient (IRLS rows of the polish's problem) is ∇H: central differences of the
    independent energy over every free pose and map coordinate."""
    inp = _world()
    _, W, prob, labels = _setup(inp)
    poses, lm = _perturbed_state(inp)
    r, J = pl._irls_system(prob, W, poses, lm, labels)
    g = 2.0 * (J.T @ r)
    x0 = np.concatenate([poses.ravel(), lm.ravel()])
    free = np.setdiff1d(np.arange(x0.size), pl.nls_problem(prob, W, lm.shape[0], labels).fixed_cols)
    P = poses.size

    def H(x):
        return _reference_energy(inp, x[:P].reshape(-1, 3), x[P:].reshape(-1, 2), labels)

    num = np.empty(free.size)
    for i, c in enumerate(free):
        d = np.zeros_like(x0)
        d[c] = FD_STEP
        num[i] = (H(x0 + d) - H(x0 - d)) / (2 * FD_STEP)
    np.testing.assert_allclose(g, num, atol=FD_GRAD_RTOL * np.abs(num).max())


@pytest.mark.parametrize("seed", [0, 1])
def test_preset_real_stops_at_scipys_optimum_of_the_independent_energy(seed):
    """preset=real with ids ends ``converged``; scipy's least_squares on the independent energy, started from
    ICM's estimate, finds no lower point: the same energy (1e-6 relative) and the same poses and map (1 mm)."""
    inp = _world(seed)
    _, _, _, labels = _setup(inp)
    res = IcmSlam(IcmParams.resolve({"preset": "real"}, inp)).solve(inp, rng=np.random.default_rng(0))
    assert res.status.value == "converged"
    assert res.extra["energy_increases"] == 0 and res.extra["outlier_gate"] == "off"
    poses, lm = np.asarray(res.poses_xyt), np.asarray(res.landmarks_xy)
    H_icm = _reference_energy(inp, poses, lm, labels)
    assert res.trace.objective[-1] == pytest.approx(H_icm, rel=SUM_RTOL)  # the recorded energy is this one
    P = poses.size - 3

    def unpack(v):
        return np.vstack([inp.x0, v[:P].reshape(-1, 3)]), v[P:].reshape(-1, 2)

    def f(v):
        w_odo, s2 = _reference_residuals(inp, *unpack(v), labels)
        return np.concatenate([w_odo.ravel(), np.sqrt(CAUCHY_K**2 * np.log1p(s2 / CAUCHY_K**2))])

    sol = least_squares(f, np.concatenate([poses[1:].ravel(), lm.ravel()]), method="trf", jac="3-point",
                        ftol=1e-15, xtol=1e-15, gtol=1e-15, max_nfev=200)
    ref_poses, ref_lm = unpack(sol.x)
    H_ref = 2.0 * sol.cost
    assert H_ref <= H_icm * (1 + 1e-12)  # scipy only goes down
    assert H_icm == pytest.approx(H_ref, rel=OPT_ENERGY_RTOL)
    assert np.abs(poses[:, :2] - ref_poses[:, :2]).max() < OPT_POSE_ATOL_M
    assert np.abs(lm - ref_lm).max() < OPT_POSE_ATOL_M


def test_range_bearing_refuses_what_it_does_not_support():
    inp = _world()
    for given in ({"correspondences": "nearest"}, {"polish": "none"}, {"covariance": True}):
        p = IcmParams.resolve({"preset": "real", "observation": "range_bearing", **given}, inp)
        with pytest.raises(ConfigError, match=f"observation=range_bearing needs .*got {next(iter(given))}="):
            IcmSlam(p).solve(inp, rng=np.random.default_rng(0))
    with pytest.raises(ValueError, match="observation must be"):
        IcmParams(observation="polar")


def test_preset_leaves_range_bearing_unset_when_given_what_it_cannot_run_with():
    """preset=real's data rule sets observation=range_bearing and odometry_only only when the given values allow
    it; otherwise both keep their defaults and the resolve note says why (a given polish=nls changes nothing)."""
    inp = _world()
    for given in ({"correspondences": "nearest"}, {"polish": "none"}, {"covariance": True}):
        q = IcmParams.resolve({"preset": "real", **given}, inp)
        assert (q.observation, q.odometry_only) == ("cartesian", False)
        note = IcmParams.resolve_note({"preset": "real", **given}, inp)
        assert note.startswith("preset=real: observation=range_bearing, odometry_only=true not applied")
        assert next(iter(given)) in note
    assert IcmParams.resolve({"preset": "real", "polish": "nls"}, inp).observation == "range_bearing"
    assert IcmParams.resolve_note({"preset": "real"}, inp) == ""
