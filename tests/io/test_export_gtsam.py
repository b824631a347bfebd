"""GTSAM loads a landmark graph export completely (issue 24 item 6).

``--format gtsam`` writes the sightings as ``BR`` lines; GTSAM's own reader (``gtsam.readG2o``) is the
reference: it must build one BetweenFactorPose2 per odometry edge / loop closure and one BearingRangeFactor2D
per attached sighting, its error at the exported estimate (plus graph's prior on x_0) must equal graph's final
cost, and GTSAM's Levenberg-Marquardt from dead reckoning must land on graph's estimate. The g2o export of the
same result warns in one line, and readG2o indeed drops its EDGE_SE2_XY lines.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from conftest import DATA
from typer.testing import CliRunner

from slamcli.api.simulate import simulate_to_file
from slamcli.api.solve import solve_file
from slamcli.cli import app
from slamcli.io import read_dataset, read_result

gtsam = pytest.importorskip("gtsam")
runner = CliRunner()
COST_RTOL = 1e-9  # same factors, same numbers: only float summation order differs
POSE_ATOL = 1e-6  # m / rad: two LM runs to the same optimum


def _count(graph, cls) -> int:
    return sum(isinstance(graph.at(i), cls) for i in range(graph.size()))


@pytest.fixture(scope="module")
def solved(tmp_path_factory):
    d = tmp_path_factory.mktemp("gtsamexp")
    simulate_to_file("loop", 4, {"n_steps": 150}, d / "d.h5")
    solve_file(d / "d.h5", "graph", {"robust": "none", "covariance": False}, d / "g.h5")
    return d, read_dataset(d / "d.h5"), read_result(d / "g.h5")


def _export(src: Path, fmt: str, out: Path):
    r = runner.invoke(app, ["export", str(src), "--format", fmt, "-o", str(out)])
    assert r.exit_code == 0, r.output
    return r


def test_gtsam_export_loads_every_factor_and_our_optimum(solved):
    d, ds, res = solved
    r = _export(d / "g.h5", "gtsam", d / "g.txt")
    assert "warning" not in r.stderr
    graph, values = gtsam.readG2o(str(d / "g.txt"), False)
    n_sightings = int(np.count_nonzero(res.assoc >= 0))
    assert n_sightings > 100 and len(res.landmarks_xy) > 3
    assert _count(graph, gtsam.BetweenFactorPose2) == ds.inputs.n_poses - 1
    assert _count(graph, gtsam.BearingRangeFactor2D) == n_sightings == graph.size() - (ds.inputs.n_poses - 1)
    lm = np.array([values.atPoint2(gtsam.symbol("l", ds.inputs.n_poses + j)) for j in range(len(res.landmarks_xy))])
    np.testing.assert_array_equal(lm, res.landmarks_xy)
    prior_std = np.asarray(res.params["prior_std"], float)
    graph.add(gtsam.PriorFactorPose2(0, gtsam.Pose2(*ds.inputs.x0), gtsam.noiseModel.Diagonal.Sigmas(prior_std)))
    cost = res.extra["final_cost"]
    assert abs(graph.error(values) - cost) <= COST_RTOL * cost
    # GTSAM's own optimum from dead reckoning (landmarks: each one's first sighting) is graph's estimate
    init = gtsam.Values()
    for t, p in enumerate(ds.inputs.odometry_xyt):
        init.insert(t, gtsam.Pose2(*p))
    obs = ds.inputs.observations
    for j in range(len(res.landmarks_xy)):
        k = int(np.flatnonzero(res.assoc == j)[0])
        x, y, th = ds.inputs.odometry_xyt[obs.step[k]]
        b = th + obs.bearing_rad[k]
        init.insert(gtsam.symbol("l", ds.inputs.n_poses + j), np.array([x + obs.range_m[k] * np.cos(b), y + obs.range_m[k] * np.sin(b)]))
    assert graph.error(init) > 2 * cost  # dead reckoning is far from the optimum: the check below is not vacuous
    opt = gtsam.LevenbergMarquardtOptimizer(graph, init).optimize()
    got = np.array([[opt.atPose2(t).x(), opt.atPose2(t).y(), opt.atPose2(t).theta()] for t in range(ds.inputs.n_poses)])
    np.testing.assert_allclose(got, res.poses_xyt, rtol=0, atol=POSE_ATOL)


def test_g2o_export_warns_that_gtsam_drops_the_landmark_edges(solved):
    d, ds, res = solved
    r = _export(d / "g.h5", "g2o", d / "g.g2o")
    n_sightings = int(np.count_nonzero(res.assoc >= 0))
    assert r.stderr.strip() == f"warning: GTSAM's readG2o skips the {n_sightings} EDGE_SE2_XY lines: use --format gtsam"
    graph, _ = gtsam.readG2o(str(d / "g.g2o"), False)
    assert graph.size() == ds.inputs.n_poses - 1  # what the warning says
    assert sum(line.startswith("EDGE_SE2_XY") for line in (d / "g.g2o").read_text().splitlines()) == n_sightings


def test_gtsam_export_of_an_imported_xy_landmark_graph(tmp_path):
    """DLR excerpt: per-row Cartesian information goes to BR σ's to first order; the dropped correlations are
    warned about, and GTSAM still builds every factor."""
    r = runner.invoke(app, ["import", "g2o", str(DATA / "dlr_excerpt.g2o"), "-o", str(tmp_path / "dlr.h5"), "-q"])
    assert r.exit_code == 0, r.output
    solve_file(tmp_path / "dlr.h5", "graph", {"init": "odometry", "covariance": False}, tmp_path / "g.h5")
    res, inp = read_result(tmp_path / "g.h5"), read_dataset(tmp_path / "dlr.h5").inputs
    r = _export(tmp_path / "g.h5", "gtsam", tmp_path / "g.txt")
    assert "BR lines drop a bearing-range correlation" in r.stderr
    graph, _ = gtsam.readG2o(str(tmp_path / "g.txt"), False)
    n_sightings = int(np.count_nonzero(res.assoc >= 0))
    assert n_sightings > 0
    assert _count(graph, gtsam.BetweenFactorPose2) == inp.n_poses - 1 + inp.constraints.n_between
    assert _count(graph, gtsam.BearingRangeFactor2D) == n_sightings
