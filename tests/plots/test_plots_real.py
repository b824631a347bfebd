"""Figures on real-recording excerpts (Victoria Park: GPS reference only, 126+ landmarks; MRCLAM team: five
robots with motion-capture truth): axis limits, reference, marker density, colours, overlays, compare tick
labels and the ``ax=`` contract of :mod:`slamcli.api.plot`. Properties are measured on the drawn artists and,
for tick labels, on the rendered pixels."""

from __future__ import annotations

import numpy as np
import pytest
from conftest import DATA
from test_plot_style import texts_outside
from typer.testing import CliRunner

from slamcli.cli import app
from slamcli.io import read_dataset, read_result
from slamcli.plots import new_figure, style
from slamcli.plots.maps import LANDMARK_PT_MAX, landmark_marker_pt

runner = CliRunner()
#: the map must show the estimate's positions between these percentiles (its robust range)
ROBUST_PCT = (1.0, 99.0)


def _cli(*args):
    r = runner.invoke(app, [*map(str, args)])
    assert r.exit_code == 0, r.output
    return r


@pytest.fixture(scope="module")
def vp(tmp_path_factory):
    """The Victoria Park excerpt solved by the EKF (ML association) and by graph SLAM."""
    d = tmp_path_factory.mktemp("vp")
    _cli("import", "victoria-park", DATA / "victoria_park_excerpt", "-o", d / "vp.h5")
    _cli("solve", d / "vp.h5", "-m", "ekf", "-p", "association=ml", "-q", "-o", d / "ekf.h5")
    _cli("solve", d / "vp.h5", "-m", "graph", "-q", "-o", d / "graph.h5")
    return d


@pytest.fixture(scope="module")
def team(tmp_path_factory):
    """The five-robot MRCLAM team excerpt solved jointly by graph SLAM."""
    d = tmp_path_factory.mktemp("team")
    _cli("import", "mrclam", DATA / "mrclam_team_excerpt", "--all-robots", "-o", d / "team.h5")
    _cli("solve", d / "team.h5", "-m", "graph", "-q", "-o", d / "graph.h5")
    return d


@pytest.fixture()
def captured(monkeypatch):
    """The figures that ``slamcli plot`` hands to save_figure."""
    import slamcli.plots as plots

    figs, real = [], plots.save_figure
    monkeypatch.setattr(plots, "save_figure", lambda fig, path, dpi=200: (figs.append(fig), real(fig, path, dpi))[1])
    return figs


def _contains(ax, xy):
    (x0, x1), (y0, y1) = sorted(ax.get_xlim()), sorted(ax.get_ylim())
    return x0 <= xy[:, 0].min() and xy[:, 0].max() <= x1 and y0 <= xy[:, 1].min() and xy[:, 1].max() <= y1


def _line(ax, label):
    return next(ln for ln in ax.lines if ln.get_label() == label)


@pytest.mark.slow
def test_victoria_park_map_shows_estimate_and_gps_with_small_markers(vp, tmp_path, captured):
    _cli("plot", "map", vp / "ekf.h5", "-q", "-o", tmp_path / "map.png")
    ax = captured[0].axes[0]
    res, ds = read_result(vp / "ekf.h5"), read_dataset(vp / "vp.h5")
    est = res.poses_xyt[:, :2]
    assert _contains(ax, np.percentile(est, ROBUST_PCT, axis=0))
    gps = _line(ax, "GPS reference")
    np.testing.assert_array_equal(gps.get_xydata(), ds.truth.ref_xy)
    assert _contains(ax, ds.truth.ref_xy)
    stars = _line(ax, "Estimated locations")
    n = len(res.landmarks_xy)
    assert n > 100 and stars.get_markersize() == landmark_marker_pt(n) < LANDMARK_PT_MAX
    assert texts_outside(captured[0]) == []


@pytest.mark.slow
def test_a_diverging_baseline_is_clipped_and_said(vp):
    """Odometry drifting 20× away from the estimate does not set the limits; the legend names the clipping."""
    from slamcli.plots.maps import plot_map

    res, ds = read_result(vp / "ekf.h5"), read_dataset(vp / "vp.h5")
    est = res.poses_xyt[:, :2]
    drift = est + 20.0 * (est - est[0]) + np.array([-240.0, 0.0])
    limits = []
    for odometry in (drift, None):
        fig, ax = new_figure(3.5, 3.6)
        plot_map(ax, None, res.landmarks_xy, None, odometry, est, ref_xy=ds.truth.ref_xy)
        fig.draw_without_rendering()
        limits.append(ax.dataLim.bounds)  # the view follows it, widened by the equal aspect
        notes = [t.get_text() for t in ax.get_legend().get_texts()]
        assert ("Odometry clipped" in notes) == (odometry is not None)
        assert _contains(ax, est) and not _contains(ax, drift)
    np.testing.assert_allclose(limits[0], limits[1])  # the baseline does not move the axes at all


@pytest.mark.slow
def test_mrclam_team_map_has_one_colour_per_robot(team, tmp_path, captured):
    _cli("plot", "map", team / "graph.h5", "-q", "-o", tmp_path / "team.png")
    ax = captured[0].axes[0]
    res, ds = read_result(team / "graph.h5"), read_dataset(team / "team.h5")
    robots = ds.inputs.robots
    colours = []
    for k, number in enumerate(robots.robot_number):
        line = _line(ax, f"Robot {int(number)}")
        np.testing.assert_array_equal(line.get_xydata(), res.poses_xyt[robots.pose_robot == k, :2])
        colours.append(line.get_color())
    assert len(set(colours)) == 5 and set(colours) <= set(style.CYCLE)
    assert style.EST_LANDMARK not in colours  # kept for the landmark stars
    assert _contains(ax, ds.truth.poses_xyt[:, :2]) and _contains(ax, res.poses_xyt[:, :2])
    assert texts_outside(captured[0]) == []


def test_overlay_of_two_solvers_one_colour_each(vp, tmp_path, captured):
    _cli("plot", "map", vp / "ekf.h5", vp / "graph.h5", "--label", "EKF", "--label", "Graph", "-q",
         "-o", tmp_path / "overlay.png")
    ax = captured[0].axes[0]
    ekf, graph = _line(ax, "EKF"), _line(ax, "Graph")
    np.testing.assert_array_equal(ekf.get_xydata(), read_result(vp / "ekf.h5").poses_xyt[:, :2])
    np.testing.assert_array_equal(graph.get_xydata(), read_result(vp / "graph.h5").poses_xyt[:, :2])
    assert ekf.get_color() != graph.get_color()
    assert "GPS reference" in [ln.get_label() for ln in ax.lines]
    assert texts_outside(captured[0]) == []
    r = runner.invoke(app, ["plot", "map", str(vp / "ekf.h5"), str(vp / "graph.h5"), "--label", "EKF", "-o",
                            str(tmp_path / "x.png")])
    assert r.exit_code == 1 and "give one per result" in r.output and "Traceback" not in r.output


def test_overlay_refuses_a_result_of_another_dataset(vp, team, tmp_path):
    r = runner.invoke(app, ["plot", "map", str(vp / "ekf.h5"), str(team / "graph.h5"), "-o", str(tmp_path / "x.png")])
    assert r.exit_code == 1 and "same dataset" in r.output and len(r.output.strip().splitlines()) == 1
    assert not (tmp_path / "x.png").exists()


def _sweep(d):
    """A results table grouped by solver and gate probability: eight long group names (the case whose tick
    labels collided at one column), ATE values spread over two decades."""
    from slamcli.metrics.aggregate import typed_frame

    rows, k = [], 0
    for solver, scale in (("ekf-ml", 1.0), ("fastslam-ml", 0.3)):
        for gate in (0.9, 0.95, 0.99, 0.999):
            for rep in range(3):
                rows.append({"run_id": f"r{k}", "label": solver, "method": solver.split("-")[0], "replicate": rep,
                             "status": "completed", "solver.gate_prob": gate,
                             "ate_rmse_m": scale * (0.05 + 5.0 * (1 - gate)) * (1 + 0.1 * rep)})
                k += 1
    d.mkdir(parents=True, exist_ok=True)
    typed_frame(rows).to_csv(d / "results.csv", index=False)


def _text_masks(fig, ax, texts):
    """Pixels (boolean image) of each text of ``texts`` alone, rendered by Agg with the layout frozen: an
    overlap test independent of any bounding-box geometry."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg

    canvas = FigureCanvasAgg(fig)
    canvas.draw()
    fig.set_layout_engine("none")  # keep the laid-out axes where they are while texts are hidden
    ax.xaxis.label.set_visible(False)  # it moves with the tick labels' extents
    shown = [t for t in texts if t.get_visible()]

    def render(visible):
        for t in texts:
            t.set_visible(t is visible)
        canvas.draw()
        return np.asarray(canvas.buffer_rgba())[..., :3].copy()

    base = render(None)
    return [np.any(render(t) != base, axis=-1) for t in shown]


def _label_masks(fig, ax):
    return _text_masks(fig, ax, ax.get_xticklabels())


@pytest.mark.parametrize("log", [False, True])
@pytest.mark.slow
def test_compare_tick_labels_do_not_touch_and_log_axis(tmp_path, captured, log):
    from slamcli.plots.curves import tick_labels_overlap

    _sweep(tmp_path / "exp")
    _cli("plot", "compare", tmp_path / "exp", "--by", "solver,gate_prob", *(["--log"] if log else []), "-q",
         "-o", tmp_path / "c.png")
    fig = captured[0]
    ax = fig.axes[0]
    assert ax.get_yscale() == ("log" if log else "linear")
    if log:  # plain decimal labels at 1-2-5 steps, no mathtext "6×10⁻¹" minor labels
        assert all(t.get_text() == "" for t in ax.yaxis.get_minorticklabels())
        values = [float(t.get_text()) for t in ax.get_yticklabels() if t.get_text()]
        lo, hi = ax.get_ylim()
        assert len([v for v in values if lo <= v <= hi]) >= 3
    assert texts_outside(fig) == []
    assert not tick_labels_overlap(ax)
    masks = _label_masks(fig, ax)
    assert len(masks) == 8 and all(m.any() for m in masks)
    assert not any(np.any(a & b) for a, b in zip(masks, masks[1:]))


@pytest.mark.slow
def test_tick_label_overlap_is_detected(tmp_path):
    """The measure is not vacuous: eight long upright labels on one column do overlap, in pixels too."""
    from slamcli.plots.curves import tick_labels_overlap

    fig, ax = new_figure(3.5, 2.6)
    ax.set_xticks(range(8), [f"fastslam-ml, gate_prob=0.9{k}" for k in range(8)])
    assert tick_labels_overlap(ax)
    masks = _label_masks(fig, ax)
    assert any(np.any(a & b) for a, b in zip(masks, masks[1:]))


def test_api_takes_one_axes_and_names_what_it_expects(vp):
    import matplotlib

    matplotlib.use("Agg", force=True)
    import matplotlib.pyplot as plt

    import slamcli as sc

    fig, axes = plt.subplots(1, 2)
    with pytest.raises(TypeError, match=r"slamcli.plot.map: ax must be one matplotlib Axes, got ndarray of 2"):
        sc.plot.map(str(vp / "ekf.h5"), ax=axes)
    with pytest.raises(TypeError, match=r"slamcli.plot.compare: ax must be one matplotlib Axes, got list"):
        sc.plot.compare(str(vp), ax=list(axes))
    ax = sc.plot.map([str(vp / "ekf.h5"), str(vp / "graph.h5")], ax=axes[0], labels=["EKF", "Graph"])
    assert ax is axes[0] and {"EKF", "Graph"} <= {ln.get_label() for ln in ax.lines}
    plt.close(fig)


def test_api_pose_errors_fill_one_axes_with_three_panels():
    """A result without an iteration trace: its x, y, θ error panels take the slot of the one Axes given."""
    import dataclasses

    import matplotlib

    matplotlib.use("Agg", force=True)
    import matplotlib.pyplot as plt
    from conftest import make_dataset, make_result

    import slamcli as sc

    ds = make_dataset()
    res = dataclasses.replace(make_result(ds, "unused.h5"), trace=None)
    fig, (left, right) = plt.subplots(1, 2, layout="constrained")
    axes = sc.plot.errors(res, ds, ax=right)
    assert len(axes) == 3 and right not in fig.axes and left in fig.axes
    assert all(a.get_position().x0 >= left.get_position().x1 for a in axes)  # in the right-hand slot
    np.testing.assert_allclose(axes[0].lines[0].get_ydata(), res.poses_xyt[:, 0] - ds.truth.poses_xyt[:, 0])
    with pytest.raises(TypeError, match=r"slamcli.plot.errors: ax must be one matplotlib Axes .* or a sequence of 3"):
        sc.plot.errors(res, ds, ax=[left])
    plt.close(fig)


def test_hybrid_map_limits_follow_the_observed_grid_not_the_odometry():
    """A 40 × 60 grid of 0.5 m cells at (-10, -5) observed only in rows 4..9, columns 10..29: corners by hand
    (x: -10 + 10·0.5 = -5 to -10 + 30·0.5 = 5; y: -5 + 4·0.5 = -3 to -5 + 10·0.5 = 0); odometry drifting to
    -240 m leaves the limits alone."""
    from types import SimpleNamespace

    from slamcli.plots.grids import draw_grid, observed_corners_xy
    from slamcli.plots.maps import plot_map

    observed = np.zeros((40, 60), np.int32)
    observed[4:10, 10:30] = 3
    grid = SimpleNamespace(prob=np.full((40, 60), 0.5), origin_xy=(-10.0, -5.0), resolution=0.5, observed=observed,
                           snapshots=None)
    corners = observed_corners_xy(grid)
    np.testing.assert_allclose(corners, [[-5.0, -3.0], [5.0, 0.0]])
    path = np.column_stack([np.linspace(-4, 4, 30), np.full(30, -1.5)])
    drift = np.column_stack([np.linspace(-4, 60, 30), np.linspace(-1.5, -240, 30)])
    fig, ax = new_figure(3.5, 3.6)
    draw_grid(ax, grid, label="frequentist grid", colorbar=True)
    plot_map(ax, None, None, None, drift, path, extent_xy=corners)
    fig.draw_without_rendering()
    assert _contains(ax, corners) and not _contains(ax, drift)
    assert max(np.ptp(ax.get_xlim()), np.ptp(ax.get_ylim())) < 3 * np.ptp(corners[:, 0])
    assert texts_outside(fig) == []


def test_nees_log_axis_keeps_every_value_and_names_one_run():
    from slamcli.plots.curves import plot_nees
    from slamcli.plots.figures import nees_title

    anees = np.r_[np.full(98, 3.0), 1e-4, 800.0]  # one near-zero step, one far above the band
    fig, ax = new_figure(3.5, 2.6)
    plot_nees(ax, np.arange(100), anees, 0.22, 9.35, 3, 1, title=nees_title(1))
    lo, hi = ax.get_ylim()
    assert lo < anees.min() and anees.max() < hi
    assert ax.get_title() == "Pose NEES of one run" and nees_title(50) == "Pose NEES over 50 runs"


@pytest.mark.slow
def test_ellipses_draw_above_the_markers_or_say_why_not(vp, team, tmp_path, captured):
    _cli("plot", "map", vp / "ekf.h5", "--ellipses", "-q", "-o", tmp_path / "e.png")
    ax = captured[0].axes[0]
    stars = _line(ax, "Estimated locations")
    assert len(ax.patches) == len(read_result(vp / "ekf.h5").landmarks_xy)
    assert all(p.get_zorder() > stars.get_zorder() for p in ax.patches)
    r = _cli("plot", "map", team / "graph.h5", "--ellipses", "-o", tmp_path / "t.png")
    assert "stores no covariances" in r.output


@pytest.mark.slow
def test_crowded_box_names_do_not_overlap():
    """Twenty pose boxes 0.1 m apart at one column: names that would touch are hidden, the rest are disjoint
    in rendered pixels."""
    from slamcli.plots.boxes import plot_boxes

    poses = np.column_stack([np.linspace(0, 2, 20), np.zeros(20), np.zeros(20)])
    w = np.array([0.04, 0.04, 0.05])
    fig, ax = new_figure(3.5, 3.6)
    plot_boxes(ax, poses - w, poses + w, np.array([[1.0, 1.0]]), np.array([[1.3, 1.2]]), wedge_radius=0.2)
    names = [t for t in ax.texts if t.get_text()[:1] in "rl"]
    shown = [t for t in names if t.get_visible()]
    assert shown[0].get_text() == "r1" and 1 < len(shown) < len(names)
    masks = _text_masks(fig, ax, names)
    assert len(masks) == len(shown) and all(m.any() for m in masks)
    assert not any(np.any(a & b) for i, a in enumerate(masks) for b in masks[i + 1:])
