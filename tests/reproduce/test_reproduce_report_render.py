"""Paper 000's post-processing section and post-radius study render from the sweeps' ``results.csv`` alone: fed
hand-written tables, they produce the rows worked out by hand here; ``prepare`` leaves out a solver whose
initial estimate is not run and applies the quick command-line axes only with ``--quick``."""

from __future__ import annotations

from pathlib import Path

import pandas as pd
import pytest
from conftest import ROOT

from slamcli.reproduce.report import Reproduction, Section, SweepOutcome

EXPERIMENTS = ROOT / "experiments"


def _rep(tmp_path: Path, quick: bool = True) -> Reproduction:
    return Reproduction(tmp_path, quick=quick, workers=1, experiments_dir=EXPERIMENTS, log=lambda s: None)


def _fake_run(monkeypatch, rep: Reproduction, rows: list[dict], calls: list | None = None) -> None:
    """``rep.run`` returns the prepared experiment with ``rows`` as its results.csv (nothing is solved)."""
    def run(file, *, add_all_solvers=False, quick_overrides=()):
        if calls is not None:
            calls.append(quick_overrides)
        cfg, missing = rep.prepare(file, quick_overrides=quick_overrides)
        return SweepOutcome(cfg, object(), None, pd.DataFrame(rows), rep.runs_dir / cfg.name, missing)

    monkeypatch.setattr(rep, "run", run)


def _pp(label, rep, err, ospa, ate, status="completed"):
    return {"label": label, "data": "loop", "replicate": rep, "status": status, "paper_err_mean_m": err,
            "lm_ospa_m": ospa, "ate_rmse_m": ate}


def _table_rows(sec: Section) -> list[str]:
    return [ln for md in sec.markdown for ln in md.splitlines() if ln.startswith("| `")]


def test_postprocess_pairs_base_and_icm_by_replicate(tmp_path, monkeypatch):
    rep = _rep(tmp_path)
    rows = [_pp("odometry", 1, 0.2, 0.6, 0.3), _pp("odometry", 2, 0.4, 0.6, 0.5),
            _pp("icm-after-odometry", 2, 0.1, 0.5, 0.2), _pp("icm-after-odometry", 1, 0.1, 0.5, 0.2),
            _pp("ekf", 1, 0.05, 0.4, 0.04), _pp("ekf", 2, 0.05, 0.4, 0.06),
            _pp("icm-after-ekf", 1, 0.1, 0.5, 0.1), _pp("icm-after-ekf", 2, 0.1, 0.5, 0.1),
            # fastslam: the ICM run of replicate 2 failed, so only replicate 1 is paired
            _pp("fastslam", 1, 0.3, 0.7, 0.3), _pp("fastslam", 2, 0.9, 0.9, 0.9),
            _pp("icm-after-fastslam", 1, 0.1, 0.5, 0.1), _pp("icm-after-fastslam", 2, 9, 9, 9, status="failed")]
    _fake_run(monkeypatch, rep, rows)  # graph and its ICM run: no row at all
    sec = rep.postprocess_section()
    assert _table_rows(sec) == [
        # mean ± population sd by hand: (0.2, 0.4) → 0.300 ± 0.100; (0.3, 0.5) → 0.400 ± 0.100
        "| `loop` | `odometry` | 2 | 0.300 ± 0.100 → 0.100 ± 0.000 | 0.600 ± 0.000 → 0.500 ± 0.000 | "
        "0.400 ± 0.100 → 0.200 ± 0.000 |",
        "| `loop` | `ekf` | 2 | 0.050 ± 0.000 → 0.100 ± 0.000 | 0.400 ± 0.000 → 0.500 ± 0.000 | "
        "0.050 ± 0.010 → 0.100 ± 0.000 |",
        "| `loop` | `fastslam` | 1 | 0.300 ± 0.000 → 0.100 ± 0.000 | 0.700 ± 0.000 → 0.500 ± 0.000 | "
        "0.300 ± 0.000 → 0.100 ± 0.000 |",
    ]
    text = "\n".join(sec.markdown)
    assert "seeds [1]" in text and "≤ 5 sweeps" in text  # the quick table of postprocess.toml
    # the claim pools the non-odometry bases: ekf lowered in 0 of 2 runs, fastslam in 1 of 1
    (claim,) = sec.claims
    assert "lower after `ekf` in 0 of 2 runs, lower after `fastslam` in 1 of 1 runs" in claim.numbers
    assert "`odometry`" not in claim.numbers


def test_postprocess_without_completed_pairs_fails_the_section(tmp_path, monkeypatch):
    rep = _rep(tmp_path)
    _fake_run(monkeypatch, rep, [_pp("ekf", 1, 0.1, 0.1, 0.1)])
    sec = rep.postprocess_section()
    assert not sec.ok and "no completed run" in sec.problems and not _table_rows(sec)


def test_prepare_leaves_out_a_solver_whose_initial_estimate_is_not_run(tmp_path):
    rep = _rep(tmp_path)
    rep.solvers = [s for s in rep.solvers if s != "fastslam"]
    rep.broken = {"fastslam": "fastslam is broken here"}
    cfg, missing = rep.prepare("postprocess.toml")
    assert missing == {"fastslam": "fastslam is broken here",
                       "icm-after-fastslam": "it starts from the result of `fastslam`, which is not run"}
    assert [s.label for s in cfg.solvers] == ["odometry", "ekf", "graph", "icm-after-odometry", "icm-after-ekf",
                                             "icm-after-graph"]


@pytest.mark.parametrize("quick, radii", [(True, (0.10, 0.25)), (False, (0.05, 0.10, 0.15, 0.20, 0.25))])
def test_quick_axes_apply_only_with_quick(tmp_path, quick, radii):
    rep = _rep(tmp_path, quick=quick)
    cfg, _ = rep.prepare("fig5-radius.toml", quick_overrides=rep.RADIUS_QUICK_AXES)
    assert dict(cfg.sweep.grid)[rep.RADIUS_AXIS] == radii


def _rad(label, rho, seed, err, n_est):
    return {"label": label, "status": "completed", Reproduction.RADIUS_AXIS: rho, "dataset_seed": seed,
            "replicate": seed, "paper_err_mean_m": err, "n_landmarks_est": n_est}


def test_radius_study_table_from_a_hand_written_results_csv(tmp_path, monkeypatch):
    rep = _rep(tmp_path)
    calls: list = []
    rows = [_rad("exact", 0.25, 0, 0.30, 40), _rad("surface", 0.25, 0, 0.10, 41), _rad("exact", 0.1, 0, 0.10, 14),
            _rad("exact", 0.1, 1, 0.30, 16), _rad("surface", 0.1, 0, 0.05, 15), _rad("surface", 0.1, 1, 0.07, 15),
            {**_rad("surface", 0.25, 1, 9.0, 1), "status": "failed"}]
    _fake_run(monkeypatch, rep, rows, calls)
    sec = Section("fig5", "t")
    rep._surface_sensitivity(sec)
    assert calls == [rep.RADIUS_QUICK_AXES]
    table = [ln for md in sec.markdown for ln in md.splitlines() if ln.startswith("| 0.")]
    assert table == ["| 0.10 | 0.200 ± 0.100 (0.100-0.300) | 0.060 ± 0.010 (0.050-0.070) | 15.0 ± 1.0 |",
                     "| 0.25 | 0.300 ± 0.000 (0.300-0.300) | 0.100 ± 0.000 (0.100-0.100) | 40.0 ± 0.0 |"]
    text = "\n".join(sec.markdown)
    assert "seeds [0, 1]" in text and "ς = 20, 3 sweeps" in text  # the quick table of fig5-radius.toml
    assert len(sec.claims) == 2  # one finding per radius
