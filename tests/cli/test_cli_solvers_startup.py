"""Fast start-up: ``slamcli solvers [NAME]`` imports no solver and no numerics (each solver's Params live in a
numpy-free params module, the same class the solver uses). The start-up *times* are measured in ``benchmarks/bench_scale.py``."""

from __future__ import annotations

import importlib
import json
import subprocess
import sys
import textwrap
from importlib import metadata

import pytest

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


#: the numpy-free modules ``slamcli solvers`` may import besides the params modules themselves
SCHEMA_SUPPORT = ("slamcli.solvers.lazy", "slamcli.solvers.icm.presets", "slamcli.solvers.graph",
                  "slamcli.solvers.isam", "slamcli.solvers.icm", "slamcli.solvers.hybrid", "slamcli.solvers.cuik")


@pytest.mark.slow
@pytest.mark.parametrize("args", [["solvers"], ["solvers", "icm"], ["solvers", "graph"], ["solvers", "fastslam"]])
def test_solvers_command_imports_no_solver_and_no_numerics(args):
    present = _modules_after(args)
    assert [m for m in present if not (m.endswith("params") or m in SCHEMA_SUPPORT)] == [], present


@pytest.mark.slow
def test_info_imports_no_solver_scipy_or_plotting(tmp_path):
    from conftest import tiny_dataset

    from slamcli.io import write_dataset

    path = write_dataset(tmp_path / "d.h5", tiny_dataset(T=5))
    # info reads HDF5 (h5py, numpy); it needs no scipy, pandas, matplotlib or solver
    assert _modules_after(["info", str(path)], heavy=("scipy", "pandas", "matplotlib")) == []


@pytest.mark.parametrize("name", registry.names())
def test_the_params_module_holds_the_class_the_solver_uses(name):
    assert registry.params_class(name) is registry.load(name).Params


PLUGIN_PARAMS = '''
from dataclasses import dataclass


@dataclass(frozen=True)
class ToyParams:
    k: int = 3


Params = ToyParams
'''

PLUGIN_SOLVER = '''
from .params import ToyParams


class ToySolver:
    Params = ToyParams

    def solve(self, inputs, *, init=None, rng, progress=None):
        raise NotImplementedError
'''

PLUGIN_WITHOUT_PARAMS_MODULE = '''
from dataclasses import dataclass


@dataclass(frozen=True)
class DynParams:
    k: int = 7


class DynSolver:
    Params = DynParams

    def solve(self, inputs, *, init=None, rng, progress=None):
        raise NotImplementedError
'''


def test_a_plugin_params_module_is_read_without_importing_the_solver(tmp_path, monkeypatch):
    pkg = tmp_path / "schemaplug"
    pkg.mkdir()
    (pkg / "__init__.py").write_text("")
    (pkg / "params.py").write_text(PLUGIN_PARAMS)
    (pkg / "solver.py").write_text(PLUGIN_SOLVER)
    (tmp_path / "dynplug.py").write_text(PLUGIN_WITHOUT_PARAMS_MODULE)
    monkeypatch.syspath_prepend(str(tmp_path))
    eps = {
        "toy": metadata.EntryPoint(name="toy", value="schemaplug.solver:ToySolver", group=registry.GROUP),
        "dyn": metadata.EntryPoint(name="dyn", value="dynplug:DynSolver", group=registry.GROUP),
    }
    monkeypatch.setattr(registry, "_entry_points", lambda: dict(eps))
    importlib.invalidate_caches()
    try:
        assert registry.params_module("schemaplug.solver:ToySolver") == "schemaplug.params"
        assert registry.describe("toy") == [("k", "int", "3")]
        assert "schemaplug.params" in sys.modules and "schemaplug.solver" not in sys.modules
        assert registry.describe("dyn") == [("k", "int", "7")]  # no dynplug_params: imported and asked
        assert "dynplug" in sys.modules
    finally:
        for m in [m for m in sys.modules if m.split(".")[0] in ("schemaplug", "dynplug")]:
            del sys.modules[m]
