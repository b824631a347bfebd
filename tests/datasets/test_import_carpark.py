"""ACFR car park (tests/data/carpark_excerpt: the first 150 scans): beacon extraction against beacons counted by
hand, the import, and the evaluation against the surveyed beacons and GPS."""

from __future__ import annotations

import json

import numpy as np
import pytest
import scipy.io as sio
from conftest import DATA
from typer.testing import CliRunner

from slamcli.cli import app
from slamcli.datasets import DatasetImportError
from slamcli.datasets.carpark import extract_beacons, import_carpark
from slamcli.io import read_dataset

CP = DATA / "carpark_excerpt"
runner = CliRunner()

# counted by hand from the raw rows (beam index: range m, intensity) of data_set.mat:
#  scan  0: 19: 3.17, 20: 3.17 (one beacon over two beams), 334: 11.56           → 2
#  scan 10: 166: 4.14                                                               → 1
#  scan 20: 135: 10.28; 340: 6.80, 341: 6.78 (one beacon)                           → 2
#  scan 30: 76: 6.00 → 1;  scan 40: 117: 8.84 → 1;  scan 50: 221: 3.89 → 1;  scan 55: no bright beam → 0
HAND_COUNTS = {0: 2, 10: 1, 20: 2, 30: 1, 40: 1, 50: 1, 55: 0}


@pytest.fixture(scope="module")
def raw():
    return sio.loadmat(CP / "data_set.mat")


def test_beacon_extraction_matches_hand_counts(raw):
    for scan, n in HAND_COUNTS.items():
        z = extract_beacons(raw["Laser"][scan], raw["Intensity"][scan])
        assert len(z) == n, scan
    z0 = extract_beacons(raw["Laser"][0], raw["Intensity"][0])
    # beams 19, 20 → mean angle 9.75°, bearing 9.75° − 90°; beam 334 → 167° − 90°
    np.testing.assert_allclose(z0, [[3.17, np.deg2rad(9.75) - np.pi / 2], [11.56, np.deg2rad(167.0) - np.pi / 2]],
                               atol=0.01)


def test_grouping_rules():
    r = np.full(361, 81.91)
    i = np.zeros(361, int)
    r[[10, 11, 12]] = [5.0, 5.1, 9.0]  # 12 is bright and adjacent but 3.9 m further: another object
    i[[10, 11, 12]] = 8192
    r[100], i[100] = 81.91, 32768  # bright but no return: not a beacon
    r[200], i[200] = 7.0, 4096  # below the threshold
    z = extract_beacons(r, i)
    np.testing.assert_allclose(z[:, 0], [5.05, 9.0])


@pytest.mark.slow
def test_import_and_evaluate(tmp_path):
    ds = import_carpark(CP)
    inp = ds.inputs
    assert inp.motion_model == "ackermann" and inp.n_poses == 1279 and ds.truth.landmarks_xy.shape == (15, 2)
    assert (inp.observations.reported_id == -1).all() and ds.truth.position_reference_only
    raw = sio.loadmat(CP / "data_set.mat")
    n_expected = sum(len(extract_beacons(raw["Laser"][s], raw["Intensity"][s])) for s in range(150))
    assert len(inp.observations) == n_expected
    data = tmp_path / "cp.h5"
    r = runner.invoke(app, ["import", "carpark", str(CP), "-o", str(data)])
    assert r.exit_code == 0, r.output
    np.testing.assert_array_equal(read_dataset(data).truth.landmarks_xy, ds.truth.landmarks_xy)
    # independent check of the car model, laser offset, bearing convention and beacon extraction: the map
    # lands on the SURVEYED beacons and the laser path on the GPS (measured: odometry 0.13 m GPS ATE and
    # 0.16 m beacon RMSE, ekf 0.08 / 0.14, graph 0.06 / 0.09 m, 14 of 15 beacons matched)
    for method in ("ekf", "graph"):
        r = runner.invoke(app, ["solve", str(data), "-m", method, "-p", "association=ml" if method == "ekf"
                                else "association=nn", "-q", "-o", str(tmp_path / f"{method}.h5")])
        assert r.exit_code == 0, r.output
        r = runner.invoke(app, ["evaluate", str(tmp_path / f"{method}.h5"), "-o", str(tmp_path / method)])
        assert r.exit_code == 0 and "surveyed landmarks matched" in r.stdout, r.output
        m = json.loads((tmp_path / method / "metrics.json").read_text())
        assert m["gps_n_matched"] > 100 and m["gps_ref_point_xy_m"] == [3.78, 0.5]
        assert m["odometry_gps_ate_aligned_rmse_m"] < 0.3
        assert m["gps_ate_aligned_rmse_m"] < m["odometry_gps_ate_aligned_rmse_m"]
        assert m["survey_lm_matched"] >= 13 and m["survey_lm_rmse_m"] < 0.3
        assert m["survey_lm_matched"] + m["survey_lm_missed"] == 15

def test_missing_file_is_one_line(tmp_path):
    with pytest.raises(DatasetImportError, match="data_set.mat: file not found"):
        import_carpark(tmp_path)


def test_inflated_size_is_measured_in_pieces_and_stops_at_the_budget():
    """A zlib stream is measured without keeping what it inflates to: the exact size when under the budget,
    and at most one piece past the budget otherwise (a 1 MB bomb never costs its inflated size)."""
    import io
    import zlib

    from slamcli.datasets import carpark

    raw = b"\0" * (10 << 20)
    packed = zlib.compress(raw)
    fh = io.BytesIO(packed + b"after")
    assert carpark._inflated_bytes(fh, len(packed), 64 << 20) == len(raw)
    assert fh.read() == b"after"  # left at the end of the stream
    fh = io.BytesIO(packed)
    n = carpark._inflated_bytes(fh, len(packed), 1 << 20)
    assert (1 << 20) < n <= (1 << 20) + 2 * carpark._PIECE


def test_a_mat_file_that_inflates_beyond_the_limit_is_refused_before_loadmat(tmp_path, monkeypatch):
    from slamcli.datasets import carpark

    d = tmp_path / "cp"
    d.mkdir()
    for name in ("data_set.mat", "beac_juan3.mat"):
        (d / name).write_bytes((CP / name).read_bytes())
    m = {k: v for k, v in sio.loadmat(d / "data_set.mat").items() if not k.startswith("__")}
    m["Index"] = np.zeros((1, 3 << 20), np.uint8)  # 3 MB of zeros: a few kB compressed
    sio.savemat(d / "data_set.mat", m, do_compression=True)
    monkeypatch.setattr(carpark, "MAX_MAT_BYTES", 2 << 20)
    monkeypatch.setattr(sio, "loadmat", lambda *a, **k: pytest.fail("loadmat reached"))
    with pytest.raises(DatasetImportError, match="data_set.mat: its variables hold more than 2 MB once inflated"):
        import_carpark(d)
