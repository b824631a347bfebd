"""Victoria Park import (tests/data/victoria_park_excerpt: the first 60 s of the ASCII files), the motion-model
tag in the schema, the sensor-frame solve with the laser offset, one-line refusals, and GPS ATE."""

from __future__ import annotations

import json

import h5py
import numpy as np
import pytest
from conftest import DATA, tiny_dataset
from typer.testing import CliRunner

from slamcli.api.solve import solve_dataset
from slamcli.cli import app
from slamcli.datasets import DatasetImportError
from slamcli.datasets.victoria_park import import_victoria_park
from slamcli.io import dataset_hash, read_dataset, write_dataset
from slamcli.models.ackermann import VICTORIA_PARK, integrate_ackermann
from slamcli.models.observation import inverse_range_bearing_offset

VP = DATA / "victoria_park_excerpt"
runner = CliRunner()


@pytest.fixture(scope="module")
def vp():
    return import_victoria_park(VP)


def test_import_keeps_every_row_in_the_window(vp):
    raw_in = np.loadtxt(VP / "inputs.dat")
    raw_m = np.loadtxt(VP / "measurements.dat")
    raw_g = np.loadtxt(VP / "gps.dat")
    inp = vp.inputs
    assert inp.n_poses == len(raw_in) and inp.dt == pytest.approx(0.025)
    np.testing.assert_array_equal(inp.controls, raw_in[:-1, 1:3])
    # scans before the first input row (0.852 s < 0.973 s) have no pose: the rest are all kept
    kept = raw_m[raw_m[:, 0] >= raw_in[0, 0] - 0.0125]
    assert len(inp.observations) == len(kept)
    np.testing.assert_allclose(inp.observations.range_m, kept[:, 1])
    np.testing.assert_allclose(inp.observations.bearing_rad, kept[:, 2] - np.pi / 2)  # π/2 = ahead
    np.testing.assert_allclose(inp.observations.diameter_m, kept[:, 3])
    assert (inp.observations.reported_id == -1).all()  # unknown correspondence
    t_obs = inp.timestamps[inp.observations.step]
    assert np.abs(t_obs - kept[:, 0]).max() <= 0.0125 + 1e-9
    assert inp.motion_model == "ackermann" and inp.vehicle == VICTORIA_PARK
    np.testing.assert_array_equal(inp.sensor_offset_xy, [3.78, 0.50])
    np.testing.assert_allclose(inp.odometry_xyt, integrate_ackermann(np.zeros(3), inp.controls, 0.025, VICTORIA_PARK))
    assert vp.truth.position_reference_only and vp.truth.obs_landmark is None
    np.testing.assert_array_equal(vp.truth.ref_xy, raw_g[(raw_g[:, 0] >= raw_in[0, 0]), 1:3])


def test_round_trip_and_old_files_read_as_ddmr(vp, tmp_path):
    write_dataset(tmp_path / "vp.h5", vp)
    back = read_dataset(tmp_path / "vp.h5")
    assert dataset_hash(back) == dataset_hash(vp)
    assert back.inputs.motion_model == "ackermann" and back.inputs.vehicle == VICTORIA_PARK
    np.testing.assert_array_equal(back.inputs.observations.diameter_m, vp.inputs.observations.diameter_m)
    np.testing.assert_array_equal(back.truth.ref_time_s, vp.truth.ref_time_s)
    # a file written before issue 14 has no @motion_model: it reads as ddmr with the sensor at the origin,
    # and its content hash does not change
    tiny = tiny_dataset()
    write_dataset(tmp_path / "old.h5", tiny)
    with h5py.File(tmp_path / "old.h5", "a") as f:
        del f["inputs"].attrs["motion_model"]
    old = read_dataset(tmp_path / "old.h5")
    assert old.inputs.motion_model == "ddmr" and old.inputs.vehicle is None
    assert not old.inputs.sensor_offset_xy.any() and old.inputs.observations.diameter_m is None
    assert dataset_hash(old) == dataset_hash(tiny)
    # an unknown tag is one line naming the field
    with h5py.File(tmp_path / "old.h5", "a") as f:
        f["inputs"].attrs["motion_model"] = "tricycle"
    r = runner.invoke(app, ["info", str(tmp_path / "old.h5")])
    assert r.exit_code == 1 and "inputs/@motion_model" in r.stderr and len(r.stderr.strip().splitlines()) == 1


def test_odometry_solver_uses_the_laser_offset(vp):
    """Solved in the sensor frame and mapped back: poses are the car-model dead reckoning of the body, and
    each landmark is the mean of its rows' inverse observations from the LASER (offset) pose."""
    res = solve_dataset(vp.inputs, "odometry", {"nn_threshold": 1.5})
    inp = vp.inputs
    np.testing.assert_allclose(res.poses_xyt, inp.odometry_xyt, atol=1e-9)
    pts = inverse_range_bearing_offset(res.poses_xyt[inp.observations.step], inp.observations.z,
                                       inp.sensor_offset_xy)
    for j in range(len(res.landmarks_xy)):
        np.testing.assert_allclose(res.landmarks_xy[j], pts[res.assoc == j].mean(0), atol=1e-8)
    assert res.extra["solved_in_sensor_frame"] == [3.78, 0.5]


@pytest.mark.slow
def test_cli_end_to_end_and_refusals(tmp_path):
    data = tmp_path / "vp.h5"
    r = runner.invoke(app, ["import", "victoria-park", str(VP), "--start", "5", "--duration", "25", "-o", str(data)])
    assert r.exit_code == 0, r.output
    assert "tree detections (no ids)" in r.stdout
    r = runner.invoke(app, ["solve", str(data), "-m", "graph", "-q", "-o", str(tmp_path / "g.h5")])
    assert r.exit_code == 0, r.output
    r = runner.invoke(app, ["evaluate", str(tmp_path / "g.h5"), "-o", str(tmp_path / "ev")])
    assert r.exit_code == 0, r.output
    assert "GPS ATE RMSE (SE(2)-aligned)" in r.stdout and "not available without ground truth" in r.stdout
    m = json.loads((tmp_path / "ev" / "metrics.json").read_text())
    assert m["gps_n_matched"] > 50 and m["gps_ate_aligned_rmse_m"] < m["odometry_gps_ate_aligned_rmse_m"] + 1.0
    assert m["final_cost"] > 0 and m["n_landmarks_est"] > 0
    # a solver that reads the controls as DDMR refuses in one line, writing nothing
    for args in (["-m", "hybrid"], ["-m", "graph", "-p", "use_controls=true"]):
        r = runner.invoke(app, ["solve", str(data), *args, "-o", str(tmp_path / "x.h5")])
        lines = r.stderr.strip().splitlines()
        assert r.exit_code == 1 and len(lines) == 1 and "ackermann" in lines[0], r.output
        assert not (tmp_path / "x.h5").exists()
    r = runner.invoke(app, ["import", "victoria-park", str(tmp_path / "nope"), "-o", str(tmp_path / "y.h5")])
    assert r.exit_code == 1 and "not a directory" in r.stderr and not (tmp_path / "y.h5").exists()


def test_malformed_file_is_one_line(tmp_path):
    d = tmp_path / "vp"
    d.mkdir()
    for name in ("inputs.dat", "measurements.dat", "gps.dat"):
        (d / name).write_text((VP / name).read_text())
    (d / "measurements.dat").write_text("1.0 2.0 x 0.3\n")
    with pytest.raises(DatasetImportError, match="measurements.dat: malformed row"):
        import_victoria_park(d)
