"""Start-up of a default graph solve (issue 25 item 1): what it imports, and the CLI building only the command it
runs (:func:`slamcli.cli.app_for`). Times are measured in ``benchmarks/bench_graph_startup.py``, not here."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest
from conftest import DATA, ROOT
from typer.testing import CliRunner

from slamcli.cli import app, app_for
from slamcli.errors import PluginError
from slamcli.solvers import nls

#: never needed to solve a pose graph with defaults: tables, plots, statistics, the JIT, the metrics
NOT_ON_SOLVE_PATH = ("pandas", "matplotlib", "scipy.stats", "scipy.special", "scipy.optimize", "numba",
                     "slamcli.metrics", "slamcli.sim", "slamcli.sweep", "slamcli.plots", "dask")
#: the other solvers' modules
OTHER_SOLVERS = ("slamcli.solvers.ekf", "slamcli.solvers.fastslam", "slamcli.solvers.icm", "slamcli.solvers.isam",
                 "slamcli.solvers.hybrid", "slamcli.solvers.cuik", "slamcli.solvers.odometry")


def _names() -> list[str]:
    return [c.name for c in app.registered_commands] + [g.name for g in app.registered_groups]


def _run(typer_app, argv: list[str]):
    res = CliRunner().invoke(typer_app, argv, terminal_width=200)
    return res.exit_code, res.output


def test_every_command_is_registered_by_name():
    # app_for matches on the registered name: a command registered without one would never be narrowed
    assert all(isinstance(n, str) and n for n in _names())
    assert {"solve", "import", "sweep", "evaluate"} <= set(_names())


@pytest.mark.parametrize("argv", [[], ["--version"], ["--help"], ["solv"], ["-q", "solve"], ["nosuch", "x"]])
def test_anything_but_a_command_name_first_runs_the_whole_app(argv):
    assert app_for(argv) is app


@pytest.mark.parametrize("name", _names())
@pytest.mark.slow
def test_narrowed_app_helps_and_fails_like_the_whole_app(name):
    narrow = app_for([name, "--help"])
    assert [c.name for c in narrow.registered_commands] + [g.name for g in narrow.registered_groups] == [name]
    assert len(app.registered_commands) + len(app.registered_groups) == len(_names())  # app itself untouched
    groups = {g.name for g in app.registered_groups}
    # a group alone prints its help; a command alone would run (``reproduce`` runs every experiment)
    for argv in ([name, "--help"], [name, "--no-such-option"], *([[name]] if name in groups else [])):
        assert _run(narrow, argv) == _run(app, argv), argv


def test_narrowed_app_runs_a_command_like_the_whole_app(tmp_path):
    argv = ["import", "g2o", str(DATA / "intel_excerpt.g2o"), "-q"]
    code_a, _ = _run(app_for(argv), [*argv, "-o", str(tmp_path / "a.h5")])
    code_b, _ = _run(app, [*argv, "-o", str(tmp_path / "b.h5")])
    assert code_a == code_b == 0
    argv = ["info", str(tmp_path / "a.h5")]
    assert _run(app_for(argv), argv) == _run(app, argv)


#: watched besides: the entry-point scan of the solver registry (``"<entry points scanned>"`` when it ran)
#: the sparse linear algebra a solve may need: CHOLMOD, or SuperLU (and the dense LAPACK wrappers it imports)
SPARSE_PATHS = ("cvxopt.cholmod", "scipy.sparse.linalg", "scipy.linalg")
WATCHED = ("rich", *SPARSE_PATHS, "importlib.metadata", "<entry points scanned>",
           "<lazy modules>")
#: what numpy.f2py / numpy.testing / numpy.ma / numpy.polynomial import when they are executed (SciPy's
#: ``from numpy import *`` executes them unless :mod:`slamcli.api.startup` deferred them)
NUMPY_UNUSED_DEPENDENCIES = ("unittest", "numpy.f2py.crackfortran", "numpy.testing._private.utils", "numpy.ma.core",
                             "numpy.polynomial.polynomial")


def _modules_after(code: str) -> list[str]:
    """Modules of :data:`NOT_ON_SOLVE_PATH` / :data:`OTHER_SOLVERS` / :data:`WATCHED` present after ``code`` ran
    in a fresh interpreter (also whether CHOLMOD is there: without it the solve needs scipy.sparse.linalg's
    SuperLU), and of :data:`NUMPY_UNUSED_DEPENDENCIES`; ``"<lazy modules>"`` when a module in ``sys.modules``
    is still a lazily executed one or slamcli's finder waits in ``sys.meta_path``."""
    probe = textwrap.dedent(f"""
        import importlib.util, json, sys
        watched = {NOT_ON_SOLVE_PATH + OTHER_SOLVERS + WATCHED + NUMPY_UNUSED_DEPENDENCIES!r}
        reg = sys.modules.get("slamcli.solvers.registry")
        if reg is not None and reg._scan_entry_points.cache_info().currsize:
            sys.modules["<entry points scanned>"] = reg
        if (any(isinstance(m, importlib.util._LazyModule) for m in list(sys.modules.values()))
                or any(type(f).__module__ == "slamcli.api.startup" for f in sys.meta_path)):
            sys.modules["<lazy modules>"] = reg
        print(json.dumps(sorted(m for m in watched if m in sys.modules)))
    """)
    out = subprocess.run([sys.executable, "-c", textwrap.dedent(code) + probe], capture_output=True, text=True,
                         timeout=300)
    assert out.returncode == 0, out.stderr
    return json.loads(out.stdout.strip().splitlines()[-1])


@pytest.fixture(scope="module")
def pose_graph(tmp_path_factory) -> Path:
    ds = tmp_path_factory.mktemp("startup") / "g.h5"
    assert _run(app, ["import", "g2o", str(DATA / "intel_excerpt.g2o"), "-q", "-o", str(ds)])[0] == 0
    return ds


def _check_solve_path(present: list[str]) -> None:
    assert not set(present) & set(NOT_ON_SOLVE_PATH + OTHER_SOLVERS), present
    # what the installed linear solver needs: CHOLMOD factorises and selinv inverts its triangular blocks with
    # numpy, so neither SuperLU nor the dense LAPACK wrappers (≈ 220 M instructions) load; SuperLU without it
    if nls.cholmod_available():
        assert "cvxopt.cholmod" in present and not {"scipy.sparse.linalg", "scipy.linalg"} & set(present), present
    else:
        assert "scipy.sparse.linalg" in present, present


def _cli_solve(data: Path, method: str, out: Path) -> str:
    """Code running ``slamcli solve DATA --method METHOD -q -o OUT`` through the console script's ``main``, then
    checking that typer built one command (:func:`slamcli.cli.app_for`) and the collector threshold the command
    set (:func:`slamcli.cli.main`)."""
    return f"""
        import gc, sys
        import typer.main
        from slamcli.cli import GC_THRESHOLD0, main
        built = []
        _build = typer.main.get_command_from_info

        def counting(*args, **kw):
            built.append((args[0] if args else kw["command_info"]).name)
            return _build(*args, **kw)

        typer.main.get_command_from_info = counting
        sys.argv = ["slamcli", "solve", {str(data)!r}, "--method", {method!r}, "-q", "-o", {str(out)!r}]
        try:
            main()
        except SystemExit as exc:
            assert not exc.code, exc.code
        assert built == ["solve"], built
        assert gc.get_threshold()[0] >= GC_THRESHOLD0
    """


@pytest.mark.slow
def test_default_graph_solve_through_the_cli_imports_only_what_it_uses(pose_graph, tmp_path):
    out = tmp_path / "r.h5"
    present = _modules_after(_cli_solve(pose_graph, "graph", out))
    assert out.exists()
    _check_solve_path(present)
    assert "rich" not in present  # -q prints nothing
    # SciPy's ``from numpy import *`` bound numpy.f2py, numpy.testing, … without executing them
    assert not set(present) & set(NUMPY_UNUSED_DEPENDENCIES), present
    assert "<lazy modules>" in present


@pytest.mark.slow
def test_default_graph_solve_through_the_api_imports_only_what_it_uses(pose_graph, tmp_path):
    out = tmp_path / "r.h5"
    present = _modules_after(f"""
        import gc
        threshold = gc.get_threshold()
        from slamcli.api.solve import solve_file
        solve_file({str(pose_graph)!r}, "graph", None, {str(out)!r})
        assert gc.get_threshold() == threshold  # only the command-line entry point changes it
    """)
    assert out.exists()
    _check_solve_path(present)
    assert "<lazy modules>" not in present, present  # the library leaves sys.modules and sys.meta_path alone


@pytest.mark.parametrize("numpy_first", [False, True])
@pytest.mark.slow
def test_deferred_numpy_submodules_are_the_real_ones_on_first_use(numpy_first):
    # registered before NumPy is imported (the command line) or after (a sweep worker that imported numpy first);
    # the references are the modules' documented behaviour and NumPy's own files, not slamcli output
    present = _modules_after(f"""
        import os, sys
        {"import numpy" if numpy_first else "assert 'numpy' not in sys.modules"}
        from slamcli.api.startup import defer_unused_numpy_submodules
        defer_unused_numpy_submodules()
        assert ("numpy" in sys.modules) == {numpy_first}  # the finder imports nothing itself
        import scipy.sparse
        import numpy as np
        executed = [m for m in {NUMPY_UNUSED_DEPENDENCIES!r} if m in sys.modules]
        assert not executed, executed
        # first touch through a submodule that the package's __init__ imports too: one module, one class
        import numpy.ma.core as ma_core
        import numpy.polynomial.polynomial as poly
        assert ma_core is np.ma.core and ma_core.MaskedArray is np.ma.MaskedArray
        assert poly is np.polynomial.polynomial and poly.Polynomial is np.polynomial.Polynomial
        assert ma_core.__spec__.name == "numpy.ma.core" and ma_core.__spec__.origin == ma_core.__file__
        np.testing.assert_allclose([1.0, 2.0], [1.0, 2.0 + 1e-12])
        try:
            np.testing.assert_allclose([1.0], [1.1])
        except AssertionError:
            pass
        else:
            raise SystemExit("assert_allclose accepted 1.0 == 1.1")
        from numpy.testing import assert_array_equal
        import numpy.testing as nt
        assert nt is np.testing is sys.modules["numpy.testing"] and nt.assert_array_equal is assert_array_equal
        inc = np.f2py.get_include()
        assert inc == os.path.join(os.path.dirname(np.__file__), "f2py", "src"), inc
        assert os.path.isfile(os.path.join(inc, "fortranobject.h"))
        import numpy.f2py.crackfortran
        assert np.ma.masked_array([1, 2, 4], mask=[0, 1, 0]).sum() == 5
        assert np.polynomial.Polynomial([1, 2])(3) == 7
        assert np.char.upper("ab") == "AB" and np.rec.array([(1, 2.0)]).f0[0] == 1
    """)
    assert {"unittest", "numpy.f2py.crackfortran", "numpy.ma.core"} <= set(present)  # loaded on use
    assert "<lazy modules>" in present  # numpy.core, numpy.strings, numpy.ctypeslib: never touched


def test_help_through_main_imports_no_numpy():
    out = subprocess.run([sys.executable, "-c", textwrap.dedent("""
        import sys
        from slamcli.cli import main
        sys.argv = ["slamcli", "--help"]
        try:
            main()
        except SystemExit as exc:
            assert not exc.code, exc.code
        assert "numpy" not in sys.modules
    """)], capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr


@pytest.mark.slow
def test_built_in_solve_without_scipy_finds_the_solver_in_the_metadata(pose_graph, tmp_path):
    # odometry imports no SciPy, so nothing else brings importlib.metadata in: the registry (entry-point scan)
    # and the result's solver_version (importlib.metadata.version) would be the only ones
    out = tmp_path / "r.h5"
    present = _modules_after(_cli_solve(pose_graph, "odometry", out))
    assert out.exists()
    # the solver is found in the package metadata (the one table of solvers): one entry-point scan
    assert "<entry points scanned>" in present, present


def test_the_installed_entry_points_are_pyprojects():
    # the package metadata is the one table of solvers; pyproject.toml is the independent reference
    import tomllib
    from importlib import metadata

    from slamcli.solvers import registry

    declared = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"][
        "entry-points"][registry.GROUP]
    ours = {ep.name: ep.value for ep in metadata.entry_points(group=registry.GROUP) if ep.dist.name == "slamcli"}
    assert ours == declared
    assert {i.name: i.target for i in registry.available() if i.package == "slamcli"} == declared


PLUGIN = """
from dataclasses import dataclass

from slamcli.solvers.base import BaseSolver


@dataclass(frozen=True)
class ToyParams:
    k: int = 3


class ToySolver(BaseSolver):
    name = "toy"
    Params = ToyParams

    def solve(self, inputs, *, init=None, rng, progress=None):
        raise NotImplementedError
"""


def test_a_plugin_installed_with_entry_points_is_found_and_cannot_replace_a_built_in(tmp_path, monkeypatch):
    # a real distribution on sys.path (dist-info with entry_points.txt), not a patched registry
    from slamcli.solvers import registry
    from slamcli.solvers.base import _distribution_version

    (tmp_path / "toyplug").mkdir()
    (tmp_path / "toyplug" / "__init__.py").write_text(PLUGIN)
    info = tmp_path / "toyplug-2.5.dist-info"
    info.mkdir()
    (info / "METADATA").write_text("Metadata-Version: 2.1\nName: toyplug\nVersion: 2.5\n")
    (info / "entry_points.txt").write_text(
        f"[{registry.GROUP}]\ntoy = toyplug:ToySolver\ngraph = toyplug:ToySolver\n")
    monkeypatch.syspath_prepend(str(tmp_path))
    registry._scan_entry_points.cache_clear()
    _distribution_version.cache_clear()
    try:
        cls = registry.load("toy")
        assert cls.__module__ == "toyplug" and cls.Params().k == 3
        assert cls.version() == "2.5"  # the plug-in's distribution, read from its metadata
        assert registry.load("graph").__module__ == "slamcli.solvers.graph.solver"
        listed = {i.name: i for i in registry.available()}
        assert (listed["toy"].package, listed["toy"].version, listed["toy"].target) == (
            "toyplug", "2.5", "toyplug:ToySolver")
        assert listed["graph"].target == "slamcli.solvers.graph.solver:GraphSlam"
        assert registry.describe("toy") == [("k", "int", "3")]
        with pytest.raises(PluginError, match=r"unknown solver 'nope'; available solvers: .*graph.*toy"):
            registry.load("nope")
    finally:
        registry._scan_entry_points.cache_clear()
        _distribution_version.cache_clear()
        sys.modules.pop("toyplug", None)


def _unused_numpy_executed_after_scipy_sparse() -> list[str]:
    """Run in a sweep worker: which of :data:`NUMPY_UNUSED_DEPENDENCIES` ``import scipy.sparse`` executed."""
    import scipy.sparse  # noqa: F401

    return [m for m in NUMPY_UNUSED_DEPENDENCIES if m in sys.modules]


@pytest.mark.slow
def test_sweep_workers_defer_numpy_submodules_like_the_command():
    from slamcli.sweep.runner import LocalPool

    pool = LocalPool(1)
    try:
        assert pool.submit(_unused_numpy_executed_after_scipy_sparse).result(timeout=120) == []
    finally:
        pool.shutdown()


@pytest.mark.slow
@pytest.mark.parametrize("command", [["sweep", "--list"], ["reproduce", "--section", "nope"]])
def test_sweep_and_reproduce_pin_one_blas_thread_before_numpy_loads(command):
    """A sweep's runs compute with one BLAS thread in the command's own process (-j 1) as in its workers
    (-j N, Dask): the command sets the thread variables, a value the user exported wins, and the CLI has not
    loaded NumPy before the command runs (the variables are read when it loads)."""
    script = ("import os, sys\nfrom slamcli.cli import app\nbefore = 'numpy' in sys.modules\n"
              f"try:\n    app({command!r})\nexcept SystemExit:\n    pass\n"
              "print(before, os.environ.get('OPENBLAS_NUM_THREADS'), os.environ.get('OMP_NUM_THREADS'))")
    env = {k: v for k, v in os.environ.items() if k not in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS")}
    out = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, env=env, timeout=120)
    assert out.stdout.split()[-3:] == ["False", "1", "1"], out.stdout + out.stderr
    env["OMP_NUM_THREADS"] = "2"
    out = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, env=env, timeout=120)
    assert out.stdout.split()[-3:] == ["False", "1", "2"], out.stdout + out.stderr
