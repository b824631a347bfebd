"""Fast start-up (issue 17): ``slamcli solvers`` imports no solver and no numerics; the static Params reader
agrees with the imported dataclasses. The start-up *times* are measured in ``benchmarks/bench_scale.py``."""

from __future__ import annotations

import json
import subprocess
import sys
import textwrap
from importlib import metadata

import pytest

from slamcli.params import describe_params
from slamcli.solvers import registry

HEAVY = ("numpy", "scipy", "h5py", "pandas", "matplotlib")


def _modules_after(cli_args: list[str], heavy: tuple[str, ...] = HEAVY) -> list[str]:
    """Heavy modules and solver modules present after running ``slamcli ARGS`` in a fresh interpreter."""
    code = textwrap.dedent(f"""
        import json, sys
        from typer.testing import CliRunner
        from slamcli.cli import app
        res = CliRunner().invoke(app, {cli_args!r}, terminal_width=300)
        assert res.exit_code == 0, res.output
        print(json.dumps(sorted(m for m in sys.modules if m.split(".")[0] in {heavy!r}
                                or (m.startswith("slamcli.solvers.") and m != "slamcli.solvers.registry"))))
    """)
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr
    return json.loads(out.stdout.strip().splitlines()[-1])


@pytest.mark.slow
def test_solvers_command_imports_no_solver_and_no_numerics():
    # the listing; ``slamcli solvers NAME`` imports that one solver to document its Params docstring
    assert _modules_after(["solvers"]) == []


@pytest.mark.slow
def test_info_imports_no_solver_scipy_or_plotting(tmp_path):
    from conftest import tiny_dataset

    from slamcli.io import write_dataset

    path = write_dataset(tmp_path / "d.h5", tiny_dataset(T=5))
    # info reads HDF5 (h5py, numpy); it needs no scipy, pandas, matplotlib or solver
    assert _modules_after(["info", str(path)], heavy=("scipy", "pandas", "matplotlib")) == []


@pytest.mark.parametrize("name", registry.names())
def test_static_params_equal_the_imported_dataclass(name):
    static = registry.describe_static(name)
    real = describe_params(registry.load(name).Params)
    assert [(f, d) for f, _t, d in static] == [(f, d) for f, _t, d in real]


PLUGIN_PARAMS = '''
import dataclasses
import math
from dataclasses import dataclass, field


@dataclass(frozen=True)
class ToyParams:
    """Fields in the forms the static reader folds."""

    angle: float = 2 * math.pi
    neg: int = -3
    pair: tuple[float, float] = field(default_factory=lambda: (1.0, 0.5))
    name: str = "a"
    limit: float = float("inf")
    anything: float | None = None
'''

PLUGIN_SOLVER = '''
import dataclasses
import functools
from .params import ToyParams as _P


def _seven():
    return 7


@functools.lru_cache(
    maxsize=None,
)
def _layout(
    a,
) -> str:
    text = """
a column-0 line inside a function: the function cut falls back to parsing the whole module
"""
    return text


@dataclasses.dataclass(frozen=True)
class DynParams:
    k: int = _seven()       # a call: the static reader must not guess, the registry imports instead


class ToySolver:
    Params = _P

    def solve(self, inputs, *, init=None, rng, progress=None):
        raise NotImplementedError


class DynSolver:
    Params = DynParams

    def solve(self, inputs, *, init=None, rng, progress=None):
        raise NotImplementedError
'''


def test_static_reader_follows_imports_folds_constants_and_falls_back(tmp_path, monkeypatch):
    pkg = tmp_path / "toyplug"
    pkg.mkdir()
    (pkg / "__init__.py").write_text("from .solver import *  # noqa: F403\n")
    (pkg / "params.py").write_text(PLUGIN_PARAMS)
    (pkg / "solver.py").write_text(PLUGIN_SOLVER)
    monkeypatch.syspath_prepend(str(tmp_path))
    eps = {
        "toy": metadata.EntryPoint(name="toy", value="toyplug:ToySolver", group=registry.GROUP),
        "dyn": metadata.EntryPoint(name="dyn", value="toyplug.solver:DynSolver", group=registry.GROUP),
    }
    monkeypatch.setattr(registry, "_entry_points", lambda: dict(eps))
    registry._module_source.cache_clear()
    try:
        static = registry.describe_static("toy")
        assert "toyplug" not in sys.modules  # read from source, not imported
        assert static == [
            ("angle", "float", "6.283185307179586"),
            ("neg", "int", "-3"),
            ("pair", "tuple[float, float]", "(1.0, 0.5)"),
            ("name", "str", "a"),
            ("limit", "float", "inf"),
            ("anything", "float | None", "None"),
        ]
        with pytest.raises(registry._NotStatic):
            registry.describe_static("dyn")
        assert registry.describe("dyn") == [("k", "int", "7")]  # fallback: imported and asked
        assert "toyplug" in sys.modules
    finally:
        registry._module_source.cache_clear()
        for m in [m for m in sys.modules if m.split(".")[0] == "toyplug"]:
            del sys.modules[m]
