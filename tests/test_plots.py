"""Plot functions draw what they are given (and nothing else); the plot CLI writes PNG/PDF atomically."""

import numpy as np
import pytest
from test_cli_evaluate import make_dataset, make_result
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


def test_save_figure_formats_and_atomicity(tmp_path):
    fig, ax = new_figure()
    ax.plot([0, 1], [0, 1])
    png = save_figure(fig, tmp_path / "a.png")
    pdf = save_figure(fig, tmp_path / "sub" / "a.pdf")
    assert png.read_bytes()[:4] == b"\x89PNG" and pdf.read_bytes()[:4] == b"%PDF"
    with pytest.raises(ConfigError, match="png or .pdf"):
        save_figure(fig, tmp_path / "a.jpg")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a.png", "sub"]


@pytest.fixture()
def runs(tmp_path):
    paths = []
    for k in range(3):
        ds = make_dataset(seed=k)
        d = tmp_path / f"d{k}.h5"
        write_dataset(d, ds)
        r = tmp_path / f"r{k}.h5"
        write_result(r, make_result(ds, d, rng_seed=k))
        paths.append(r)
    return paths


@pytest.mark.parametrize("kind,ext", [("map", "png"), ("errors", "pdf"), ("mapchange", "png"), ("nees", "png")])
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
    r = runner.invoke(app, ["plot", "map", *map(str, runs), "-o", str(tmp_path / "x.png")])
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
