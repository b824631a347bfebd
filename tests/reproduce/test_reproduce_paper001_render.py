"""The paper 001 Map 4 renderer reads only a finished sweep folder: fed a hand-written ``results.csv``, a small
simulated ``dataset.h5`` and a hand-made ``result.h5`` (poses = truth + 0.1 m in x, covariance 0.1² I, grids
0.1 / 0.2 off the true 0/1 occupancy) it writes the table row worked out by hand here."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from slamcli.io import write_dataset, write_result
from slamcli.reproduce.paper001 import MAP4_DATA, MAP4_LABELS, MAP4_SOLVER, render_map4
from slamcli.sim.simulate import simulate_scenario
from slamcli.types import SolverResult, Status

#: the pose offset of the hand-made result (m, along x) and its standard deviation in every coordinate
OFFSET_X, SD = 0.1, 0.1
#: how far the frequentist and log-odds grids sit from the true 0/1 occupancy (every cell)
FREQ_OFF, LOGODDS_OFF = 0.1, 0.2
WALL_S, CPU_S = 3.2, 7.4


def _grid(truth_grid, off: float, last_step: int):
    """The true grid with probabilities ``off`` away from 0/1, every cell observed, one snapshot at the end."""
    prob = np.where(truth_grid.prob > 0.5, 1.0 - off, off).astype(np.float32)
    return dataclasses.replace(truth_grid, prob=prob, observed=np.ones(prob.shape, np.int32),
                               snapshot_step=np.array([last_step]), snapshots=prob[None].copy())


def _sweep_folder(root: Path, status: str = "completed") -> tuple[Path, object]:
    ds = simulate_scenario("hybrid-map4", 1, {"walls.laps": 0, "n_steps": 12, "walls.resolution": 1.0,
                                              "sensor.n_beams": 8})
    tr = ds.truth
    poses = tr.poses_xyt + np.array([OFFSET_X, 0.0, 0.0])
    T = len(poses) - 1
    res = SolverResult(solver="hybrid", solver_version="0", params={}, status=Status.COMPLETED, message="",
                       poses_xyt=poses, landmarks_xy=np.zeros((0, 2)), assoc=np.full(len(ds.inputs.observations), -1),
                       pose_cov=np.broadcast_to(SD**2 * np.eye(3), (T + 1, 3, 3)).copy(), wall_time_s=WALL_S,
                       grids={"frequentist": _grid(tr.occupancy, FREQ_OFF, T),
                              "logodds": _grid(tr.occupancy, LOGODDS_OFF, T)})
    exp = root / "paper001-map4"
    (exp / "r0").mkdir(parents=True)
    write_dataset(exp / "r0" / "dataset.h5", ds)
    write_result(exp / "r0" / "result.h5", res)
    pd.DataFrame([{"run_id": "r0", "label": MAP4_SOLVER, "data": MAP4_DATA, "replicate": 1, "status": status,
                   "solve_cpu_s": CPU_S, "path": "r0"}]).to_csv(exp / "results.csv", index=False)
    return exp, ds


def _table_row(text: str, label: str) -> list[str]:
    line = next(ln for ln in text.splitlines() if ln.startswith(f"| {label} |"))
    return [c.strip() for c in line.strip().strip("|").split("|")]


@pytest.mark.slow
def test_map4_renderer_writes_the_hand_worked_row(tmp_path):
    exp, ds = _sweep_folder(tmp_path)
    text, ok = render_map4({"paper001-map4": exp}, tmp_path / "out", quick=True)
    assert ok
    odo = ds.inputs.odometry_xyt[:, :2] - ds.truth.poses_xyt[:, :2]
    row = _table_row(text, MAP4_LABELS[1])
    assert row == [MAP4_LABELS[1], "12", "0", f"{np.max(np.hypot(*odo.T)):.3g}",
                   "0.1",  # mean position error: the offset
                   "1",  # NEES: 0.1² / 0.1² in x, 0 in y and θ
                   "100 %",  # 0.1 m inside 3·0.1 m
                   "n/a",  # no lap end in a 12-step run
                   "0.1 / 0.2", "1 / 1", "3 / 7"]  # wall from the result, CPU from results.csv
    assert (tmp_path / "out" / "map-4-laser--first-120-steps.png").is_file()
    assert "QUICK MODE" in text


def test_map4_renderer_without_a_completed_run_says_so(tmp_path):
    exp, _ = _sweep_folder(tmp_path, "failed")
    text, ok = render_map4({"paper001-map4": exp}, tmp_path / "out", quick=False)
    assert not ok
    assert f"**{MAP4_LABELS[0]}: failed**" in text and "results.csv" in text


def test_nees_monte_carlo_is_read_from_the_sweep_files(tmp_path):
    """``consistency_study`` from a hand-written ``paper001-nees-map1`` folder: 2 seeds per stabilising scale, the
    poses off by 0.1 m (3×) and 0.2 m (10×) in x with σ = 0.1 m: NEES 1 and 4 at every step; configurations
    without rows (the noisy sensor, 1×) are left out; the band is scipy's χ²(3N)/N."""
    from scipy.stats import chi2

    from slamcli.reproduce.paper001 import NEES_SCALE_COLUMN, NEES_SOLVER, consistency_study
    from slamcli.reproduce.sweep_runs import SweepRuns

    ds = simulate_scenario("hybrid-map1", 1, {"walls.width": 40.0, "walls.height": 40.0, "walls.corridor": 8.0,
                                              "walls.laps": 0, "n_steps": 10, "sensor.n_beams": 2})
    exp = tmp_path / "paper001-nees-map1"
    rows = []
    for i, (scale, offset, rep) in enumerate([(3.0, 0.1, 0), (3.0, 0.1, 1), (10.0, 0.2, 0), (10.0, 0.2, 1)]):
        d = exp / f"r{i}"
        d.mkdir(parents=True)
        write_dataset(d / "dataset.h5", ds)
        T = ds.inputs.n_poses
        write_result(d / "result.h5", SolverResult(
            solver="hybrid", solver_version="0", params={}, status=Status.COMPLETED, message="",
            poses_xyt=ds.truth.poses_xyt + np.array([offset, 0.0, 0.0]), landmarks_xy=np.zeros((0, 2)),
            assoc=np.full(len(ds.inputs.observations), -1), pose_cov=np.broadcast_to(SD**2 * np.eye(3), (T, 3, 3)).copy()))
        rows.append({"run_id": f"r{i}", "label": NEES_SOLVER, "data": "laser", "replicate": rep, "status": "completed",
                     NEES_SCALE_COLUMN: scale, "solve_cpu_s": 0.1, "path": f"r{i}"})
    pd.DataFrame(rows).to_csv(exp / "results.csv", index=False)
    mc = consistency_study({"paper001-nees-map1": SweepRuns(exp)}, quick=True)
    assert [c["label"] for c in mc] == ["Map 1 (small) laser, 3×", "Map 1 (small) laser, 10×"]
    lo, hi = chi2.ppf([0.025, 0.975], 6) / 2
    for c, anees in zip(mc, (1.0, 4.0)):
        assert c["n_seeds"] == 2 and c["anees_mean"] == pytest.approx(anees)
        assert c["lo"] == pytest.approx(lo) and c["hi"] == pytest.approx(hi) and c["inside"] == 1.0
