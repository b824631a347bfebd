"""Export (TUM/KITTI/g2o/CSV) checked against evo's APE and GTSAM's readG2o; import of foreign trajectories."""

import numpy as np
import pandas as pd
import pytest
from typer.testing import CliRunner

from slamcli.api.evaluate import evaluate_files
from slamcli.api.interop import export_file, import_trajectory_file, trajectory_at
from slamcli.api.simulate import simulate_to_file
from slamcli.api.solve import solve_file
from slamcli.cli import app
from slamcli.datasets.g2o import read_graph
from slamcli.io import export as ex
from slamcli.io import read_dataset, read_result
from slamcli.models import se2

runner = CliRunner()


@pytest.fixture(scope="module")
def run(tmp_path_factory):
    d = tmp_path_factory.mktemp("export")
    data = d / "loop.h5"
    simulate_to_file("loop", 3, {"n_steps": 200}, data)
    res = d / "graph.h5"
    solve_file(data, "graph", {}, res)
    return d, data, res


def test_tum_and_kitti_lift_planar_poses(tmp_path):
    poses = np.array([[1.0, 2.0, 0.3], [-4.0, 0.5, -3.0], [0.0, 0.0, np.pi - 1e-9]])
    ex.write_tum(tmp_path / "a.tum", [0.0, 0.5, 1.0], poses)
    a = np.loadtxt(tmp_path / "a.tum")
    # hand values for the second pose: q = (0, 0, sin(-1.5), cos(-1.5))
    np.testing.assert_allclose(a[1], [0.5, -4.0, 0.5, 0.0, 0.0, 0.0, np.sin(-1.5), np.cos(-1.5)], rtol=0, atol=1e-15)
    t, back = ex.read_tum(tmp_path / "a.tum")
    np.testing.assert_allclose(back, poses, atol=1e-12)
    ex.write_kitti(tmp_path / "a.kitti", poses)
    k = np.loadtxt(tmp_path / "a.kitti").reshape(-1, 3, 4)
    np.testing.assert_allclose(k[0], [[np.cos(0.3), -np.sin(0.3), 0, 1], [np.sin(0.3), np.cos(0.3), 0, 2], [0, 0, 1, 0]],
                               atol=1e-15)
    np.testing.assert_allclose(ex.read_kitti(tmp_path / "a.kitti"), poses, atol=1e-12)


def _evo_ape(ref_path, est_path, align):
    from evo.core import metrics, sync
    from evo.tools import file_interface

    ref = file_interface.read_tum_trajectory_file(str(ref_path))
    est = file_interface.read_tum_trajectory_file(str(est_path))
    ref, est = sync.associate_trajectories(ref, est)
    if align:
        est.align(ref, correct_scale=False)
    ape = metrics.APE(metrics.PoseRelation.translation_part)
    ape.process_data((ref, est))
    return ape.get_statistic(metrics.StatisticsType.rmse)


@pytest.mark.slow
def test_evo_ape_equals_our_ate(run, tmp_path):
    pytest.importorskip("evo")
    _, data, res = run
    export_file(res, "tum", tmp_path / "est.tum")
    export_file(data, "tum", tmp_path / "ref.tum")
    m = evaluate_files(res)
    unaligned = _evo_ape(tmp_path / "ref.tum", tmp_path / "est.tum", align=False)
    aligned = _evo_ape(tmp_path / "ref.tum", tmp_path / "est.tum", align=True)
    assert m["ate_rmse_m"] > 0.005 and m["aligned_ate_rmse_m"] < m["ate_rmse_m"]  # a non-trivial comparison
    assert unaligned == pytest.approx(m["ate_rmse_m"], rel=1e-6)
    assert aligned == pytest.approx(m["aligned_ate_rmse_m"], rel=1e-6)


def test_gtsam_readg2o_reads_our_export(run, tmp_path):
    gtsam = pytest.importorskip("gtsam")
    _, data, res_path = run
    out = tmp_path / "graph.g2o"
    s = export_file(res_path, "g2o", out)
    res, ds = read_result(res_path), read_dataset(data)
    graph, values = gtsam.readG2o(str(out), False)
    n = len(res.poses_xyt)
    got = np.array([[values.atPose2(i).x(), values.atPose2(i).y(), values.atPose2(i).theta()] for i in range(n)])
    np.testing.assert_allclose(got, res.poses_xyt, rtol=0, atol=1e-12)
    from gtsam.symbol_shorthand import L

    lms = np.array([values.atPoint2(L(n + l)) for l in range(len(res.landmarks_xy))])
    np.testing.assert_allclose(lms, res.landmarks_xy, rtol=0, atol=1e-12)
    # the odometry factors: measured increments and the σ the graph solver uses
    d = se2.between(ds.inputs.odometry_xyt[:-1], ds.inputs.odometry_xyt[1:])
    assert graph.size() == n - 1
    for t in (0, n // 2, n - 2):
        f = graph.at(t)
        m = f.measured()
        np.testing.assert_allclose([m.x(), m.y(), m.theta()], d[t], atol=1e-12)
        np.testing.assert_allclose(f.noiseModel().sigmas(), ds.inputs.noise.odometry_std, rtol=1e-12)
    # landmark edges (GTSAM's loader skips EDGE_SE2_XY; our g2o reader parses them): offsets and covariances
    g = read_graph(out)
    assert len(g["landmark_obs"]) + len(g["odometry"]) == s["n_edges"]
    obs = ds.inputs.observations
    rows = np.flatnonzero(res.assoc >= 0)
    assert len(g["landmark_obs"]) == len(rows)
    sr, sb = ds.inputs.noise.range_std, ds.inputs.noise.bearing_std
    for k in (0, len(rows) // 2, len(rows) - 1):
        i, l, xy, cov, _ = g["landmark_obs"][k]
        row = rows[k]
        assert i == obs.step[row] and l == n + res.assoc[row]
        r, b = obs.range_m[row], obs.bearing_rad[row]
        np.testing.assert_allclose(xy, [r * np.cos(b), r * np.sin(b)], atol=1e-12)
        # first-order propagation with a finite-difference Jacobian of (r, b) -> r [cos b, sin b]
        h = 1e-6
        f = lambda rb: rb[0] * np.array([np.cos(rb[1]), np.sin(rb[1])])
        J = np.column_stack([(f([r + h, b]) - f([r - h, b])) / (2 * h), (f([r, b + h]) - f([r, b - h])) / (2 * h)])
        np.testing.assert_allclose(cov, J @ np.diag([sr**2, sb**2]) @ J.T, rtol=1e-6)


def test_csv_export_is_tidy(run, tmp_path):
    _, data, res_path = run
    export_file(res_path, "csv", tmp_path / "r.csv")
    df = pd.read_csv(tmp_path / "r.csv")
    res = read_result(res_path)
    poses = df[df.kind == "pose"]
    lms = df[df.kind == "landmark"]
    np.testing.assert_array_equal(poses[["x_m", "y_m", "theta_rad"]].to_numpy(), res.poses_xyt)
    np.testing.assert_array_equal(lms[["x_m", "y_m"]].to_numpy(), res.landmarks_xy)
    np.testing.assert_array_equal(poses["cov_tt"].to_numpy(), res.pose_cov[:, 2, 2])


def test_cli_export_and_errors(run, tmp_path):
    _, data, res = run
    r = runner.invoke(app, ["export", str(res), "--format", "kitti", "-o", str(tmp_path / "e.kitti")])
    assert r.exit_code == 0, r.output
    assert len(np.loadtxt(tmp_path / "e.kitti")) == len(read_result(res).poses_xyt)
    r = runner.invoke(app, ["export", str(res), "--format", "ply", "-o", str(tmp_path / "e.ply")])
    assert r.exit_code == 2 and "'tum', 'kitti', 'g2o', 'gtsam', 'csv'" in r.output
    assert not (tmp_path / "e.ply").exists()


def test_interpolation_hand_values():
    t = np.array([0.0, 1.0, 2.0])
    P = np.array([[0.0, 0.0, 3.0], [2.0, 4.0, -3.0], [2.0, 6.0, 0.0]])
    out, exact = trajectory_at(t, P, [0.25, 1.0, 1.5, 2.5, -0.1])
    # heading 3.0 → -3.0 goes the short way through ±π: 3 + 0.25·(2π − 6)
    np.testing.assert_allclose(out[0], [0.5, 1.0, 3.0 + 0.25 * (2 * np.pi - 6.0)], atol=1e-12)
    np.testing.assert_allclose(out[1], P[1])
    np.testing.assert_allclose(out[2], [2.0, 5.0, -1.5], atol=1e-12)
    assert np.isnan(out[3]).all() and np.isnan(out[4]).all()
    assert exact.tolist() == [False, True, False, False, False]


def test_import_trajectory_roundtrip_and_interpolation(run, tmp_path):
    d, data, res_path = run
    res = read_result(res_path)
    ds = read_dataset(data)
    ts = ds.inputs.timestamps
    # round trip: export our estimate, import it back → same poses, same ATE
    export_file(res_path, "tum", tmp_path / "est.tum")
    imp = tmp_path / "imp.h5"
    r = runner.invoke(app, ["import", "trajectory", str(tmp_path / "est.tum"), "--data", str(data), "-o", str(imp)])
    assert r.exit_code == 0, r.output
    back = read_result(imp)
    np.testing.assert_allclose(back.poses_xyt, res.poses_xyt, atol=1e-12)
    assert back.extra["n_matched"] == len(ts)
    assert evaluate_files(imp)["ate_rmse_m"] == pytest.approx(evaluate_files(res_path)["ate_rmse_m"], rel=1e-12)
    # a foreign estimator at every 4th stamp on another clock (+100 s): the rest is interpolated
    keep = np.unique(np.r_[0:len(ts):4, len(ts) - 1])
    ex.write_tum(tmp_path / "sub.tum", ts[keep] + 100.0, res.poses_xyt[keep])
    sub = import_trajectory_file(tmp_path / "sub.tum", data, tmp_path / "sub.h5", time_offset=-100.0)
    assert sub.extra["n_matched"] == len(keep) and sub.extra["n_interpolated"] == len(ts) - len(keep)
    k = 5  # between stamps 4 and 8: s = 1/4
    a, b = res.poses_xyt[4], res.poses_xyt[8]
    np.testing.assert_allclose(sub.poses_xyt[k, :2], a[:2] + 0.25 * (b[:2] - a[:2]), atol=1e-9)
    # no overlap → one line, no file
    r = runner.invoke(app, ["import", "trajectory", str(tmp_path / "sub.tum"), "--data", str(data),
                            "-o", str(tmp_path / "x.h5")])
    assert r.exit_code == 1 and "no time overlap" in r.output and len(r.output.strip().splitlines()) == 1
    assert not (tmp_path / "x.h5").exists()
    # partial coverage: error by default, hold on request
    ex.write_tum(tmp_path / "part.tum", ts[10:], res.poses_xyt[10:])
    with pytest.raises(Exception, match="10 of"):
        import_trajectory_file(tmp_path / "part.tum", data, tmp_path / "p.h5")
    held = import_trajectory_file(tmp_path / "part.tum", data, tmp_path / "p.h5", extrapolate="hold")
    assert held.extra["n_held"] == 10
    np.testing.assert_allclose(held.poses_xyt[:10], np.repeat(res.poses_xyt[10][None], 10, 0))
    # KITTI by index
    ex.write_kitti(tmp_path / "e.kitti", res.poses_xyt)
    kit = import_trajectory_file(tmp_path / "e.kitti", data, tmp_path / "k.h5")
    np.testing.assert_allclose(kit.poses_xyt, res.poses_xyt, atol=1e-12)
    ex.write_kitti(tmp_path / "short.kitti", res.poses_xyt[:-1])
    with pytest.raises(Exception, match="--times"):
        import_trajectory_file(tmp_path / "short.kitti", data, tmp_path / "k2.h5")


def test_moved_result_and_dataset_still_evaluate(run, tmp_path):
    import shutil

    _, data, _ = run
    (tmp_path / "x" / "data").mkdir(parents=True)
    shutil.copy(data, tmp_path / "x" / "data" / "d.h5")
    solve_file(tmp_path / "x" / "data" / "d.h5", "odometry", {}, tmp_path / "x" / "res" / "r.h5")
    assert read_result(tmp_path / "x" / "res" / "r.h5").extra["dataset_relpath"] == "../data/d.h5"
    shutil.move(tmp_path / "x", tmp_path / "y")  # the recorded absolute path is gone
    m = evaluate_files(tmp_path / "y" / "res" / "r.h5")
    assert m["dataset_path"] == str(tmp_path / "y" / "res" / "../data/d.h5")
    assert m["ate_rmse_m"] > 0
