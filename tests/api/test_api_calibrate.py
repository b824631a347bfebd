"""The importers' noise measurements (slamcli/api/calibrate.py, the "Noise" sections of the Victoria Park
and car-park importers): the scan-to-scan estimator recovers a known simulated σ, is robust to mismatches,
and on the shipped car-park excerpt the documented trade-off holds — the NIS-calibrated noise puts the EKF's
mean NIS inside its χ² band while the conservative defaults sit far below it, and the calibrated noise turns
rejected detections into extra landmarks."""

from __future__ import annotations

import numpy as np
import pytest
from conftest import DATA, car_world
from typer.testing import CliRunner

from slamcli.api.calibrate import observation_noise, robust_std, scan_pair_residuals
from slamcli.api.solve import solve_dataset
from slamcli.cli import app
from slamcli.datasets import carpark, victoria_park
from slamcli.io import read_dataset
from slamcli.metrics.reference import mean_nis_band
from slamcli.solvers.sensor_frame import to_sensor_frame


def test_scan_to_scan_estimator_recovers_simulated_sensor_noise():
    """Car world: laser σ_r = 0.05 m, σ_b = 0.005 rad, scans every 0.2 s; the odometry error over one gap
    (σ_v dt √8 ≈ 4 mm) is small against σ_r, so the estimate is within 15 % of the truth."""
    ds = car_world(seed=2, T=2400)
    sr, sb, n = observation_noise(to_sensor_frame(ds.inputs))
    assert n > 300
    assert sr == pytest.approx(0.05, rel=0.15) and sb == pytest.approx(0.005, rel=0.15), (sr, sb, n)


def test_robust_std_ignores_a_minority_of_outliers():
    rng = np.random.default_rng(0)
    r = rng.normal(0, 0.1, (4000, 2))
    r[:200] = 50.0  # 5 % gross mismatches
    np.testing.assert_allclose(robust_std(r), 0.1, rtol=0.12)
    assert np.std(r, axis=0).min() > 10  # the plain standard deviation is ruined


def test_carpark_excerpt_nis_trade_off():
    ds = carpark.import_carpark(DATA / "carpark_excerpt")
    sr, sb, _ = observation_noise(to_sensor_frame(ds.inputs))
    # the excerpt reproduces the whole run's scan-to-scan σ (0.0104 m, 0.0026 rad) within 25 %
    assert sr == pytest.approx(0.0104, rel=0.25) and sb == pytest.approx(0.0026, rel=0.25), (sr, sb)
    runs = {}
    for label, noise in (("defaults", None),
                         ("calibrated", carpark.default_noise(range_std=0.0104, bearing_std=0.0026, v_std=0.25,
                                                              steer_std=np.radians(1.5)))):
        d = carpark.import_carpark(DATA / "carpark_excerpt", noise=noise)
        res = solve_dataset(d.inputs, "ekf", {"association": "ml"})
        runs[label] = (mean_nis_band(res.extra["mean_nis"], res.extra["n_updates"]), len(res.landmarks_xy))
    (b_def, n_def), (b_cal, n_cal) = runs["defaults"], runs["calibrated"]
    assert b_cal["nis_inside_band"], b_cal
    assert b_def["nis_mean"] < b_def["nis_band_lo"] - 1.0, b_def  # conservative: far below the band
    assert n_cal > n_def + 5, (n_cal, n_def)  # ... and the calibrated gate starts extra landmarks


def test_victoria_park_excerpt_scan_pairs():
    """The first 60 s: thousands of scan pairs, robust σ well below the conservative defaults."""
    ds = victoria_park.import_victoria_park(DATA / "victoria_park_excerpt")
    nu = scan_pair_residuals(to_sensor_frame(ds.inputs))
    s = robust_std(nu) / np.sqrt(2)
    assert len(nu) > 1500
    assert s[0] < victoria_park.DEFAULT_RANGE_STD / 5 and s[1] < victoria_park.DEFAULT_BEARING_STD / 2, s


def test_import_noise_options(tmp_path):
    runner = CliRunner()
    out = tmp_path / "vp.h5"
    r = runner.invoke(app, ["import", "victoria-park", str(DATA / "victoria_park_excerpt"), "--duration", "5",
                            "--range-std", "0.061", "--bearing-std", "0.0043", "--v-std", "0.25", "-q", "-o", str(out)])
    assert r.exit_code == 0, r.output
    n = read_dataset(out).inputs.noise
    assert n.range_std == 0.061 and n.bearing_std == 0.0043 and n.motion_std[0] == 0.25
    np.testing.assert_allclose(n.odometry_std[:2], np.array(victoria_park.DEFAULT_ODOMETRY_STD[:2]) / 2)
    assert n.motion_std[1] == victoria_park.DEFAULT_MOTION_STD[1]
    r = runner.invoke(app, ["import", "carpark", str(DATA / "carpark_excerpt"), "--range-std", "-1", "-o",
                            str(tmp_path / "c.h5")])
    assert r.exit_code == 1 and "--range-std" in r.stderr and not (tmp_path / "c.h5").exists()
