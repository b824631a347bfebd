"""Compression settings (issue 17): files are written with ``schema.COMPRESSION``; files written with other
filters (v1's gzip-4, lzf, none) read back bit-identically through the same reader."""

from __future__ import annotations

import h5py
import numpy as np
import pytest
from conftest import tiny_dataset

from slamcli.io import dataset_hash, read_dataset, read_result, schema, write_dataset, write_result
from slamcli.solvers.odometry import OdometryParams, OdometrySolver


def test_new_files_use_the_one_compression_constant(tmp_path):
    path = write_dataset(tmp_path / "d.h5", tiny_dataset(T=30))
    with h5py.File(path, "r") as f:
        d = f["inputs/observations/range_m"]
        assert d.compression == schema.COMPRESSION["compression"] == "gzip"
        assert d.compression_opts == schema.GZIP_LEVEL == 1
        assert d.shuffle and d.fletcher32


@pytest.mark.parametrize(
    "filters",
    [
        {"compression": "gzip", "compression_opts": 4, "shuffle": True, "fletcher32": True},  # schema v1 as first written
        {"compression": "lzf", "shuffle": True, "fletcher32": True},
        {"fletcher32": True},
    ],
    ids=["gzip4", "lzf", "none"],
)
def test_files_written_with_other_filters_read_identically(tmp_path, monkeypatch, filters):
    ds = tiny_dataset(T=60, gps_every=7, report_ids=True)
    res = OdometrySolver(OdometryParams()).solve(ds.inputs, rng=np.random.default_rng(0))
    new_d, new_r = write_dataset(tmp_path / "new.h5", ds), write_result(tmp_path / "new_r.h5", res)
    monkeypatch.setattr(schema, "COMPRESSION", dict(filters))
    import slamcli.io.result as result_mod

    monkeypatch.setattr(result_mod, "COMPRESSION", dict(filters))
    old_d, old_r = write_dataset(tmp_path / "old.h5", ds), write_result(tmp_path / "old_r.h5", res)
    with h5py.File(old_d, "r") as f:
        assert f["inputs/observations/range_m"].compression == filters.get("compression")
    a, b = read_dataset(new_d), read_dataset(old_d)
    assert dataset_hash(a) == dataset_hash(b) == dataset_hash(ds)
    np.testing.assert_array_equal(a.truth.poses_xyt, b.truth.poses_xyt)
    ra, rb = read_result(new_r), read_result(old_r)
    for name in ("poses_xyt", "landmarks_xy", "assoc"):
        assert getattr(ra, name).tobytes() == getattr(rb, name).tobytes() == getattr(res, name).tobytes()
