"""``graph``'s marginals (selected inverse of H) against ``gtsam.Marginals`` at the same point (issue 17).

GTSAM linearises its own factor graph (PriorFactorPose2, BetweenFactorPose2, BearingRangeFactor2D, built
in :mod:`test_graph_gtsam` from GTSAM's types) at *our* optimum. The measurements are made noise-free (exact
odometry and range/bearing from the simulated truth), so every residual at the optimum is ~0: then GTSAM's
body-frame Jacobians (which carry the derivative of Pose2's Logmap at the residual) and our world-frame
ones describe the same linearisation, and both sides invert the same information matrix up to the chart
change ``Σ_w = J Σ_b Jᵀ``, ``J = blkdiag(R(θ), 1)`` — agreement to round-off (1e-8), not to the optimiser's
tolerance. (With noisy data the two information matrices differ by O(residual) terms: ~1e-7 relative.)
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from slamcli.models import observation
from slamcli.solvers import frontend, graph
from slamcli.solvers.nls import cholmod_available
from slamcli.types import Status

gtsam = pytest.importorskip("gtsam")
from gtsam.symbol_shorthand import L, X  # noqa: E402 - after the importorskip guard
from test_graph_gtsam import _gtsam_graph, _values  # noqa: E402

pytestmark = pytest.mark.skipif(not cholmod_available(), reason="needs CHOLMOD (cvxopt)")


def test_selected_inverse_marginals_equal_gtsam_marginals_at_the_same_point():
    from conftest import tiny_dataset

    ds = tiny_dataset(T=120, n_landmarks=10, seed=5, report_ids=True, clutter_every=0)
    obs, truth = ds.inputs.observations, ds.truth
    z = observation.range_bearing(truth.poses_xyt[obs.step], truth.landmarks_xy[truth.obs_landmark])
    inputs = replace(ds.inputs, odometry_xyt=truth.poses_xyt.copy(),
                     observations=replace(obs, range_m=z[:, 0], bearing_rad=z[:, 1]))
    params = graph.GraphParams(association="reported")
    res = graph.GraphSlam(params).solve(inputs, rng=np.random.default_rng(0))
    assert res.status == Status.CONVERGED and res.pose_cov is not None
    assert np.abs(res.poses_xyt - truth.poses_xyt).max() < 1e-8  # noise-free: the optimum is the truth
    assoc = frontend.associate_reported(inputs.observations)
    n_lm = int(assoc.max()) + 1
    g = _gtsam_graph(inputs, assoc, params.prior_std)
    marg = gtsam.Marginals(g, _values(res.poses_xyt, res.landmarks_xy))
    worst_p = worst_l = 0.0
    for t in range(inputs.n_poses):
        th = res.poses_xyt[t, 2]
        J = np.array([[np.cos(th), -np.sin(th), 0.0], [np.sin(th), np.cos(th), 0.0], [0.0, 0.0, 1.0]])
        Sw = J @ marg.marginalCovariance(X(t)) @ J.T
        worst_p = max(worst_p, np.abs(res.pose_cov[t] - Sw).max() / np.abs(Sw).max())
    for j in range(n_lm):
        Sl = marg.marginalCovariance(L(j))
        worst_l = max(worst_l, np.abs(res.landmark_cov[j] - Sl).max() / np.abs(Sl).max())
    assert worst_p < 1e-10, worst_p
    assert worst_l < 1e-10, worst_l
