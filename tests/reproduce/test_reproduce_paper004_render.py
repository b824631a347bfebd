"""The paper 004 renderer reads only finished sweep folders: fed hand-written ``results.csv`` files (and two
hand-made result files for the graph cross-check) it produces the counts and fractions worked out by hand here."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pandas as pd

from slamcli.io import write_result
from slamcli.reproduce.paper004 import SweepRuns, _md, monte_carlo_table, wrong_bounds
from slamcli.types import BoxHypotheses, SolverResult, Status

NAN = math.nan


def sweep_folder(root: Path, name: str, rows: list[dict]) -> SweepRuns:
    """A sweep folder holding only ``results.csv`` (paths relative to it, as the sweep writes them)."""
    d = root / name
    d.mkdir()
    base = {"status": "completed", "solver_status": "completed", "data": "cuik-room"}
    pd.DataFrame([{**base, "run_id": f"r{i}", "path": f"r{i}", **r} for i, r in enumerate(rows)]).to_csv(
        d / "results.csv", index=False)
    return SweepRuns(d)


def result(solver: str, poses_xyt, landmarks_xy, assoc, hypotheses=None) -> SolverResult:
    return SolverResult(solver=solver, solver_version="0", params={}, status=Status.COMPLETED, message="",
                        poses_xyt=np.asarray(poses_xyt, float), landmarks_xy=np.asarray(landmarks_xy, float),
                        assoc=np.asarray(assoc, np.int64), hypotheses=hypotheses)


def set_row(rep, soundness, survived, index, n_hyp, label):
    return {"label": label, "replicate": rep, "set_soundness": soundness,
            "set_true_correspondence_survived": survived, "set_true_hypothesis_index": index,
            "set_n_hypotheses": n_hyp}


def test_monte_carlo_table_from_hand_written_sweeps(tmp_path):
    known = sweep_folder(tmp_path, "known", [set_row(0, 1.0, True, 0, 1, "known"),
                                             set_row(1, 1.0, True, 0, 1, "known"),
                                             set_row(2, 0.8, True, 0, 1, "known")])
    unknown = sweep_folder(tmp_path, "unknown", [set_row(0, 1.0, True, 0, 1, "unknown"),
                                                 set_row(1, NAN, False, -1, 3, "unknown")])
    nosep = sweep_folder(tmp_path, "nosep", [set_row(0, 1.0, True, 2, 40, "unknown")])
    graph = sweep_folder(tmp_path, "graph", [{"label": "graph", "replicate": 0},
                                             {"label": "graph", "replicate": 1, "status": "failed"}])
    # cuik (known, replicate 0): one hypothesis, 3 poses, 2 landmarks; observation i sees landmark row i
    lo = np.array([[[0, 0, -1], [1, 0, -1], [2, 0, -1]]], float)
    hb = BoxHypotheses(assoc=np.array([[0, 1]]), pose_lo=lo, pose_hi=lo + [0.5, 0.5, 2.0],
                       landmark_lo=np.array([[[5.0, 5.0], [8.0, 8.0]]]),
                       landmark_hi=np.array([[[6.0, 6.0], [9.0, 9.0]]]), n_landmarks=np.array([2]),
                       landmark_type=np.zeros((1, 2), np.int64))
    (tmp_path / "known" / "r0").mkdir()
    write_result(tmp_path / "known" / "r0" / "result.h5",
                 result("cuik", lo[0], [[0, 0], [0, 0]], [0, 1], hb))
    # graph: poses 0 and 1 inside their boxes, pose 2 beside it (x 3.0 > 2.5); its landmark rows are swapped
    # (assoc [1, 0]): row 1 (5.5, 5.5) is inside label 0's box, row 0 (9.5, 8.5) beside label 1's (x > 9)
    (tmp_path / "graph" / "r0").mkdir()
    write_result(tmp_path / "graph" / "r0" / "result.h5",
                 result("graph", [[0.1, 0.1, 0], [1.2, 0.3, 0.5], [3.0, 0.2, 0]], [[9.5, 8.5], [5.5, 5.5]],
                        [1, 0]))
    checks: dict = {}
    rows, _ = monte_carlo_table(known, unknown, nosep, graph, checks)
    assert rows == [
        ["soundness = 100 % (unique correspondence)", 3, "2 of 3"],
        ["soundness of the true hypothesis (unknown correspondence, with and without the separation prior)", 3,
         "2 of 3"],
        ["true correspondence survived (with and without the separation prior)", 3, "2 of 3"],
        ["true correspondence ranked first (separation prior)", 2, "1 of 2"],
        ["surviving hypotheses, declared 5 m separation: distribution", 2, "1 runs × 1, 1 runs × 3"],
        ["surviving hypotheses, no separation prior: distribution", 1, "1 runs × 40"],
        ["`graph` poses inside the `cuik` boxes", 1, "66.7 %"],
        ["`graph` landmarks inside the `cuik` boxes", 1, "50.0 %"],
    ]
    assert checks == {"soundness_all": False, "truth_always_survives": False}
    table = _md(["check", "runs", "result"], rows).splitlines()
    assert table[2] == "| soundness = 100 % (unique correspondence) | 3 | 2 of 3 |"


def test_wrong_bounds_counts_empty_boxes_as_caught_and_other_failures_as_unexpected(tmp_path):
    # the "loop" runs: caught (every box empty) by full at seeds 0 and 1, by full-3B at seed 1; none of the
    # "all" runs caught; one full-3B "all" run crashed (not a catch)
    rows = []
    for rep in (0, 1):
        for label in ("paper", "full", "full-3B"):
            crashed = label == "full-3B" and rep == 0
            rows.append({"label": label, "data": "all", "replicate": rep,
                         "status": "failed" if crashed else "completed", "solver_status": "" if crashed else
                         "completed"})
            caught = label == "full" or (label == "full-3B" and rep == 1)
            rows.append({"label": label, "data": "loop", "replicate": rep,
                         "status": "failed" if caught else "completed",
                         "solver_status": "failed" if caught else "completed"})
    wb = wrong_bounds(sweep_folder(tmp_path, "wrong", rows))
    assert wb["n"] == 2 and wb["unexpected"] == 1
    assert wb["loop"] == {"paper": 0, "full": 2, "full+3B": 1} and wb["loop_caught_seeds"] == [1]
    assert all(v["caught"] == 0 for v in wb["all"].values())


def test_section_runs_through_the_sweep_hook_and_reports_a_missing_solver(tmp_path):
    # `reproduce --section paper004` reaches paper004.section(rep) (the sweep-driven hook of report.py): with
    # every experiment naming an unregistered solver, nothing runs, each is reported, and the exit is non-zero
    from typer.testing import CliRunner

    from slamcli.cli import app
    from slamcli.experiments import path
    from slamcli.reproduce.paper004 import EXPERIMENTS

    exp_dir = tmp_path / "experiments"
    exp_dir.mkdir()
    for name in EXPERIMENTS:
        text = (path() / f"{name}.toml").read_text()
        (exp_dir / f"{name}.toml").write_text(text.replace('method = "cuik"', 'method = "not-a-solver"')
                                              .replace('method = "graph"', 'method = "not-a-solver"'))
    res = CliRunner().invoke(app, ["reproduce", "--quick", "--out", str(tmp_path / "out"), "--experiments",
                                   str(exp_dir), "--section", "paper004", "--quiet"])
    assert res.exit_code == 1 and "paper004" in res.output
    report = (tmp_path / "out" / "REPORT.md").read_text()
    assert "## Paper 004: CuikSLAM with unknown correspondence (interval boxes, `cuik`) — FAILED" in report
    assert report.count("> **Not run: `") == sum(
        (path() / f"{n}.toml").read_text().count("[[solver]]") for n in EXPERIMENTS)
    assert not (tmp_path / "out" / "runs").exists() or not any((tmp_path / "out" / "runs").rglob("result.h5"))
