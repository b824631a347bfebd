"""The benchmark suite (``experiments/suite.toml``), ``[sweep] absent = "skip"``, the ``solver=`` / ``+solver=``
overrides and the leaderboard of ``slamcli aggregate --leaderboard``.

Recordings are the small excerpts of tests/data laid out as a shared datasets folder (as in
tests/sweep/test_sweep_data.py). References: the leaderboard's numbers are computed here by hand from a hand-written
results.csv with closed forms (Student t with 2 degrees of freedom: F(t) = 1/2 + t / (2 sqrt(2 + t²)), so the
0.975 quantile is 0.95 sqrt(2 / (1 − 0.95²)) and the two-sided p of t is 1 − t / sqrt(2 + t²)); expected run
lists are enumerated by brute force from the documented order.
"""

from __future__ import annotations

import math
from importlib import metadata
from pathlib import Path

import pandas as pd
import pytest
from conftest import ROOT
from typer.testing import CliRunner

from slamcli import experiments
from slamcli.cli import app
from slamcli.datasets import registry as reg
from slamcli.errors import ConfigError
from slamcli.metrics.aggregate import leaderboard
from slamcli.solvers import registry as solvers
from slamcli.sweep.config import apply_overrides, load_experiment, quick_variant
from slamcli.sweep.expand import RegistryResolver, expand

runner = CliRunner()
#: the suite's solver labels, in file order
SUITE_SOLVERS = ["odometry", "ekf", "fastslam", "graph", "isam", "icm-real"]
#: tolerance on numbers computed two ways (closed form here, scipy in the code)
CLOSE = 1e-9


@pytest.fixture()
def shared(shared_datasets):
    """A shared datasets folder with the MRCLAM (robot 1), car-park and Victoria Park excerpts under their
    registry folders, and an empty data folder for the import cache; every other recording is absent."""
    return shared_datasets({"mrclam_dataset7": "mrclam_excerpt", "acfr_carpark": "carpark_excerpt",
                            "victoria_park": "victoria_park_excerpt"})


# -- absent recordings -------------------------------------------------------------------------------------


def _exp(folder: Path, absent: str | None) -> Path:
    p = folder / "exp.toml"
    p.write_text('[experiment]\nname = "real"\n\n'
                 '[[data]]\nrecording = "mrclam3"\nrobot = 1\nlabel = "m3-r1"\n\n'
                 '[[data]]\nrecording = "mrclam3"\nrobot = 2\nlabel = "m3-r2"\n\n'
                 '[[data]]\nrecording = "acfr-carpark"\n\n'
                 '[[data]]\nrecording = "mrclam4"\n\n'
                 '[[solver]]\nmethod = "odometry"\n'
                 + (f'\n[sweep]\nabsent = "{absent}"\n' if absent else ""))
    return p


def test_absent_recording_is_skipped_with_one_line_each(shared):
    exp = _exp(shared, "skip")
    res = runner.invoke(app, ["sweep", str(exp), "--dry-run", "-o", str(shared / "out")])
    assert res.exit_code == 0
    fetch = "dataset '{0}' is not on this machine: run `slamcli datasets fetch {0}` (or `slamcli datasets add {0} DIR` " \
            "for a copy you have)"
    assert res.stderr.splitlines() == [f"skipped m3-r1, m3-r2: {fetch.format('mrclam3')}",
                                       f"skipped mrclam4: {fetch.format('mrclam4')}"]
    runs = expand(load_experiment(exp)).runs
    assert [r.dataset.label for r in runs] == ["acfr-carpark"]
    assert "1 runs" in res.stdout and not (shared / "out").exists()


def test_absent_default_fails_and_all_absent_is_one_line(shared):
    for absent in (None, "fail"):
        res = runner.invoke(app, ["sweep", str(_exp(shared, absent)), "--dry-run"])
        assert res.exit_code == 1
        assert res.stderr.startswith(f"error: {shared / 'exp.toml'}: data[0].recording: dataset 'mrclam3' is not on")
    exp = _exp(shared, "skip")
    exp.write_text(exp.read_text().replace('recording = "acfr-carpark"', 'recording = "mrclam5"'))
    with pytest.raises(ConfigError, match=r"exp.toml: \[\[data\]\]: none of the experiment's datasets is on this "
                                          r"machine \(skipped m3-r1, m3-r2: dataset 'mrclam3'"):
        expand(load_experiment(exp))
    exp.write_text(exp.read_text().replace('absent = "skip"', 'absent = "ignore"'))
    with pytest.raises(ConfigError, match=r"exp.toml: sweep.absent: 'ignore' is not one of fail, skip"):
        load_experiment(exp)


# -- the shipped suite -------------------------------------------------------------------------------------


def _suite():
    path = experiments.find("suite")
    assert path is not None
    return load_experiment(path)


def _documented(labels_present: list[str], simulated: list[str], replicates: int) -> list[tuple[str, int, str]]:
    """(data, replicate, solver) in the documented order: entries in file order, replicates (one for a
    recording), solvers in file order."""
    out = []
    for data in labels_present:
        out += [(data, 0, s) for s in SUITE_SOLVERS]
    for data in simulated:
        out += [(data, rep, s) for rep in range(replicates) for s in SUITE_SOLVERS]
    return out


def test_suite_parses_and_expands_with_the_test_registry(shared):
    cfg = _suite()
    assert [s.label for s in cfg.solvers] == SUITE_SOLVERS
    assert cfg.solver("icm-real").params == {"preset": "real"} and cfg.sweep.absent == "skip"
    # every registered recording except the graphs is an entry: each MRCLAM dataset's five robots, Victoria
    # Park's first 300 s, the car park
    recordings = {d.name for d in cfg.data if d.kind == "recording"}
    graphs = {n for n, e in reg.registry().items() if e.importer == "g2o"}
    assert recordings == set(reg.registry()) - graphs
    mrclam = [(d.name, d.options["robot"]) for d in cfg.data if d.name.startswith("mrclam")]
    assert mrclam == [(f"mrclam{k}", r) for k in range(1, 10) for r in range(1, 6)]
    assert cfg.entry("victoria-park-300s").options == {"duration": 300}

    present = [f"mrclam7-r{r}" for r in range(1, 6)] + ["victoria-park-300s", "acfr-carpark"]
    runs = expand(cfg).runs
    assert [(r.dataset.label, r.replicate, r.label) for r in runs] == \
        _documented(present, ["paper-sim1", "paper-sim2"], 10)
    quick = expand(quick_variant(cfg)).runs
    assert [(r.dataset.label, r.replicate, r.label) for r in quick] == \
        _documented(present, ["paper-sim1", "paper-sim2"], 2)
    assert {r.dataset.overrides["n_steps"] for r in quick if r.dataset.simulated} == {300}

    res = runner.invoke(app, ["sweep", "suite", "--dry-run", "--quick", "-o", str(shared / "out")],
                        terminal_width=300)
    assert res.exit_code == 0, res.output
    skipped = res.stderr.splitlines()
    assert [line.split(":")[0] for line in skipped] == \
        [f"skipped {', '.join(f'mrclam{k}-r{r}' for r in range(1, 6))}" for k in (1, 2, 3, 4, 5, 6, 8, 9)]
    assert f"{len(quick)} runs" in res.stdout


def test_solver_overrides_select_and_add(shared):
    cfg = _suite()
    known = RegistryResolver().known_keys
    kept = apply_overrides(cfg, ["solver=icm-real,odometry", "data=acfr-carpark"], known)
    assert [s.label for s in kept.solvers] == ["odometry", "icm-real"]  # file order
    added = apply_overrides(cfg, ["+solver=mine", "solver.mine.nn_threshold=2.0"], lambda kind, name: None)
    assert [(s.label, s.method) for s in added.solvers][-1] == ("mine", "mine")
    assert [s.label for s in added.solvers][:-1] == SUITE_SOLVERS
    for items, message in ((["solver=ekff"], r"solver: no \[\[solver\]\] labelled 'ekff'; did you mean 'ekf'"),
                           (["+solver=ekf"], r"\+solver: 'ekf' is already a \[\[solver\]\] label"),
                           (["+solver=a.b"], r"\+solver: 'a.b' is not a solver name")):
        with pytest.raises(ConfigError, match=message):
            apply_overrides(cfg, items, known)


@pytest.fixture()
def mine_plugin(monkeypatch):
    """A third-party solver plugin ``mine``: an entry point to the odometry solver's class."""
    fake = dict(solvers._entry_points())
    fake["mine"] = metadata.EntryPoint(name="mine", value="slamcli.solvers.odometry:OdometrySolver",
                                       group=solvers.GROUP)
    monkeypatch.setattr(solvers, "_entry_points", lambda: dict(fake))


def _tutorial_commands() -> list[list[str]]:
    """The commands of the last ``bash`` block of docs/suite.md (its smoke check), without ``slamcli``."""
    import re
    import shlex

    text = (ROOT / "docs" / "suite.md").read_text()
    block = re.findall(r"```bash\n(.*?)```", text, re.S)[-1]
    return [shlex.split(line)[1:] for line in block.splitlines() if line.startswith("slamcli ")]


@pytest.mark.slow
def test_plugin_on_the_suite_then_leaderboard(shared, mine_plugin, monkeypatch):
    """The tutorial's smoke check (docs/suite.md) as written, on the car-park excerpt: the plugin is the
    odometry solver under another name, so against the odometry baseline its difference is exactly 0."""
    monkeypatch.chdir(shared)
    first, second, board_cmd = _tutorial_commands()
    assert first[:2] == ["sweep", "suite"] and sorted(second) == sorted([*first, "+solver=mine"])
    assert runner.invoke(app, first).exit_code == 0
    res = runner.invoke(app, second)
    assert res.exit_code == 0, res.output
    assert "1 done, 0 failed, 2 skipped of 3" in res.stderr  # the built-ins already on disk are not re-run
    res = runner.invoke(app, board_cmd)
    assert res.exit_code == 0, res.output
    out = shared / "results" / "suite"
    board = pd.read_csv(out / "leaderboard.csv")
    ate = board[board["metric"] == "ate_reference_m"].set_index("label")
    assert list(ate.index) == ["odometry", "graph", "mine"]
    assert ate.loc["mine", "mean_diff"] == 0.0 and ate.loc["mine", "mean"] == ate.loc["odometry", "mean"]
    results = pd.read_csv(out / "results.csv").set_index("label")
    assert ate.loc["graph", "mean"] == results.loc["graph", "gps_ate_aligned_rmse_m"]  # the car park's reference
    assert "| mine | " in res.stdout and (out / "leaderboard.tex").is_file()


# -- the leaderboard renderer ------------------------------------------------------------------------------


RESULTS_CSV = """run_id,label,data,reference,dataset_id,replicate,status,ate_rmse_m,gps_ate_aligned_rmse_m,lm_rmse_matched_m,survey_lm_rmse_m,solve_time_s
r1,A,sim,truth,d1,0,completed,1.0,,0.1,,1.0
r2,B,sim,truth,d1,0,completed,1.5,,0.3,,2.0
r3,A,sim,truth,d2,1,completed,2.0,,0.2,,1.0
r4,B,sim,truth,d2,1,completed,2.0,,0.3,,2.0
r5,A,sim,truth,d3,2,completed,3.0,,0.3,,1.0
r6,B,sim,truth,d3,2,completed,4.0,,0.3,,2.0
r7,A,park,gps,p1,0,completed,,3.0,,0.4,0.5
r8,B,park,gps,p1,0,completed,,2.0,,0.7,0.25
r9,B,park,gps,p2,1,failed,,99.0,,99.0,99.0
"""
#: Student t 0.975 quantile with 2 degrees of freedom (closed form, module docstring)
T975_2 = 0.95 * math.sqrt(2 / (1 - 0.95**2))


def test_leaderboard_of_a_hand_written_results_table(tmp_path):
    (tmp_path / "results.csv").write_text(RESULTS_CSV)
    res = runner.invoke(app, ["aggregate", str(tmp_path), "--leaderboard", "--baseline", "A"])
    assert res.exit_code == 0, res.output
    board = pd.read_csv(tmp_path / "leaderboard.csv").set_index(["label", "data", "metric"])

    # sim ATE (truth): A = 1, 2, 3 (mean 2, s 1); B = 1.5, 2, 4 (mean 2.5, s² = (1 + 0.25 + 2.25) / 2)
    a, b = board.loc[("A", "sim", "ate_reference_m")], board.loc[("B", "sim", "ate_reference_m")]
    assert a["mean"] == 2.0 and abs(a["ci_high"] - (2 + T975_2 / math.sqrt(3))) < CLOSE
    s_b = math.sqrt(1.75)
    assert b["mean"] == 2.5 and abs(b["ci_high"] - (2.5 + T975_2 * s_b / math.sqrt(3))) < CLOSE
    # B − A = 0.5, 0, 1: mean 0.5, s_d 0.5, t = sqrt(3), p = 1 − t / sqrt(2 + t²)
    assert abs(b["mean_diff"] - 0.5) < CLOSE and b["n_pairs"] == 3
    p = 1 - math.sqrt(3) / math.sqrt(5)
    assert abs(b["p_t"] - p) < CLOSE
    assert math.isnan(a["mean_diff"])  # the baseline itself
    # the failed park run is left out; the park's ATE is its GPS ATE, its landmark error the survey's; no
    # dataset has a matched-landmark count, so that metric has no rows
    park = board.loc[("B", "park", "ate_reference_m")]
    assert park["n"] == 1 and park["mean"] == 2.0 and park["mean_diff"] == -1.0 and math.isnan(park["p_t"])
    assert abs(board.loc[("B", "park", "lm_reference_m"), "mean_diff"] - 0.3) < CLOSE
    assert abs(board.loc[("B", "sim", "lm_reference_m"), "mean_diff"] - 0.1) < CLOSE
    assert "lm_reference_matched" not in set(board.index.get_level_values("metric"))

    md = (tmp_path / "leaderboard.md").read_text().splitlines()
    assert md[0] == ("| solver | sim: ATE vs reference (m) | sim: landmark RMSE vs reference (m) | sim: solve time (s) "
                     "| park: ATE vs reference (m) | park: landmark RMSE vs reference (m) | park: solve time (s) |")
    # precision: sim ATE's smallest half-width 2.48 → 1 decimal; the park's means only → 3 significant digits
    # of 2.0 → 2 decimals; both lower ends of the sim ATE intervals fall below 0 (clipped, *)
    cells = md[2].split(" | ")
    assert cells[0] == "| A" and cells[1] == "2.0 ± 2.5* (baseline)" and cells[4] == "3.00† (baseline)"
    cells = md[3].split(" | ")
    assert cells[1] == f"2.5 ± 3.3* (Δ +0.5, p {p:.3f})" and cells[4] == "2.00† (Δ -1.00, p —)"
    assert cells[3] == "2.00 ± 0.00 (Δ +1.00, p —)"  # equal differences: the t test is undefined
    assert "\\multicolumn{3}{c}{sim} & \\multicolumn{3}{c}{park}" in (tmp_path / "leaderboard.tex").read_text()
    assert res.stdout.startswith(md[0])


def test_leaderboard_bad_baseline_and_options_are_one_line(tmp_path):
    (tmp_path / "results.csv").write_text(RESULTS_CSV)
    res = runner.invoke(app, ["aggregate", str(tmp_path), "--leaderboard", "--baseline", "C"])
    assert res.exit_code == 1 and res.stderr == "error: --baseline 'C' is not a solver configuration; choose one of A, B\n"
    res = runner.invoke(app, ["aggregate", str(tmp_path), "--leaderboard", "--by", "data"])
    assert res.exit_code == 1 and "drop --by/--metric" in res.stderr
    assert not (tmp_path / "leaderboard.csv").exists()
    with pytest.raises(ConfigError, match="needs the results column 'data'"):
        leaderboard(pd.DataFrame({"label": ["A"]}))


def test_swept_solver_and_scenario_values_are_their_own_rows_and_groups():
    """A solver.<label>.* axis makes one configuration per value (the other labels' runs have no such cell),
    a scenario.* axis one dataset group per value; pairing stays on dataset_id within a group. Integer axes
    are Int64 columns, as read_table restores them."""
    df = pd.DataFrame({
        "label": ["A", "B", "B", "A", "B", "B"], "data": ["loop"] * 6, "reference": ["truth"] * 6,
        "dataset_id": ["d1", "d1", "d1", "d2", "d2", "d2"], "status": ["completed"] * 6,
        "solver.B.k": pd.array([None, 1, 2, None, 1, 2], dtype="Int64"), "scenario.n_steps": [50, 50, 50, 80, 80, 80],
        "ate_rmse_m": [1.0, 1.25, 1.5, 2.0, 2.5, 3.0]})
    board = leaderboard(df, baseline="A").set_index(["label", "data", "metric"])
    ate = board.xs("ate_reference_m", level="metric")
    assert list(dict.fromkeys(ate.index.get_level_values(0))) == ["A", "B, k=1", "B, k=2"]
    assert list(dict.fromkeys(ate.index.get_level_values(1))) == ["loop, n_steps=50", "loop, n_steps=80"]
    # each (configuration, dataset) cell is one run: B, k=2 on n_steps=80 is 3.0, 1.0 above A's 2.0
    cell = ate.loc[("B, k=2", "loop, n_steps=80")]
    assert cell["n"] == 1 and cell["mean"] == 3.0 and cell["mean_diff"] == 1.0
