"""The figure style (issue 24 item 4): labels stay inside a one-column figure, names and units come from the
metric registry, and every figure kind still looks as its committed baseline image.

* **Inside the figure**: each figure is drawn at ``--size 3.5x2.6`` (one IEEE column) and every visible text
  artist's window extent (titles, axis labels, drawn tick labels, legends, annotations, colorbar labels) must
  lie inside the figure's bounding box.
* **Image comparison** (``matplotlib.testing.compare.compare_images``): the figures below are drawn from
  fixed arrays (no random draw; seeded where noise is wanted), on Agg, in DejaVu Sans (ships with matplotlib)
  without hinting, from matplotlib's default rc (whatever other tests changed), and compared with
  ``tests/plots/baseline_images/*.png`` at an RMS tolerance of :data:`IMAGE_TOL` (0-255 scale). The baselines are
  tied to the matplotlib minor version named in ``tests/plots/baseline_images/VERSION`` (text layout changes between
  releases); under another version the comparison is skipped with that reason. To regenerate the baselines
  after an intended change of the style (or for a new matplotlib), run
  ``SLAMCLI_UPDATE_BASELINES=1 pytest tests/plots/test_plot_style.py`` and look at the new images before committing.
"""

from __future__ import annotations

import os
from pathlib import Path
from types import SimpleNamespace

import matplotlib
import matplotlib.style
import numpy as np
import pytest

matplotlib.use("Agg")

from test_plots import make_runs
from typer.testing import CliRunner

from slamcli.cli import app
from slamcli.plots import new_figure, save_figure

runner = CliRunner()
BASELINES = Path(__file__).parent / "baseline_images"
#: RMS difference allowed between a figure and its baseline (0-255 grey levels)
IMAGE_TOL = 2.0
#: rc settings that make text rasterisation reproducible (as matplotlib's own image tests do)
DETERMINISTIC_RC = {"text.hinting": "none", "font.family": "DejaVu Sans"}
COLUMN = (3.5, 2.6)


# ----------------------------------------------------------------------------------------- the inside check
def _visible_texts(fig, renderer):
    """Every text artist that the renderer draws: titles, labels, legends, annotations, and the tick labels
    of the ticks inside each axis' view interval (matplotlib keeps, but does not draw, the others)."""
    from matplotlib.text import Text

    ticks = set()
    for ax in fig.axes:
        for axis in (ax.xaxis, ax.yaxis):
            lo, hi = sorted(axis.get_view_interval())
            for tick in axis.get_major_ticks() + axis.get_minor_ticks():
                if not lo - 1e-9 * abs(hi - lo) <= tick.get_loc() <= hi + 1e-9 * abs(hi - lo):
                    ticks.update((id(tick.label1), id(tick.label2)))
    for t in fig.findobj(Text):
        if t.get_visible() and t.get_text().strip() and id(t) not in ticks:
            yield t


def texts_outside(fig) -> list[str]:
    """Texts whose window extent leaves the figure's bounding box (after a full draw), with their extents."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg

    canvas = FigureCanvasAgg(fig)
    canvas.draw()
    renderer = canvas.get_renderer()
    box = fig.bbox
    out = []
    for t in _visible_texts(fig, renderer):
        e = t.get_window_extent(renderer)
        if e.x0 < box.x0 - 0.5 or e.y0 < box.y0 - 0.5 or e.x1 > box.x1 + 0.5 or e.y1 > box.y1 + 0.5:
            out.append(f"{t.get_text()!r} at {e.bounds}")
    return out


@pytest.mark.slow
def test_inside_check_catches_a_clipped_label():
    """The check is not vacuous: a label pushed off the figure is reported."""
    fig, ax = new_figure(*COLUMN)
    ax.plot([0, 1], [0, 1])
    ax.set_ylabel("y (m)")
    assert texts_outside(fig) == []
    ax.text(1.2, 0.5, "far off to the right", transform=ax.transAxes)
    assert any("far off" in s for s in texts_outside(fig))


@pytest.fixture()
def runs(tmp_path):
    return make_runs(tmp_path)


@pytest.fixture()
def captured(monkeypatch):
    """The figures that ``slamcli plot`` hands to save_figure."""
    import slamcli.plots as plots

    figs = []
    real = plots.save_figure

    def keep(fig, path, dpi=200):
        figs.append(fig)
        return real(fig, path, dpi=dpi)

    monkeypatch.setattr(plots, "save_figure", keep)
    return figs


def _cli_cases(runs, sweep):
    r0, rs = str(runs[0]), [str(r) for r in runs]
    return {"map": ["map", r0, "--ellipses", "--pose-ellipse-every", "10"],
            "errors (trace)": ["errors", r0],
            "mapchange": ["mapchange", *rs, "--label", "ICM, paper weights", "--label", "ICM, information",
                          "--label", "ICM, joint steps"],
            "nees": ["nees", *rs],
            "compare": ["compare", str(sweep), "--by", "solver,provisional_min_hits"]}


@pytest.mark.parametrize("size,inches", [("3.5x2.6", COLUMN), ("page", (7.16, 3.2))])
@pytest.mark.slow
def test_every_cli_figure_keeps_its_labels_inside(runs, tmp_path, captured, size, inches):
    """One column (3.5 in) and both columns (7.16 in, ``--size page``)."""
    from conftest import write_sweep_table

    write_sweep_table(tmp_path / "exp")
    for name, args in _cli_cases(runs, tmp_path / "exp").items():
        captured.clear()
        r = runner.invoke(app, ["plot", *args, "--size", size, "-q", "-o", str(tmp_path / "f.png")])
        assert r.exit_code == 0, (name, r.output)
        (fig,) = captured
        assert tuple(fig.get_size_inches()) == inches
        assert texts_outside(fig) == [], name


@pytest.mark.slow
def test_pose_errors_boxes_and_occupancy_keep_labels_inside():
    for make in (_fig_pose_errors, _fig_boxes, _fig_grid):
        fig = make()
        assert tuple(fig.get_size_inches()) == COLUMN
        assert texts_outside(fig) == [], make.__name__


def test_occupancy_map_has_a_colorbar_and_pose_errors_are_in_radians():
    fig = _fig_grid()
    cbar_axes = [c for ax in fig.axes for c in ax.child_axes if c.get_ylabel() == "occupancy probability"]
    assert len(cbar_axes) == 1 and cbar_axes[0].get_ylim() == (0.0, 1.0)
    from slamcli.plots.style import FONT_PT, apply_style

    apply_style(fig)  # the style reaches the colorbar (an inset axis, not in fig.axes)
    assert cbar_axes[0].yaxis.label.get_fontsize() == FONT_PT
    fig = _fig_pose_errors()
    assert fig.axes[2].get_ylabel() == "Δθ (rad)"
    # the θ error is drawn unconverted (radians, as in the tables)
    np.testing.assert_allclose(fig.axes[2].lines[0].get_ydata(), _pose_err()[:, 2])


@pytest.mark.slow
def test_map_title_has_no_file_name_and_label_names_the_estimate(runs, tmp_path, captured):
    r = runner.invoke(app, ["plot", "map", str(runs[0]), "--label", "ICM", "-q", "-o", str(tmp_path / "m.png")])
    assert r.exit_code == 0, r.output
    ax = captured[0].axes[0]
    assert ax.get_title() == "toy" and runs[0].name not in ax.get_title()
    assert "ICM" in [t.get_text() for t in ax.get_legend().get_texts()]
    r = runner.invoke(app, ["plot", "mapchange", *map(str, runs), "--label", "a", "-o", str(tmp_path / "c.png")])
    assert r.exit_code == 1 and "1 label(s) for 3 result(s)" in r.output


@pytest.mark.slow
def test_a_long_title_wraps_inside_one_column(runs, tmp_path, captured):
    title = "ICM on paper-sim1, information weights, gated initialisation, seeds 0-9, 30 sweeps"
    r = runner.invoke(app, ["plot", "errors", str(runs[0]), "--title", title, "--size", "column", "-q",
                            "-o", str(tmp_path / "e.png")])
    assert r.exit_code == 0, r.output
    assert captured[0].axes[0].get_title() == title and texts_outside(captured[0]) == []


@pytest.mark.slow
def test_mapchange_default_labels_are_solver_names_numbered(runs, tmp_path, captured):
    r = runner.invoke(app, ["plot", "mapchange", *map(str, runs[:2]), "-q", "-o", str(tmp_path / "c.png")])
    assert r.exit_code == 0, r.output
    labels = [t.get_text() for t in captured[0].axes[0].get_legend().get_texts()]
    assert labels == ["toy (1)", "toy (2)"]  # not "toy: r0.h5"


@pytest.mark.slow
def test_cli_pdf_embeds_no_type3_font(runs, tmp_path):
    from test_plot_fonts import _font_subtypes

    out = tmp_path / "map.pdf"
    r = runner.invoke(app, ["plot", "map", str(runs[0]), "-q", "-o", str(out)])
    assert r.exit_code == 0, r.output
    kinds = _font_subtypes(out.read_bytes())
    assert b"Type3" not in kinds and kinds & {b"TrueType", b"CIDFontType2"}


def test_named_sizes():
    from slamcli.plots import parse_size
    from slamcli.plots.style import COLUMN_IN, PAGE_IN

    assert parse_size("column", (1, 1)) == (COLUMN_IN, 2.6) and parse_size("page", (1, 1))[0] == PAGE_IN == 7.16


# -------------------------------------------------------------------------------------- figures from arrays
def _square_path(n=41):
    s = np.linspace(0, 4, n)
    x = np.clip(s, 0, 1) * 8 - np.clip(s - 2, 0, 1) * 8
    y = np.clip(s - 1, 0, 1) * 6 - np.clip(s - 3, 0, 1) * 6
    return np.column_stack([x, y])


def _fig_map():
    from slamcli.plots.maps import plot_map

    fig, ax = new_figure(*COLUMN)
    path = _square_path()
    true_lm = np.array([[2.0, -1.5], [6.0, 1.5], [9.5, 3.0], [4.0, 7.5], [-1.5, 4.0]])
    est_lm = true_lm[:4] + np.array([[0.2, -0.1], [-0.15, 0.2], [0.1, 0.1], [0.3, -0.2]])
    bend = np.column_stack([np.zeros(len(path)), 0.02 * np.arange(len(path))])
    plot_map(ax, true_lm, est_lm, path, path + 3 * bend, path + bend,
             landmark_cov=np.stack([np.diag([0.04, 0.02])] * 4), label="ICM")
    return fig


def _fig_errors():
    from slamcli.plots.curves import plot_error_curves

    fig, ax = new_figure(*COLUMN)
    it = np.arange(11)
    mean = 0.8 * np.exp(-it / 3) + 0.1
    plot_error_curves(ax, it, 0.5 * mean, mean, 2.0 * mean)
    return fig


def _fig_nees():
    from slamcli.plots.curves import plot_nees

    fig, ax = new_figure(*COLUMN)
    k = np.arange(60)
    plot_nees(ax, k, 3.0 + 2.5 * np.sin(k / 6.0) ** 2 + k / 30.0, 2.36, 3.72, 3, 50, fraction_inside=0.4)
    return fig


def _fig_mapchange():
    from slamcli.plots.curves import plot_map_change

    fig, ax = new_figure(*COLUMN)
    it = np.arange(15)
    plot_map_change(ax, it, 1e-2 * 0.5 ** it, label="paper weights", log=True)
    plot_map_change(ax, it, 1e-2 * 0.8 ** it, label="information weights", log=True)
    return fig


def _pose_err():
    k = np.arange(50)
    return np.column_stack([0.05 * np.sin(k / 5), 0.04 * np.cos(k / 7), 0.01 * np.sin(k / 3)])


def _fig_pose_errors():
    from slamcli.plots.curves import plot_pose_errors

    fig, axes = new_figure(*COLUMN, nrows=3, sharex=True)
    sig = np.broadcast_to([0.03, 0.03, 0.006], (50, 3))
    plot_pose_errors(axes, np.arange(50), _pose_err(), sig, 3.0, np.array([1.0, 1.0, 0.96]))
    return fig


def _fig_compare():
    from slamcli.metrics.aggregate import CompareGroups
    from slamcli.plots.figures import draw_compare

    fig, ax = new_figure(*COLUMN)
    g = CompareGroups(("ekf, gate_prob=0.9", "ekf, gate_prob=0.99", "icm"),
                      (np.array([0.12, 0.15, 0.11, 0.2]), np.array([0.1, 0.09, 0.14, 0.12]),
                       np.array([0.05, 0.07, 0.06, 0.04])), "ate_rmse_m", ("label", "solver.ekf.gate_prob"))
    draw_compare(ax, g)
    return fig


def _fig_boxes():
    from slamcli.plots.boxes import plot_boxes

    fig, ax = new_figure(*COLUMN)
    poses = np.array([[0.0, 0.0, 0.0], [3.0, 0.5, 0.3], [6.0, 1.5, 0.6]])
    w = np.array([0.2, 0.3, 0.1])
    lms = np.array([[2.0, 3.0], [5.0, 4.0]])
    plot_boxes(ax, poses - w, poses + w, lms - 0.3, lms + 0.4, poses, lms, wedge_radius=0.8)
    return fig


def _fig_grid():
    from slamcli.plots.grids import draw_grid, observed_corners_xy
    from slamcli.plots.maps import plot_map

    fig, ax = new_figure(*COLUMN)
    yy, xx = np.mgrid[0:40, 0:60]
    prob = np.full((40, 60), 0.5)
    prob[(np.abs(xx - 30) < 25) & (np.abs(yy - 20) < 15)] = 0.1
    prob[(np.abs(xx - 30) == 25) | (np.abs(yy - 20) == 15)] = 0.95
    grid = SimpleNamespace(prob=prob, origin_xy=(-1.0, -1.0), resolution=0.25, snapshots=None, observed=None)
    draw_grid(ax, grid, label="occupancy (frequentist)", colorbar=True)
    path = np.column_stack([np.linspace(2, 12, 20), 4 + np.sin(np.linspace(0, 3, 20))])
    plot_map(ax, None, None, None, None, path, title="hybrid", extent_xy=observed_corners_xy(grid))
    return fig


FIGURES = {"map": _fig_map, "errors": _fig_errors, "nees": _fig_nees, "mapchange": _fig_mapchange,
           "pose_errors": _fig_pose_errors, "compare": _fig_compare, "boxes": _fig_boxes, "grid": _fig_grid}


def _mpl_minor() -> str:
    return "matplotlib " + ".".join(matplotlib.__version__.split(".")[:2])


def _draw(make, path):
    with matplotlib.style.context("default"), matplotlib.rc_context(DETERMINISTIC_RC):
        fig = make()
        outside = texts_outside(fig)
        return save_figure(fig, path, dpi=80), outside


@pytest.mark.parametrize("name", sorted(FIGURES))
@pytest.mark.slow
def test_figure_matches_baseline_image(name, tmp_path):
    actual, outside = _draw(FIGURES[name], tmp_path / f"{name}.png")
    assert outside == [], name
    assert_matches_baseline(actual, name)


def assert_matches_baseline(actual: Path, name: str) -> None:
    """``actual`` (a PNG) equals ``baseline_images/<name>.png`` to :data:`IMAGE_TOL` (module docstring: the
    matplotlib version check and ``SLAMCLI_UPDATE_BASELINES``)."""
    from matplotlib.testing.compare import compare_images

    expected = BASELINES / f"{name}.png"
    if os.environ.get("SLAMCLI_UPDATE_BASELINES"):
        BASELINES.mkdir(exist_ok=True)
        expected.write_bytes(actual.read_bytes())
        (BASELINES / "VERSION").write_text(_mpl_minor() + "\n")
        pytest.skip(f"baseline {expected.name} written")
    assert expected.is_file(), f"no baseline {expected}; run with SLAMCLI_UPDATE_BASELINES=1 and commit it"
    made_with = (BASELINES / "VERSION").read_text().strip()
    if made_with != _mpl_minor():
        pytest.skip(f"baselines made with {made_with}, running {_mpl_minor()}: regenerate them")
    diff = compare_images(str(expected), str(actual), tol=IMAGE_TOL)
    assert diff is None, diff


@pytest.mark.slow
def test_image_comparison_detects_a_style_change(tmp_path):
    """The comparison is not vacuous: the same figure with another colour for the estimate fails it."""
    from matplotlib.testing.compare import compare_images

    import slamcli.plots.style as style

    same, _ = _draw(_fig_map, tmp_path / "same.png")
    old = style.ESTIMATE
    try:
        style.ESTIMATE = "#FF0000"
        actual, _ = _draw(_fig_map, tmp_path / "map.png")
    finally:
        style.ESTIMATE = old
    assert compare_images(str(same), str(actual), tol=IMAGE_TOL) is not None


def test_reproduce_compare_figure_is_the_plot_compare_implementation():
    """The report's compare figure draws through draw_compare, like `slamcli plot compare` (no own boxplot)."""
    import inspect

    from slamcli.cli import plot_cmd
    from slamcli.reproduce.report import Reproduction

    report_src = inspect.getsource(Reproduction.compare_section)
    assert "draw_compare(" in report_src and "boxplot" not in report_src
    assert "draw_compare(" in inspect.getsource(plot_cmd._compare)
