"""MRCLAM importer: parsing, barcode mapping, resampling arithmetic (hand-computed and brute force), residuals
of the real excerpt against its motion-capture truth, schema round trip, one-line errors, and
``slamcli import`` → ``solve`` → ``evaluate`` end to end.

Data: ``tests/data/mrclam_excerpt`` (45 s of robot 1 of MRCLAM Dataset 7, see its PROVENANCE.txt) and tiny
hand-written recordings in ``tmp_path``. Nothing here reads the shared datasets folder.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from conftest import DATA
from typer.testing import CliRunner

from slamcli.cli import app
from slamcli.datasets import DatasetImportError
from slamcli.datasets.mrclam import (
    default_noise,
    import_mrclam,
    load_mrclam,
    nearest_steps,
    residual_noise,
    zoh_average,
)
from slamcli.errors import SlamcliError
from slamcli.io import dataset_hash, read_dataset, write_dataset
from slamcli.models.angles import angle_diff
from slamcli.models.motion import integrate
from slamcli.models.se2 import interpolate_poses

EXCERPT = DATA / "mrclam_excerpt"
HEADER = "# UTIAS MRCLAM (test)\n# hand-written\n# format\n# columns\n"
runner = CliRunner()

# Barcodes.dat of Dataset 7: subject -> barcode (subjects 1-5 robots, 6-20 landmarks)
BARCODES = {1: 5, 2: 14, 3: 41, 4: 32, 5: 23, 6: 63, 7: 81, 8: 7, 9: 70, 10: 45, 11: 27, 12: 18, 13: 54,
            14: 61, 15: 90, 16: 36, 17: 16, 18: 9, 19: 72, 20: 25}


def _raw_rows(path: Path) -> np.ndarray:
    return np.loadtxt(path, comments="#")


@pytest.fixture(scope="module")
def excerpt():
    return import_mrclam(EXCERPT, 1, dt=0.1)


# -- parsing -----------------------------------------------------------------------------------------------
def test_parse_counts_and_landmark_order():
    raw = load_mrclam(EXCERPT, 1)
    assert raw.barcodes.shape == (20, 2)
    assert dict(zip(raw.barcodes[:, 0].tolist(), raw.barcodes[:, 1].tolist())) == BARCODES
    np.testing.assert_array_equal(raw.landmark_subjects, np.arange(6, 21))
    assert raw.landmarks_xy.shape == (15, 2)
    np.testing.assert_allclose(raw.landmarks_xy[0], [0.58842660, -4.28209684])  # subject 6
    np.testing.assert_allclose(raw.landmarks_xy[-1], [1.24714039, 4.46386435])  # subject 20
    assert raw.odometry.shape == (346, 3)
    assert raw.groundtruth.shape == (271, 4)
    assert raw.measurements.shape == (272, 4)
    # first data row of each file, verbatim
    np.testing.assert_allclose(raw.odometry[0], [1248446288.339, 0.074, -0.219], rtol=0, atol=1e-6)
    np.testing.assert_allclose(raw.measurements[0], [1248446288.535, 14, 2.527, -0.086], rtol=0, atol=1e-6)
    np.testing.assert_allclose(raw.groundtruth[-1], [1248446333.228, 2.30033710, -1.74613120, -2.40750000],
                               rtol=0, atol=1e-6)


def test_barcodes_map_to_landmark_index_and_robots_are_dropped_or_clutter():
    drop = import_mrclam(EXCERPT, 1, dt=0.1, non_landmark="drop")
    clut = import_mrclam(EXCERPT, 1, dt=0.1, non_landmark="clutter")
    # independent mapping of the file rows that fall in the window
    m = _raw_rows(EXCERPT / "Robot1_Measurement.dat")
    t_ref, (w0, w1) = clut.metadata["time_origin_unix_s"], clut.metadata["window_unix_s"]
    inside = (m[:, 0] >= w0 - 0.05) & (m[:, 0] < w1 + 0.05)
    subj_of = {b: s for s, b in BARCODES.items()}
    expect = np.array([subj_of[int(b)] - 6 if subj_of[int(b)] >= 6 else -1 for b in m[inside, 1]])
    np.testing.assert_array_equal(clut.inputs.observations.reported_id, expect)
    np.testing.assert_array_equal(clut.truth.obs_landmark, expect)
    np.testing.assert_allclose(clut.inputs.observations.range_m, m[inside, 2])
    n_robot = int(np.sum(expect < 0))
    assert n_robot == 11 == clut.metadata["n_robot_rows_in_window"] == drop.metadata["n_robot_rows_in_window"]
    assert len(drop.inputs.observations) == len(clut.inputs.observations) - n_robot == 259
    np.testing.assert_array_equal(drop.inputs.observations.reported_id, expect[expect >= 0])
    assert np.all(drop.inputs.observations.reported_id == drop.truth.obs_landmark)  # no misreads here
    assert drop.metadata["n_misread_rows"] == 0
    # e.g. barcode 54 is subject 13 = landmark index 7; barcode 14 is robot 2 (the only robot seen here)
    assert set(np.unique(m[inside, 1]).astype(int)) == {7, 14, 18, 27, 45, 54, 63, 70, 81}
    np.testing.assert_array_equal(np.unique(clut.inputs.observations.reported_id[m[inside, 1] == 54]), [7])
    assert np.all(clut.inputs.observations.reported_id[m[inside, 1] == 14] == -1)
    assert t_ref == pytest.approx(1248446288.339)


# -- resampling arithmetic ---------------------------------------------------------------------------------
def test_zoh_average_hand_computed():
    t = np.array([0.0, 0.03, 0.03, 0.10, 0.25])  # a duplicate stamp at 0.03: the later row (3) holds
    u = np.array([[1.0, -1.0], [2.0, -2.0], [3.0, -3.0], [4.0, -4.0], [5.0, -5.0]])
    got = zoh_average(t, u, np.array([0.0, 0.1, 0.2, 0.3]))
    # [0, .1): 1·.03 + 3·.07 = .24;  [.1, .2): 4·.1;  [.2, .3): 4·.05 + 5·.05 (last row holds on)
    np.testing.assert_allclose(got[:, 0], [2.4, 4.0, 4.5], rtol=1e-12)
    np.testing.assert_allclose(got[:, 1], [-2.4, -4.0, -4.5], rtol=1e-12)
    # a grid that starts inside a row and ends inside a gap
    np.testing.assert_allclose(zoh_average(t, u, np.array([0.02, 0.05]))[0, 0], (1 * 0.01 + 3 * 0.02) / 0.03)
    with pytest.raises(ValueError):
        zoh_average(t, u, np.array([-0.1, 0.1]))


def test_zoh_average_matches_brute_force_on_real_log():
    raw = load_mrclam(EXCERPT, 1)
    t = raw.odometry[:, 0] - raw.odometry[0, 0]
    grid = 0.37 + 0.1 * np.arange(200)
    got = zoh_average(t, raw.odometry[:, 1:], grid)
    # brute force: sample the held signal on a 1e-4 s midpoint grid and average within each interval
    fine = np.arange(grid[0], grid[-1], 1e-4) + 0.5e-4
    held = raw.odometry[np.searchsorted(t, fine, side="right") - 1, 1:]
    k = np.floor((fine - grid[0]) / 0.1).astype(int)
    ref = np.stack([np.bincount(k, held[:, j]) / np.bincount(k) for j in range(2)], 1)
    np.testing.assert_allclose(got, ref, atol=2e-3 * np.abs(raw.odometry[:, 1:]).max())


def test_interpolate_poses_linear_and_on_the_circle():
    t = np.array([0.0, 1.0, 3.0])
    p = np.array([[0.0, 0.0, 3.1], [1.0, 2.0, -3.1], [3.0, 2.0, -3.0]])
    got = interpolate_poses(t, p, np.array([0.0, 0.5, 0.25, 2.0, 3.0]))
    np.testing.assert_allclose(got[:, :2], [[0, 0], [0.5, 1.0], [0.25, 0.5], [2.0, 2.0], [3.0, 2.0]], atol=1e-12)
    # 3.1 → -3.1 crosses ±π the short way (+0.0832 rad), never through 0
    assert got[1, 2] == pytest.approx(-np.pi, abs=1e-12) or got[1, 2] == pytest.approx(np.pi, abs=1e-12)
    assert angle_diff(got[2, 2], 3.1 + 0.25 * (2 * np.pi - 6.2)) == pytest.approx(0.0, abs=1e-12)
    assert got[3, 2] == pytest.approx(-3.05, abs=1e-12)
    np.testing.assert_array_equal(nearest_steps(np.array([0.949, 0.951, 1.0, 1.149]), 0.9, 0.1), [0, 1, 1, 2])


def _write(d: Path, name: str, rows: list[str]) -> None:
    (d / name).write_text(HEADER + "".join(r + "\n" for r in rows))


@pytest.fixture()
def tiny(tmp_path):
    """A hand-made recording: v = 0.1 m/s straight along +x, then a turn; one landmark per barcode kind."""
    d = tmp_path / "mini"
    d.mkdir()
    _write(d, "Barcodes.dat", ["1 5", "2 14", "6 63", "7 81"])
    _write(d, "Landmark_Groundtruth.dat", ["7 4.0 1.0 0.001 0.001", "6 2.0 0.0 0.001 0.001"])
    _write(d, "Robot1_Odometry.dat", [
        "100.00 0.1 0.0", "100.05 0.1 0.0", "100.05 0.2 0.0",  # duplicate stamp: 0.2 holds from 100.05
        "100.10 0.2 0.5", "100.40 0.0 0.0",
    ])
    _write(d, "Robot1_Groundtruth.dat", [
        "99.90 0.0 0.0 0.0", "100.00 0.0 0.0 0.0", "100.20 0.03 0.0 0.1", "100.50 0.06 0.0 0.2",
    ])
    _write(d, "Robot1_Measurement.dat", [
        "100.04 63 2.0 0.0",   # landmark subject 6 -> index 0, nearest step 0 (t=0.04 → 0.4 → 0)
        "100.06 81 4.1 0.24",  # subject 7 -> index 1, step 1
        "100.11 14 1.0 0.1",   # robot 2 -> clutter/drop, step 1
        "100.26 99 3.0 -0.2",  # unknown barcode, step 3
        "100.37 63 1.9 3.15",  # bearing > π is wrapped; step 4 (0.37 → 3.7 → 4); a misread (true ≈ −0.16)
        "100.50 63 1.8 0.0",   # nearest step 5 > T = 4: outside the window
    ])
    return d


def test_tiny_recording_end_to_end_arithmetic(tiny):
    ds = import_mrclam(tiny, 1, dt=0.1, non_landmark="clutter")
    inp, tr = ds.inputs, ds.truth
    assert ds.metadata["time_origin_unix_s"] == pytest.approx(100.0)  # max(first odometry, first truth)
    # window: odometry ends at 100.40, truth at 100.50 → 0.4 s → T = 4
    np.testing.assert_allclose(inp.timestamps, [0.0, 0.1, 0.2, 0.3, 0.4], atol=1e-12)
    # controls: [0,.1): .1·.05 + .2·.05 → .15; [.1,.2): (.2, .5); [.2,.3), [.3,.4): (.2, .5)
    np.testing.assert_allclose(inp.controls, [[0.15, 0.0], [0.2, 0.5], [0.2, 0.5], [0.2, 0.5]], atol=1e-9)
    np.testing.assert_allclose(inp.odometry_xyt, integrate(inp.x0, inp.controls, 0.1), atol=0)
    np.testing.assert_allclose(inp.x0, [0.0, 0.0, 0.0], atol=1e-12)
    # truth at t = 0.1, 0.3: halfway between the rows at 100.0/100.2 and a third of the way 100.2 → 100.5
    np.testing.assert_allclose(tr.poses_xyt[1], [0.015, 0.0, 0.05], atol=1e-9)
    np.testing.assert_allclose(tr.poses_xyt[3], [0.04, 0.0, 0.1 + 0.1 / 3], atol=1e-9)
    np.testing.assert_allclose(tr.landmarks_xy, [[2.0, 0.0], [4.0, 1.0]])  # subject order 6, 7
    obs = inp.observations
    np.testing.assert_array_equal(obs.step, [0, 1, 1, 3, 4])
    np.testing.assert_array_equal(obs.reported_id, [0, 1, -1, -1, 0])
    np.testing.assert_array_equal(tr.obs_landmark, [0, 1, -1, -1, -1])  # the sensor says 0, the truth disagrees
    assert ds.metadata["n_misread_rows"] == 1
    unchecked = import_mrclam(tiny, 1, dt=0.1, non_landmark="clutter", misread_gate=np.inf)
    np.testing.assert_array_equal(unchecked.truth.obs_landmark, [0, 1, -1, -1, 0])
    np.testing.assert_array_equal(obs.offsets, [0, 1, 3, 3, 4, 5])
    assert obs.bearing_rad[4] == pytest.approx(3.15 - 2 * np.pi)
    assert ds.metadata["observed_max_timing_error_s"] == pytest.approx(0.04)
    assert ds.metadata["max_timing_error_s"] == pytest.approx(0.05)
    assert ds.metadata["n_robot_rows_in_window"] == 1 and ds.metadata["n_unknown_barcode_rows_in_window"] == 1
    dropped = import_mrclam(tiny, 1, dt=0.1)
    np.testing.assert_array_equal(dropped.inputs.observations.step, [0, 1, 4])
    np.testing.assert_array_equal(dropped.inputs.observations.reported_id, [0, 1, 0])
    np.testing.assert_array_equal(dropped.truth.obs_landmark, [0, 1, -1])
    # --start / --duration cut the window on the same axis
    part = import_mrclam(tiny, 1, dt=0.1, start=0.1, duration=0.2)
    np.testing.assert_allclose(part.inputs.timestamps, [0.1, 0.2, 0.3], atol=1e-12)
    np.testing.assert_allclose(part.inputs.x0, tr.poses_xyt[1], atol=1e-12)
    np.testing.assert_allclose(part.inputs.controls, inp.controls[1:3], atol=1e-12)
    np.testing.assert_array_equal(part.inputs.observations.step, [0])  # row at 100.06 → step 0 (t=0.1)
    # a control delay shifts every velocity row later
    late = import_mrclam(tiny, 1, dt=0.1, control_delay=0.05)
    assert late.metadata["time_origin_unix_s"] == pytest.approx(100.05)


# -- the real excerpt against its ground truth -------------------------------------------------------------
def test_excerpt_shapes_timing_and_dead_reckoning(excerpt):
    inp = excerpt.inputs
    T = inp.n_poses - 1
    assert T == 448 and inp.timestamps[0] == 0.0
    assert inp.controls.shape == (T, 2) and excerpt.truth.poses_xyt.shape == (T + 1, 3)
    np.testing.assert_allclose(np.diff(inp.timestamps), 0.1, atol=1e-9)
    np.testing.assert_array_equal(inp.x0, excerpt.truth.poses_xyt[0])
    np.testing.assert_allclose(inp.odometry_xyt, integrate(inp.x0, inp.controls, 0.1), atol=0)
    # every measurement sits at most dt/2 from its pose time
    m = _raw_rows(EXCERPT / "Robot1_Measurement.dat")
    landmark_rows = np.isin(m[:, 1], [BARCODES[s] for s in range(6, 21)])
    t_rel = m[landmark_rows, 0] - excerpt.metadata["time_origin_unix_s"]
    t_rel = t_rel[(t_rel >= -0.05) & (t_rel < inp.timestamps[-1] + 0.05)]
    err = np.abs(t_rel - inp.timestamps[inp.observations.step])
    assert err.max() <= 0.05 + 1e-9
    assert excerpt.metadata["observed_max_timing_error_s"] == pytest.approx(err.max())
    # the robot really moved: 3.0 m of true path; dead reckoning drifts but stays within a metre
    path = np.sum(np.hypot(*np.diff(excerpt.truth.poses_xyt[:, :2], axis=0).T))
    assert 2.5 < path < 4.0
    drift = np.hypot(*(inp.odometry_xyt[:, :2] - excerpt.truth.poses_xyt[:, :2]).T)
    assert 0.1 < drift.max() < 1.0


def test_excerpt_measurement_and_control_residuals(excerpt):
    r = residual_noise(excerpt)
    # measured on this excerpt: range median +0.055 m (σ 0.040), bearing median -0.003 rad (σ 0.009),
    # controls vs truth-differenced velocity: σ_v 0.005 m/s, σ_ω 0.027 rad/s
    assert 0.0 < r["range_median"] < 0.1
    assert r["range_std"] < 0.06
    assert abs(r["bearing_median"]) < 0.01 and r["bearing_std"] < 0.015
    assert abs(r["v_median"]) < 0.01 and r["v_std"] < 0.01
    assert abs(r["omega_median"]) < 0.01 and r["omega_std"] < 0.05
    # the default noise spec is not over-confident on this excerpt
    n = default_noise(0.1)
    assert n.range_std >= r["range_std"] and n.bearing_std >= r["bearing_std"]
    assert n.motion_std[0] >= r["v_std"] and n.motion_std[1] >= r["omega_std"]


def test_round_trip_through_schema(excerpt, tmp_path):
    path = write_dataset(tmp_path / "mrclam.h5", excerpt)
    back = read_dataset(path)
    assert dataset_hash(back) == dataset_hash(excerpt)
    for name in ("timestamps", "x0", "controls", "odometry_xyt"):
        np.testing.assert_array_equal(getattr(back.inputs, name), getattr(excerpt.inputs, name))
    for name in ("step", "range_m", "bearing_rad", "reported_id", "offsets"):
        np.testing.assert_array_equal(getattr(back.inputs.observations, name),
                                      getattr(excerpt.inputs.observations, name))
    np.testing.assert_array_equal(back.truth.poses_xyt, excerpt.truth.poses_xyt)
    np.testing.assert_array_equal(back.truth.obs_landmark, excerpt.truth.obs_landmark)
    assert back.metadata["scenario"] == "mrclam:mrclam_excerpt:robot1"
    assert back.metadata["scenario_params"]["robot"] == 1


# -- errors ------------------------------------------------------------------------------------------------
def _copy_excerpt(tmp_path) -> Path:
    d = tmp_path / "copy"
    d.mkdir()
    for f in EXCERPT.glob("*.dat"):
        (d / f.name).write_text(f.read_text())
    return d


@pytest.mark.parametrize(
    ("mutate", "kwargs", "fragment"),
    [
        (None, {"robot": 4}, "Robot4_Odometry.dat: file not found (robots present: Robot1)"),
        (lambda d: (d / "Robot1_Groundtruth.dat").unlink(), {}, "Robot1_Groundtruth.dat: file not found"),
        (lambda d: _append(d, "Robot1_Odometry.dat", "1248446333.5 0.1 fast"), {},
         "Robot1_Odometry.dat:351: omega is not a number: 'fast'"),
        (lambda d: _append(d, "Robot1_Measurement.dat", "1248446333.5 61 1.0"), {},
         "Robot1_Measurement.dat:277: expected 4 columns (time, barcode, range, bearing), got 3"),
        (lambda d: _append(d, "Robot1_Measurement.dat", "1248446333.5 61.5 1.0 0.0"), {},
         "Robot1_Measurement.dat:277: barcode must be an integer"),
        (lambda d: _append(d, "Robot1_Groundtruth.dat", "1248446000.0 1 2 3"), {},
         "Robot1_Groundtruth.dat:276: time goes backwards"),
        (lambda d: _append(d, "Robot1_Odometry.dat", "1248446333.5 nan 0.0"), {}, "v is not finite"),
        (lambda d: _shift_times(d, "Robot1_Groundtruth.dat", 1000.0), {}, "do not overlap in time"),
        (None, {"start": 50.0}, "--start: 50 s is past the last full step"),
        (None, {"duration": 60.0}, "--duration: 60 s exceeds the 44.806 s"),
        (None, {"dt": 0.0}, "--dt: must be a finite number > 0"),
        (None, {"non_landmark": "keep"}, "non_landmark: must be 'drop' or 'clutter'"),
    ],
)
def test_bad_input_raises_one_line_import_error(tmp_path, mutate, kwargs, fragment):
    d = _copy_excerpt(tmp_path)
    if mutate is not None:
        mutate(d)
    with pytest.raises(DatasetImportError) as exc:
        import_mrclam(d, **{"robot": 1, **kwargs})
    msg = str(exc.value)
    assert isinstance(exc.value, SlamcliError) and "\n" not in msg
    assert fragment in msg, msg


def _append(d: Path, name: str, row: str) -> None:
    with open(d / name, "a") as fh:
        fh.write(row + "\n")


def _shift_times(d: Path, name: str, by: float) -> None:
    rows = _raw_rows(d / name)
    rows[:, 0] += by
    _write(d, name, [" ".join(f"{v:.3f}" for v in r) for r in rows])


def test_missing_directory_error():
    with pytest.raises(DatasetImportError, match="no/such/dir: not a directory"):
        load_mrclam("no/such/dir", 1)


# -- CLI end to end ----------------------------------------------------------------------------------------
def run(*args):
    return runner.invoke(app, [str(a) for a in args], terminal_width=200)


def test_cli_import_solve_evaluate_ekf_beats_dead_reckoning(tmp_path):
    data = tmp_path / "mrclam.h5"
    res = run("import", "mrclam", EXCERPT, "--robot", "1", "--dt", "0.1", "-o", data)
    assert res.exit_code == 0, res.output
    assert "448 steps" in res.stdout and "259 observations" in res.stdout and "11 robot" in res.stdout
    ds = read_dataset(data)
    assert dataset_hash(ds) == dataset_hash(import_mrclam(EXCERPT, 1, dt=0.1))
    res = run("solve", data, "--method", "ekf", "--param", "association=known", "-o", tmp_path / "ekf.h5")
    assert res.exit_code == 0, res.output
    res = run("evaluate", tmp_path / "ekf.h5", "-o", tmp_path / "eval", "-q")
    assert res.exit_code == 0, res.output
    m = json.loads((tmp_path / "eval" / "metrics.json").read_text())
    # measured: EKF ATE 0.116 m vs dead reckoning 0.246 m; all 15 landmarks, all within 0.25 m
    assert np.isfinite(m["ate_rmse_m"]) and m["ate_rmse_m"] < 0.7 * m["odometry_ate_rmse_m"]
    assert 0.15 < m["odometry_ate_rmse_m"] < 0.35
    assert m["n_landmarks_est"] <= 15


@pytest.mark.slow
def test_cli_import_options_and_errors(tmp_path):
    out = tmp_path / "a.h5"
    res = run("import", "mrclam", EXCERPT, "--start", "5", "--duration", "10", "--dt", "0.02",
              "--non-landmark", "clutter", "--range-std", "0.1", "--omega-std", "0.05", "--max-range", "8", "-q", "-o", out)
    assert res.exit_code == 0, res.output
    ds = read_dataset(out)
    assert ds.inputs.n_poses == 501 and ds.inputs.timestamps[0] == pytest.approx(5.0)
    assert ds.inputs.noise.range_std == 0.1 and ds.inputs.noise.bearing_std == default_noise(0.02).bearing_std
    np.testing.assert_allclose(ds.inputs.noise.motion_std, [default_noise(0.02).motion_std[0], 0.05])
    assert ds.inputs.noise.odometry_std[2] == pytest.approx(0.05 * 0.02)
    assert ds.inputs.max_range == 8.0 and ds.metadata["sensor"]["file_range_min_max_m"] == [1.084, 5.452]
    for args, fragment in [
        (("mrclam", tmp_path / "nope", "-o", tmp_path / "b.h5"), "not a directory"),
        (("mrclam", EXCERPT, "--robot", "3", "-o", tmp_path / "b.h5"), "Robot3_Odometry.dat: file not found"),
        (("mrclam", EXCERPT, "--duration", "100", "-o", tmp_path / "b.h5"), "--duration"),
        (("mrclam", EXCERPT, "--max-range", "0", "-o", tmp_path / "b.h5"), "--max-range: must be > 0"),
        (("mrclam", EXCERPT), "-o/--out is required"),
    ]:
        res = run("import", *args)
        assert res.exit_code == 1, res.output
        lines = res.stderr.strip().splitlines()
        assert len(lines) == 1 and lines[0].startswith("error: ") and fragment in lines[0], res.stderr
        assert "Traceback" not in res.output
    res = run("import", "mrclam", EXCERPT, "--non-landmark", "x", "-o", tmp_path / "b.h5")
    assert res.exit_code == 2 and "--non-landmark" in res.stderr and "'drop', 'clutter'" in res.stderr
    assert not (tmp_path / "b.h5").exists()


# -- irregular stamps: isolated disorder is repaired, the rest refused with its count ----------------------
def _swap_lines(d: Path, name: str, a: int, b: int) -> None:
    """Swap the 1-based lines ``a`` and ``b`` of ``d/name``."""
    lines = (d / name).read_text().splitlines(keepends=True)
    lines[a - 1], lines[b - 1] = lines[b - 1], lines[a - 1]
    (d / name).write_text("".join(lines))


@pytest.mark.parametrize(("name", "line"), [("Robot1_Odometry.dat", 5), ("Robot1_Measurement.dat", 59),
                                            ("Robot1_Groundtruth.dat", 100)])
def test_one_swapped_stamp_is_sorted_back_and_counted(tmp_path, name, line):
    """One swapped pair of rows (the odometry's at the first data line) imports as the unswapped file does."""
    d = _copy_excerpt(tmp_path)
    t_a, t_b = _raw_rows(d / name)[line - 5: line - 3, 0]
    assert t_a < t_b  # the pair really is out of order once swapped
    _swap_lines(d, name, line, line + 1)
    raw = load_mrclam(d, 1)
    table = {"Robot1_Odometry.dat": raw.odometry, "Robot1_Measurement.dat": raw.measurements,
             "Robot1_Groundtruth.dat": raw.groundtruth}[name]
    # the reference is the original excerpt's file, in its own order
    np.testing.assert_array_equal(table, _raw_rows(EXCERPT / name))
    assert table[line - 5, 0] == t_a and table[line - 4, 0] == t_b
    ds = import_mrclam(d, 1, dt=0.1)
    assert ds.metadata["stamp_repairs"] == {
        name: {"n_out_of_order": 1, "reordered_lines": [line, line + 1], "n_duplicate_stamps": 0,
               "duplicate_lines": []}}
    ref = import_mrclam(EXCERPT, 1, dt=0.1)
    assert ref.metadata["stamp_repairs"] == {}
    np.testing.assert_array_equal(ds.inputs.controls, ref.inputs.controls)
    np.testing.assert_array_equal(ds.truth.poses_xyt, ref.truth.poses_xyt)
    np.testing.assert_array_equal(ds.inputs.observations.z, ref.inputs.observations.z)
    np.testing.assert_array_equal(ds.inputs.observations.step, ref.inputs.observations.step)


def test_duplicate_truth_stamp_keeps_the_last_row_and_is_listed(tmp_path):
    d = _copy_excerpt(tmp_path)
    gt = _raw_rows(d / "Robot1_Groundtruth.dat")
    lines = (d / "Robot1_Groundtruth.dat").read_text().splitlines(keepends=True)
    # a second row with the stamp of data row 50 (line 54) and a pose 1 m off, placed right after it: it wins
    moved = gt[49].copy()
    moved[1] += 1.0
    lines.insert(54, " ".join(repr(float(v)) for v in moved) + "\n")
    (d / "Robot1_Groundtruth.dat").write_text("".join(lines))
    ds = import_mrclam(d, 1, dt=0.1)
    rep = ds.metadata["stamp_repairs"]["Robot1_Groundtruth.dat"]
    assert rep == {"n_out_of_order": 0, "reordered_lines": [], "n_duplicate_stamps": 1, "duplicate_lines": [54]}
    # truth at the grid time nearest that stamp interpolates towards the later (shifted) row
    src = np.vstack([gt[:49], moved[None], gt[50:]])  # the file with the later of the two rows only
    ref = np.interp(ds.inputs.timestamps, src[:, 0] - ds.metadata["time_origin_unix_s"], src[:, 1])
    np.testing.assert_allclose(ds.truth.poses_xyt[:, 0], ref, atol=1e-9)


@pytest.mark.parametrize(("mutate", "fragment"), [
    # one row 5 places from its own: not a local swap
    (lambda d: _swap_lines(d, "Robot1_Odometry.dat", 20, 25),
     "Robot1_Odometry.dat:21: time goes backwards (1248446290.614 after 1248446291.133); 2 row(s) out of time "
     "order, up to 5 rows from their place"),
    # five separate swapped pairs in a 346-row file: more than max(4, 1 %) rows out of order
    (lambda d: [_swap_lines(d, "Robot1_Odometry.dat", a, a + 1) for a in (10, 30, 50, 70, 90)],
     "5 row(s) out of time order, up to 1 rows from their place"),
])
def test_disorder_a_sort_cannot_explain_is_refused_with_its_count(tmp_path, mutate, fragment):
    d = _copy_excerpt(tmp_path)
    mutate(d)
    with pytest.raises(DatasetImportError) as exc:
        import_mrclam(d, 1)
    assert fragment in str(exc.value) and "\n" not in str(exc.value), str(exc.value)


def test_out_of_order_count_matches_brute_force():
    """``n - longest non-decreasing subsequence`` against an O(n²) dynamic programme on random stamps."""
    from slamcli.datasets.mrclam import _n_out_of_order

    rng = np.random.default_rng(7)
    for _ in range(200):
        t = rng.integers(0, 6, size=rng.integers(1, 12)).astype(float)
        best = np.ones(len(t), int)
        for i in range(len(t)):
            for j in range(i):
                if t[j] <= t[i]:
                    best[i] = max(best[i], best[j] + 1)
        assert _n_out_of_order(t) == len(t) - best.max()


def test_cli_import_summary_names_the_repair(tmp_path):
    d = _copy_excerpt(tmp_path)
    _swap_lines(d, "Robot1_Odometry.dat", 5, 6)
    res = run("import", "mrclam", d, "-o", tmp_path / "r.h5")
    assert res.exit_code == 0, res.output
    assert "repaired stamps: Robot1_Odometry.dat 1 out of order (lines 5, 6 sorted)" in res.stdout
    assert read_dataset(tmp_path / "r.h5").metadata["stamp_repairs"]["Robot1_Odometry.dat"]["n_out_of_order"] == 1


def test_team_import_counts_each_robots_repair(tmp_path):
    """Four robots of one public dataset were refused for one swapped row each: a team import repairs the
    swap in robot 2's log, lists it under robot 2, says so in the summary, and imports robot 2's controls as
    the unswapped excerpt gives them."""
    from slamcli.datasets.mrclam import import_mrclam_team

    team_src = DATA / "mrclam_team_excerpt"
    d = tmp_path / "team"
    d.mkdir()
    for f in team_src.glob("*.dat"):
        (d / f.name).write_text(f.read_text())
    _swap_lines(d, "Robot2_Odometry.dat", 5, 6)
    ds = import_mrclam_team(d, [1, 2])
    per = {pr["robot"]: pr["stamp_repairs"] for pr in ds.metadata["per_robot"]}
    assert per[1] == {} and per[2]["Robot2_Odometry.dat"]["reordered_lines"] == [5, 6]
    ref = import_mrclam_team(team_src, [1, 2])
    np.testing.assert_array_equal(ds.inputs.controls, ref.inputs.controls)
    res = run("import", "mrclam", d, "--robots", "1,2", "-o", tmp_path / "t.h5")
    assert res.exit_code == 0, res.output
    assert "repaired stamps: Robot2_Odometry.dat 1 out of order (lines 5, 6 sorted)" in res.stdout
