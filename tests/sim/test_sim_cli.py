"""``slamcli simulate`` and ``slamcli.api.simulate.simulate_to_file``: files, determinism, one-line errors."""

from __future__ import annotations

import numpy as np
import pytest
from typer.testing import CliRunner

from slamcli.api.simulate import simulate_to_file
from slamcli.cli import app
from slamcli.errors import ConfigError
from slamcli.io import read_dataset
from slamcli.sim import config_from_dict, resolve_scenario, simulate_scenario

runner = CliRunner()


def _same(a, b):
    ia, ib = a.inputs, b.inputs
    for k in ("controls", "odometry_xyt", "timestamps", "x0"):
        np.testing.assert_array_equal(getattr(ia, k), getattr(ib, k), err_msg=k)
    for k in ("step", "range_m", "bearing_rad", "sensor", "reported_id", "offsets"):
        np.testing.assert_array_equal(getattr(ia.observations, k), getattr(ib.observations, k), err_msg=k)
    for k in ("poses_xyt", "landmarks_xy", "obs_landmark"):
        np.testing.assert_array_equal(getattr(a.truth, k), getattr(b.truth, k), err_msg=k)


@pytest.mark.slow
def test_cli_simulate_writes_file_equal_to_library_run(tmp_path):
    out = tmp_path / "a.h5"
    res = runner.invoke(app, ["simulate", "--scenario", "loop", "--seed", "4", "--set", "sensor.max_range=6",
                              "--set", "clutter.rate=0.5", "-o", str(out)])
    assert res.exit_code == 0, res.output
    assert "loop seed 4: 500 steps" in res.output
    ds = read_dataset(out)
    _same(ds, simulate_scenario("loop", seed=4, overrides={"sensor.max_range": 6, "clutter.rate": 0.5}))
    assert ds.metadata["seed"] == 4 and ds.metadata["scenario"] == "loop"
    assert config_from_dict(ds.metadata["config"]) == resolve_scenario(
        "loop", {"sensor.max_range": "6", "clutter.rate": "0.5"})
    out2 = tmp_path / "b.h5"
    assert runner.invoke(app, ["simulate", "-s", "loop", "--seed", "4", "--set", "sensor.max_range=6", "--set",
                               "clutter.rate=0.5", "-q", "-o", str(out2)]).exit_code == 0
    _same(ds, read_dataset(out2))


@pytest.mark.parametrize(
    "args, message",
    [
        (["--set", "sensor.max_range=far"], "error: --set sensor.max_range: expected a number, got 'far'"),
        (["--set", "sensor.nope=1"], "error: --set: unknown key 'sensor.nope'; did you mean 'sensor.kind'"),
        (["--set", "nokeyvalue"], "error: --set: expected key=value"),
        (["--set", "sensor.detection_prob=2"], "detection_prob must be in [0, 1]"),
        (["--seed", "-3"], "error: --seed: must be in [0, 2^63)"),
        (["--set", "world.n_landmarks=500"], "error: world: cannot place 500 random landmarks"),
    ],
)
def test_cli_bad_input_one_line_exit_1_no_file(tmp_path, args, message):
    out = tmp_path / "x.h5"
    res = runner.invoke(app, ["simulate", "--scenario", "loop", *args, "-o", str(out)])
    assert res.exit_code == 1
    lines = [ln for ln in res.output.splitlines() if ln.strip()]
    assert len(lines) == 1 and message in lines[0], res.output
    assert "Traceback" not in res.output
    assert not out.exists() and list(tmp_path.iterdir()) == []


def test_cli_unknown_scenario_and_list(tmp_path):
    res = runner.invoke(app, ["simulate", "--scenario", "nope", "-o", str(tmp_path / "x.h5")])
    assert res.exit_code == 1 and "unknown scenario 'nope'; known: loop, paper-sim1, paper-sim2, octagon" in res.output
    res = runner.invoke(app, ["simulate", "--list"])
    assert res.exit_code == 0
    for name in ("loop", "paper-sim1", "paper-sim2", "octagon"):
        assert name in res.output
    res = runner.invoke(app, ["simulate", "--scenario", "octagon", "--keys"])
    assert res.exit_code == 0 and "world.octagon_radius = 7.12" in res.output


def test_simulate_to_file_validates_before_writing(tmp_path):
    out = tmp_path / "y.h5"
    with pytest.raises(ConfigError):
        simulate_to_file("loop", 0, ["robot.v_max=-1"], out)
    assert not out.exists()
    calls = []
    ds = simulate_to_file("loop", 1, {"n_steps": 50}, out, progress=lambda d, t: calls.append((d, t)))
    assert out.exists() and calls == [(0, 50), (50, 50)]
    _same(ds, read_dataset(out))
