"""Start-up of a default graph solve (issue 25 item 1): what it imports, and the CLI building only the command it
runs (:func:`slamcli.cli.app_for`). Times are measured in ``benchmarks/bench_graph_startup.py``, not here."""

from __future__ import annotations

import json
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest
from typer.testing import CliRunner

from slamcli.cli import app, app_for

DATA = Path(__file__).parent / "data"
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


def _modules_after(code: str) -> list[str]:
    """Modules of :data:`NOT_ON_SOLVE_PATH` / :data:`OTHER_SOLVERS` present after ``code`` ran in a fresh
    interpreter (also whether CHOLMOD is there: without it the solve needs scipy.sparse.linalg's SuperLU)."""
    probe = textwrap.dedent(f"""
        import json, sys
        watched = {NOT_ON_SOLVE_PATH + OTHER_SOLVERS + ("rich", "scipy.sparse.linalg", "sksparse")!r}
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
    if "sksparse" in present:  # CHOLMOD factorises; SciPy's SuperLU (scipy.sparse.linalg) is the fallback only
        assert "scipy.sparse.linalg" not in present, present


def test_default_graph_solve_through_the_cli_imports_only_what_it_uses(pose_graph, tmp_path):
    out = tmp_path / "r.h5"
    present = _modules_after(f"""
        import sys
        from slamcli.cli import main
        sys.argv = ["slamcli", "solve", {str(pose_graph)!r}, "--method", "graph", "-q", "-o", {str(out)!r}]
        try:
            main()
        except SystemExit as exc:
            assert not exc.code, exc.code
    """)
    assert out.exists()
    _check_solve_path(present)
    assert "rich" not in present  # -q prints nothing


def test_default_graph_solve_through_the_api_imports_only_what_it_uses(pose_graph, tmp_path):
    out = tmp_path / "r.h5"
    present = _modules_after(f"""
        from slamcli.api.solve import solve_file
        solve_file({str(pose_graph)!r}, "graph", None, {str(out)!r})
    """)
    assert out.exists()
    _check_solve_path(present)
