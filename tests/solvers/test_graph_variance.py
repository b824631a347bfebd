"""Self-calibrating noise of the graph (slamcli.solvers.graph.calibrate_noise) on a simulation with known σ.

The simulator draws odometry increments with ``N(0, diag(odometry.std²))`` and sightings with ``range_std`` /
``bearing_std``; the solver is told a NoiseSpec wrong by factors 0.3-3 per group. Iterated VCE from that wrong
start (the sensor's reported ids as the association, every pose) must recover the simulator's σ within
sampling error: the σ estimate's relative standard deviation is ``1/√(2ρ_g)`` (χ²_ρ), the test allows 4 of
them (seeded; here 1.3-15 %).
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from slamcli.sim import simulate_scenario
from slamcli.solvers.graph import (
    NOISE_GROUPS,
    GraphParams,
    GraphSlam,
    calibrate_noise,
    noise_row_groups,
    noise_sigmas,
    noise_with_sigmas,
)

TRUE_SIGMA = np.array([0.01, 0.004, 0.003, 0.08, 0.02])  # odometry x, lateral, heading; range, bearing
WRONG = np.array([2.0, 0.5, 0.3, 3.0, 0.5])  # the told σ / the true σ


@pytest.fixture(scope="module")
def told_wrong():
    ds = simulate_scenario("loop", seed=3, overrides={
        "n_steps": 1000, "sensor.report_ids": True, "odometry.std": TRUE_SIGMA[:3].tolist(),
        "sensor.range_std": float(TRUE_SIGMA[3]), "sensor.bearing_std": float(TRUE_SIGMA[4])})
    np.testing.assert_allclose(noise_sigmas(ds.inputs.noise), TRUE_SIGMA)  # the simulator's own NoiseSpec
    return dataclasses.replace(ds.inputs, noise=noise_with_sigmas(ds.inputs.noise, TRUE_SIGMA * WRONG))


@pytest.mark.slow
def test_iterated_vce_recovers_the_simulators_sigmas(told_wrong):
    inp = told_wrong
    g = GraphSlam(GraphParams(association="reported", robust="none", covariance=False)).solve(
        inp, rng=np.random.default_rng(0))
    cal = calibrate_noise(inp, g.assoc, g.poses_xyt, g.landmarks_xy, tol=1e-3, max_reweights=60)
    assert cal.vce.converged
    red = cal.vce.rounds[-1].components.redundancy
    rel_sd = 1.0 / np.sqrt(2.0 * red)
    err = cal.sigma / TRUE_SIGMA - 1.0
    assert np.all(np.abs(err) < 4 * rel_sd), dict(zip(NOISE_GROUPS, err / rel_sd))
    # the returned optimum is the last round's, under the σ reported
    np.testing.assert_allclose(noise_sigmas(cal.noise), cal.sigma)
    assert cal.vce.rounds[0].scale.tolist() == [1.0] * 5


def test_row_groups_follow_the_blocks(told_wrong):
    from slamcli.solvers.graph import build_gtsam_problem

    inp = told_wrong
    g = GraphSlam(GraphParams(association="reported", robust="none", covariance=False)).solve(
        inp, rng=np.random.default_rng(0))
    gp = build_gtsam_problem(inp, g.assoc, g.poses_xyt, g.landmarks_xy, GraphParams(robust="none", use_gps=False))
    grp = noise_row_groups(gp.problem)
    names = [b.name for b in gp.problem.blocks]
    assert names[:2] == ["prior", "odometry"]
    sizes = [b.n_factors * np.shape(b.sqrt_info)[-1] for b in gp.problem.blocks]
    assert grp.size == sum(sizes)
    assert np.all(grp[:3] == -1)
    assert np.array_equal(np.bincount(grp[grp >= 0], minlength=5),
                          [inp.n_poses - 1] * 3 + [gp.problem.blocks[2].n_factors] * 2)


def test_vce_rounds_evaluate_every_factor_block_once(told_wrong):
    """A VCE round's Jacobian and residuals (``nls.whitened_system``) come from one ``evaluate`` of every block
    and no residual-only pass; the residuals equal that pass (``nls.residual_vector``) and the Jacobian central
    differences of it (a few columns)."""
    from slamcli.solvers import nls
    from slamcli.solvers.graph import build_gtsam_problem

    inp = told_wrong
    g = GraphSlam(GraphParams(association="reported", robust="none", covariance=False)).solve(
        inp, rng=np.random.default_rng(0))
    gp = build_gtsam_problem(inp, g.assoc, g.poses_xyt, g.landmarks_xy, GraphParams(robust="none", use_gps=False))
    x = gp.x0
    calls = {"evaluate": 0, "residual": 0}

    def counted(fn, kind):
        def wrapped(v):
            calls[kind] += 1
            return fn(v)
        return wrapped

    blocks = [dataclasses.replace(b, evaluate=counted(b.evaluate, "evaluate"),
                                  residual=None if b.residual is None else counted(b.residual, "residual"))
              for b in gp.problem.blocks]
    J, e = nls.whitened_system(dataclasses.replace(gp.problem, blocks=blocks), x)
    assert calls == {"evaluate": len(blocks), "residual": 0}
    e_ref = nls.residual_vector(gp.problem, x)
    np.testing.assert_allclose(e, e_ref, rtol=1e-14, atol=1e-14)
    rng = np.random.default_rng(1)
    for c in rng.choice(x.size, 12, replace=False):
        h = np.zeros(x.size)
        h[c] = 1e-6
        fd = (nls.residual_vector(gp.problem, x + h) - nls.residual_vector(gp.problem, x - h)) / 2e-6
        np.testing.assert_allclose(J[:, c].toarray().ravel(), fd, atol=1e-5 * max(1.0, np.abs(fd).max()))
