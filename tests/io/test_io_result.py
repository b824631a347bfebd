"""Result schema v1: round trips (with and without optional parts), atomic writes, bad inputs."""

from __future__ import annotations

import dataclasses
import os

import h5py
import numpy as np
import pytest

from slamcli.errors import SchemaError, SlamcliError
from slamcli.io import read_result, write_result
from slamcli.io import result as io_result
from slamcli.types import IterationTrace, SolverResult, Status


def make_result(*, full: bool = True, status: Status = Status.CONVERGED) -> SolverResult:
    rng = np.random.default_rng(3)
    T1, L, N = 21, 4, 30
    A = rng.normal(size=(T1, 3, 3))
    B = rng.normal(size=(L, 2, 2))
    trace = IterationTrace.from_lists(
        objective=[10.0, 4.0, 3.5],
        map_change=[0.0, 0.3, 0.01],
        time_s=[0.001, 0.002, 0.002],
        landmarks_per_iter=[rng.normal(size=(3, 2)), rng.normal(size=(4, 2)), rng.normal(size=(4, 2))],
        poses_per_iter=[rng.normal(size=(T1, 3)), rng.normal(size=(T1, 3))],
        pose_iterations=[0, 2],
    )
    return SolverResult(
        solver="graph",
        solver_version="0.1.0",
        params={"max_iterations": 20, "tol": 1e-8, "kernel": "huber", "sigmas": [0.1, 0.2], "opt": None},
        status=status,
        message="converged after 2 iterations",
        poses_xyt=rng.normal(size=(T1, 3)),
        landmarks_xy=rng.normal(size=(L, 2)),
        assoc=rng.integers(-1, L, size=N),
        pose_cov=A @ A.transpose(0, 2, 1) if full else None,
        landmark_cov=B @ B.transpose(0, 2, 1) if full else None,
        trace=trace if full else None,
        wall_time_s=0.125,
        dataset_hash="sha256:" + "ab" * 32,
        extra={"dataset_path": "/data/a.h5", "used_truth_association": True, "n_new": np.int64(3)},
    )


def same(a, b):
    a, b = np.asarray(a), np.asarray(b)
    return a.shape == b.shape and a.dtype == b.dtype and a.tobytes() == b.tobytes()


def test_round_trip_full(tmp_path):
    res = make_result()
    back = read_result(write_result(tmp_path / "r.h5", res))
    for name in ("poses_xyt", "landmarks_xy", "assoc", "pose_cov", "landmark_cov"):
        assert same(getattr(back, name), getattr(res, name)), name
    for name in ("objective", "map_change", "time_s", "landmarks_xy", "landmark_offsets"):
        assert same(getattr(back.trace, name), getattr(res.trace, name)), name
    assert back.trace.landmarks_at(1).shape == (4, 2)
    for name in ("poses_xyt", "pose_iterations"):
        assert same(getattr(back.trace, name), getattr(res.trace, name)), name
    assert same(back.trace.poses_at(2), res.trace.poses_xyt[1]) and back.trace.poses_at(1) is None
    assert back.status is Status.CONVERGED
    assert (back.solver, back.solver_version, back.message) == (res.solver, res.solver_version, res.message)
    assert back.params == res.params
    assert back.wall_time_s == res.wall_time_s
    assert back.dataset_hash == res.dataset_hash
    assert back.extra == {"dataset_path": "/data/a.h5", "used_truth_association": True, "n_new": 3}
    with h5py.File(tmp_path / "r.h5", "r") as f:
        assert f.attrs["schema"] == "slamcli.result" and f.attrs["dataset_path"] == "/data/a.h5"
        assert f["poses_xyt"].compression == "gzip" and f["poses_xyt"].attrs["frame"] == "world"


def test_round_trip_minimal(tmp_path):
    res = make_result(full=False, status=Status.COMPLETED)
    res = dataclasses.replace(res, extra={}, landmarks_xy=np.zeros((0, 2)), assoc=np.full(30, -1))
    back = read_result(write_result(tmp_path / "r.h5", res))
    assert back.pose_cov is None and back.landmark_cov is None and back.trace is None
    assert back.landmarks_xy.shape == (0, 2)
    assert back.status is Status.COMPLETED and back.extra == {}


def test_failed_status_may_hold_nan(tmp_path):
    res = dataclasses.replace(make_result(full=False, status=Status.FAILED),
                              poses_xyt=np.full((5, 3), np.nan), message="diverged")
    back = read_result(write_result(tmp_path / "r.h5", res))
    assert back.status is Status.FAILED and np.isnan(back.poses_xyt).all()


def test_failed_write_leaves_no_file(tmp_path, monkeypatch):
    real = io_result.write_array
    calls = {"n": 0}

    def flaky(*a, **k):
        calls["n"] += 1
        if calls["n"] == 3:
            raise OSError("disk full")
        return real(*a, **k)

    monkeypatch.setattr(io_result, "write_array", flaky)
    with pytest.raises(SlamcliError, match=r"r\.h5: cannot write file \(disk full\)"):
        write_result(tmp_path / "r.h5", make_result())
    assert os.listdir(tmp_path) == []


def test_unwritable_destinations_are_one_line_errors(tmp_path):
    (tmp_path / "adir").mkdir()
    with pytest.raises(SlamcliError, match="adir: is a directory"):
        write_result(tmp_path / "adir", make_result())
    (tmp_path / "afile").write_text("x")
    with pytest.raises(SlamcliError, match="cannot write file"):
        write_result(tmp_path / "afile" / "r.h5", make_result())
    assert sorted(os.listdir(tmp_path)) == ["adir", "afile"] and os.listdir(tmp_path / "adir") == []


def test_unserialisable_params(tmp_path):
    res = dataclasses.replace(make_result(), params={"f": object()})
    with pytest.raises(SchemaError, match="not JSON-serialisable"):
        write_result(tmp_path / "r.h5", res)
    assert os.listdir(tmp_path) == []


# -- bad inputs ------------------------------------------------------------------------------------------
@pytest.fixture()
def good(tmp_path):
    return write_result(tmp_path / "good.h5", make_result())


def expect_error(path, *fragments):
    with pytest.raises(SchemaError) as info:
        read_result(path)
    msg = str(info.value)
    assert "\n" not in msg and str(path) in msg
    for frag in fragments:
        assert frag in msg, msg


def replace(path, name, data):
    with h5py.File(path, "r+") as f:
        del f[name]
        f.create_dataset(name, data=data)


def test_dataset_file_is_not_a_result(tmp_path):
    from conftest import tiny_dataset

    from slamcli.io import write_dataset

    p = write_dataset(tmp_path / "d.h5", tiny_dataset(T=5))
    expect_error(p, "@schema", "expected 'slamcli.result', got 'slamcli.dataset'")


def test_truncated(good):
    size = good.stat().st_size
    with open(good, "r+b") as fh:
        fh.truncate(size // 2)
    expect_error(good, "truncated or corrupt")


def test_not_hdf5(tmp_path):
    p = tmp_path / "r.h5"
    p.write_bytes(b"\x00" * 100)
    expect_error(p, "not an HDF5 file")


def test_wrong_version(good):
    with h5py.File(good, "r+") as f:
        f.attrs["schema_version"] = 0
    expect_error(good, "@schema_version", "unsupported version 0")


def test_unknown_status(good):
    with h5py.File(good, "r+") as f:
        f.attrs["status"] = "ok"
    expect_error(good, "@status", "unknown status 'ok'")


def test_missing_poses(good):
    with h5py.File(good, "r+") as f:
        del f["poses_xyt"]
    expect_error(good, "poses_xyt: missing dataset")


def test_nan_pose_when_not_failed(good):
    p = make_result().poses_xyt.copy()
    p[2, 1] = np.nan
    replace(good, "poses_xyt", p)
    expect_error(good, "poses_xyt", "non-finite")


def test_assoc_label_out_of_range(good):
    a = make_result().assoc.copy()
    a[5] = 4
    replace(good, "assoc", a)
    expect_error(good, "assoc", "label 4 at row 5 out of range [-1, 3]")


def test_pose_cov_length_mismatch(good):
    replace(good, "pose_cov", make_result().pose_cov[:-1])
    expect_error(good, "pose_cov", "does not match len(poses_xyt)")


def test_landmark_cov_wrong_shape(good):
    replace(good, "landmark_cov", np.zeros((4, 3, 3)))
    expect_error(good, "landmark_cov", "expected shape (*, 2, 2)")


def test_trace_length_mismatch(good):
    replace(good, "trace/time_s", np.zeros(2))
    expect_error(good, "trace/time_s", "does not match len(trace/objective)")


def test_trace_offsets_bad(good):
    replace(good, "trace/landmark_offsets", np.array([0, 3, 2, 11]))
    expect_error(good, "trace/landmark_offsets", "must rise monotonically")


def test_trace_poses_every_iteration_chunked_per_iteration(tmp_path):
    res = make_result()
    rng = np.random.default_rng(8)
    poses = rng.normal(size=(3, res.poses_xyt.shape[0], 3))
    tr = dataclasses.replace(res.trace, poses_xyt=poses, pose_iterations=None)  # None = every iteration
    path = write_result(tmp_path / "r.h5", dataclasses.replace(res, trace=tr))
    with h5py.File(path, "r") as f:
        ds = f["trace/poses_xyt"]
        assert ds.chunks == (1, 21, 3) and ds.compression == "gzip" and ds.shuffle
        np.testing.assert_array_equal(f["trace/pose_iterations"][()], [0, 1, 2])
    back = read_result(path)
    assert same(back.trace.poses_xyt, poses)
    for k in range(3):
        assert same(back.trace.poses_at(k), poses[k])


def test_trace_without_poses_reads(tmp_path):
    res = make_result()
    tr = dataclasses.replace(res.trace, poses_xyt=None, pose_iterations=None)
    path = write_result(tmp_path / "r.h5", dataclasses.replace(res, trace=tr))
    with h5py.File(path, "r") as f:
        assert "poses_xyt" not in f["trace"] and "pose_iterations" not in f["trace"]
    back = read_result(path)
    assert back.trace.poses_xyt is None and back.trace.poses_at(0) is None


def test_trace_poses_bad_shape(good):
    replace(good, "trace/poses_xyt", np.zeros((2, 21, 2)))
    expect_error(good, "trace/poses_xyt", "expected shape (*, *, 3)")


def test_trace_poses_wrong_pose_count(good):
    replace(good, "trace/poses_xyt", np.zeros((2, 20, 3)))
    expect_error(good, "trace/poses_xyt", "expected shape (*, 21, 3)")


def test_trace_poses_non_finite(good):
    p = make_result().trace.poses_xyt.copy()
    p[1, 4, 2] = np.inf
    replace(good, "trace/poses_xyt", p)
    expect_error(good, "trace/poses_xyt", "non-finite value inf at index (1, 4, 2)")


def test_trace_pose_iterations_bad(good):
    replace(good, "trace/pose_iterations", np.array([0, 3]))
    expect_error(good, "trace/pose_iterations", "must rise strictly within [0, 2]")
    replace(good, "trace/pose_iterations", np.array([0]))
    expect_error(good, "trace/pose_iterations", "does not match len(trace/poses_xyt)")


def test_params_json_invalid(good):
    with h5py.File(good, "r+") as f:
        f.attrs["params_json"] = "[1,"
    expect_error(good, "@params_json", "invalid JSON")


def test_negative_wall_time(good):
    with h5py.File(good, "r+") as f:
        f.attrs["wall_time_s"] = -1.0
    expect_error(good, "@wall_time_s", ">= 0")


def test_missing_result_file(tmp_path):
    expect_error(tmp_path / "none.h5", "no such file")
