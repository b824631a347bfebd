"""Lossless graph import: every edge keeps its information matrix, all tags, ``--max-poses``.

The reference for the DLR excerpt is an independent fit: the file's lines are parsed here, the per-edge
model (``EDGE_SE2``: SE(2) log error of ``d⁻¹ ⊕ x_i⁻¹ ⊕ x_j`` as GTSAM's ``BetweenFactorPose2``;
``EDGE_SE2_XY``: landmark in the pose frame minus the measured offset) is written with its own small SE(2)
code, whitened by each edge's information and minimised with ``scipy.optimize.least_squares`` in the file's
own axes (no body-frame change).
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from conftest import DATA
from scipy.optimize import least_squares
from typer.testing import CliRunner

from slamcli.api.solve import solve_dataset
from slamcli.cli import app
from slamcli.datasets import DatasetImportError
from slamcli.datasets.g2o import import_graph, read_graph
from slamcli.io import read_dataset

DLR = DATA / "dlr_excerpt.g2o"
INTEL = DATA / "intel_excerpt.g2o"
runner = CliRunner()


def _wrap(a):
    return (np.asarray(a) + np.pi) % (2 * np.pi) - np.pi


def _log(x, y, th):
    """SE(2) logarithm ``[v_x, v_y, ω]`` of one pose (θ wrapped), by solving ``V v = t``."""
    th = float(_wrap(th))
    if abs(th) < 1e-9:
        return np.array([x, y, th])
    V = np.array([[math.sin(th), -(1 - math.cos(th))], [1 - math.cos(th), math.sin(th)]]) / th
    v = np.linalg.solve(V, [x, y])
    return np.array([v[0], v[1], th])


def _rel(a, b):
    """Pose of b in a's frame."""
    c, s = math.cos(a[2]), math.sin(a[2])
    dx, dy = b[0] - a[0], b[1] - a[1]
    return np.array([c * dx + s * dy, -s * dx + c * dy, b[2] - a[2]])


def _dlr_reference():
    lines = [ln.split() for ln in DLR.read_text().splitlines() if ln.split()]
    v = {int(f[1]): np.array(f[2:5], float) for f in lines if f[0] == "VERTEX_SE2"}
    vl = {int(f[1]): np.array(f[2:4], float) for f in lines if f[0] == "VERTEX_XY"}
    edges = [f for f in lines if f[0] == "EDGE_SE2"]
    obs = [f for f in lines if f[0] == "EDGE_SE2_XY"]
    pids = sorted({int(f[1]) for f in edges} | {int(f[2]) for f in edges})
    lids = sorted({int(f[2]) for f in obs})
    P = {p: k for k, p in enumerate(pids)}
    Lm = {lid: k for k, lid in enumerate(lids)}
    nP = len(pids)

    def chol_t(m):
        return np.linalg.cholesky(m).T  # LᵀL = m

    E = [(P[int(f[1])], P[int(f[2])], np.array(f[3:6], float),
          chol_t(np.array([[float(f[6]), float(f[7]), float(f[8])], [float(f[7]), float(f[9]), float(f[10])],
                           [float(f[8]), float(f[10]), float(f[11])]]))) for f in edges]
    O = [(P[int(f[1])], Lm[int(f[2])], np.array(f[3:5], float),
          chol_t(np.array([[float(f[5]), float(f[6])], [float(f[6]), float(f[7])]]))) for f in obs]
    prior = v[pids[0]]

    def residuals(z):
        x = z[: 3 * nP].reshape(-1, 3)
        m = z[3 * nP :].reshape(-1, 2)
        out = [_log(*_rel(prior, x[0])) / 1e-4]
        for i, j, d, L in E:
            err = _rel(d, _rel(x[i], x[j]))  # d⁻¹ ⊕ (x_i⁻¹ ⊕ x_j)
            out.append(L @ _log(*err))
        for i, lj, zz, L in O:
            c, s = math.cos(x[i, 2]), math.sin(x[i, 2])
            dx, dy = m[lj] - x[i, :2]
            out.append(L @ (np.array([c * dx + s * dy, -s * dx + c * dy]) - zz))
        return np.concatenate(out)

    z0 = np.concatenate([np.array([v[p] for p in pids]).ravel(), np.array([vl[lid] for lid in lids]).ravel()])
    sol = least_squares(residuals, z0, method="trf", x_scale="jac", ftol=1e-15, xtol=1e-15, gtol=1e-15, max_nfev=200)
    x = sol.x[: 3 * nP].reshape(-1, 3)
    m = sol.x[3 * nP :].reshape(-1, 2)
    return x, m, 0.5 * float(sol.fun @ sol.fun), lids, residuals, nP


@pytest.mark.slow
def test_dlr_excerpt_optimum_equals_direct_least_squares_of_the_per_edge_model():
    ds = import_graph(DLR)
    inp = ds.inputs
    c = inp.constraints
    assert c.odometry_info.shape == (59, 3, 3) and c.observation_info.shape == (258, 2, 2)
    assert c.observation_model == "xy" and c.n_between == 0
    x_ref, m_ref, cost_ref, lids, residuals, nP = _dlr_reference()
    res = solve_dataset(inp, "graph", {"association": "reported", "covariance": False})
    assert res.status.value == "converged"
    assert abs(res.extra["final_cost"] - cost_ref) <= 1e-6 * cost_ref
    np.testing.assert_allclose(res.poses_xyt[:, :2], x_ref[:, :2], atol=1e-6)  # world positions: same frame
    np.testing.assert_allclose(_wrap(res.poses_xyt[:, 2] - (x_ref[:, 2] - math.pi / 2)), 0, atol=1e-6)  # forward -y
    lm = np.empty_like(m_ref)
    rid = inp.observations.reported_id
    for row, lab in enumerate(res.assoc):
        lm[rid[row]] = res.landmarks_xy[lab]
    assert ds.metadata["landmark_ids"] == lids
    np.testing.assert_allclose(lm, m_ref, atol=1e-6)

    # the old lossy import (one median σ per quantity) optimises another cost: its optimum is measurably
    # worse in the file's own cost, and its poses are off — the check above could fail
    lossy = solve_dataset(inp, "graph", {"association": "reported", "covariance": False, "edge_info": False})
    lm_lossy = np.empty_like(m_ref)
    for row, lab in enumerate(lossy.assoc):
        lm_lossy[rid[row]] = lossy.landmarks_xy[lab]
    p_lossy = lossy.poses_xyt.copy()
    p_lossy[:, 2] += math.pi / 2
    f = residuals(np.concatenate([p_lossy.ravel(), lm_lossy.ravel()]))
    assert 0.5 * float(f @ f) > (1 + 1e-3) * cost_ref
    assert np.max(np.abs(lossy.poses_xyt[:, :2] - x_ref[:, :2])) > 1e-3


def test_tags_toro_gtsam_and_loop_closures(tmp_path):
    f = tmp_path / "mixed.graph"
    f.write_text(
        "VERTEX2 0 1 2 0.5\n"
        "EDGE2 0 1 1.0 0.0 0.1 10 1 20 30 2 3\n"  # TORO order ff fs ss rr fr sr
        "ODOMETRY 1 2 1.0 0.1 0.0 0.04 0 0 0.01 0 0.0025\n"  # covariance
        "EDGE_SE2 2 3 1.0 0.0 0.0 100 0 0 100 0 400\n"
        "EDGE_SE2 3 0 -0.5 2.0 -1.5 50 0 0 60 0 70\n"  # a loop closure, reversed direction
        "EDGE_SE2 0 1 1.1 0.0 0.1 5 0 0 5 0 5\n"  # a duplicate of the first odometry edge
        "LANDMARK2 1 10 2.0 1.0 4 1 5\n"
        "LANDMARK 2 11 3.0 -1.0 0.25 0 1.0\n"
    )
    g = read_graph(f)
    np.testing.assert_allclose(g["pose_edges"][0][4], [[10, 1, 2], [1, 20, 3], [2, 3, 30]])
    np.testing.assert_allclose(g["pose_edges"][1][4], np.linalg.inv(np.diag([0.04, 0.01, 0.0025])))
    np.testing.assert_allclose(g["sightings"][0][4], [[4, 1], [1, 5]])
    np.testing.assert_allclose(g["sightings"][1][4], np.diag([4.0, 1.0]))
    ds = import_graph(f, forward="x")
    c = ds.inputs.constraints
    assert ds.inputs.n_poses == 4 and c.n_between == 2 and ds.metadata["n_loop_closures"] == 2
    np.testing.assert_array_equal(c.between_ij, [[3, 0], [0, 1]])
    np.testing.assert_allclose(c.between_xyt, [[-0.5, 2.0, -1.5], [1.1, 0.0, 0.1]])
    np.testing.assert_allclose(c.between_info[0], np.diag([50.0, 60.0, 70.0]))
    np.testing.assert_allclose(c.odometry_info[0], [[10, 1, 2], [1, 20, 3], [2, 3, 30]])
    np.testing.assert_allclose(c.odometry_info[2], np.diag([100.0, 100.0, 400.0]))
    np.testing.assert_allclose(ds.inputs.x0, [1, 2, 0.5])
    # forward = y: info over (x, y) is rotated, R₃ Λ R₃ᵀ with R = R(−π/2)
    dy = import_graph(f, forward="y").inputs.constraints
    np.testing.assert_allclose(dy.between_info[0], np.diag([60.0, 50.0, 70.0]), atol=1e-12)
    np.testing.assert_allclose(dy.between_xyt[0], [2.0, 0.5, -1.5], atol=1e-12)


def test_bearing_range_rows_keep_their_sigmas(tmp_path):
    f = tmp_path / "br.txt"
    f.write_text("ODOMETRY 0 1 1 0 0 0.01 0 0 0.01 0 0.001\nBR 1 7 0.3 5.0 0.02 0.1\nBR 0 7 0.2 6.0 0.04 0.3\n")
    ds = import_graph(f)
    inp = ds.inputs
    c = inp.constraints
    assert c.observation_model == "range_bearing"
    np.testing.assert_allclose(inp.observations.z, [[6.0, 0.2], [5.0, 0.3]], atol=1e-12)
    np.testing.assert_allclose(c.observation_info, [np.diag([1 / 0.09, 1 / 0.0016]), np.diag([100.0, 2500.0])])
    assert inp.noise.range_std == pytest.approx(0.2) and inp.noise.bearing_std == pytest.approx(0.03)


@pytest.mark.slow
def test_max_poses_keeps_a_prefix_and_its_closures(tmp_path):
    full = import_graph(INTEL)
    part = import_graph(INTEL, max_poses=280)
    assert part.inputs.n_poses == 280 and full.inputs.n_poses == 300
    np.testing.assert_array_equal(part.inputs.odometry_xyt, full.inputs.odometry_xyt[:280])
    keep = np.all(full.inputs.constraints.between_ij < 280, axis=1)
    np.testing.assert_array_equal(part.inputs.constraints.between_ij, full.inputs.constraints.between_ij[keep])
    assert 0 < keep.sum() < len(keep)
    with pytest.raises(DatasetImportError, match="--max-poses: must be >= 2"):
        import_graph(INTEL, max_poses=1)
    out = tmp_path / "i.h5"
    res = runner.invoke(app, ["import", "g2o", str(INTEL), "--max-poses", "280", "-o", str(out)])
    assert res.exit_code == 0, res.output
    assert f"280 poses, {int(keep.sum())} loop closures" in res.stdout
    back = read_dataset(out).inputs.constraints
    np.testing.assert_array_equal(back.between_info, part.inputs.constraints.between_info)
    res = runner.invoke(app, ["info", str(out)])
    assert res.exit_code == 0 and f"{int(keep.sum())} loop closures" in res.stdout
    r = tmp_path / "r.h5"
    res = runner.invoke(app, ["solve", str(out), "-m", "graph", "-p", "init=chordal", "-p", "covariance=false",
                              "-o", str(r), "-q"])
    assert res.exit_code == 0, res.output
    from slamcli.io import read_result

    counts = read_result(r).extra["chi2_outliers"]
    assert counts["loop_closure"]["factors"] == int(keep.sum()) and counts["odometry"]["factors"] == 279
    res = runner.invoke(app, ["info", str(r)], terminal_width=200)
    lc = counts["loop_closure"]
    assert res.exit_code == 0
    assert f"loop_closure {lc['over_95']}/{lc['over_99']} of {lc['factors']}" in res.stdout
