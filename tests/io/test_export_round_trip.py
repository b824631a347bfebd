"""Export → import → solve, and sightings counted in and out of every export format.

Round trip: the EKF result of ``test_export_lossless``'s cluttered loop (some sightings unassociated), exported with
``--format gtsam``, read back by ``slamcli import g2o`` and solved there by ``slamcli solve -m graph -p
association=reported -p init_from=init --init R.h5`` must equal solving the original dataset with the EKF's
association from the same start (``-p association=init --init R.h5 -p init_from=init``): the same factors
(unassociated sightings become landmarks of their own, which fit them exactly and move nothing), so the same
optimum to :data:`ROUND_TRIP_TOL` — only the order of float sums differs. Both solves use
``group_returns=false``: the file holds one BR line per sighting, while the default merges the rows of one
(pose, landmark) pair into one mean measurement on the original dataset (a different objective when the EKF
gave a pose two sightings of one landmark). The independent reference is GTSAM:
``readG2o`` of the exported file plus the same prior on x_0 (σ = 1e-4), optimised by its Levenberg-Marquardt,
equal to ours to :data:`GTSAM_TOL` (its own stopping rule, not ours). On a real excerpt (MRCLAM robot 5, one
row per pose-landmark pair) the round trip holds with the graph solver's defaults.

Counting: for every format of ``slamcli export`` the file is parsed here (evo's readers for TUM/KITTI, pandas
for CSV, line tags for g2o/GTSAM) and what it holds is counted against the result: poses, landmarks and
sightings. None may drop any silently: g2o and GTSAM hold every sighting (and read them back), TUM and KITTI
say they hold poses only, CSV names the poses and landmarks it holds.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from conftest import DATA
from test_export_lossless import _invoke, cluttered  # noqa: F401  (module fixture: a cluttered loop, its EKF result)

from slamcli.cli.export_cmd import EXPORT_FORMATS
from slamcli.io import read_dataset, read_result

#: m and rad: our two solves of the same factors from the same start (float summation order only)
ROUND_TRIP_TOL = 1e-8
#: m and rad: ours against GTSAM's Levenberg-Marquardt on the exported file (different stopping rules)
GTSAM_TOL = 1e-5
#: relative: the final costs of the two solves
COST_RTOL = 1e-9
#: evo parses the text we wrote (17 significant digits); the yaw goes through a quaternion
FILE_TOL = 1e-9


def _with_ekf(fixture):
    d, ds = fixture
    ekf = read_result(d / "ekf.h5")
    assert np.count_nonzero(ekf.assoc < 0) > 0  # clutter the EKF left unassociated
    return d, ds, ekf


def test_gtsam_export_import_solve_equals_solving_the_original(cluttered):  # noqa: F811
    d, ds, ekf = _with_ekf(cluttered)
    _invoke(["export", d / "ekf.h5", "--format", "gtsam", "-o", d / "ekf.txt", "-q"])
    _invoke(["import", "g2o", d / "ekf.txt", "-o", d / "back.h5", "-q"])
    common = ["-m", "graph", "-p", "init_from=init", "--init", d / "ekf.h5", "-p", "robust=none",
              "-p", "covariance=false", "-p", "group_returns=false", "-q"]
    _invoke(["solve", d / "back.h5", *common, "-p", "association=reported", "-o", d / "back_graph.h5"])
    _invoke(["solve", d / "d.h5", *common, "-p", "association=init", "-o", d / "orig_graph.h5"])
    back, orig = read_result(d / "back_graph.h5"), read_result(d / "orig_graph.h5")
    assert orig.status.value == back.status.value == "converged"
    assert np.max(np.abs(orig.poses_xyt - ekf.poses_xyt)) > 1e-3  # the solve moved the start: not vacuous
    np.testing.assert_allclose(back.poses_xyt, orig.poses_xyt, rtol=0, atol=ROUND_TRIP_TOL)
    assert back.extra["final_cost"] == pytest.approx(orig.extra["final_cost"], rel=COST_RTOL)
    # every sighting the EKF associated sees the same landmark position in both; the others see their own
    seen = orig.assoc >= 0
    np.testing.assert_allclose(back.landmarks_xy[back.assoc[seen]], orig.landmarks_xy[orig.assoc[seen]], rtol=0,
                               atol=ROUND_TRIP_TOL)
    assert len(back.landmarks_xy) == len(orig.landmarks_xy) + np.count_nonzero(~seen)
    n = ds.inputs.n_poses

    gtsam = pytest.importorskip("gtsam")
    graph, values = gtsam.readG2o(str(d / "ekf.txt"), False)
    graph.add(gtsam.PriorFactorPose2(0, gtsam.Pose2(*ds.inputs.x0), gtsam.noiseModel.Diagonal.Sigmas([1e-4] * 3)))
    params = gtsam.LevenbergMarquardtParams()
    params.setRelativeErrorTol(1e-14)
    params.setAbsoluteErrorTol(1e-14)
    out = gtsam.LevenbergMarquardtOptimizer(graph, values, params).optimize()
    ref = np.array([[out.atPose2(i).x(), out.atPose2(i).y(), out.atPose2(i).theta()] for i in range(n)])
    err = orig.poses_xyt - ref
    err[:, 2] = np.angle(np.exp(1j * err[:, 2]))
    assert np.max(np.abs(err)) < GTSAM_TOL
    assert orig.extra["final_cost"] == pytest.approx(graph.error(out), rel=GTSAM_TOL)


def test_round_trip_on_a_real_excerpt_with_default_parameters(tmp_path):
    """MRCLAM robot 5 (tests/data excerpt, point sensor): the same round trip with the graph solver's defaults
    (robust kernel ``auto``, grouped returns) equals solving the original dataset."""
    data = DATA / "mrclam_team_excerpt"
    _invoke(["import", "mrclam", data, "--robot", "5", "-q", "-o", tmp_path / "d.h5"])
    _invoke(["solve", tmp_path / "d.h5", "-m", "ekf", "-q", "-o", tmp_path / "ekf.h5"])
    _invoke(["export", tmp_path / "ekf.h5", "--format", "gtsam", "-q", "-o", tmp_path / "ekf.txt"])
    _invoke(["import", "g2o", tmp_path / "ekf.txt", "-q", "-o", tmp_path / "back.h5"])
    common = ["-m", "graph", "-p", "init_from=init", "--init", tmp_path / "ekf.h5", "-p", "covariance=false", "-q"]
    _invoke(["solve", tmp_path / "back.h5", *common, "-p", "association=reported", "-o", tmp_path / "b.h5"])
    _invoke(["solve", tmp_path / "d.h5", *common, "-p", "association=init", "-o", tmp_path / "o.h5"])
    back, orig = read_result(tmp_path / "b.h5"), read_result(tmp_path / "o.h5")
    assert orig.status.value == back.status.value == "converged"
    assert np.max(np.abs(orig.poses_xyt - read_result(tmp_path / "ekf.h5").poses_xyt)) > 1e-3
    np.testing.assert_allclose(back.poses_xyt, orig.poses_xyt, rtol=0, atol=ROUND_TRIP_TOL)
    assert back.extra["final_cost"] == pytest.approx(orig.extra["final_cost"], rel=COST_RTOL)


def _count_file(fmt: str, path: Path) -> dict:
    """Poses, landmarks and sightings in an exported file, by a parser that is not slamcli's."""
    if fmt in ("tum", "kitti"):
        from evo.tools import file_interface

        traj = (file_interface.read_tum_trajectory_file(str(path)) if fmt == "tum"
                else file_interface.read_kitti_poses_file(str(path)))
        xy = traj.positions_xyz[:, :2]
        T = np.asarray(traj.poses_se3)
        yaw = np.arctan2(T[:, 1, 0], T[:, 0, 0])
        return {"poses": np.column_stack([xy, yaw]), "landmarks": None, "sightings": None}
    if fmt == "csv":
        df = pd.read_csv(path)
        p = df[df["kind"] == "pose"]
        return {"poses": p[["x_m", "y_m", "theta_rad"]].to_numpy(), "landmarks": int((df["kind"] == "landmark").sum()),
                "sightings": None}
    rows = [ln.split() for ln in path.read_text().splitlines() if ln.split()]
    tag = "EDGE_SE2_XY" if fmt == "g2o" else "BR"
    return {"poses": np.array([[float(v) for v in f[2:5]] for f in rows if f[0] == "VERTEX_SE2"]),
            "landmarks": sum(f[0] == "VERTEX_XY" for f in rows), "sightings": sum(f[0] == tag for f in rows)}


@pytest.mark.parametrize("source", ["result", "truth"])
@pytest.mark.parametrize("fmt", EXPORT_FORMATS)
def test_every_format_counts_sightings_in_and_out(cluttered, tmp_path, fmt, source):  # noqa: F811
    d, ds, ekf = _with_ekf(cluttered)
    src = d / "ekf.h5" if source == "result" else d / "d.h5"
    poses = ekf.poses_xyt if source == "result" else ds.truth.poses_xyt
    n_lm = len(ekf.landmarks_xy) if source == "result" else len(ds.truth.landmarks_xy)
    assoc = ekf.assoc if source == "result" else ds.truth.obs_landmark
    n_obs, n_alone = len(ds.inputs.observations), int(np.count_nonzero(np.asarray(assoc) < 0))
    assert n_alone > 0  # clutter: the sightings an export once dropped
    out = tmp_path / f"x.{fmt}"
    msg = _invoke(["export", src, "--format", fmt, "-o", out]).stdout
    got = _count_file(fmt, out)
    err = got["poses"] - poses
    err[:, 2] = np.angle(np.exp(1j * err[:, 2]))
    assert got["poses"].shape == poses.shape and np.max(np.abs(err)) < FILE_TOL
    assert f"{len(poses)} poses" in msg
    if got["landmarks"] is None:
        assert f"{fmt.upper()} holds poses only" in msg
    elif got["sightings"] is None:  # CSV: the map, no sightings (and says how many landmarks it holds)
        assert got["landmarks"] == n_lm and f"{n_lm} landmarks" in msg and "sightings" not in msg
    else:
        assert got["sightings"] == n_obs and got["landmarks"] == n_lm + n_alone
        assert f"{n_obs} sightings" in msg and f"{n_alone} unassociated" in msg
        r = _invoke(["import", "g2o", out, "-o", tmp_path / "back.h5"])  # counted in
        assert len(read_dataset(tmp_path / "back.h5").inputs.observations) == n_obs
        assert f"{n_obs} observations" in r.stdout
