"""Baseline images of ``slamcli plot`` on real-recording excerpts, beside the simulated ones of
``test_plot_style.py`` (same rendering rules, tolerance and ``SLAMCLI_UPDATE_BASELINES=1`` regeneration):

* ``real_vp_map``: the Victoria Park excerpt solved by the EKF (ML association), GPS reference drawn;
* ``real_vp_overlay``: ``plot map ekf.h5 graph.h5``, the EKF and graph SLAM on that excerpt in one figure;
* ``real_team_map``: the five-robot MRCLAM excerpt solved jointly by graph SLAM, one colour per robot;
* ``real_mrclam_compare``: ``plot compare`` of a sweep of odometry, EKF and graph SLAM over the five robots of
  the MRCLAM excerpt, each imported alone with its motion-capture truth (15 runs, ATE RMSE).

Each figure is drawn by the command at one column width (3.5 in) and must keep every text inside the figure.
The compare figure's points are also checked against the ATE recomputed here from the result files and the
truth (``sqrt(mean ‖p̂ − p‖²)``, unaligned).
"""

from __future__ import annotations

import matplotlib
import matplotlib.style
import numpy as np
import pytest
from conftest import DATA
from test_plot_style import DETERMINISTIC_RC, assert_matches_baseline, texts_outside
from test_plots_real import _cli, team, vp  # noqa: F401  (module fixtures: the solved excerpts)

from slamcli.io import read_dataset, read_result

matplotlib.use("Agg")
ROBOTS = (1, 2, 3, 4, 5)
SOLVERS = ("odometry", "ekf", "graph")
#: m: ATE values as drawn (float64 through results.csv) against the ones recomputed here
ATE_TOL = 1e-9

#: solves real excerpts in its fixtures: slow for the edit loop (make test runs it)
pytestmark = pytest.mark.slow


@pytest.fixture(scope="module")
def mrclam_sweep(tmp_path_factory):
    """A sweep of three solvers over the five MRCLAM robots, each imported alone (a ``file`` entry each)."""
    d = tmp_path_factory.mktemp("mrclam_sweep")
    for k in ROBOTS:
        _cli("import", "mrclam", DATA / "mrclam_team_excerpt", "--robot", k, "-q", "-o", d / f"r{k}.h5")
    data = "".join(f'[[data]]\nfile = "r{k}.h5"\n' for k in ROBOTS)
    solvers = "".join(f'[[solver]]\nmethod = "{m}"\n' for m in SOLVERS)
    (d / "exp.toml").write_text(f'[experiment]\nname = "mrclam-solvers"\n\n{data}\n{solvers}')
    _cli("sweep", d / "exp.toml", "-o", d / "out", "-q")
    return d, d / "out" / "mrclam-solvers"


def _figure(monkeypatch, tmp_path, name, *args):
    """The figure ``slamcli plot *args`` draws, re-saved at the baseline resolution, and the texts outside it."""
    import slamcli.plots as plots

    figs, real = [], plots.save_figure
    monkeypatch.setattr(plots, "save_figure", lambda fig, path, dpi=200: (figs.append(fig), real(fig, path, dpi))[1])
    with matplotlib.style.context("default"), matplotlib.rc_context(DETERMINISTIC_RC):
        _cli("plot", *args, "-q", "-o", tmp_path / "cli.png")  # the default size: one column (3.5 in) wide
        fig = figs[0]
        return fig, real(fig, tmp_path / f"{name}.png", dpi=80), texts_outside(fig)


def test_victoria_park_map_matches_baseline(vp, tmp_path, monkeypatch):  # noqa: F811
    _, png, outside = _figure(monkeypatch, tmp_path, "real_vp_map", "map", vp / "ekf.h5")
    assert outside == []
    assert_matches_baseline(png, "real_vp_map")


def test_victoria_park_overlay_matches_baseline(vp, tmp_path, monkeypatch):  # noqa: F811
    fig, png, outside = _figure(monkeypatch, tmp_path, "real_vp_overlay", "map", vp / "ekf.h5", vp / "graph.h5",
                                "--label", "EKF", "--label", "Graph")
    assert {"EKF", "Graph", "GPS reference"} <= {ln.get_label() for ln in fig.axes[0].lines}
    assert outside == []
    assert_matches_baseline(png, "real_vp_overlay")


def test_mrclam_team_map_matches_baseline(team, tmp_path, monkeypatch):  # noqa: F811
    _, png, outside = _figure(monkeypatch, tmp_path, "real_team_map", "map", team / "graph.h5")
    assert outside == []
    assert_matches_baseline(png, "real_team_map")


def test_compare_of_real_solves_matches_baseline(mrclam_sweep, tmp_path, monkeypatch):
    d, exp = mrclam_sweep
    fig, png, outside = _figure(monkeypatch, tmp_path, "real_mrclam_compare", "compare", exp, "--by", "solver")
    ax = fig.axes[0]
    assert [t.get_text().split("\n")[0] for t in ax.get_xticklabels()] == sorted(SOLVERS)
    expected: dict[str, list[float]] = {m: [] for m in SOLVERS}
    for run in exp.glob("*/result.h5"):
        res, ds = read_result(run), read_dataset(run.parent / "dataset.h5")
        err = res.poses_xyt[:, :2] - ds.truth.poses_xyt[:, :2]
        expected[res.solver].append(np.sqrt(np.mean(np.sum(err**2, axis=1))))
    for pos, solver in enumerate(sorted(SOLVERS), start=1):
        drawn = next(ln for ln in ax.lines if ln.get_marker() == "o" and abs(np.mean(ln.get_xdata()) - pos) < 0.5)
        assert len(expected[solver]) == len(ROBOTS)
        np.testing.assert_allclose(np.sort(drawn.get_ydata()), np.sort(expected[solver]), rtol=0, atol=ATE_TOL)
    assert outside == []
    assert_matches_baseline(png, "real_mrclam_compare")
