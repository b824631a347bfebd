"""Plot functions draw what they are given (and nothing else); the plot CLI writes PNG/PDF atomically."""

import numpy as np
import pytest
from conftest import DATA, make_dataset, make_result
from typer.testing import CliRunner

from slamcli.cli import app
from slamcli.errors import ConfigError
from slamcli.io import write_dataset, write_result
from slamcli.plots import new_figure, save_figure
from slamcli.plots.curves import plot_error_curves, plot_map_change, plot_nees
from slamcli.plots.maps import covariance_ellipse, plot_map

runner = CliRunner()


def test_covariance_ellipse_geometry():
    w, h, a = covariance_ellipse(np.diag([4.0, 1.0]), n_sigma=2.0)
    assert (w, h) == pytest.approx((8.0, 4.0))
    assert np.isclose(np.mod(a, 180.0), 0.0) or np.isclose(np.mod(a, 180.0), 180.0)
    # major axis along the 45° diagonal
    R = np.array([[1, -1], [1, 1]]) / np.sqrt(2)
    w, h, a = covariance_ellipse(R @ np.diag([9.0, 1.0]) @ R.T, n_sigma=1.0)
    assert (w, h) == pytest.approx((6.0, 2.0))
    assert np.mod(a, 180.0) == pytest.approx(45.0)


def test_plot_map_draws_given_arrays():
    _fig, ax = new_figure()
    true_lm = np.array([[0.0, 0.0], [1.0, 1.0]])
    est_lm = np.array([[0.1, 0.0], [1.0, 1.1], [3.0, 3.0]])
    path = np.column_stack([np.linspace(0, 3, 10), np.zeros(10)])
    plot_map(ax, true_lm, est_lm, path, path + 0.1, path - 0.1, landmark_cov=np.stack([np.eye(2) * 0.01] * 3))
    labels = [t.get_text() for t in ax.get_legend().get_texts()]
    assert labels[:5] == ["True trajectory", "Odometry", "Estimated trajectory", "Real locations",
                          "Estimated locations"]
    est_line = next(ln for ln in ax.lines if ln.get_label() == "Estimated locations")
    np.testing.assert_array_equal(est_line.get_xydata(), est_lm)
    assert len(ax.patches) == 3
    assert ax.get_xlabel() == "x (m)" and ax.get_ylabel() == "y (m)"


def test_curves_draw_given_arrays():
    _, ax = new_figure()
    it = np.arange(4)
    plot_error_curves(ax, it, [0.1, 0.05, 0.02, 0.01], [0.5, 0.3, 0.2, 0.1], [2.0, 1.0, 0.5, 0.3])
    np.testing.assert_array_equal(ax.lines[1].get_ydata(), [0.5, 0.3, 0.2, 0.1])
    assert "(m)" in ax.get_ylabel()
    _, ax = new_figure()
    plot_map_change(ax, it, [0.0, 0.03, 0.01, 0.002])
    np.testing.assert_allclose(ax.lines[0].get_ydata(), [30.0, 10.0, 2.0])  # iteration 0 dropped, in mm
    _fig, ax = new_figure()
    plot_nees(ax, np.arange(3), [3.0, 2.9, 5.0], 2.36, 3.72, 3, 50, fraction_inside=2 / 3)
    assert any("67% of steps inside" in t.get_text() for t in ax.get_legend().get_texts())


@pytest.mark.slow
def test_save_figure_formats_and_atomicity(tmp_path):
    fig, ax = new_figure()
    ax.plot([0, 1], [0, 1])
    png = save_figure(fig, tmp_path / "a.png")
    pdf = save_figure(fig, tmp_path / "sub" / "a.pdf")
    assert png.read_bytes()[:4] == b"\x89PNG" and pdf.read_bytes()[:4] == b"%PDF"
    with pytest.raises(ConfigError, match="png, .pdf or .svg"):
        save_figure(fig, tmp_path / "a.jpg")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a.png", "sub"]


def make_runs(tmp_path, n=3):
    """``n`` toy result files (with covariances and an iteration trace) of ``n`` toy datasets."""
    paths = []
    for k in range(n):
        ds = make_dataset(seed=k)
        d = tmp_path / f"d{k}.h5"
        write_dataset(d, ds)
        r = tmp_path / f"r{k}.h5"
        write_result(r, make_result(ds, d, rng_seed=k))
        paths.append(r)
    return paths


@pytest.fixture()
def runs(tmp_path):
    return make_runs(tmp_path)


@pytest.mark.parametrize("kind,ext", [("map", "png"), ("errors", "pdf"), ("mapchange", "png"), ("nees", "png")])
@pytest.mark.slow
def test_plot_cli_kinds(runs, tmp_path, kind, ext):
    out = tmp_path / f"{kind}.{ext}"
    args = ["plot", kind, *(map(str, runs) if kind in ("nees", "mapchange") else [str(runs[0])]), "-o", str(out)]
    if kind == "map":
        args.append("--ellipses")
    r = runner.invoke(app, args)
    assert r.exit_code == 0, r.output
    assert out.stat().st_size > 1000


def test_plot_cli_errors(runs, tmp_path):
    r = runner.invoke(app, ["plot", "bogus", str(runs[0]), "-o", str(tmp_path / "x.png")])
    assert r.exit_code == 1 and "unknown plot kind" in r.output
    r = runner.invoke(app, ["plot", "errors", *map(str, runs), "-o", str(tmp_path / "x.png")])
    assert r.exit_code == 1 and "exactly one" in r.output
    # NEES from results without covariances: "not available", no image
    ds = make_dataset()
    d = tmp_path / "nc.h5"
    write_dataset(d, ds)
    nc = tmp_path / "nc_res.h5"
    write_result(nc, make_result(ds, d, covariances=False))
    r = runner.invoke(app, ["plot", "nees", str(runs[0]), str(nc), "-o", str(tmp_path / "n.png")])
    assert r.exit_code == 1 and "not available" in r.output
    assert not (tmp_path / "n.png").exists() and not (tmp_path / "x.png").exists()


def test_plot_map_legend_without_ground_truth():
    _fig, ax = new_figure()
    path = np.column_stack([np.linspace(0, 3, 10), np.zeros(10)])
    plot_map(ax, None, np.array([[1.0, 1.0]]), None, path + 0.1, path, legend_note="No ground truth in dataset")
    labels = [t.get_text() for t in ax.get_legend().get_texts()]
    assert labels == ["Odometry", "Estimated trajectory", "Estimated locations", "Start", "End",
                      "No ground truth in dataset"]
    # start and end markers at the estimate's first and last pose
    lines = {ln.get_label(): ln for ln in ax.lines}
    np.testing.assert_array_equal(lines["Start"].get_xydata(), path[:1])
    np.testing.assert_array_equal(lines["End"].get_xydata(), path[-1:])


@pytest.fixture()
def truthless(tmp_path):
    """The DLR excerpt imported from g2o (no ground truth) and solved by the graph solver, via the CLI."""

    g2o = DATA / "dlr_excerpt.g2o"
    data, res = tmp_path / "dlr.h5", tmp_path / "dlr_graph.h5"
    r = runner.invoke(app, ["import", "g2o", str(g2o), "-q", "-o", str(data)])
    assert r.exit_code == 0, r.output
    r = runner.invoke(app, ["solve", str(data), "--method", "graph", "-q", "-o", str(res)])
    assert r.exit_code == 0, r.output
    return data, res


@pytest.mark.slow
def test_plot_map_without_ground_truth_draws_estimate_and_odometry(truthless, tmp_path):
    from slamcli.cli.plot_cmd import _map
    from slamcli.io import read_dataset, read_result

    data, res_path = truthless
    ds, res = read_dataset(data), read_result(res_path)
    assert ds.truth is None
    out = tmp_path / "map.png"
    r = runner.invoke(app, ["plot", "map", str(res_path), "--ellipses", "-o", str(out)])
    assert r.exit_code == 0, r.output
    assert out.read_bytes()[:4] == b"\x89PNG" and out.stat().st_size > 1000
    assert f"{data} has no ground truth; drew the estimate and odometry only" in r.stdout
    # what the command draws: estimate and odometry from the files, no truth, and the legend says so
    _fig, ax = new_figure()
    _map(ax, res_path, None, True, False, 0, None)
    lines = {ln.get_label(): ln for ln in ax.lines}
    labels = [t.get_text() for t in ax.get_legend().get_texts()]
    assert labels == ["Odometry", "Estimated trajectory", "Estimated locations", "Start", "End",
                      "No ground truth in dataset"]
    np.testing.assert_array_equal(lines["Estimated trajectory"].get_xydata(), res.poses_xyt[:, :2])
    np.testing.assert_array_equal(lines["Odometry"].get_xydata(), ds.inputs.odometry_xyt[:, :2])
    np.testing.assert_array_equal(lines["Estimated locations"].get_xydata(), res.landmarks_xy)


@pytest.mark.slow
def test_truth_metrics_on_a_truthless_dataset_are_one_line_errors(truthless, tmp_path):
    data, res_path = truthless
    for args in (["plot", "errors", str(res_path), "-o", str(tmp_path / "e.png")],
                 ["plot", "nees", str(res_path), "-o", str(tmp_path / "n.png")]):
        r = runner.invoke(app, args)
        lines = r.stderr.strip().splitlines()
        assert r.exit_code == 1 and len(lines) == 1, (args, r.output)
        assert lines[0].startswith("error: ") and str(data) in lines[0] and "no ground truth" in lines[0]
        assert "Traceback" not in r.output
    assert not (tmp_path / "e.png").exists() and not (tmp_path / "n.png").exists()
    # evaluate works without ground truth (issue 14): the solver's own metrics, and what is not available
    r = runner.invoke(app, ["evaluate", str(res_path), "-o", str(tmp_path / "ev")])
    assert r.exit_code == 0 and "not available without ground truth" in r.stdout, r.output
