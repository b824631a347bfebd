"""The one JSON / UTC / atomic-write helper (slamcli.io.schema), which the sweep runner uses too (issue 21)."""

from __future__ import annotations

import enum
import json
import re
from pathlib import Path

import numpy as np
import pytest

from slamcli.io.schema import utc_now, write_json
from slamcli.sweep import runner


class Colour(enum.Enum):
    RED = "red"


def test_write_json_converts_numpy_enums_and_paths_and_keeps_inf(tmp_path):
    path = tmp_path / "m.json"
    write_json(path, {"b": np.float32(1.5), "a": np.arange(3), "c": Colour.RED, "d": Path("x/y"),
                      "e": float("inf"), "f": (1, 2)})
    # the expected text written out by hand: sorted keys, indent 2, Python's Infinity, final newline
    assert path.read_text() == ('{\n  "a": [\n    0,\n    1,\n    2\n  ],\n  "b": 1.5,\n  "c": "red",\n'
                                '  "d": "x/y",\n  "e": Infinity,\n  "f": [\n    1,\n    2\n  ]\n}\n')


def test_write_json_refuses_unknown_types_and_leaves_the_old_file(tmp_path):
    path = tmp_path / "status.json"
    path.write_text('{"old": true}\n')
    with pytest.raises(TypeError, match="object is not JSON serialisable"):
        write_json(path, {"x": object()})
    assert path.read_text() == '{"old": true}\n'
    assert sorted(p.name for p in tmp_path.iterdir()) == ["status.json"]  # no temporary left behind


def test_utc_now_is_seconds_with_z():
    assert re.fullmatch(r"\d{4}-\d\d-\d\dT\d\d:\d\d:\d\dZ", utc_now())


def test_runner_writes_through_the_io_helpers():
    assert runner.write_json is write_json and runner.utc_now is utc_now
    assert not hasattr(runner, "_json_default") and not hasattr(runner, "_utc_now")


def test_runner_status_file_uses_the_one_utc_format(tmp_path):
    from slamcli.sweep.expand import DatasetSpec, RunSpec

    ds = DatasetSpec(dataset_id="d0", scenario="loop", overrides={}, resolved={}, replicate=0, seed=1)
    run = RunSpec(run_id="r0", experiment="e", label="odometry", method="odometry", params={}, param_overrides={},
                  seed=0, solver_stream=0, oracle_association=False, evaluate={}, dataset=ds)
    summary = runner.record_dead_run(run, tmp_path, "worker died")
    status = json.loads((tmp_path / "r0" / "status.json").read_text())
    assert summary["status"] == "failed" and status["error"] == "worker died"
    assert re.fullmatch(r"\d{4}-\d\d-\d\dT\d\d:\d\d:\d\dZ", status["started_utc"])
