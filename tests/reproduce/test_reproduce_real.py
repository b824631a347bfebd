"""The real-data reproduce sections: outcome sentences and tables follow the rows they describe, and the renderers
build those rows from a sweep folder alone (a hand-written results.csv and the run files they read)."""

from __future__ import annotations

import pytest
from conftest import DATA

from slamcli.reproduce import real as pr


def _row(name, ate, odo, refused=None, n_lm=10):
    return {"solver": name, "params": "defaults", "refused": refused, "status": "completed", "gps_ate": ate,
            "odo_gps_ate": odo, "n_lm": n_lm, "wall_s": 1.0, "n_gps": 50, "survey_matched": 12,
            "survey_rmse": 0.2}


def test_gps_sentences_follow_the_numbers():
    rows = [_row("a", 1.5, 2.0), _row("b", 0.5, 2.0), _row("c", 4.5, 2.0),
            _row("cuik", None, None, refused="solver 'cuik' needs bounds")]
    text = " ".join(pr._gps_sentences(rows, "X"))
    assert "`b` has the lowest aligned GPS ATE (0.500 m over 50 fixes)" in text
    assert "2 of 3 solvers beat dead reckoning (a, b)" in text
    assert "`c` (4.50 m)" in text and "Refused in one line: cuik." in text
    rows = [_row("a", 2.5, 2.0)]
    assert "None of the 1 solvers beats dead reckoning." in " ".join(pr._gps_sentences(rows, "X"))


def test_gps_table_shows_refusal_line_and_survey_columns():
    rows = [_row("ekf", 0.25, 1.0), _row("hybrid", None, None, refused="supports ddmr only")]
    tab = pr._gps_table(rows, True, 15)
    assert tab[0].endswith("| beacons found of 15 | beacon RMSE (m) |")
    assert all(line.count("|") == tab[0].count("|") for line in tab)
    assert "refused: supports ddmr only" in tab[3] and "| 0.25 | 10 | 1.0 | 12 | 0.20 |" in tab[2]


def test_mrclam_sentences_mean_over_robots():
    rows = [{"robot": r, "solver": s, "refused": None, "ate": a, "odo_ate": 1.0}
            for r, s, a in ((1, "ekf", 0.4), (2, "ekf", 0.6), (1, "graph", 0.2), (2, "graph", 1.2),
                            (1, "odometry", 1.0))]
    text = " ".join(pr._mrclam_sentences(rows))
    assert "`ekf` has the lowest mean ATE (0.500 m)" in text and "`graph` 0.700 m" in text
    assert "Runs worse than dead reckoning: `graph` robot 2." in text  # not odometry: it is the reference


def test_icm_verdicts_follow_the_rows():
    def gps(ate, found=15):
        return [{"solver": pr.ICM_PRESET_ROW, "refused": None, "gps_ate": ate, "survey_matched": found,
                 "n_survey": 15}]

    def mr(icm, graph, other_graph=0.1):
        # the goal's baseline is graph's defaults row, not another graph configuration (here a better one)
        return [{"robot": 1, "solver": pr.ICM_PRESET_ROW, "refused": None, "ate": icm, "wall_s": 3.0},
                {"robot": 1, "solver": "graph", "refused": None, "ate": other_graph, "wall_s": 1.0},
                {"robot": 1, "solver": pr.GRAPH_BASELINE_ROW, "refused": None, "ate": graph, "wall_s": 2.0}]

    good = pr.icm_verdicts(gps(1.39), gps(0.44), mr(0.33, 0.31), "VP")
    assert [("**met**" in v) for v in good] == [True, True, True]
    assert "GPS ATE 1.390 m, goal ≤ 1.4 m" in good[0]
    assert "robot 1 0.3300 vs 0.3100 m, ratio 1.065, solve time 1.50×" in good[2] and "graph (defaults)" in good[2]
    bad = pr.icm_verdicts(gps(1.41), gps(0.44, found=14), mr(0.35, 0.31), "VP")  # 0.35 > 1.1 · 0.31 = 0.341
    assert [("**not met**" in v) for v in bad] == [True, True, True]
    missing = pr.icm_verdicts([], None, [], "VP")
    assert all("not checked" in v for v in missing)


# -- the renderers fed a hand-written sweep folder (results.csv + the run files they read) ---------------------

def _results_csv(exp_dir, header: str, rows: list[str]) -> None:
    exp_dir.mkdir(parents=True, exist_ok=True)
    (exp_dir / "results.csv").write_text("\n".join([header, *rows]) + "\n", encoding="utf-8")


def _config(run_dir, **options) -> None:
    import json

    run_dir.mkdir(parents=True, exist_ok=True)
    (run_dir / "config.json").write_text(json.dumps({"dataset": {"options": options}}), encoding="utf-8")


def test_gps_renderer_table_from_a_hand_written_results_csv(tmp_path):
    exp = tmp_path / "real-carpark"
    _results_csv(exp, "run_id,label,method,data,status,solver_status,error,solve_time_s,metric.wall_time_s,path,"
                      "gps_ate_aligned_rmse_m,odometry_gps_ate_aligned_rmse_m,n_landmarks_est,gps_n_matched,"
                      "survey_lm_matched,survey_lm_rmse_m",
                 ["a1,odometry,odometry,acfr-carpark,completed,completed,,0.2,0.01,a1,0.13,0.13,14,160,12.0,0.161",
                  "a2,hybrid,hybrid,acfr-carpark,failed,,\"SolverError: /r/datasets/00cb.h5: solver 'hybrid' "
                  "supports the motion model(s) ddmr, but the dataset uses 'ackermann'\",,,a2,,,,,,",
                  "a3,icm-real,icm,acfr-carpark,completed,converged,,0.7,0.56,a3,0.0827,0.13,15,160,15.0,0.1425"])
    params = {"odometry": "nn_threshold=1.5", "icm-real": "preset=real, max_sweeps=5"}
    rows = pr.gps_rows(pr.sweep_records(exp), params)
    assert pr._gps_table(rows, True, 15) == [
        "| solver | parameters | status | GPS ATE aligned (m) | map size | wall time (s) | beacons found of 15 | "
        "beacon RMSE (m) |",
        "|---|---|---|---|---|---|---|---|",
        "| `odometry` | nn_threshold=1.5 | completed | 0.13 | 14 | 0.0 | 12 | 0.16 |",
        "| `hybrid` | defaults | refused: solver 'hybrid' supports the motion model(s) ddmr, but the dataset uses "
        "'ackermann' | — | — | — | — | — |",
        "| `icm (preset=real)` | preset=real, max_sweeps=5 | converged | 0.08 | 15 | 0.6 | 15 | 0.14 |"]
    assert rows[2]["run_dir"] == exp / "a3"  # the run folder the map figure reads, joined onto the sweep's


def test_mrclam_renderer_table_from_a_hand_written_results_csv(tmp_path):
    exp = tmp_path / "real-mrclam"
    _results_csv(exp, "run_id,label,method,data,status,solver_status,error,solve_time_s,path,ate_rmse_m,"
                      "odometry_ate_rmse_m,lm_rmse_matched_m,lm_n_matched,lm_n_true,lm_n_est",
                 ["b1,graph,graph,mrclam7-r2,completed,converged,,0.31,b1,0.1204,0.2461,0.335,8,15,9",
                  "b2,ekf,ekf,mrclam7-r3,completed,completed,,1.26,b2,0.3,0.25,0.5,7.0,15.0,7"])
    _config(exp / "b1", robot=2, dt=0.1)
    _config(exp / "b2", robot=3)
    rows = pr.mrclam_rows(pr.sweep_records(exp), {"graph": "association=reported, robust=huber"})
    assert pr._mrclam_table(rows)[2:] == [
        "| 2 | `graph` | association=reported, robust=huber | converged | 0.12 | 0.25 | 8 / 15 | 0.34 | 0.3 |",
        "| 3 | `ekf` | defaults | completed | 0.30 | 0.25 | 7 / 15 | 0.50 | 1.3 |"]


def test_refusal_strips_the_exception_class_and_the_dataset_path():
    assert pr.refusal("SolverError: /x/y/ab.h5: solver 'cuik' needs bounds\nTraceback ...") == \
        "solver 'cuik' needs bounds"
    assert pr.refusal("worker failed: OSError: disk") == "worker failed: OSError: disk"


def test_multi_robot_renderer_reads_the_team_run_files(tmp_path):
    """Joint ATE from the team result (the motion capture shifted by (0.3, 0.4) m: 0.5 m for every robot), solo
    ATE from results.csv, dead reckoning from the team dataset (RMSE by numpy)."""
    import numpy as np

    from slamcli.datasets.mrclam import import_mrclam_team
    from slamcli.io import write_dataset, write_result
    from slamcli.reproduce import real_multi as rm
    from slamcli.types import SolverResult, Status

    data = DATA / "mrclam_team_excerpt"
    team = import_mrclam_team(data, [1, 2, 3, 4, 5])
    exp = tmp_path / "real-multi"
    rows = []
    for label in ("graph", "icm"):
        run = exp / f"{label}-team"
        _config(run, **{"all-robots": True})
        write_dataset(run / "dataset.h5", team)
        shifted = team.truth.poses_xyt + np.array([0.3, 0.4, 0.0])
        write_result(run / "result.h5", SolverResult(label, "0", {}, Status.CONVERGED, "", shifted,
                                                     np.zeros((0, 2)), np.full(len(team.inputs.observations), -1)))
        rows.append(f"{label}-team,{label},mrclam7-team,completed,converged,0.5,{label}-team,")
        for n in range(1, 6):
            _config(exp / f"{label}-{n}", **{"all-robots": True, "solo": n})
            solo_ate = 0.1 * n + (0.05 if label == "icm" else 0.0)
            rows.append(f"{label}-{n},{label},mrclam7-solo{n},completed,converged,0.1,{label}-{n},{solo_ate}")
    _results_csv(exp, "run_id,label,data,status,solver_status,solve_time_s,path,ate_rmse_m", rows)

    m = rm.measure(exp)
    fp = team.inputs.robots.first_pose
    odo = [float(np.sqrt(np.mean(np.sum((team.inputs.odometry_xyt[a:b, :2] - team.truth.poses_xyt[a:b, :2]) ** 2,
                                         axis=1)))) for a, b in zip(fp[:-1], fp[1:])]
    table = [line for line in rm.render(m, True, "S", 10, tmp_path) if line.startswith("| ")]
    assert table[1:] == [f"| {n} | {odo[n - 1]:.3f} | {0.1 * n:.3f} | 0.500 | {0.1 * n + 0.05:.3f} | 0.500 |"
                         for n in range(1, 6)]
    assert m["seconds"] == pytest.approx({"graph_joint": 0.5, "graph_solo": 0.5, "icm_joint": 0.5, "icm_solo": 0.5})
    assert (tmp_path / "real_multi_ate.csv").is_file()


def test_excerpt_registry_points_the_registry_at_the_excerpts_and_restores_it(tmp_path, monkeypatch):
    import os

    from slamcli.datasets import registry

    monkeypatch.setenv(registry.ENV_SHARED, "/nowhere")
    monkeypatch.setenv(registry.ENV_REGISTRY, str(tmp_path / "reg.toml"))
    monkeypatch.delenv(registry.ENV_DATA_DIR, raising=False)
    with pr.excerpt_registry(tmp_path / "q", {"acfr_carpark": "carpark_excerpt"}) as source:
        how, where = registry.where("acfr-carpark")
        assert where.resolve() == (DATA / "carpark_excerpt").resolve()
        assert how == "$SLAMCLI_DATASETS" and registry.data_dir() == tmp_path / "q" / "cache"
    assert source == "the excerpts shipped in `tests/data` (`tests/data/carpark_excerpt`)"
    assert os.environ[registry.ENV_SHARED] == "/nowhere" and registry.ENV_DATA_DIR not in os.environ
    assert os.environ[registry.ENV_REGISTRY] == str(tmp_path / "reg.toml")


@pytest.mark.slow
def test_multi_robot_section_runs_through_the_sweep_and_resumes(tmp_path):
    """``reproduce --section real-multi --quick``: the runs are the sweep's (results.csv under runs/), the report
    has one row per robot, and a second reproduce into the same folder runs nothing again."""
    import pandas as pd

    from slamcli.reproduce.report import reproduce

    log: list[str] = []
    assert not reproduce(tmp_path, quick=True, workers=1, only=["real-multi"], log=log.append).failed
    runs = pd.read_csv(tmp_path / "runs" / "real-multi" / "results.csv")
    assert len(runs) == 2 * 6 and set(runs["status"]) == {"completed"}  # graph and icm: team + five solo
    report = (tmp_path / "REPORT.md").read_text(encoding="utf-8")
    assert [line.split(" | ")[0] for line in report.splitlines() if line[:3] in {f"| {n}" for n in range(1, 6)}] \
        == [f"| {n}" for n in range(1, 6)]
    log.clear()
    assert not reproduce(tmp_path, quick=True, workers=1, only=["real-multi"], log=log.append).failed
    assert any("0 done, 0 failed, 12 skipped" in line for line in log)
