"""The notebook API `import slamcli as sc`: in memory and with files, same numbers as the CLI workflows."""

import subprocess
import sys

import numpy as np
import pytest

import slamcli as sc
from slamcli.errors import ConfigError, SlamcliError
from slamcli.io import dataset_hash, read_result
from slamcli.plots import new_figure
from slamcli.types import Dataset, SolverResult


@pytest.fixture(scope="module")
def mem():
    ds = sc.simulate("loop", seed=1, n_steps=120)
    r = sc.solve(ds, "icm", R=(1,))
    return ds, r


def test_import_is_lazy_and_cheap():
    code = "import sys, slamcli; assert 'numpy' not in sys.modules, 'numpy'; slamcli.solve; print('numpy' in sys.modules)"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    assert out.strip() == "True"  # loaded on first use, not at import
    assert set(sc.__all__) >= {"simulate", "solve", "evaluate", "plot", "export", "aggregate", "load"}
    with pytest.raises(AttributeError):
        sc.no_such_thing  # noqa: B018


def test_in_memory_round(mem):
    ds, r = mem
    assert isinstance(ds, Dataset) and isinstance(r, SolverResult)
    assert ds.inputs.n_poses == 121 and r.params["R"] == [1.0]
    assert r.dataset_hash == dataset_hash(ds)
    m = sc.evaluate(r, ds)
    # the ATE recomputed by hand from the arrays
    e = np.linalg.norm(r.poses_xyt[:, :2] - ds.truth.poses_xyt[:, :2], axis=1)
    assert m["ate_rmse_m"] == pytest.approx(np.sqrt(np.mean(e**2)), rel=1e-12)
    m2, ev = sc.evaluate(r, ds, tables=True)
    assert m2 == m and len(ev.per_step) == 121


def test_files_give_the_same_numbers(mem, tmp_path):
    ds, r = mem
    d = sc.simulate("loop", seed=1, n_steps=120, out=tmp_path / "loop.h5")
    assert dataset_hash(d) == dataset_hash(ds)  # same seed, same data, whether or not it is written
    rf = sc.solve(tmp_path / "loop.h5", "icm", R=(1,), out=tmp_path / "icm.h5")
    np.testing.assert_array_equal(rf.poses_xyt, r.poses_xyt)
    assert read_result(tmp_path / "icm.h5").extra["dataset_relpath"] == "loop.h5"
    m_file = sc.evaluate(tmp_path / "icm.h5")  # finds the recorded dataset
    m_mem = sc.evaluate(r, ds)
    assert m_file["ate_rmse_m"] == m_mem["ate_rmse_m"] and m_file["lm_ospa_m"] == m_mem["lm_ospa_m"]
    assert isinstance(sc.load(tmp_path / "icm.h5"), SolverResult)
    assert isinstance(sc.load(tmp_path / "loop.h5"), Dataset)
    sc.save(r, tmp_path / "mem.h5")
    np.testing.assert_array_equal(read_result(tmp_path / "mem.h5").landmarks_xy, r.landmarks_xy)
    # export from memory equals export from files
    sc.export(r, "tum", tmp_path / "a.tum", data=ds)
    sc.export(tmp_path / "icm.h5", "tum", tmp_path / "b.tum")
    assert (tmp_path / "a.tum").read_text() == (tmp_path / "b.tum").read_text()


def test_parameters_and_errors(mem):
    ds, _ = mem
    with pytest.raises(ConfigError, match="unknown parameter 'nope'"):
        sc.solve(ds, "ekf", nope=1)
    with pytest.raises(SlamcliError, match="unknown solver|not registered|available"):
        sc.solve(ds, "bogus")
    other = sc.simulate("loop", seed=2, n_steps=120)
    r = sc.solve(ds, "odometry")
    with pytest.raises(SlamcliError, match="another dataset"):
        sc.evaluate(r, other)
    assert "icm" in sc.solver_names() and "ekf" in sc.solver_names()


def test_plot_facade_draws_the_arrays(mem):
    ds, r = mem
    _, ax = new_figure()
    sc.plot.map(r, ds, ax=ax)
    est = [ln for ln in ax.lines if ln.get_label() == "Estimated trajectory"][0]
    np.testing.assert_array_equal(est.get_xydata(), r.poses_xyt[:, :2])
    _, ax = new_figure()
    sc.plot.mapchange([r], ax=ax)
    assert ax.get_yscale() == "log" and len(ax.lines[0].get_ydata()) > 0
    ekf = sc.solve(ds, "ekf")
    _, axes = new_figure(nrows=3)
    sc.plot.errors(ekf, ds, ax=axes)
    np.testing.assert_allclose(axes[0].lines[0].get_ydata(), ekf.poses_xyt[:, 0] - ds.truth.poses_xyt[:, 0])
