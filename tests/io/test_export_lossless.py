"""Lossless graph export (issue 39 item 4): every sighting written, landmark ids apart from pose ids, and
slamcli's own g2o/GTSAM exports read back by ``slamcli import g2o`` with the same objective.

The objective is the graph solver's factor graph without its prior on x_0 (the files carry none), evaluated
(1) on the original dataset at the result's estimate with the result's association, (2) on the re-imported
file at the file's vertices with the file's landmark ids, and (3) by GTSAM (``readG2o``'s
``graph.error``) at the same vertices — the independent reference. Unassociated sightings are written as
landmarks of their own placed where they were seen: they add nothing at those values.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest
from conftest import DATA
from typer.testing import CliRunner

from slamcli.api.simulate import simulate_to_file
from slamcli.api.solve import solve_file
from slamcli.cli import app
from slamcli.io import read_dataset, read_result
from slamcli.solvers.graph.build import build_gtsam_problem, pack_state
from slamcli.solvers.graph.params import GraphParams
from slamcli.solvers.nls.optimize import residual_vector

gtsam = pytest.importorskip("gtsam")
COST_RTOL = 1e-9  # the same factors at the same values: only float summation order differs
runner = CliRunner()


def _objective(inputs, assoc, poses, lms) -> float:
    gp = build_gtsam_problem(inputs, np.asarray(assoc, np.int64), poses, lms, GraphParams(robust="none", group_returns=False))
    problem = dataclasses.replace(gp.problem, blocks=[b for b in gp.problem.blocks if b.name != "prior"])
    r = residual_vector(problem, pack_state(poses, lms))
    return 0.5 * float(r @ r)


def _file_values(path: Path) -> tuple[np.ndarray, dict]:
    rows = [ln.split() for ln in path.read_text().splitlines()]
    poses = np.array([[float(v) for v in f[2:5]] for f in rows if f[0] == "VERTEX_SE2"])
    lms = {int(f[1]): np.array(f[2:4], float) for f in rows if f[0] == "VERTEX_XY"}
    return poses, lms


def _invoke(args):
    r = runner.invoke(app, [str(a) for a in args])
    assert r.exit_code == 0, r.output
    return r


@pytest.fixture(scope="module")
def cluttered(tmp_path_factory):
    """An EKF (maximum-likelihood association) and a graph result on a simulated loop with clutter."""
    d = tmp_path_factory.mktemp("lossless")
    simulate_to_file("loop", 3, {"n_steps": 150, "clutter.rate": 0.3}, d / "d.h5")
    solve_file(d / "d.h5", "ekf", {}, d / "ekf.h5")
    solve_file(d / "d.h5", "graph", {"robust": "none", "covariance": False}, d / "graph.h5")
    return d, read_dataset(d / "d.h5")


@pytest.mark.parametrize("solver", ["ekf", "graph"])
@pytest.mark.slow
def test_gtsam_export_round_trip_keeps_every_sighting_and_the_objective(cluttered, solver):
    d, ds = cluttered
    res = read_result(d / f"{solver}.h5")
    n_obs = len(ds.inputs.observations)
    n_alone = int(np.count_nonzero(res.assoc < 0))
    out = d / f"{solver}.txt"
    r = _invoke(["export", d / f"{solver}.h5", "--format", "gtsam", "-o", out])
    if solver == "ekf":
        assert n_alone > 0  # clutter the EKF left unassociated: the case the export used to drop
    assert (f"{len(res.landmarks_xy)} landmarks, {n_obs} sightings"
            + (f" ({n_alone} unassociated, written as landmarks of their own)" if n_alone else "")) in r.stdout
    lines = [ln.split() for ln in out.read_text().splitlines()]
    assert sum(f[0] == "BR" for f in lines) == n_obs  # counted out
    n = ds.inputs.n_poses
    lm_ids = [int(f[1]) for f in lines if f[0] == "VERTEX_XY"]
    assert lm_ids == list(range(n, n + len(res.landmarks_xy) + n_alone))  # apart from the pose ids 0..n-1

    back_path = d / f"{solver}_back.h5"
    r = _invoke(["import", "g2o", out, "-o", back_path])
    back = read_dataset(back_path)
    assert len(back.inputs.observations) == n_obs  # counted in
    assert f"{len(res.landmarks_xy) + n_alone} landmarks, {n_obs} observations" in r.stdout

    poses, lms = _file_values(out)
    np.testing.assert_array_equal(poses, res.poses_xyt)
    M = np.array([lms[i] for i in back.metadata["landmark_ids"]])
    ours_back = _objective(back.inputs, back.inputs.observations.reported_id, poses, M)
    ours_orig = _objective(ds.inputs, res.assoc, res.poses_xyt, res.landmarks_xy)
    graph, values = gtsam.readG2o(str(out), False)
    assert graph.size() == n - 1 + n_obs
    ref = graph.error(values)
    assert ref > 1.0
    assert ours_orig == pytest.approx(ref, rel=COST_RTOL)
    assert ours_back == pytest.approx(ref, rel=COST_RTOL)


def test_g2o_export_of_an_xy_landmark_graph_round_trips(tmp_path):
    """DLR excerpt (Cartesian sightings, per-edge information): g2o export → import → the same objective as
    the original import at the result's estimate (g2o carries xy information exactly)."""
    _invoke(["import", "g2o", DATA / "dlr_excerpt.g2o", "-o", tmp_path / "dlr.h5", "-q"])
    solve_file(tmp_path / "dlr.h5", "graph", {"init": "odometry", "covariance": False}, tmp_path / "g.h5")
    ds, res = read_dataset(tmp_path / "dlr.h5"), read_result(tmp_path / "g.h5")
    r = _invoke(["export", tmp_path / "g.h5", "--format", "g2o", "-o", tmp_path / "g.g2o"])
    n_obs = len(ds.inputs.observations)
    assert f"{n_obs} sightings" in r.stdout
    _invoke(["import", "g2o", tmp_path / "g.g2o", "-o", tmp_path / "back.h5", "-q"])
    back = read_dataset(tmp_path / "back.h5")
    assert len(back.inputs.observations) == n_obs
    poses, lms = _file_values(tmp_path / "g.g2o")
    M = np.array([lms[i] for i in back.metadata["landmark_ids"]])
    ours_orig = _objective(ds.inputs, res.assoc, res.poses_xyt, res.landmarks_xy)
    ours_back = _objective(back.inputs, back.inputs.observations.reported_id, poses, M)
    assert ours_orig > 1e-3
    assert ours_back == pytest.approx(ours_orig, rel=COST_RTOL)


@pytest.mark.slow
def test_messages_say_what_each_format_holds(cluttered):
    d, _ = cluttered
    r = _invoke(["export", d / "ekf.h5", "--format", "tum", "-o", d / "e.tum"])
    assert "landmark" not in r.stdout and "poses; TUM holds poses only" in r.stdout
    r = _invoke(["export", d / "ekf.h5", "--format", "kitti", "-o", d / "e.kitti"])
    assert "landmark" not in r.stdout and "poses; KITTI holds poses only" in r.stdout
    r = _invoke(["export", d / "ekf.h5", "--format", "csv", "-o", d / "e.csv"])
    n_lm = len(read_result(d / "ekf.h5").landmarks_xy)
    assert f"poses, {n_lm} landmarks)" in r.stdout and "sightings" not in r.stdout


def test_export_replaces_an_earlier_export_but_a_slamcli_file_only_with_force(cluttered):
    d, _ = cluttered
    target = d / "victim.h5"
    target.write_bytes((d / "d.h5").read_bytes())
    r = runner.invoke(app, ["export", str(d / "ekf.h5"), "--format", "tum", "-o", str(target)])
    assert r.exit_code == 2 and r.output.strip().splitlines()[0] == (
        f"error: -o {target}: exists and is a slamcli dataset, not an export; --force replaces it")
    assert target.read_bytes() == (d / "d.h5").read_bytes()  # untouched
    _invoke(["export", d / "ekf.h5", "--format", "tum", "-o", target, "--force"])
    assert target.read_text().count("\n") == read_result(d / "ekf.h5").poses_xyt.shape[0]
    _invoke(["export", d / "ekf.h5", "--format", "kitti", "-o", target])  # an earlier export: replaced


def test_an_older_gtsam_export_with_landmark_ids_from_zero_imports(tmp_path):
    """Earlier exports numbered landmarks from 0 (GTSAM keys them L(l), apart from poses): BR sightings put
    landmark ids in their own space under the default convention, so the duplicate id 0 is no clash."""
    f = tmp_path / "old.txt"
    f.write_text("VERTEX_SE2 0 0.0 0.0 0.0\nVERTEX_SE2 1 1.0 0.0 0.0\nVERTEX_XY 0 2.0 1.0\n"
                 "EDGE_SE2 0 1 1.0 0.0 0.0 100.0 0.0 0.0 100.0 0.0 400.0\n"
                 "BR 0 0 0.4636476090008061 2.23606797749979 0.01 0.1\nBR 1 0 0.7853981633974483 1.4142135623730951 0.01 0.1\n")
    r = _invoke(["import", "g2o", f, "-o", tmp_path / "old.h5"])
    assert "2 poses, 0 loop closures, 1 landmarks, 2 observations" in r.stdout
    assert "landmark ids: own id space" in r.stdout
