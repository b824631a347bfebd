"""Dataset schema v1: bit-identical round trips, content hash, atomic writes, one test per bad input."""

from __future__ import annotations

import dataclasses
import os
from pathlib import Path

import h5py
import numpy as np
import pytest
from conftest import tiny_dataset

from slamcli.errors import SchemaError
from slamcli.io import atomic_path, dataset_hash, read_dataset, read_header, write_dataset
from slamcli.io import dataset as io_dataset

INPUT_ARRAYS = ("timestamps", "x0", "controls", "odometry_xyt", "gps_step", "gps_xy")
OBS_ARRAYS = ("step", "range_m", "bearing_rad", "sensor", "reported_id", "offsets")


def assert_identical(a: np.ndarray, b: np.ndarray) -> None:
    a, b = np.asarray(a), np.asarray(b)
    assert a.shape == b.shape
    assert a.tobytes() == b.tobytes()


@pytest.fixture(scope="module")
def ds():
    return tiny_dataset(T=40, gps_every=5, report_ids=True)


@pytest.fixture()
def good(tmp_path, ds) -> Path:
    return write_dataset(tmp_path / "good.h5", ds)


# --------------------------------------------------------------------------------------------------------
# round trips
# --------------------------------------------------------------------------------------------------------
def test_round_trip_bit_identical(good, ds):
    back = read_dataset(good)
    for name in INPUT_ARRAYS:
        assert_identical(getattr(back.inputs, name), np.asarray(getattr(ds.inputs, name), float if "step" not in name else np.int64))
    for name in OBS_ARRAYS:
        got, want = getattr(back.inputs.observations, name), getattr(ds.inputs.observations, name)
        assert got.dtype == want.dtype, name
        assert_identical(got, want)
    for name in ("poses_xyt", "landmarks_xy", "obs_landmark"):
        assert_identical(getattr(back.truth, name), getattr(ds.truth, name))
    for name in ("motion_std", "odometry_std"):
        assert_identical(getattr(back.inputs.noise, name), getattr(ds.inputs.noise, name))
    assert back.inputs.noise.range_std == ds.inputs.noise.range_std
    assert back.inputs.noise.bearing_std == ds.inputs.noise.bearing_std
    assert back.inputs.dt == ds.inputs.dt
    assert back.inputs.max_range == ds.inputs.max_range
    assert back.inputs.gps_std == ds.inputs.gps_std
    assert back.metadata == ds.metadata
    assert dataset_hash(back) == dataset_hash(ds)


def test_round_trip_without_gps_infinite_range_and_no_truth(tmp_path):
    ds = tiny_dataset(T=10, clutter_every=0)
    ds = dataclasses.replace(ds, truth=None, inputs=dataclasses.replace(ds.inputs, max_range=float("inf")))
    back = read_dataset(write_dataset(tmp_path / "d.h5", ds))
    assert back.truth is None
    assert back.inputs.max_range == float("inf")
    assert back.inputs.gps_step.shape == (0,) and back.inputs.gps_xy.shape == (0, 2)
    assert dataset_hash(back) == dataset_hash(ds)


def test_round_trip_empty_observation_table(tmp_path):
    ds = tiny_dataset(T=5, n_landmarks=0, clutter_every=0)
    assert len(ds.inputs.observations) == 0
    back = read_dataset(write_dataset(tmp_path / "d.h5", ds))
    assert len(back.inputs.observations) == 0
    assert back.inputs.observations.offsets.tolist() == [0] * 7
    assert back.truth.landmarks_xy.shape == (0, 2)


def test_with_truth_false_does_not_read_truth(good):
    with h5py.File(good, "r+") as f:  # a broken truth group must not matter when truth is not read
        del f["truth/obs_landmark"]
    back = read_dataset(good, with_truth=False)
    assert back.truth is None
    with pytest.raises(SchemaError, match="truth/obs_landmark: missing dataset"):
        read_dataset(good)


def test_file_layout_attributes_and_compression(good, ds):
    with h5py.File(good, "r") as f:
        assert f.attrs["schema"] == "slamcli.dataset" and f.attrs["schema_version"] == 1
        assert f.attrs["seed"] == 0 and f.attrs["scenario"] == "tiny-test"
        assert f.attrs["dt"] == ds.inputs.dt
        assert "max_range" in f.attrs["scenario_params_json"]
        assert set(f) == {"inputs", "truth"}
        for name in ("inputs/controls", "inputs/observations/range_m", "truth/poses_xyt"):
            d = f[name]
            assert d.compression == "gzip" and d.shuffle and d.chunks is not None
            assert "units" in d.attrs and "frame" in d.attrs
        assert f["inputs/observations/bearing_rad"].attrs["units"] == "rad"
        assert f["truth/landmarks_xy"].attrs["frame"] == "world"
    hdr = read_header(good)
    assert hdr["scenario_params_json"] == ds.metadata["scenario_params"]
    assert hdr["has_truth"] is True


def test_hash_is_content_based(tmp_path, ds):
    a = write_dataset(tmp_path / "a.h5", ds)
    b = write_dataset(tmp_path / "b.h5", ds)
    assert a.read_bytes() != b"" and dataset_hash(read_dataset(a)) == dataset_hash(read_dataset(b))
    h0 = dataset_hash(ds)
    assert h0.startswith("sha256:") and len(h0) == 7 + 64
    r = ds.inputs.observations.range_m.copy()
    r[3] = np.nextafter(r[3], np.inf)  # one ulp in one observation changes the hash
    obs2 = dataclasses.replace(ds.inputs.observations, range_m=r)
    assert dataset_hash(dataclasses.replace(ds, inputs=dataclasses.replace(ds.inputs, observations=obs2))) != h0
    lm = ds.truth.landmarks_xy.copy()
    lm[0, 0] += 1e-9
    assert dataset_hash(dataclasses.replace(ds, truth=dataclasses.replace(ds.truth, landmarks_xy=lm))) != h0
    assert dataset_hash(dataclasses.replace(ds, metadata={**ds.metadata, "seed": 1})) != h0
    # metadata other than seed/scenario (e.g. a note) does not enter the hash
    assert dataset_hash(dataclasses.replace(ds, metadata={**ds.metadata, "note": "x"})) == h0


# --------------------------------------------------------------------------------------------------------
# atomic writes
# --------------------------------------------------------------------------------------------------------
def test_failed_write_leaves_no_file(tmp_path, ds, monkeypatch):
    calls = {"n": 0}
    real = io_dataset.write_array

    def flaky(*args, **kwargs):
        calls["n"] += 1
        if calls["n"] == 5:
            raise RuntimeError("disk full")
        return real(*args, **kwargs)

    monkeypatch.setattr(io_dataset, "write_array", flaky)
    with pytest.raises(RuntimeError, match="disk full"):
        write_dataset(tmp_path / "out.h5", ds)
    assert os.listdir(tmp_path) == []


def test_failed_write_keeps_existing_file(tmp_path, ds):
    target = write_dataset(tmp_path / "out.h5", ds)
    before = target.read_bytes()
    bad = dataclasses.replace(ds, metadata={"x": object()})
    with pytest.raises(SchemaError, match="metadata: not JSON-serialisable"):
        write_dataset(target, bad)
    assert target.read_bytes() == before
    assert sorted(os.listdir(tmp_path)) == ["out.h5"]


def test_atomic_path_creates_parent_and_renames(tmp_path):
    target = tmp_path / "sub" / "x.bin"
    with atomic_path(target) as tmp:
        assert tmp.parent == target.parent and tmp != target
        tmp.write_bytes(b"abc")
        assert not target.exists()
    assert target.read_bytes() == b"abc"
    assert os.listdir(target.parent) == ["x.bin"]


# --------------------------------------------------------------------------------------------------------
# bad inputs: one test each; every message is one line naming the file and the field
# --------------------------------------------------------------------------------------------------------
def expect_error(path, *fragments):
    with pytest.raises(SchemaError) as info:
        read_dataset(path)
    msg = str(info.value)
    assert "\n" not in msg
    assert str(path) in msg
    for frag in fragments:
        assert frag in msg, msg
    return msg


def replace_dataset(path, name, data):
    with h5py.File(path, "r+") as f:
        del f[name]
        f.create_dataset(name, data=data)


def test_missing_file(tmp_path):
    expect_error(tmp_path / "nope.h5", "no such file")


def test_directory(tmp_path):
    expect_error(tmp_path, "is a directory")


def test_not_hdf5(tmp_path):
    p = tmp_path / "x.h5"
    p.write_text("time,x,y\n0,1,2\n")
    expect_error(p, "not an HDF5 file")


@pytest.mark.parametrize("fraction", [0.3, 0.7, 0.97])
def test_truncated_file(good, fraction):
    size = good.stat().st_size
    with open(good, "r+b") as fh:
        fh.truncate(int(size * fraction))
    expect_error(good, "truncated or corrupt")


def test_wrong_schema_name(good):
    with h5py.File(good, "r+") as f:
        f.attrs["schema"] = "slamcli.result"
    expect_error(good, "@schema", "expected 'slamcli.dataset'")


def test_wrong_schema_version(good):
    with h5py.File(good, "r+") as f:
        f.attrs["schema_version"] = 2
    expect_error(good, "@schema_version", "unsupported version 2")


def test_missing_schema_attribute(good):
    with h5py.File(good, "r+") as f:
        del f.attrs["schema"]
    expect_error(good, "@schema", "missing attribute")


def test_missing_inputs_group(good):
    with h5py.File(good, "r+") as f:
        del f["inputs"]
    expect_error(good, "inputs: missing group")


def test_missing_truth_group_when_declared(good):
    with h5py.File(good, "r+") as f:
        del f["truth"]
    expect_error(good, "truth: missing group")


def test_missing_dataset(good):
    with h5py.File(good, "r+") as f:
        del f["inputs/controls"]
    expect_error(good, "inputs/controls: missing dataset")


def test_controls_length_mismatch(good, ds):
    replace_dataset(good, "inputs/controls", ds.inputs.controls[:-1])
    expect_error(good, "inputs/controls", "length 39 does not match T")


def test_odometry_wrong_shape(good, ds):
    replace_dataset(good, "inputs/odometry_xyt", ds.inputs.odometry_xyt[:, :2])
    expect_error(good, "inputs/odometry_xyt", "expected shape (*, 3), got (41, 2)")


def test_nan_in_odometry(good, ds):
    odo = ds.inputs.odometry_xyt.copy()
    odo[7, 2] = np.nan
    replace_dataset(good, "inputs/odometry_xyt", odo)
    expect_error(good, "inputs/odometry_xyt", "non-finite value nan at index (7, 2)")


def test_inf_in_range(good, ds):
    r = ds.inputs.observations.range_m.copy()
    r[4] = np.inf
    replace_dataset(good, "inputs/observations/range_m", r)
    expect_error(good, "inputs/observations/range_m", "non-finite value inf at index 4")


def test_negative_range(good, ds):
    r = ds.inputs.observations.range_m.copy()
    r[2] = -0.5
    replace_dataset(good, "inputs/observations/range_m", r)
    expect_error(good, "inputs/observations/range_m", "negative range -0.5 at row 2")


def test_bearing_in_degrees(good, ds):
    replace_dataset(good, "inputs/observations/bearing_rad", np.degrees(ds.inputs.observations.bearing_rad))
    expect_error(good, "inputs/observations/bearing_rad", "outside [-pi, pi]")


def test_offsets_not_monotone(good, ds):
    off = ds.inputs.observations.offsets.copy()
    off[10], off[11] = off[11] + 1, off[10]
    replace_dataset(good, "inputs/observations/offsets", off)
    expect_error(good, "inputs/observations/offsets", "not monotone")


def test_offsets_do_not_match_steps(good, ds):
    off = ds.inputs.observations.offsets.copy()
    k = int(np.flatnonzero(np.diff(off) > 0)[0]) + 1  # shift one boundary, still monotone
    off[k] -= 1
    replace_dataset(good, "inputs/observations/offsets", off)
    expect_error(good, "inputs/observations/offsets", "do not match the step column")


def test_offsets_wrong_length(good, ds):
    replace_dataset(good, "inputs/observations/offsets", ds.inputs.observations.offsets[:-1])
    expect_error(good, "inputs/observations/offsets", "does not match T+2")


def test_offsets_last_entry(good, ds):
    off = ds.inputs.observations.offsets.copy()
    off[-1] += 3
    replace_dataset(good, "inputs/observations/offsets", off)
    expect_error(good, "inputs/observations/offsets", "last offset")


def test_step_out_of_range(good, ds):
    s = ds.inputs.observations.step.copy()
    s[-1] = 41
    replace_dataset(good, "inputs/observations/step", s)
    expect_error(good, "inputs/observations/step", "value 41", "out of range [0, 40]")


def test_observation_column_length_mismatch(good, ds):
    replace_dataset(good, "inputs/observations/bearing_rad", ds.inputs.observations.bearing_rad[:-2])
    expect_error(good, "inputs/observations/bearing_rad", "does not match len(inputs/observations/step)")


def test_float_step_column(good, ds):
    replace_dataset(good, "inputs/observations/step", ds.inputs.observations.step.astype(float))
    expect_error(good, "inputs/observations/step", "expected integer data")


def test_reported_id_below_minus_one(good, ds):
    rid = ds.inputs.observations.reported_id.copy()
    rid[0] = -5
    replace_dataset(good, "inputs/observations/reported_id", rid)
    expect_error(good, "inputs/observations/reported_id", "below -1")


def test_timestamps_not_increasing(good, ds):
    ts = ds.inputs.timestamps.copy()
    ts[5] = ts[4]
    replace_dataset(good, "inputs/timestamps", ts)
    expect_error(good, "inputs/timestamps", "not strictly increasing at index 5")


def test_nonpositive_dt(good):
    with h5py.File(good, "r+") as f:
        f.attrs["dt"] = -0.1
    expect_error(good, "@dt", "must be > 0")


def test_negative_noise_std(good):
    replace_dataset(good, "inputs/noise/range_std", -0.1)
    expect_error(good, "inputs/noise/range_std", ">= 0")


def test_nan_max_range(good):
    replace_dataset(good, "inputs/max_range", np.nan)
    expect_error(good, "inputs/max_range", "must be > 0")


def test_invalid_metadata_json(good):
    with h5py.File(good, "r+") as f:
        f.attrs["metadata_json"] = "{not json"
    expect_error(good, "@metadata_json", "invalid JSON")


def test_partial_gps(good):
    with h5py.File(good, "r+") as f:
        del f["inputs/gps_xy"]
    expect_error(good, "inputs/gps_xy", "missing dataset")


def test_gps_step_out_of_range(good, ds):
    g = ds.inputs.gps_step.copy()
    g[-1] = 99
    replace_dataset(good, "inputs/gps_step", g)
    expect_error(good, "inputs/gps_step", "value 99")


def test_truth_pose_length_mismatch(good, ds):
    replace_dataset(good, "truth/poses_xyt", ds.truth.poses_xyt[:-3])
    expect_error(good, "truth/poses_xyt", "length 38 does not match")


def test_truth_label_out_of_range(good, ds):
    lab = ds.truth.obs_landmark.copy()
    lab[1] = 6  # only 6 landmarks: valid labels are -1..5
    replace_dataset(good, "truth/obs_landmark", lab)
    expect_error(good, "truth/obs_landmark", "value 6", "out of range [-1, 5]")


def test_group_where_dataset_expected(good):
    with h5py.File(good, "r+") as f:
        del f["inputs/x0"]
        f.create_group("inputs/x0")
    expect_error(good, "inputs/x0", "expected a dataset, found a group")


@pytest.mark.slow
def test_random_byte_corruption_gives_schema_error_or_valid_data(good):
    """Overwrite 16 random bytes at 80 random offsets: reading either succeeds (unused or plain data bytes)
    or raises a one-line SchemaError, never another exception or a traceback-worthy crash."""
    raw = good.read_bytes()
    rng = np.random.default_rng(0)
    outcomes = {"ok": 0, "schema": 0}
    for _ in range(80):
        b = bytearray(raw)
        off = int(rng.integers(0, len(b) - 16))
        b[off : off + 16] = rng.integers(0, 256, 16, dtype=np.uint8).tobytes()
        good.write_bytes(bytes(b))
        try:
            read_dataset(good)
            outcomes["ok"] += 1
        except SchemaError as exc:
            assert "\n" not in str(exc) and str(good) in str(exc)
            outcomes["schema"] += 1
    assert outcomes["schema"] > 0


def test_checksum_detects_a_flipped_data_byte(good):
    with h5py.File(good, "r") as f:
        d = f["inputs/observations/range_m"]
        assert d.fletcher32
        info = d.id.get_chunk_info(0)
        where = info.byte_offset + info.size // 2
    b = bytearray(good.read_bytes())
    b[where] ^= 0x01
    good.write_bytes(bytes(b))
    expect_error(good, "inputs/observations/range_m", "unreadable data, file truncated or corrupt")
