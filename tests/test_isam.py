"""The incremental smoother (``--method isam``): with its final batch step it ends at batch ``graph`` LM's
optimum (same factors, same association) within 1e-6 on ``loop`` and on the MRCLAM excerpt; without it, its
own estimate is checked against the batch optimum and its association against the simulator's truth."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from slamcli.models.angles import angle_diff
from slamcli.sim import simulate_scenario
from slamcli.solvers.graph import GraphParams, GraphSlam
from slamcli.solvers.isam import IsamParams, IsamSlam

EXCERPT = Path(__file__).parent / "data" / "mrclam_excerpt"
TOL = 1e-6


def _same_optimum(a, b) -> None:
    assert np.abs(a.poses_xyt[:, :2] - b.poses_xyt[:, :2]).max() <= TOL
    assert np.abs(angle_diff(a.poses_xyt[:, 2], b.poses_xyt[:, 2])).max() <= TOL
    assert a.landmarks_xy.shape == b.landmarks_xy.shape
    assert np.abs(a.landmarks_xy - b.landmarks_xy).max() <= TOL
    assert np.array_equal(a.assoc, b.assoc)


@pytest.fixture(scope="module")
def loop_ids():
    return simulate_scenario("loop", seed=1, overrides={"sensor.report_ids": True})


def test_final_batch_equals_graph_lm_on_loop_with_reported_ids(loop_ids):
    rng = np.random.default_rng(0)
    inc = IsamSlam(IsamParams(final_batch=True)).solve(loop_ids.inputs, rng=rng)
    bat = GraphSlam(GraphParams(association="reported")).solve(loop_ids.inputs, rng=rng)
    _same_optimum(inc, bat)
    assert abs(inc.extra["final_cost"] - bat.extra["final_cost"]) <= TOL * bat.extra["final_cost"]


def test_unknown_association_on_loop_finds_every_landmark_once_and_ends_at_graphs_optimum():
    ds = simulate_scenario("loop", seed=1)
    rng = np.random.default_rng(0)
    inc = IsamSlam(IsamParams(final_batch=True)).solve(ds.inputs, rng=rng)
    assert inc.extra["association"] == "nn"
    # every label is one true landmark and every true landmark one label (truth read here, not by the solver)
    true_lm = np.asarray(ds.truth.landmarks_xy, float)
    d = np.linalg.norm(inc.landmarks_xy[:, None, :] - true_lm[None], axis=2)
    assert inc.landmarks_xy.shape[0] == true_lm.shape[0]
    assert sorted(np.argmin(d, axis=1).tolist()) == list(range(true_lm.shape[0]))
    bat = GraphSlam(GraphParams(association="init")).solve(ds.inputs, init=inc, rng=rng)
    _same_optimum(inc, bat)


def test_smoother_estimate_without_final_batch_is_near_the_batch_optimum(loop_ids):
    """Keyframes end at the keyframe graph's optimum (end batch step); the poses between keyframes follow
    odometry, so they are near, not at, the full graph's optimum."""
    rng = np.random.default_rng(0)
    inc = IsamSlam(IsamParams()).solve(loop_ids.inputs, rng=rng)
    bat = GraphSlam(GraphParams(association="reported")).solve(loop_ids.inputs, rng=rng)
    err = np.linalg.norm(inc.poses_xyt[:, :2] - bat.poses_xyt[:, :2], axis=1)
    assert np.median(err) < 1e-5
    assert err.max() < 0.05
    assert np.abs(inc.landmarks_xy - bat.landmarks_xy).max() < 1e-3


def test_final_batch_equals_graph_lm_on_the_mrclam_excerpt():
    from slamcli.datasets.mrclam import import_mrclam

    ds = import_mrclam(EXCERPT, 1, dt=0.1)
    rng = np.random.default_rng(0)
    inc = IsamSlam(IsamParams(final_batch=True)).solve(ds.inputs, rng=rng)
    bat = GraphSlam(GraphParams()).solve(ds.inputs, rng=rng)
    assert inc.extra["association"] == "reported" and inc.extra["robust"] == bat.extra["robust"] == "cauchy"
    _same_optimum(inc, bat)


def test_params_are_validated():
    with pytest.raises(ValueError):
        IsamParams(lag_s=0.0)
    with pytest.raises(ValueError):
        IsamParams(gate_prob=1.0)
