"""Landmark pose-graph importer (g2o / GTSAM text): chain order, body-frame change, covariance reading and
propagation, a noise-free hand-made graph recovered exactly by the graph solver, one-line errors, CLI.

Data: ``tests/data/dlr_excerpt.g2o`` and ``tests/data/victoria_park_excerpt.txt`` (see PROVENANCE-graphs.txt)
and graphs written in ``tmp_path``.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from conftest import DATA
from typer.testing import CliRunner

from slamcli.api.solve import solve_dataset
from slamcli.cli import app
from slamcli.datasets import DatasetImportError
from slamcli.datasets.g2o import import_graph
from slamcli.io import read_dataset
from slamcli.models.angles import angle_diff, wrap_angle
from slamcli.models.motion import integrate
from slamcli.models.observation import inverse_range_bearing, range_bearing
from slamcli.models.se2 import between

DLR = DATA / "dlr_excerpt.g2o"
VP = DATA / "victoria_park_excerpt.txt"
runner = CliRunner()


def _lines(path: Path, tag: str) -> list[list[str]]:
    return [ln.split() for ln in path.read_text().splitlines() if ln.split() and ln.split()[0] == tag]


def test_dlr_excerpt_chain_reproduces_the_composed_vertices():
    ds = import_graph(DLR)
    inp = ds.inputs
    assert ds.truth is None and ds.metadata["forward_axis"] == "-y"
    assert inp.n_poses == 60 and len(inp.observations) == 258 and ds.metadata["n_landmarks"] == 26
    # dlr.g2o's VERTEX_SE2 lines are the composed odometry (printed to 6 decimals): our chain of the converted
    # increments must land on them, with the heading turned by -pi/2 (forward = -y)
    vert = {int(f[1]): np.array(f[2:5], float) for f in _lines(DLR, "VERTEX_SE2")}
    chain = [int(_lines(DLR, "EDGE_SE2")[0][1])] + [int(f[2]) for f in _lines(DLR, "EDGE_SE2")]
    V = np.array([vert[i] for i in chain])
    np.testing.assert_allclose(inp.odometry_xyt[:, :2], V[:, :2], atol=1e-5)
    np.testing.assert_allclose(angle_diff(inp.odometry_xyt[:, 2], V[:, 2] - math.pi / 2), 0, atol=1e-9)
    # controls: forward increment and turn per nominal second
    inc = between(inp.odometry_xyt[:-1], inp.odometry_xyt[1:])
    np.testing.assert_allclose(inp.controls, inc[:, [0, 2]], atol=1e-12)
    assert np.all(inp.controls[:, 0] > 0)  # the robot drives forward in the converted frame


def test_body_frame_change_keeps_the_world_geometry():
    a = import_graph(DLR, forward="-y").inputs
    b = import_graph(DLR, forward="x").inputs
    np.testing.assert_allclose(a.odometry_xyt[:, :2], b.odometry_xyt[:, :2], atol=1e-12)
    np.testing.assert_allclose(angle_diff(a.odometry_xyt[:, 2], b.odometry_xyt[:, 2]), -math.pi / 2, atol=1e-12)
    np.testing.assert_allclose(a.observations.range_m, b.observations.range_m, atol=1e-12)
    # the same landmark positions in the world, whichever body axes the rows are expressed in
    oa, ob = a.observations, b.observations
    ma = inverse_range_bearing(a.odometry_xyt[oa.step], oa.z)
    mb = inverse_range_bearing(b.odometry_xyt[ob.step], ob.z)
    np.testing.assert_allclose(ma, mb, atol=1e-9)
    # σ_x and σ_y of the increments swap under a quarter turn
    np.testing.assert_allclose(a.noise.odometry_std, b.noise.odometry_std[[1, 0, 2]], rtol=1e-12)


def test_victoria_park_covariances_and_landmark_rows():
    ds = import_graph(VP)
    inp = ds.inputs
    assert ds.metadata["forward_axis"] == "x"
    assert inp.n_poses == 250 and len(inp.observations) == 165 and ds.metadata["n_landmarks"] == 24
    # ODOMETRY ... 0.0001 0 0 4e-06 0 4e-06 is a covariance (GTSAM's COV layout)
    np.testing.assert_allclose(inp.noise.odometry_std, [0.01, 0.002, 0.002], rtol=1e-12)
    # LANDMARK ... 0.4 0 0.4: σ_r = √0.4, σ_b = √0.4 / r (first-order polar propagation), median over rows
    rows = _lines(VP, "LANDMARK")
    xy = np.array([f[3:5] for f in rows], float)
    r = np.hypot(xy[:, 0], xy[:, 1])
    assert inp.noise.range_std == pytest.approx(math.sqrt(0.4), rel=1e-12)
    assert inp.noise.bearing_std == pytest.approx(np.median(math.sqrt(0.4) / r), rel=1e-12)
    # rows: file order within a step, ids mapped to ascending landmark indices
    ids = sorted({int(f[2]) for f in rows})
    assert ds.metadata["landmark_ids"] == ids
    pose_ids = [int(_lines(VP, "ODOMETRY")[0][1])] + [int(f[2]) for f in _lines(VP, "ODOMETRY")]
    step = np.array([pose_ids.index(int(f[1])) for f in rows])
    order = np.argsort(step, kind="stable")
    np.testing.assert_array_equal(inp.observations.step, step[order])
    np.testing.assert_array_equal(inp.observations.reported_id, [ids.index(int(rows[k][2])) for k in order])
    np.testing.assert_allclose(inp.observations.range_m, r[order], rtol=1e-12)
    np.testing.assert_allclose(inp.observations.bearing_rad, np.arctan2(xy[order, 1], xy[order, 0]), atol=1e-15)


def _write_graph(path: Path, poses, landmarks, seen, phi: float) -> None:
    """A noise-free g2o file whose body frame is slamcli's rotated by -phi (forward = R(phi)ᵀ x-axis)."""
    c, s = math.cos(phi), math.sin(phi)
    R = np.array([[c, -s], [s, c]])  # slamcli body → file body
    out = [f"VERTEX_SE2 0 {poses[0, 0]:.17g} {poses[0, 1]:.17g} {wrap_angle(poses[0, 2] - phi):.17g}"]
    info_odo = "1e4 0 0 4e4 0 1e3"  # file axes: σ = 0.01, 0.005, 0.0316
    pid = [2 * k for k in range(len(poses))]  # shared id space: poses even, landmarks odd
    for k in range(len(poses) - 1):
        d = between(poses[k], poses[k + 1])
        dx, dy = R @ d[:2]
        out.append(f"EDGE_SE2 {pid[k]} {pid[k + 1]} {dx:.17g} {dy:.17g} {d[2]:.17g} {info_odo}")
        for j in seen[k]:
            z = range_bearing(poses[k], landmarks[j])
            lx, ly = R @ (z[0] * np.array([math.cos(z[1]), math.sin(z[1])]))
            out.append(f"EDGE_SE2_XY {pid[k]} {2 * j + 1} {lx:.17g} {ly:.17g} 400 0 100")
    path.write_text("\n".join(out) + "\n")


def test_noise_free_graph_is_recovered_exactly(tmp_path):
    poses = integrate(np.array([1.0, -2.0, 0.3]), np.column_stack([np.full(30, 0.5), 0.2 * np.sin(np.arange(30) / 4)]), 1.0)
    landmarks = np.array([[3.0, 1.0], [6.0, -1.0], [2.0, 4.0], [8.0, 3.0], [5.0, 6.0]])
    seen = [[j for j in range(5) if np.hypot(*(landmarks[j] - poses[k, :2])) < 6.0] for k in range(len(poses))]
    f = tmp_path / "toy.g2o"
    _write_graph(f, poses, landmarks, seen, phi=-math.pi / 2)
    ds = import_graph(f, dt=0.5)
    inp = ds.inputs
    assert ds.metadata["forward_axis"] == "-y"
    np.testing.assert_allclose(inp.odometry_xyt[:, :2], poses[:, :2], atol=1e-9)
    np.testing.assert_allclose(angle_diff(inp.odometry_xyt[:, 2], poses[:, 2]), 0, atol=1e-9)
    obs = inp.observations
    np.testing.assert_allclose(obs.z, range_bearing(poses[obs.step], landmarks[obs.reported_id]), atol=1e-9)
    np.testing.assert_allclose(np.diff(inp.timestamps), 0.5)
    np.testing.assert_allclose(inp.controls[:, 0], 0.5 / 0.5, atol=1e-12)  # 0.5 m per 0.5 s step
    # file information diag(1e4, 4e4, 1e3) about file axes; forward = -y swaps x and y
    np.testing.assert_allclose(inp.noise.odometry_std, [0.005, 0.01, 1e3**-0.5], rtol=1e-12)
    np.testing.assert_allclose(inp.noise.motion_std, [0.005 / 0.5, 1e3**-0.5 / 0.5], rtol=1e-12)
    # landmark information diag(400, 100) in file axes → slamcli (x, y) covariance diag(0.01, 0.0025)...
    r = obs.range_m
    bx, by = np.cos(obs.bearing_rad), np.sin(obs.bearing_rad)
    var_r = 0.01 * bx**2 + 0.0025 * by**2
    var_b = (0.01 * by**2 + 0.0025 * bx**2) / r**2
    assert inp.noise.range_std == pytest.approx(np.median(np.sqrt(var_r)), rel=1e-9)
    assert inp.noise.bearing_std == pytest.approx(np.median(np.sqrt(var_b)), rel=1e-9)
    # every factor is exact, so the graph optimum is the truth; a wrong sign or axis anywhere would move it
    res = solve_dataset(inp, "graph", {"association": "reported", "covariance": False})
    np.testing.assert_allclose(res.poses_xyt[:, :2], poses[:, :2], atol=1e-6)
    lm = np.full((5, 2), np.nan)
    for row, lab in enumerate(res.assoc):
        lm[obs.reported_id[row]] = res.landmarks_xy[lab]
    np.testing.assert_allclose(lm, landmarks, atol=1e-6)


@pytest.mark.parametrize(
    ("text", "fragment"),
    [
        ("EDGE_SE3 0 1 1 2 3\n", "toy.g2o:1: unsupported tag 'EDGE_SE3'"),
        ("EDGE_SE2 0 1 1 0 0 1 0 0 1 0\n", "toy.g2o:1: EDGE_SE2 needs 11 numbers, got 10"),
        ("EDGE_SE2 0 1 1 0 0 1 0 0 1 0 x\n", "toy.g2o:1: not a number: 'x'"),
        ("EDGE_SE2 0 1.5 1 0 0 1 0 0 1 0 1\n", "toy.g2o:1: ids must be non-negative integers"),
        ("EDGE_SE2 0 1 1 0 0 1 0 0 -1 0 1\n",
         "toy.g2o:1: EDGE_SE2 matrix is not positive definite read as information, g2o order (convention auto); "
         "valid under --convention isam"),
        ("# only a comment\nVERTEX_SE2 0 0 0 0\n", "no odometry edges"),
        ("VERTEX_SE2 0 0 0 0\nVERTEX_SE2 0 1 0 0\nEDGE_SE2 0 1 1 0 0 1 0 0 1 0 1\n",
         "toy.g2o:2: duplicate vertex id 0 (first declared at line 1)"),
        ("VERTEX_SE2 0 0 0 0\nVERTEX_XY 0 1 0\nEDGE_SE2 0 1 1 0 0 1 0 0 1 0 1\n",
         "toy.g2o:2: duplicate vertex id 0 (first declared at line 1) (convention auto: poses and landmarks share "
         "one id space; --convention gtsam or isam read landmark ids in their own space)"),
        ("EDGE_SE2 0 9223372036854775808 1 0 0 1 0 0 1 0 1\n", "toy.g2o:1: id 9223372036854775808 ≥ 2^63"),
        ("VERTEX_SE2 0 0 0 0\nVERTEX_SE2 1 1 0 0\nEDGE_SE2 0 1 1 0 0 1 0 0 1 0 1\nEDGE_SE2 1 2 1 0 0 1 0 0 1 0 1\n",
         "toy.g2o:4: edge to unknown pose vertex 2"),
        ("EDGE_SE2 0 1 1 0 0 1 0 0 1 0 1\nEDGE_SE2_XY 1 0 1 0 1 0 1\n", "toy.g2o:2: landmark id 0 is also a pose id"),
        ("VERTEX_XY 5 1 1\nEDGE_SE2 0 1 1 0 0 1 0 0 1 0 1\nEDGE_SE2_XY 1 6 1 0 1 0 1\n",
         "toy.g2o:3: sighting of unknown landmark vertex 6"),
        ("EDGE_SE2 0 1 1 0 0 1 0 0 1 0 1\nEDGE_SE2 1 1 1 0 0 1 0 0 1 0 1\n", "toy.g2o:2: edge from pose 1 to itself"),
        ("EDGE_SE2 0 1 1 0 0 1 0 0 1 0 1\nBR 1 5 0.1 2 0 0.1\n", "toy.g2o:2: BR needs σ_bearing > 0"),
        ("EDGE_SE2 0 1 1 0 0 1 0 0 1 0 1\nBR 1 5 0.1 2 0.1 0.1\nEDGE_SE2_XY 0 5 1 0 1 0 1\n",
         "mixes Cartesian (EDGE_SE2_XY/LANDMARK) and bearing-range (BR) sightings"),
        ("EDGE_SE2 0 1 1 0 0 1 0 0 1 0 1\nEDGE_SE2_XY 7 9 1 0 1 0 1\n",
         "toy.g2o:2: landmark observation from pose 7, which is not on the odometry chain"),
    ],
)
def test_bad_graph_files_raise_one_line_errors(tmp_path, text, fragment):
    f = tmp_path / "toy.g2o"
    f.write_text(text)
    with pytest.raises(DatasetImportError) as exc:
        import_graph(f)
    assert fragment in str(exc.value) and "\n" not in str(exc.value)


def test_bad_arguments(tmp_path):
    with pytest.raises(DatasetImportError, match="nope.g2o: file not found"):
        import_graph(tmp_path / "nope.g2o")
    with pytest.raises(DatasetImportError, match="--forward: must be auto, x, y, -x or -y"):
        import_graph(DLR, forward="z")
    with pytest.raises(DatasetImportError, match="--dt: must be a finite number > 0"):
        import_graph(DLR, dt=-1.0)


@pytest.mark.slow
def test_cli_import_g2o_solve_and_evaluate_says_no_truth(tmp_path):
    data = tmp_path / "vp.h5"
    res = runner.invoke(app, ["import", "g2o", str(VP), "-o", str(data)])
    assert res.exit_code == 0, res.output
    assert "250 poses, 0 loop closures, 24 landmarks, 165 observations" in res.stdout
    ds = read_dataset(data)
    assert ds.truth is None
    np.testing.assert_array_equal(ds.inputs.odometry_xyt, import_graph(VP).inputs.odometry_xyt)
    res = runner.invoke(app, ["import", "g2o", str(VP), "--bearing-std", "0.2", "-q", "-o", str(tmp_path / "v2.h5")])
    assert res.exit_code == 0, res.output
    v2 = read_dataset(tmp_path / "v2.h5").inputs.noise
    assert v2.bearing_std == 0.2 and v2.range_std == ds.inputs.noise.range_std
    res = runner.invoke(app, ["import", "g2o", str(VP), "--range-std", "-1", "-o", str(tmp_path / "v3.h5")])
    assert res.exit_code == 1 and "--range-std: must be a finite number >= 0" in res.stderr
    res = runner.invoke(app, ["solve", str(data), "--method", "graph", "--param", "association=reported",
                              "-o", str(tmp_path / "r.h5")])
    assert res.exit_code == 0, res.output
    res = runner.invoke(app, ["evaluate", str(tmp_path / "r.h5"), "-q"])  # no truth: own-model metrics only
    assert res.exit_code == 0, res.output
    res = runner.invoke(app, ["import", "g2o", str(tmp_path / "missing.g2o"), "-o", str(tmp_path / "x.h5")])
    assert res.exit_code == 1 and res.stderr.startswith("error: ") and "file not found" in res.stderr
    assert not (tmp_path / "x.h5").exists()


def _graph_text(truth, edges, vertices=None):
    """A g2o file with exact EDGE_SE2 measurements between ``truth`` poses along ``edges``."""
    from slamcli.models import se2

    lines = [f"VERTEX_SE2 {k} {v[0]:.17g} {v[1]:.17g} {v[2]:.17g}" for k, v in enumerate(vertices)] if vertices is not None else []
    for i, j in edges:
        d = se2.between(truth[i], truth[j])
        lines.append(f"EDGE_SE2 {i} {j} {d[0]:.17g} {d[1]:.17g} {d[2]:.17g} 100 0 0 100 0 400")
    return "\n".join(lines) + "\n"


def _truth(n=10):
    th = np.linspace(0.0, 1.5, n)
    return np.column_stack([np.cumsum(np.cos(th)), np.cumsum(np.sin(th)), th])


@pytest.mark.parametrize("with_vertices", [True, False])
def test_any_connected_graph_imports_and_solves_to_the_truth(tmp_path, with_vertices):
    """Two runs merged into one file: poses 0-4 and 5-9, no edge 4 → 5 but 0 → 5 and 2 → 7 tie them
    (GTSAM and g2o read such graphs). Exact measurements: the optimum is the truth."""
    truth = _truth()
    edges = [(k, k + 1) for k in range(4)] + [(k, k + 1) for k in range(5, 9)] + [(0, 5), (2, 7)]
    rng = np.random.default_rng(4)
    verts = truth + rng.normal(scale=0.05, size=truth.shape) if with_vertices else None
    f = tmp_path / "merged.g2o"
    f.write_text(_graph_text(truth, edges, verts))
    ds = import_graph(f)
    assert ds.metadata["components"] == 1 and ds.metadata["virtual_odometry_steps"] == 1
    assert "1 consecutive pose id pair(s) without an edge" in ds.metadata["import_note"]
    assert ("vertices" in ds.metadata["init_source"]) == with_vertices
    res = solve_dataset(ds.inputs, "graph", {"covariance": False})
    from slamcli.models import se2

    # the prior holds x_0 at the file's (perturbed) start vertex: compare the poses relative to x_0
    np.testing.assert_allclose(se2.between(res.poses_xyt[[0] * 10], res.poses_xyt),
                               se2.between(truth[[0] * 10], truth), atol=1e-6)


def test_disconnected_graph_gets_one_prior_per_component(tmp_path):
    truth = _truth()
    edges = [(k, k + 1) for k in range(4)] + [(k, k + 1) for k in range(5, 9)]  # two runs, nothing between
    f = tmp_path / "two.g2o"
    f.write_text(_graph_text(truth, edges))
    ds = import_graph(f)
    md = ds.metadata
    assert md["components"] == 2 and md["component_priors"] == [5]
    assert "2 disconnected components, one prior per component (on poses 5)" in md["import_note"]
    res = runner.invoke(app, ["import", "g2o", str(f), "-o", str(tmp_path / "two.h5")])
    assert res.exit_code == 0 and res.stdout.count("one prior per component") == 1
    sol = solve_dataset(ds.inputs, "graph", {"covariance": False})
    from slamcli.models import se2

    for a, b in [(0, 4), (5, 9), (6, 8)]:  # relative poses within each component are the truth's
        np.testing.assert_allclose(se2.between(sol.poses_xyt[a], sol.poses_xyt[b]), se2.between(truth[a], truth[b]),
                                   atol=1e-6)
