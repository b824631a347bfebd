"""Datasets in experiment files: ``[[data]]`` entries (scenario, registered recording, graph, dataset file),
the ``data`` sweep axis, and the content-addressed import cache shared by every sweep.

Recordings are the small excerpts of tests/data, laid out as a shared datasets folder (``$SLAMCLI_DATASETS``)
under the registry names mrclam7 and acfr-carpark, with the import cache in a temporary ``$SLAMCLI_DATA_DIR``.
References: expected run lists are enumerated here by brute force from the documented order; an imported
dataset is compared with the importer called directly on the excerpt; sha256 values come from hashlib.
"""

from __future__ import annotations

import hashlib
import itertools
import shutil
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from conftest import DATA, ROOT
from typer.testing import CliRunner

import slamcli.datasets.options as importer_options
from slamcli.cli import app
from slamcli.datasets import registry as reg
from slamcli.errors import ConfigError
from slamcli.sweep.config import apply_overrides, load_experiment, parse_experiment
from slamcli.sweep.expand import LiteralResolver, expand
from slamcli.sweep.runner import run_sweep

VERS = {"slamcli": "test", "schema": 1}
runner = CliRunner()

HEAD = '[experiment]\nname = "real"\n\n'
ODOMETRY = '[[solver]]\nmethod = "odometry"\n'


@pytest.fixture()
def shared(shared_datasets):
    """A shared datasets folder holding the MRCLAM and car-park excerpts as mrclam7 and acfr-carpark, and an
    empty data folder for the import cache."""
    return shared_datasets({"mrclam_dataset7": "mrclam_excerpt", "acfr_carpark": "carpark_excerpt"})


@pytest.fixture()
def import_calls(monkeypatch):
    """Every call of the importer entry point the cache uses, as ``(importer, options)``."""
    calls = []
    real = importer_options.import_recording

    def counting(importer, path, options):
        calls.append((importer, dict(options)))
        return real(importer, path, options)

    monkeypatch.setattr(importer_options, "import_recording", counting)
    return calls


def _experiment(folder: Path, body: str, name: str = "exp.toml") -> Path:
    p = folder / name
    p.write_text(HEAD + body + ODOMETRY)
    return p


def _sweep(path: Path, out: Path):
    return run_sweep(expand(load_experiment(path)), out)


def _folder_sha(folder: Path) -> str:
    lines = "".join(f"{f.name} {hashlib.sha256(f.read_bytes()).hexdigest()}\n" for f in sorted(folder.iterdir())
                    if f.is_file() and not f.name.startswith("."))
    return hashlib.sha256(lines.encode()).hexdigest()


# -- recordings through the registry and the cache ---------------------------------------------------------


@pytest.mark.slow
def test_recording_entry_resolves_through_registry_and_is_imported_once(shared, import_calls):
    from slamcli.datasets.mrclam import import_mrclam
    from slamcli.io import read_dataset

    exp = _experiment(shared, '[[data]]\nrecording = "mrclam7"\nrobot = 1\nduration = 20\n\n'
                              '[[data]]\nrecording = "acfr-carpark"\nrange-std = 0.2\n\n')
    first = _sweep(exp, shared / "out1")
    assert first.ok and len(import_calls) == 2
    assert import_calls[0] == ("mrclam", {"robot": 1, "duration": 20.0})
    df = pd.read_csv(shared / "out1" / "real" / "results.csv")
    assert list(df["data"]) == ["mrclam7", "acfr-carpark"]
    assert list(df["data_kind"]) == ["recording", "recording"]
    assert list(df["reference"]) == ["truth", "gps"]  # motion-capture truth; the car park's GPS
    assert df["ate_rmse_m"].notna().tolist() == [True, False]

    # the dataset the runs solved is the importer's output on the excerpt, with the same options
    ds_id = df["dataset_id"][0]
    swept = read_dataset(shared / "out1" / "real" / "datasets" / f"{ds_id}.h5")
    direct = import_mrclam(DATA / "mrclam_excerpt", 1, duration=20.0)
    assert np.array_equal(swept.inputs.odometry_xyt, direct.inputs.odometry_xyt)
    assert np.array_equal(swept.truth.poses_xyt, direct.truth.poses_xyt)

    # content-addressed cache: named by the dataset id, recording the source folder's sha256
    record = (shared / "cache" / "imported" / f"{ds_id}.json").read_text()
    assert _folder_sha(shared / "shared" / "mrclam_dataset7") in record

    # a second sweep (another results folder, then the same one again) imports nothing
    assert _sweep(exp, shared / "out2").ok and len(import_calls) == 2
    assert _sweep(exp, shared / "out1").counts.skipped == 2 and len(import_calls) == 2
    assert list(pd.read_csv(shared / "out2" / "real" / "results.csv")["dataset_id"]) == list(df["dataset_id"])

    # other options are another dataset: imported once more
    exp.write_text(exp.read_text().replace("duration = 20", "duration = 10"))
    assert _sweep(exp, shared / "out3").ok and len(import_calls) == 3
    assert import_calls[-1] == ("mrclam", {"robot": 1, "duration": 10.0})


def test_missing_recording_fails_before_any_run(shared, import_calls):
    exp = _experiment(shared, '[[data]]\nscenario = "loop"\n\n[[data]]\nrecording = "mrclam3"\n\n')
    out = shared / "out"
    res = runner.invoke(app, ["sweep", str(exp), "-o", str(out)])
    assert res.exit_code == 1 and res.stdout == ""
    assert res.stderr == (f"error: {exp}: data[1].recording: dataset 'mrclam3' is not on this machine: run "
                          "`slamcli datasets fetch mrclam3` (or `slamcli datasets add mrclam3 DIR` for a copy you "
                          "have)\n")
    assert not out.exists() and import_calls == []


def test_unknown_recording_and_option_are_one_line_with_did_you_mean(shared):
    exp = _experiment(shared, '[[data]]\nrecording = "mrclam77"\n\n')
    with pytest.raises(ConfigError, match=r"data\[0\]\.recording: 'mrclam77' is not a registered dataset; did "
                                          r"you mean 'mrclam7'"):
        expand(load_experiment(exp))
    exp = _experiment(shared, '[[data]]\nrecording = "mrclam7"\nrange_std = 0.1\n\n')
    with pytest.raises(ConfigError, match=r"data\[0\]\.range_std: not an option of `slamcli import mrclam`; did "
                                          r"you mean 'range-std'"):
        expand(load_experiment(exp))
    exp = _experiment(shared, '[[data]]\nrecording = "mrclam7"\nrobot = "one"\n\n')
    with pytest.raises(ConfigError, match=r"data\[0\]\.robot: expected an integer, got 'one'"):
        expand(load_experiment(exp))


def test_graph_and_dataset_file_by_path_inside_the_experiment_folder(shared, import_calls):
    from slamcli.datasets.g2o import import_graph
    from slamcli.io import write_dataset

    shutil.copy(DATA / "dlr_excerpt.g2o", shared / "dlr_small.g2o")
    write_dataset(shared / "day1.h5", import_graph(DATA / "dlr_excerpt.g2o"))
    exp = _experiment(shared, '[[data]]\ngraph = "dlr_small.g2o"\n\n[[data]]\nfile = "day1.h5"\n\n')
    assert _sweep(exp, shared / "out").ok
    df = pd.read_csv(shared / "out" / "real" / "results.csv")
    assert list(df["data"]) == ["dlr_small", "day1"] and list(df["data_kind"]) == ["graph", "file"]
    assert list(df["reference"]) == ["none", "none"] and import_calls == [("g2o", {})]
    # the same graph bytes give the same import whether named as a graph or given as its dataset file
    assert df["dataset_id"].nunique() == 2

    (shared / "sub").mkdir()
    for line in ('file = "../day1.h5"', f'file = "{shared / "day1.h5"}"', 'graph = "../dlr_small.g2o"'):
        inner = shared / "sub" / "exp.toml"
        inner.write_text(HEAD + f"[[data]]\n{line}\n\n" + ODOMETRY)
        with pytest.raises(ConfigError, match=r"data\[0\]\.(file|graph): .* leaves the experiment file's folder"):
            load_experiment(inner)


# -- data as a sweep axis ----------------------------------------------------------------------------------


ENTRIES = [{"scenario": "loop", "parameters": {"n_steps": 50}}, {"scenario": "octagon", "label": "oct"},
           {"recording": "rec", "robot": 2}]
SOLVERS = [{"method": "a", "params": {"gain": 1.0}}, {"method": "b"}]
KINDS = {"loop": "scenario", "oct": "scenario", "rec": "recording"}


def _cfg(sweep: dict, data=ENTRIES):
    raw = {"experiment": {"name": "axis"}, "data": data, "solver": SOLVERS, "sweep": {"replicates": 3, **sweep}}
    return parse_experiment(raw, source="axis.toml")


def _runs(cfg):
    return [(r.dataset.label, r.point.get("solver.a.gain"), r.replicate, r.label)
            for r in expand(cfg, resolver=LiteralResolver(), run_versions=VERS).runs]


def _documented(labels, gains, replicates=(0, 1, 2)):
    """The documented order by brute force: data (as listed) × gain, then replicates (one for a recording),
    then solvers; a solver.a.* axis does not apply to b, whose repeated runs are dropped (first kept)."""
    out = []
    for data, gain in itertools.product(labels, gains):
        for rep in replicates if KINDS[data] == "scenario" else replicates[:1]:
            for solver in ("a", "b"):
                key = (data, gain if solver == "a" else None, rep, solver)
                if key not in out:
                    out.append(key)
    return out


def test_data_grid_axis_expands_as_documented():
    cfg = _cfg({"grid": {"data": ["rec", "loop"], "solver.a.gain": [1.0, 2.0]}})
    runs = _runs(cfg)
    assert runs == _documented(["rec", "loop"], [1.0, 2.0])
    assert len(runs) == 3 + 9  # rec: 2 gains × a + b once; loop: 3 replicates × (2 gains × a + b)

    # without a data axis every entry is used, in file order, as the slowest axis
    assert _runs(_cfg({"grid": {"solver.a.gain": [1.0, 2.0]}})) == _documented(["loop", "oct", "rec"], [1.0, 2.0])

    # the command line selects the same way (a list is a grid axis, one value fixes the entry)
    known = lambda kind, name: None  # no key sets: only the data labels are checked
    base = _cfg({"grid": {"solver.a.gain": [1.0, 2.0]}})
    assert _runs(apply_overrides(base, ["data=rec,loop"], known)) == _runs(cfg)
    assert _runs(apply_overrides(base, ["data=oct"], known)) == _documented(["oct"], [1.0, 2.0])
    with pytest.raises(ConfigError, match=r"axis.toml \(command line\): data: no \[\[data\]\] entry labelled "
                                          r"'octagon'; did you mean 'oct'"):
        apply_overrides(base, ["data=octagon"], known)


def test_data_in_a_zip_group_and_scenario_axes_leave_recordings_alone():
    cfg = _cfg({"zip": {"data": ["loop", "rec"], "solver.a.gain": [1.0, 2.0]}})
    assert _runs(cfg) == _documented(["loop"], [1.0]) + _documented(["rec"], [2.0])

    cfg = _cfg({"grid": {"scenario.n_steps": [20, 40]}})
    runs = expand(cfg, resolver=LiteralResolver(), run_versions=VERS).runs
    per_data = {lab: sum(r.dataset.label == lab for r in runs) for lab in KINDS}
    assert per_data == {"loop": 2 * 3 * 2, "oct": 2 * 3 * 2, "rec": 2}  # n_steps × replicates × solvers; rec once
    assert all("scenario.n_steps" not in r.point for r in runs if r.dataset.label == "rec")
    assert {r.dataset.overrides["n_steps"] for r in runs if r.dataset.label == "loop"} == {20, 40}


def test_scenario_table_is_the_one_entry_shorthand():
    sw = {"grid": {"solver.a.gain": [1.0, 2.0]}}
    short = parse_experiment({"experiment": {"name": "axis"}, "scenario": {"name": "loop", "parameters": {
        "n_steps": 50}}, "solver": SOLVERS, "sweep": {"replicates": 3, **sw}}, source="axis.toml")
    ids = [r.run_id for r in expand(short, resolver=LiteralResolver(), run_versions=VERS).runs]
    entry = _cfg(sw, data=ENTRIES[:1])
    assert ids == [r.run_id for r in expand(entry, resolver=LiteralResolver(), run_versions=VERS).runs]


@pytest.mark.parametrize("data, message", [
    ([{"scenario": "loop", "recording": "mrclam7"}], r"data\[0\]: give exactly one of scenario, recording, graph, "
                                                     r"file \(got scenario, recording\)"),
    ([{"label": "x"}], r"data\[0\]: give exactly one of"),
    ([{"scenario": "loop"}, {"scenario": "loop"}], r"data\[1\]\.label: duplicate label 'loop'"),
    ([{"file": "a.h5", "robot": 1}], r"data\[0\]\.robot: unknown key"),
    ([{"scenario": "loop", "robot": 1}], r"data\[0\]\.robot: unknown key"),
])
def test_bad_data_entries_are_one_line(data, message):
    with pytest.raises(ConfigError, match=message):
        _cfg({}, data=data)
    with pytest.raises(ConfigError, match=r"give either one \[scenario\] table or \[\[data\]\] entries"):
        parse_experiment({"experiment": {"name": "x"}, "scenario": {"name": "loop"}, "data": ENTRIES,
                          "solver": SOLVERS}, source="x.toml")


@pytest.mark.slow
def test_multi_robot_recording_takes_the_import_flags(tmp_path, monkeypatch, import_calls):
    from slamcli.datasets.mrclam import import_mrclam_team
    from slamcli.io import read_dataset

    shutil.copytree(DATA / "mrclam_team_excerpt", tmp_path / "shared" / "mrclam_dataset7")
    monkeypatch.setenv(reg.ENV_SHARED, str(tmp_path / "shared"))
    monkeypatch.setenv(reg.ENV_DATA_DIR, str(tmp_path / "cache"))
    monkeypatch.delenv(reg.ENV_REGISTRY, raising=False)
    exp = tmp_path / "exp.toml"
    exp.write_text(HEAD + '[[data]]\nrecording = "mrclam7"\nall-robots = true\nrange-std = 0.1\n\n'
                   '[[solver]]\nmethod = "graph"\n')  # odometry takes one robot only
    assert _sweep(exp, tmp_path / "out").ok
    assert import_calls == [("mrclam", {"all-robots": True, "range-std": 0.1})]
    ds_id = pd.read_csv(tmp_path / "out" / "real" / "results.csv")["dataset_id"][0]
    swept = read_dataset(tmp_path / "out" / "real" / "datasets" / f"{ds_id}.h5")
    direct = import_mrclam_team(DATA / "mrclam_team_excerpt", [1, 2, 3, 4, 5])  # the five RobotN files
    assert np.array_equal(swept.inputs.odometry_xyt, direct.inputs.odometry_xyt)
    assert swept.inputs.noise.range_std == 0.1 != direct.inputs.noise.range_std


def test_docs_datasets_example_expands_as_it_says(shared):
    import re

    text = (ROOT / "docs" / "experiments.md").read_text()
    block = re.findall(r"```toml\n(.*?)```", text, re.S)[1]
    exp = shared / "docs.toml"
    exp.write_text(block)
    runs = expand(load_experiment(exp)).runs
    assert "It runs 15 runs" in text and len(runs) == 15
    per_data = {lab: sum(r.dataset.label == lab for r in runs) for lab in ("mrclam7", "acfr-carpark", "loop")}
    assert per_data == {"mrclam7": 1 + 2, "acfr-carpark": 1 + 2, "loop": 3 * (1 + 2)}
    assert len(expand(apply_overrides(load_experiment(exp), ["data=mrclam7"], lambda kind, name: None)).runs) == 3


def test_registered_graph_by_name_and_content_addressed_ids(shared):
    (shared / "shared" / "dlr_g2o").mkdir()
    shutil.copy(DATA / "dlr_excerpt.g2o", shared / "shared" / "dlr_g2o" / "dlr.g2o")
    exp = _experiment(shared, '[[data]]\ngraph = "dlr"\nmax-poses = 50\n\n[[data]]\nrecording = "mrclam7"\n\n')
    first = {r.dataset.label: r.dataset for r in expand(load_experiment(exp)).runs}
    assert first["dlr"].kind == "graph" and first["dlr"].source["options"] == {"max-poses": 50}
    assert first["dlr"].source["source_sha256"] == hashlib.sha256(
        (DATA / "dlr_excerpt.g2o").read_bytes()).hexdigest()

    # the id follows the content: the same bytes elsewhere give the same id, a changed source another one
    moved = shared / "moved"
    shutil.move(shared / "shared" / "mrclam_dataset7", moved)
    reg.add("mrclam7", moved)
    assert {r.dataset.label: r.dataset.dataset_id for r in expand(load_experiment(exp)).runs} == \
        {k: v.dataset_id for k, v in first.items()}
    with open(moved / "Barcodes.dat", "a") as fh:
        fh.write("# one more comment line\n")
    again = {r.dataset.label: r.dataset.dataset_id for r in expand(load_experiment(exp)).runs}
    assert again["dlr"] == first["dlr"].dataset_id and again["mrclam7"] != first["mrclam7"].dataset_id

    exp.write_text(exp.read_text().replace('graph = "dlr"', 'graph = "acfr-carpark"'))
    with pytest.raises(ConfigError, match=r"data\[0\]\.graph: 'acfr-carpark' is a recording read by `slamcli "
                                          r"import carpark`: write recording = 'acfr-carpark'"):
        expand(load_experiment(exp))


@pytest.mark.parametrize("options, message", [
    ("robots = [1, 2]\nall-robots = true", r"data\[0\]\.all-robots: not an option of a multi-robot import \(robots\)"),
    ("all-robots = true\nrobot = 2", r"data\[0\]\.robot: not an option of a multi-robot import \(all-robots\)"),
    ('non-landmark = "keep"', r"data\[0\]\.non-landmark: 'keep' is not one of drop, clutter"),
])
def test_contradictory_import_options_fail_before_any_run(shared, options, message):
    exp = _experiment(shared, f'[[data]]\nrecording = "mrclam7"\n{options}\n\n')
    with pytest.raises(ConfigError, match=message):
        expand(load_experiment(exp))


def test_selecting_only_recordings_drops_the_scenario_keys(shared):
    exp = _experiment(shared, '[[data]]\nrecording = "mrclam7"\n\n[[data]]\nscenario = "loop"\n\n'
                              '[sweep]\nreplicates = 2\ngrid = { "scenario.n_steps" = [50, 100] }\n\n'
                              '[quick]\n"scenario.n_steps" = 20\n')
    from slamcli.sweep.config import quick_variant
    from slamcli.sweep.expand import RegistryResolver

    cfg = apply_overrides(quick_variant(load_experiment(exp)), ["data=mrclam7"], RegistryResolver().known_keys)
    runs = expand(cfg).runs
    assert [(r.dataset.label, r.replicate, r.point) for r in runs] == [("mrclam7", 0, {})]


@pytest.mark.parametrize("entry, message", [
    ('scenario = "lop"', r"data\[1\]\.scenario: unknown scenario 'lop'; did you mean 'loop'"),
    ('scenario = "loop"\n[data.parameters]\nn_stepz = 5', r"data\[1\]\.parameters\.n_stepz: unknown scenario key "
                                                         r"'n_stepz'; did you mean 'n_steps'"),
    ('scenario = "loop"\n[data.parameters]\nn_steps = "many"', r"data\[1\]\.parameters\.n_steps: expected an integer"),
])
def test_scenario_entries_are_checked_like_the_scenario_table(shared, entry, message):
    exp = _experiment(shared, f'[[data]]\nrecording = "mrclam7"\n\n[[data]]\n{entry}\n\n')
    with pytest.raises(ConfigError, match=message):
        expand(load_experiment(exp))


def test_solo_option_is_one_robot_of_the_team_import_on_its_time_grid(tmp_path, monkeypatch):
    from slamcli.datasets.mrclam import import_mrclam_team
    from slamcli.datasets.team import solo_dataset
    from slamcli.io import read_dataset

    shutil.copytree(DATA / "mrclam_team_excerpt", tmp_path / "shared" / "mrclam_dataset7")
    monkeypatch.setenv(reg.ENV_SHARED, str(tmp_path / "shared"))
    monkeypatch.setenv(reg.ENV_DATA_DIR, str(tmp_path / "cache"))
    monkeypatch.delenv(reg.ENV_REGISTRY, raising=False)
    exp = tmp_path / "exp.toml"
    exp.write_text(HEAD + '[[data]]\nrecording = "mrclam7"\nall-robots = true\nsolo = 3\n\n' + ODOMETRY)
    assert _sweep(exp, tmp_path / "out").ok
    ds_id = pd.read_csv(tmp_path / "out" / "real" / "results.csv")["dataset_id"][0]
    swept = read_dataset(tmp_path / "out" / "real" / "datasets" / f"{ds_id}.h5")
    team = import_mrclam_team(DATA / "mrclam_team_excerpt", [1, 2, 3, 4, 5])
    direct = solo_dataset(team, 2)  # robot number 3 is the third robot of the team
    assert swept.inputs.robots is None
    assert np.array_equal(swept.inputs.odometry_xyt, direct.inputs.odometry_xyt)
    assert np.array_equal(swept.truth.poses_xyt, direct.truth.poses_xyt)
    assert len(swept.inputs.odometry_xyt) == len(team.inputs.odometry_xyt) // 5  # the team's time grid

    exp.write_text(HEAD + '[[data]]\nrecording = "mrclam7"\nall-robots = true\nsolo = 7\n\n' + ODOMETRY)
    assert not _sweep(exp, tmp_path / "out7").ok  # not an imported robot: the import fails, no run


def test_solo_option_needs_a_team_import(shared):
    exp = _experiment(shared, '[[data]]\nrecording = "mrclam7"\nsolo = 2\n\n')
    with pytest.raises(ConfigError, match=r"data\[0\]\.solo: needs a multi-robot import"):
        expand(load_experiment(exp))
