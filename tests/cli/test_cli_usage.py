"""CLI polish (issue 13 items 6-9): usage errors, help summaries, 80 columns, iteration counts, association
defaults, parameter documentation, experiment reference, TOML "did you mean", paper-ready plots."""

import dataclasses
import re
import struct
import tomllib
import typing

import numpy as np
import pytest
from conftest import ROOT
from typer.testing import CliRunner

from slamcli.api.simulate import simulate_to_file
from slamcli.api.solve import solve_file
from slamcli.cli import app
from slamcli.cli.app import iteration_count, short_help
from slamcli.errors import ConfigError
from slamcli.io import read_dataset, read_result
from slamcli.params import allowed_values, param_docs
from slamcli.solvers import registry
from slamcli.sweep.config import load_experiment, parse_experiment
from slamcli.sweep.expand import expand

runner = CliRunner()
W80 = {"COLUMNS": "80"}


@pytest.fixture(scope="module")
def loop(tmp_path_factory):
    d = tmp_path_factory.mktemp("polish")
    simulate_to_file("loop", 2, {"n_steps": 120}, d / "loop.h5")
    simulate_to_file("loop", 2, {"n_steps": 120, "sensor.report_ids": True}, d / "ids.h5")
    return d


# -- item 9: usage errors, help, 80 columns, iteration counts, build system ---------------------------------


@pytest.mark.parametrize("args, first", [
    (["solve", "--bogus"], "error: No such option: --bogus"),
    (["solve"], "error: Missing argument 'DATA'."),
    (["export", "x.h5"], "error: Missing option '--format'"),
])
def test_usage_error_is_one_line_plus_hint(args, first):
    r = runner.invoke(app, args)
    assert r.exit_code == 2
    lines = r.output.strip().splitlines()
    assert len(lines) == 2 and lines[0].startswith(first), r.output
    assert re.fullmatch(r"hint: see 'slamcli \w+ --help'", lines[1])


def test_help_summaries_are_whole_words_and_fit_80_columns():
    r = runner.invoke(app, ["--help"], env=W80)
    assert r.exit_code == 0
    assert max(len(line) for line in r.output.splitlines()) <= 80
    cmds = r.output.split("Commands:")[1].strip().splitlines()
    assert len(cmds) >= 11
    for line in cmds:
        summary = line.split(None, 1)[1]
        assert not summary.endswith("..."), line  # click's own truncation never kicks in
        assert not re.search(r"\bFigs?\.$", summary)
    assert short_help("Run the paper experiments (Figs. 5, 6). More.") == "Run the paper experiments (Figs. 5, 6)"
    long = "Summarise a dataset (steps, duration, landmarks, observations per pose, noise) in a table."
    s = short_help(long, limit=40)
    assert s.endswith(" …") and long.startswith(s[:-2]) and not long[len(s) - 2].isalnum()  # between words


def test_solve_summary_fits_80_and_counts_iterations_like_the_trace(loop, tmp_path):
    out = tmp_path / "icm.h5"
    r = runner.invoke(app, ["solve", str(loop / "loop.h5"), "-m", "icm", "-p", "max_sweeps=7", "-o", str(out)],
                      env=W80)
    assert r.exit_code == 0, r.output
    res = read_result(out)
    n = len(res.trace) - 1  # row 0 of the trace is the initialisation
    assert iteration_count(res) == n and f", {n} iterations:" in r.output
    assert f"{n} ICM sweeps" in res.message or str(n) in res.message
    # every line fits 80 columns except the one naming the output path (as long as pytest's tmp path)
    assert max(len(line) for line in r.output.splitlines() if str(out) not in line) <= 80, r.output
    info = runner.invoke(app, ["info", str(out)], env=W80)
    assert re.search(rf"iterations\s+│\s+{n}\s", info.output)


def test_build_system_needs_setuptools_77():
    cfg = tomllib.loads((ROOT / "pyproject.toml").read_text())
    req = [r for r in cfg["build-system"]["requires"] if r.startswith("setuptools")][0]
    assert int(re.search(r">=(\d+)", req).group(1)) >= 77 and cfg["project"]["license"] == "MIT"
    assert any(d.startswith("evo") for d in cfg["project"]["optional-dependencies"]["test"])


# -- item 7: association defaults ----------------------------------------------------------------------------


@pytest.mark.parametrize("method", ["ekf", "fastslam"])
@pytest.mark.slow
def test_auto_association_picks_reported_ids_or_ml(loop, tmp_path, method):
    extra = ["-p", "n_particles=10"] if method == "fastslam" else []
    r = runner.invoke(app, ["solve", str(loop / "loop.h5"), "-m", method, *extra, "-o", str(tmp_path / "a.h5"), "-q"])
    assert r.exit_code == 0, r.output  # failed before: "association=known needs sensor-reported ids"
    auto = read_result(tmp_path / "a.h5")
    assert auto.params["association"] == "auto" and auto.extra["association"] == "ml"
    ml = solve_file(loop / "loop.h5", method, {"association": "ml", **dict(e.split("=") for e in extra[1::2])},
                    tmp_path / "ml.h5")
    np.testing.assert_array_equal(auto.poses_xyt, ml.poses_xyt)  # auto = ml on a sensor without ids
    ids = solve_file(loop / "ids.h5", method, dict(e.split("=") for e in extra[1::2]), tmp_path / "i.h5")
    known = solve_file(loop / "ids.h5", method, {"association": "known", **dict(e.split("=") for e in extra[1::2])},
                       tmp_path / "k.h5")
    assert ids.extra["association"] == "known"
    np.testing.assert_array_equal(ids.poses_xyt, known.poses_xyt)
    assert read_dataset(loop / "ids.h5").inputs.observations.reported_id.min() >= 0


# -- item 6: parameter documentation, experiment reference, TOML keys ----------------------------------------


def test_every_solver_parameter_is_documented_once():
    for info in registry.available():
        cls = registry.load(info.name)
        docs = param_docs(cls.Params)
        hints = typing.get_type_hints(cls.Params)
        for f in dataclasses.fields(cls.Params):
            assert f.name in docs and docs[f.name][1], f"{info.name}.{f.name} has no description"
        r = runner.invoke(app, ["solvers", info.name], env=W80)
        assert r.exit_code == 0
        assert max(len(line) for line in r.output.splitlines()) <= 80
        for f in dataclasses.fields(cls.Params):
            assert re.search(rf"^{f.name}  \[", r.output, re.M), f"{info.name}.{f.name} not shown"
            for v in allowed_values(hints[f.name]):
                assert v in r.output
    r = runner.invoke(app, ["solvers", "ekf"], env=W80)
    assert "association  [auto | known | ml]  default: auto" in r.output
    assert "maximum-likelihood association by Mahalanobis" in r.output  # the docstring text itself


def _toml_block(text: str) -> str:
    return re.search(r"```toml\n(.*?)```", text, re.S).group(1)


def test_docs_example_loads_and_expands(tmp_path):
    p = tmp_path / "example.toml"
    p.write_text(_toml_block((ROOT / "docs" / "experiments.md").read_text()))
    cfg = load_experiment(p)
    exp = expand(cfg)
    assert len(exp.runs) == 40  # the count the document states
    labels = {r.label for r in exp.runs}
    assert labels == {"odometry", "ekf-ml", "icm"}


def test_config_docstring_example_is_valid():
    import slamcli.sweep.config as config

    text = config.__doc__.split("An experiment file::")[1].split("Sweep keys:")[0]
    body = "\n".join(line[4:] for line in text.splitlines())
    cfg = parse_experiment(tomllib.loads(body), source="docstring")
    assert len(expand(cfg).runs) == 50 * 2 * 2 * 2


@pytest.mark.parametrize("edit, message", [
    (("n_steps = 300", "n_stepz = 300"),
     "scenario.parameters.n_stepz: unknown scenario key 'n_stepz'; did you mean 'n_steps'?"),
    (("gate_prob = 0.99\n", "gate_prb = 0.99\n"),
     "solver[1].params.gate_prb: unknown parameter 'gate_prb' of ekf; did you mean 'gate_prob'?"),
    (('"solver.ekf-ml.gate_prob"', '"solver.ekf-ml.gate_prb"'),
     "sweep.grid 'solver.ekf-ml.gate_prb': unknown parameter 'gate_prb' of ekf; did you mean 'gate_prob'?"),
    (("rpe_unit =", "rpe_units ="), "evaluate.rpe_units: unknown option 'rpe_units'; did you mean 'rpe_unit'?"),
    (('name = "loop"', 'name = "lop"'), "scenario.name: unknown scenario 'lop'; did you mean 'loop'?"),
    (("[evaluate]", "[evalute]"), "evalute: unknown key; did you mean 'evaluate'?"),
    (("n_steps = 300", 'n_steps = "300 steps"'), "scenario.parameters.n_steps: expected an integer, got '300 steps'"),
    (('association = "ml"', 'association = "mle"'), "solver[1].params.association: 'mle' is not one of auto, known, ml"),
    (("[0.95, 0.99]", '[0.95, "high"]'), "sweep.grid 'solver.ekf-ml.gate_prob': expected a number, got 'high'"),
])
@pytest.mark.slow
def test_toml_errors_name_toml_keys_with_did_you_mean(tmp_path, edit, message):
    text = _toml_block((ROOT / "docs" / "experiments.md").read_text())
    assert edit[0] in text
    p = tmp_path / "x.toml"
    p.write_text(text.replace(edit[0], edit[1], 1))
    with pytest.raises(ConfigError) as info:
        expand(load_experiment(p))
    assert str(info.value).startswith(f"{p}: {message}")
    assert "--set" not in str(info.value) and "--param" not in str(info.value)
    r = runner.invoke(app, ["sweep", str(p), "--dry-run"])
    assert r.exit_code == 1 and len(r.output.strip().splitlines()) == 1


# -- item 8: plots ---------------------------------------------------------------------------------------------


def _png_size(path):
    w, h = struct.unpack(">II", path.read_bytes()[16:24])
    return w, h


@pytest.mark.slow
def test_plot_dpi_size_formats_quiet(loop, tmp_path):
    ekf = tmp_path / "ekf.h5"
    solve_file(loop / "loop.h5", "ekf", {}, ekf)
    r = runner.invoke(app, ["plot", "map", str(ekf), "-o", str(tmp_path / "a.png"), "--dpi", "50",
                            "--size", "4x3", "-q"])
    assert r.exit_code == 0 and r.output == ""
    assert _png_size(tmp_path / "a.png") == (200, 150)  # 4 in × 50 dpi, 3 in × 50 dpi
    r = runner.invoke(app, ["plot", "map", str(ekf), "-o", str(tmp_path / "a.svg")])
    assert r.exit_code == 0 and (tmp_path / "a.svg").read_text().lstrip().startswith("<?xml")
    r = runner.invoke(app, ["plot", "map", str(ekf), "-o", str(tmp_path / "a.png"), "--size", "big"])
    assert r.exit_code == 1 and "--size" in r.output


@pytest.mark.slow
def test_plot_errors_of_a_filter_draws_sigma_bands(loop, tmp_path):
    from slamcli.api.plot import errors
    from slamcli.plots import new_figure

    ekf = tmp_path / "ekf.h5"
    res = solve_file(loop / "loop.h5", "ekf", {}, ekf)
    r = runner.invoke(app, ["plot", "errors", str(ekf), "-o", str(tmp_path / "e.pdf"), "--sigma", "2"])
    assert r.exit_code == 0, r.output  # failed before with "no iteration trace"
    ds = read_dataset(loop / "loop.h5")
    err_x = res.poses_xyt[:, 0] - ds.truth.poses_xyt[:, 0]
    sx = np.sqrt(res.pose_cov[:, 0, 0])
    share = np.mean(np.abs(err_x) <= 2 * sx)
    assert f"x {100 * share:.1f}%" in r.output
    _, axes = new_figure(nrows=3)
    errors(res, ds, ax=axes, n_sigma=2)
    band = axes[0].collections[0].get_paths()[0].vertices[:, 1]
    np.testing.assert_allclose(band.max(), 2 * sx.max(), rtol=1e-12)


def test_nees_and_mapchange_use_log_axes_with_band_visible():
    from slamcli.plots import new_figure
    from slamcli.plots.curves import plot_map_change, plot_nees

    _, ax = new_figure()
    anees = np.array([3.0, 40.0, 300.0, 2.0])  # an inconsistent filter
    plot_nees(ax, np.arange(4), anees, 2.36, 3.72, 3, 50)
    lo, hi = ax.get_ylim()
    assert ax.get_yscale() == "log" and lo <= 2.36 / 2 and hi >= 300.0 and lo > 0
    _, ax = new_figure()
    plot_map_change(ax, np.arange(5), [0.0, 1.0, 1e-2, 1e-4, 0.0], label="fast", log=True)
    plot_map_change(ax, np.arange(5), [0.0, 2.0, 1.5, 1.2, 1.1], label="slow", log=True)
    assert ax.get_yscale() == "log"
    np.testing.assert_allclose(ax.lines[0].get_ydata(), [1000.0, 10.0, 0.1])  # zeros left out, in mm


@pytest.mark.slow
def test_command_output_fits_80_columns(loop, tmp_path):
    d = str(tmp_path)
    ekf = tmp_path / "ekf.h5"
    solve_file(loop / "loop.h5", "ekf", {}, ekf)
    commands = [
        ["simulate", "--list"],
        ["simulate", "-s", "loop", "--seed", "4", "--set", "n_steps=50", "-o", f"{d}/s.h5"],
        ["solvers"], ["solvers", "graph"],
        ["evaluate", str(ekf), "-o", f"{d}/ev"],
        ["info", str(ekf)],
        ["plot", "nees", str(ekf), "-o", f"{d}/n.png"],
        ["plot", "errors", str(ekf), "-o", f"{d}/e.png"],
        ["export", str(ekf), "-f", "g2o", "-o", f"{d}/e.g2o"],
        ["export", str(ekf), "-f", "tum", "-o", f"{d}/e.tum"],
        ["import", "trajectory", f"{d}/e.tum", "--data", str(loop / "loop.h5"), "-o", f"{d}/imp.h5"],
        ["--help"], ["plot", "--help"], ["export", "--help"], ["aggregate", "--help"], ["import", "--help"],
    ]
    for args in commands:
        r = runner.invoke(app, args, env=W80)
        assert r.exit_code == 0, (args, r.output)
        long = [ln for ln in r.output.splitlines() if len(ln) > 80 and d not in ln and str(loop) not in ln]
        assert not long, (args, long)
