"""The real-data reproduce section's outcome sentences and tables are computed from the rows they describe."""

from __future__ import annotations

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

    def mr(icm, graph):
        return [{"robot": 1, "solver": pr.ICM_PRESET_ROW, "refused": None, "ate": icm},
                {"robot": 1, "solver": "graph", "refused": None, "ate": graph}]

    good = pr.icm_verdicts(gps(1.39), gps(0.44), mr(0.33, 0.31), "VP")
    assert [("**met**" in v) for v in good] == [True, True, True]
    assert "GPS ATE 1.390 m, goal ≤ 1.4 m" in good[0] and "robot 1 0.330 vs 0.310 m" in good[2]
    bad = pr.icm_verdicts(gps(1.41), gps(0.44, found=14), mr(0.35, 0.31), "VP")  # 0.35 > 1.1 · 0.31 = 0.341
    assert [("**not met**" in v) for v in bad] == [True, True, True]
    missing = pr.icm_verdicts([], None, [], "VP")
    assert all("not checked" in v for v in missing)
