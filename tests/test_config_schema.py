"""One configuration schema: the same bad value gives the same one-line message through ``-p``, an experiment
file and the Python API; an unknown key gets "did you mean" on every path."""

from __future__ import annotations

import pytest
from typer.testing import CliRunner

import slamcli as api
from slamcli.cli import app
from slamcli.errors import ConfigError
from slamcli.params import build_params, convert
from slamcli.sim import simulate_scenario
from slamcli.sweep.config import load_experiment
from slamcli.sweep.expand import expand

#: what every path must say about ``max_sweeps = "abc"`` for icm, after naming where the value came from
BAD_VALUE_TEXT = "max_sweeps: expected an integer, got 'abc'"

EXPERIMENT = """
[experiment]
name = "bad"
[scenario]
name = "loop"
[[solver]]
method = "icm"
[solver.params]
{key} = {value}
"""


@pytest.fixture(scope="module")
def dataset(tmp_path_factory):
    path = tmp_path_factory.mktemp("schema") / "loop.h5"
    api.simulate("loop", seed=0, out=path, overrides={"n_steps": 30})
    return path


def _cli_error(args) -> str:
    r = CliRunner().invoke(app, args)
    assert r.exit_code != 0
    lines = [ln for ln in r.output.splitlines() if ln.startswith("error:")]
    assert len(lines) == 1, r.output
    return lines[0]


def _toml_error(tmp_path, key: str, value: str) -> str:
    path = tmp_path / "exp.toml"
    path.write_text(EXPERIMENT.format(key=key, value=value))
    with pytest.raises(ConfigError) as info:
        expand(load_experiment(path))
    return str(info.value)


def _api_error(dataset, **params) -> str:
    with pytest.raises(ConfigError) as info:
        api.solve(dataset, "icm", **params)
    return str(info.value)


def test_the_same_bad_value_gives_the_same_line_on_every_path(dataset, tmp_path):
    cli = _cli_error(["solve", str(dataset), "-m", "icm", "-p", "max_sweeps=abc", "-o", str(tmp_path / "r.h5")])
    toml = _toml_error(tmp_path, "max_sweeps", '"abc"')
    py = _api_error(dataset, max_sweeps="abc")
    for msg, where in ((cli, "--param (icm)"), (toml, "exp.toml: solver[0].params"), (py, "--param (icm)")):
        assert "\n" not in msg and msg.endswith(BAD_VALUE_TEXT), msg
        assert where in msg, msg
    assert not (tmp_path / "r.h5").exists()


def test_an_unknown_key_gets_did_you_mean_on_every_path(dataset, tmp_path):
    cli = _cli_error(["solve", str(dataset), "-m", "icm", "-p", "max_sweep=3", "-o", str(tmp_path / "r.h5")])
    toml = _toml_error(tmp_path, "max_sweep", "3")
    py = _api_error(dataset, max_sweep=3)
    for msg in (cli, toml, py):
        assert "'max_sweep'" in msg and "did you mean 'max_sweeps'?" in msg and "\n" not in msg, msg


def test_unknown_scenario_key_and_importer_option_get_did_you_mean():
    with pytest.raises(ConfigError, match=r"unknown key 'sensor\.range_sd'; did you mean 'sensor\.range_std'"):
        simulate_scenario("loop", seed=0, overrides={"sensor.range_sd": 0.1})
    from slamcli.datasets.options import check_options

    with pytest.raises(ConfigError, match=r"data\[0\]\.robto: .*did you mean 'robot'"):
        check_options("mrclam", {"robto": 2}, "data[0]")


@pytest.mark.parametrize(("value", "tp", "expected"), [
    ("1,2,3", tuple[float, ...], (1.0, 2.0, 3.0)),
    ("[[1, 0], [0, 2]]", tuple[tuple[float, ...], ...], ((1.0, 0.0), (0.0, 2.0))),
    ("none", float | None, None),
    ("on", bool, True),
    ("1e3", int, 1000),
])
def test_command_line_notations(value, tp, expected):
    assert convert(value, tp, "--param x") == expected


def test_explicit_value_wins_over_a_preset_in_the_schema():
    from slamcli.solvers.icm import IcmParams

    p = build_params(IcmParams, ["preset=real", "accelerate=none"])
    assert p.accelerate == "none" and p.merge is True  # given kept; unset filled by the preset


EVALUATE = """
[experiment]
name = "ev"
[scenario]
name = "loop"
[[solver]]
method = "odometry"
[evaluate]
{body}
"""


def _runs(tmp_path, body: str):
    path = tmp_path / "ev.toml"
    path.write_text(EVALUATE.format(body=body))
    return expand(load_experiment(path)).runs


def test_evaluate_cutoff_m_is_the_schema_name_and_cutoff_its_old_spelling(tmp_path):
    old, new = _runs(tmp_path, "cutoff = 2.0"), _runs(tmp_path, "cutoff_m = 2.0")
    assert [r.run_id for r in old] == [r.run_id for r in new]  # one option, one run id
    assert all(r.evaluate["cutoff"] == 2.0 for r in new)
    with pytest.raises(ConfigError, match=r"cutoff_m and cutoff \(its old spelling\) both given") as info:
        _runs(tmp_path, "cutoff = 2.0\ncutoff_m = 2.0")
    assert "\n" not in str(info.value)
    with pytest.raises(ConfigError, match=r"cutoff_m: .*must be") as info:
        _runs(tmp_path, "cutoff_m = -1.0")
    with pytest.raises(ConfigError, match=r"evaluate.cutof_m: unknown option 'cutof_m'; did you mean 'cutoff_m'"):
        _runs(tmp_path, "cutof_m = 1.0")


def test_a_conflict_between_given_keys_is_one_line_even_at_default_values():
    from slamcli.solvers.icm import IcmParams

    with pytest.raises(ConfigError, match=r"R given with weights=information") as info:
        build_params(IcmParams, ["preset=real", "weights=information", "R=1"])  # R=1 is R's default
    assert "\n" not in str(info.value)
