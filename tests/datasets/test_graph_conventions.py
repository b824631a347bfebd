"""Graph files read with explicit conventions give GTSAM's cost at the same values (issue 37 item 1).

Reference: GTSAM's own loaders (``gtsam.load2D`` with each noise format, ``gtsam.readG2o``) on the same file;
for iSAM's square-root-information format, which GTSAM has no loader for, GTSAM factors built here from the
file's text (``noiseModel.Gaussian.SqrtInformation``, a ``CustomFactor`` for the landmark offset in the pose
frame). Our cost is the graph solver's factor graph on the imported dataset, without its prior on the first
pose (GTSAM's loaders add none), at seeded random values; GTSAM's is ``graph.error(values)``.
"""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path

import numpy as np
import pytest
from conftest import DATA
from typer.testing import CliRunner

from slamcli.cli import app
from slamcli.datasets import DatasetImportError
from slamcli.datasets.g2o import import_graph, read_graph
from slamcli.solvers.graph.build import build_gtsam_problem, pack_state
from slamcli.solvers.graph.params import GraphParams
from slamcli.solvers.nls.optimize import residual_vector

gtsam = pytest.importorskip("gtsam")
COST_RTOL = 1e-9  # the same factors at the same values: only float summation order differs
L = gtsam.symbol_shorthand.L
runner = CliRunner()


def _values(pose_ids, lm_ids, seed: int, tie=None) -> tuple[dict, dict, gtsam.Values]:
    """Seeded random poses / landmarks by file id, and the same as GTSAM Values (``tie``: id → id whose value
    it takes, for poses merged by EQUIV)."""
    rng = np.random.default_rng(seed)
    poses = {p: np.array([*rng.uniform(-5, 5, 2), rng.uniform(-math.pi, math.pi)]) for p in pose_ids}
    lms = {m: rng.uniform(-5, 5, 2) for m in lm_ids}
    v = gtsam.Values()
    for p, x in poses.items():
        v.insert(p, gtsam.Pose2(*x))
    for a, b in (tie or {}).items():
        v.insert(a, gtsam.Pose2(*poses[b]))
    for m, x in lms.items():
        v.insert(L(m), np.asarray(x))
    return poses, lms, v


def _our_cost(path: Path, convention: str, poses: dict, lms: dict) -> float:
    """½‖whitened residuals‖² of the graph solver's factors (prior on x_0 left out) on the imported file."""
    ds = import_graph(path, forward="x", convention=convention)
    inp = ds.inputs
    P = np.array([poses[p] for p in sorted(poses)])
    M = np.array([lms[m] for m in ds.metadata["landmark_ids"]]).reshape(-1, 2)
    gp = build_gtsam_problem(inp, inp.observations.reported_id, P, M, GraphParams(robust="none"))
    problem = dataclasses.replace(gp.problem, blocks=[b for b in gp.problem.blocks if b.name != "prior"])
    r = residual_vector(problem, pack_state(P, M))
    return 0.5 * float(r @ r)


def _pose_ids(path: Path, convention: str) -> list[int]:
    g = read_graph(path, convention)
    return sorted({e[0] for e in g["pose_edges"]} | {e[1] for e in g["pose_edges"]})


def _landmark_ids(path: Path, convention: str) -> list[int]:
    return sorted({o[1] for o in read_graph(path, convention)["sightings"]})


@pytest.mark.parametrize(("name", "convention", "fmt"), [
    ("gtsam_example_excerpt.graph", "gtsam", "NoiseFormatAUTO"),  # EDGE2 [a 0 b c 0 0]: TORO-order covariance
    ("w20000_excerpt.txt", "gtsam", "NoiseFormatAUTO"),  # EDGE2 [a 0 0 b 0 c]: g2o-order covariance
    ("victoria_park_excerpt.txt", "gtsam", "NoiseFormatAUTO"),  # LANDMARK → GTSAM's bearing-range σ's
    ("toro_nondiagonal.graph", "toro", "NoiseFormatTORO"),
    ("toro_nondiagonal.graph", "auto", "NoiseFormatTORO"),  # EDGE2 by tag: TORO information
    ("w20000_excerpt.txt", "g2o", "NoiseFormatG2O"),
    ("intel_excerpt.g2o", "g2o", "NoiseFormatG2O"),
    ("intel_excerpt.g2o", "auto", "NoiseFormatG2O"),
])
@pytest.mark.slow
def test_cost_equals_gtsam_load2d(name, convention, fmt):
    path = DATA / name
    graph, _ = gtsam.load2D(str(path), noiseFormat=getattr(gtsam.NoiseFormat, fmt))
    pose_ids, lm_ids = _pose_ids(path, convention), _landmark_ids(path, convention)
    assert graph.size() == len(read_graph(path, convention)["pose_edges"]) + len(
        read_graph(path, convention)["sightings"])  # the same factors, none skipped by either reader
    for seed in (1, 2):
        poses, lms, values = _values(pose_ids, lm_ids, seed)
        ref = graph.error(values)
        assert ref > 1.0  # random values: a cost far from zero, so the comparison is not vacuous
        assert _our_cost(path, convention, poses, lms) == pytest.approx(ref, rel=COST_RTOL)


def test_readg2o_is_the_g2o_convention():
    path = DATA / "intel_excerpt.g2o"
    graph, _ = gtsam.readG2o(str(path), False)
    poses, lms, values = _values(_pose_ids(path, "g2o"), [], 3)
    assert _our_cost(path, "g2o", poses, lms) == pytest.approx(graph.error(values), rel=COST_RTOL)


def test_equiv_merges_poses_and_keeps_gtsam_cost_at_tied_values():
    """w100 (GTSAM's examples, TORO tags): EQUIV a b merges b into the smaller id. GTSAM's load2D ignores
    EQUIV, so its cost at values where every merged pose equals its representative is ours plus the constant
    of the edges between merged poses (reported by the import)."""
    path = DATA / "w100_equiv_excerpt.graph"
    g = read_graph(path, "toro")
    tie = {b: a for a, b, _ in g["merged"]}
    assert len(tie) == 9 and all(a < b for b, a in tie.items())
    graph, _ = gtsam.load2D(str(path), noiseFormat=gtsam.NoiseFormat.NoiseFormatTORO)
    ds = import_graph(path, forward="x", convention="toro")
    md = ds.metadata
    assert ds.inputs.n_poses == 30 - 9 and md["equiv_dropped_edges"] > 0
    assert graph.size() == len(g["pose_edges"]) + md["equiv_dropped_edges"]
    poses, lms, values = _values(_pose_ids(path, "toro"), [], 4, tie=tie)
    ours = _our_cost(path, "toro", poses, lms)
    assert ours > 1.0
    assert ours + md["equiv_dropped_cost"] == pytest.approx(graph.error(values), rel=COST_RTOL)


def _isam_gtsam_graph(path: Path) -> gtsam.NonlinearFactorGraph:
    """GTSAM factors for an iSAM file, from its text: Λ = RᵀR with R the upper triangle given."""
    graph = gtsam.NonlinearFactorGraph()
    for line in path.read_text().splitlines():
        f = line.split()
        if not f or f[0].startswith("#"):
            continue
        i, j, v = int(f[1]), int(f[2]), [float(x) for x in f[3:]]
        if f[0] in ("ODOMETRY", "EDGE2"):
            R = np.array([[v[3], v[4], v[5]], [0, v[6], v[7]], [0, 0, v[8]]])
            graph.add(gtsam.BetweenFactorPose2(i, j, gtsam.Pose2(*v[:3]), gtsam.noiseModel.Gaussian.SqrtInformation(R)))
        else:  # LANDMARK: the landmark in the pose's frame
            R = np.array([[v[2], v[3]], [0, v[4]]])
            z = np.array(v[:2])

            def err(this, values, H, z=z):
                pose, m = values.atPose2(this.keys()[0]), values.atPoint2(this.keys()[1])
                local = pose.transformTo(m)
                if H is not None:  # ∂/∂(pose tangent), ∂/∂m of Rᵀ(m − t)
                    H[0] = np.array([[-1.0, 0.0, local[1]], [0.0, -1.0, -local[0]]])
                    H[1] = pose.rotation().matrix().T
                return local - z

            graph.add(gtsam.CustomFactor(gtsam.noiseModel.Gaussian.SqrtInformation(R), [i, L(j)], err))
    return graph


def test_isam_square_root_information_and_own_landmark_ids():
    path = DATA / "isam_landmarks.txt"
    # every refusal names the reading it assumed and the conventions that read the line
    with pytest.raises(DatasetImportError, match=r"isam_landmarks.txt:17: EDGE2 matrix is not positive definite "
                                                 r"read as information, toro order \(convention auto\); valid "
                                                 r"under .*--convention isam \(sqrt-information, g2o order\)"):
        import_graph(path)
    with pytest.raises(DatasetImportError, match=r"isam_landmarks.txt:5: landmark id 0 is also a pose id "
                                                 r"\(convention g2o: .*--convention gtsam or isam"):
        import_graph(path, convention="g2o")
    graph = _isam_gtsam_graph(path)
    ds = import_graph(path, forward="x", convention="isam")
    assert ds.metadata["landmark_id_space"] == "own id space" and ds.metadata["landmark_ids"] == [0, 1, 2]
    assert ds.inputs.n_poses == 7 and len(ds.inputs.observations) == 9 and ds.metadata["n_loop_closures"] == 1
    for seed in (5, 6):
        poses, lms, values = _values(range(7), range(3), seed)
        ref = graph.error(values)
        assert ref > 1.0
        assert _our_cost(path, "isam", poses, lms) == pytest.approx(ref, rel=COST_RTOL)


def test_gtsam_convention_refuses_what_load2d_cannot_read(tmp_path):
    f = tmp_path / "g.graph"
    f.write_text("EDGE2 0 1 1 0 0 20 2 15 30 1 3\n")  # not diagonal: load2D's AUTO refuses it too
    with pytest.raises(DatasetImportError, match=r"g.graph:1: EDGE2 matrix .* has no diagonal layout GTSAM's load2D "
                                                 r"recognises \(convention gtsam\); valid under --convention toro"):
        import_graph(f, convention="gtsam")
    with pytest.raises(ValueError, match="unrecognized covariance matrix format"):
        gtsam.load2D(str(f))
    f.write_text("EDGE_SE2 0 1 1 0 0 1 0 0 1 0 1\nEDGE_SE2_XY 0 5 1 0 1 0 1\n")
    with pytest.raises(DatasetImportError, match=r"g.graph:2: EDGE_SE2_XY is not read by GTSAM's load2D "
                                                 r"\(convention gtsam, which skips it\); pass --convention g2o"):
        import_graph(f, convention="gtsam")
    f.write_text("ODOMETRY 0 1 1 0 0 1 0 0 1 0 1\nLANDMARK 0 5 1 0 0.4 0 0.9\n")
    with pytest.raises(DatasetImportError, match=r"g.graph:2: LANDMARK covariance .* is not c·I"):
        import_graph(f, convention="gtsam")


def test_cli_summary_names_the_convention(tmp_path):
    out = tmp_path / "w.h5"
    r = runner.invoke(app, ["import", "g2o", str(DATA / "w100_equiv_excerpt.graph"), "--convention", "toro",
                            "-o", str(out)])
    assert r.exit_code == 0, r.output
    assert "convention toro: EDGE2 information, toro order; landmark ids: shared with pose ids; EQUIV merged 9 " \
           "pose(s)" in r.stdout
    r = runner.invoke(app, ["import", "g2o", str(DATA / "isam_landmarks.txt"), "-o", str(tmp_path / "i.h5")])
    assert r.exit_code == 1 and r.output.count("\n") == 1 and "--convention isam" in r.output
    r = runner.invoke(app, ["import", "g2o", str(DATA / "isam_landmarks.txt"), "--convention", "isam",
                            "-o", str(tmp_path / "i.h5")])
    assert r.exit_code == 0, r.output
    assert ("convention isam: ODOMETRY sqrt-information, g2o order; LANDMARK sqrt-information; EDGE2 "
            "sqrt-information, g2o order; landmark ids: own id space") in r.stdout


@pytest.mark.parametrize(("name", "convention"), [
    ("gtsam_example_excerpt.graph", "gtsam"),
    ("victoria_park_excerpt.txt", "gtsam"),
    ("toro_nondiagonal.graph", "toro"),
    ("isam_landmarks.txt", "isam"),
])
def test_imports_solve_to_gtsams_optimum(name, convention):
    """The graph solver on the import ends at the cost GTSAM's Levenberg-Marquardt reaches on GTSAM's own
    reading of the file (plus the solver's prior on the first pose, added to GTSAM's graph)."""
    from slamcli.api.solve import solve_dataset

    path = DATA / name
    ds = import_graph(path, forward="x", convention=convention)
    params = {"robust": "none", "covariance": False}
    if len(ds.inputs.observations):
        params["association"] = "reported"
    res = solve_dataset(ds.inputs, "graph", params)
    assert res.status.value == "converged", res.message
    if convention == "isam":
        graph = _isam_gtsam_graph(path)
        init = gtsam.Values()
        for p, x in enumerate(ds.inputs.odometry_xyt):
            init.insert(p, gtsam.Pose2(*x))
        for m in range(3):
            init.insert(L(m), np.zeros(2))
    else:
        fmt = gtsam.NoiseFormat.NoiseFormatTORO if convention == "toro" else gtsam.NoiseFormat.NoiseFormatAUTO
        graph, init = gtsam.load2D(str(path), noiseFormat=fmt)
    first = _pose_ids(path, convention)[0]
    sigmas = np.asarray(res.params["prior_std"], float)
    graph.add(gtsam.PriorFactorPose2(first, gtsam.Pose2(*ds.inputs.x0), gtsam.noiseModel.Diagonal.Sigmas(sigmas)))
    params = gtsam.LevenbergMarquardtParams()
    params.setRelativeErrorTol(1e-14)
    params.setAbsoluteErrorTol(1e-14)
    params.setMaxIterations(500)
    ref = gtsam.LevenbergMarquardtOptimizer(graph, init, params).optimize()
    assert graph.error(init) > 1.5 * graph.error(ref)  # the start is not already the optimum
    assert res.extra["final_cost"] == pytest.approx(graph.error(ref), rel=1e-6)  # two optimisers: 1e-6
