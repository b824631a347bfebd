"""Monte-Carlo consistency of EKF-SLAM (known association) on the ``loop`` scenario.

EVALUATION-METHOD.md §A1: at step k of run i, ``ε_k⁽ⁱ⁾ = e_kᵀ P_k⁻¹ e_k`` with ``e = x − x̂`` (heading wrapped)
and ``P_k`` the filter's 3×3 pose block; the average over N independent runs satisfies
``N ε̄_k ~ χ²(N·3)``, so a consistent filter has ``ε̄_k ∈ chi2.ppf([0.025, 0.975], 3N)/N`` ([2.36, 3.72] for
N = 50) at about 95 % of the steps. Un-normalised convention (E[ε] = 3).

Same world in every run (the landmarks of the seed-0 world are passed as ``world.extra_landmarks`` with
``world.layout=none``; the rectangular path has no jitter), independent noise seeds per run. Steps 0 and 1
are excluded: P_0 = 0 (known start pose) and P_1 = G_u M G_uᵀ has rank 2 (two actuation noises, three pose
coordinates), so the pose error lives in a 2-D subspace there and is not χ²(3).
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy.stats import chi2

from slamcli.models.angles import wrap_pose_error
from slamcli.sim import simulate_scenario
from slamcli.solvers.ekf import EkfParams, EkfSlam

N_RUNS = 50
N_STEPS = 500  # the scenario's full loop (one lap plus a bit, so the loop closes)


def average_pose_nees(n_runs: int = N_RUNS, n_steps: int = N_STEPS, params: EkfParams | None = None) -> np.ndarray:
    """Average pose NEES ``ε̄_k (n_steps − 1,)`` for k = 2..n_steps over ``n_runs`` runs."""
    params = params or EkfParams(association="known")
    world = simulate_scenario("loop", seed=0, overrides={"n_steps": 1}).truth.landmarks_xy
    overrides = {
        "n_steps": n_steps,
        "world.layout": "none",
        "world.extra_landmarks": tuple(world.ravel().tolist()),
        "sensor.report_ids": True,
    }
    eps = np.zeros(n_steps - 1)
    for i in range(n_runs):
        ds = simulate_scenario("loop", seed=1 + i, overrides=overrides)
        np.testing.assert_array_equal(ds.truth.landmarks_xy, world)  # same world, new noise
        res = EkfSlam(params).solve(ds.inputs, rng=np.random.default_rng(i))
        e = wrap_pose_error(ds.truth.poses_xyt[2:] - res.poses_xyt[2:])  # (T-1, 3), heading wrapped
        eps += np.einsum("ti,ti->t", e, np.linalg.solve(res.pose_cov[2:], e[..., None])[..., 0])  # solve, not inv
    return eps / n_runs


@pytest.mark.slow
def test_monte_carlo_average_pose_nees_inside_chi2_band(record_property):
    eps_bar = average_pose_nees()
    lo, hi = chi2.ppf([0.025, 0.975], N_RUNS * 3) / N_RUNS
    inside = float(np.mean((eps_bar >= lo) & (eps_bar <= hi)))
    record_property("ekf_nees_fraction_inside", inside)
    record_property("ekf_nees_mean", float(eps_bar.mean()))
    print(f"EKF loop: average pose NEES inside [{lo:.2f}, {hi:.2f}] at {inside:.1%} of steps, mean {eps_bar.mean():.2f}")
    assert inside >= 0.90, (inside, eps_bar.mean())
    # and not trivially conservative: the time-average is near its expectation 3
    assert 2.5 < eps_bar.mean() < 3.5


def test_nees_detects_an_overconfident_filter():
    # the same machinery must flag a filter that under-reports its noise (σ_r, σ_b × 0.2): the check can fail
    eps_bar = average_pose_nees(n_runs=10, n_steps=200, params=EkfParams(association="known", obs_std_scale=0.2))
    hi = chi2.ppf(0.975, 10 * 3) / 10
    assert np.mean(eps_bar > hi) > 0.5
