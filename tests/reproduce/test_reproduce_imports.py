"""No module of ``slamcli/reproduce/`` solves: its runs go through the sweep engine (experiment files), and its
renderers read what the sweeps wrote.

The check reads each module's AST: every import (module level or inside a function, relative ones resolved)
and every call. A module breaks the rule when it imports ``slamcli.api.solve`` or a solver module (anything under
``slamcli.solvers`` but the read-only :data:`METADATA` modules), or calls a function or method named like a solve
(:data:`SOLVE_CALLS`).
"""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

import slamcli

REPRODUCE = Path(slamcli.__file__).resolve().parent / "reproduce"

#: solver-package modules a renderer may read: names and documentation, no solving
METADATA = {
    "slamcli.solvers.registry": "the registered solver names and whether one loads (the report's solver list)",
    "slamcli.solvers.icm.presets": "the documented expansion of an ICM preset, quoted in the real-data section",
}
#: calls that solve: the api's entry points and a solver object's method
SOLVE_CALLS = frozenset({"solve", "solve_dataset", "solve_file", "make_solver"})


def _imports(tree: ast.AST, module: str) -> list[str]:
    """Every module name ``tree`` imports; ``from pkg import name`` also yields ``pkg.name`` (it may be a
    submodule), relative imports resolved against ``module`` (``slamcli.reproduce.x``)."""
    out = []
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            out += [a.name for a in node.names]
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                parent = module.split(".")[: -node.level]
                base = ".".join(parent + ([base] if base else []))
            out.append(base)
            out += [f"{base}.{a.name}" for a in node.names]
    return out


def _called_names(tree: ast.AST) -> list[str]:
    out = []
    for node in ast.walk(tree):
        if isinstance(node, ast.Call):
            f = node.func
            out.append(f.attr if isinstance(f, ast.Attribute) else f.id if isinstance(f, ast.Name) else "")
    return out


def violations(source: str, module: str) -> list[str]:
    """What in ``source`` (the text of module ``module``) solves or imports a solver, one line each."""
    tree = ast.parse(source)
    bad = []
    for name in _imports(tree, module):
        parts = name.split(".")
        metadata = any(".".join(parts[:i]) in METADATA for i in range(1, len(parts) + 1))
        solver = name.startswith("slamcli.solvers.") and not metadata  # (the package itself: its __init__)
        if solver or name == "slamcli.api.solve" or name.startswith("slamcli.api.solve."):
            bad.append(f"imports {name}")
    bad += [f"calls {name}()" for name in _called_names(tree) if name in SOLVE_CALLS]
    return sorted(set(bad))


def _modules() -> list[Path]:
    return sorted(REPRODUCE.glob("*.py"))


def test_the_checker_sees_imports_and_calls_that_solve():
    src = ("import slamcli.solvers.ekf\nfrom slamcli.api.solve import solve_dataset\n"
           "from ..solvers import graph\nfrom slamcli.solvers.registry import names\n"
           "def f(x):\n    from slamcli.api import solve\n    return x.solve(1) + solve_dataset(x)\n")
    assert violations(src, "slamcli.reproduce.m") == [
        "calls solve()", "calls solve_dataset()", "imports slamcli.api.solve",
        "imports slamcli.api.solve.solve_dataset", "imports slamcli.solvers.ekf", "imports slamcli.solvers.graph"]
    clean = "from slamcli.solvers import registry\nfrom slamcli.sweep.runner import load_results\nload_results(1)\n"
    assert violations(clean, "slamcli.reproduce.m") == []


@pytest.mark.parametrize("path", _modules(), ids=lambda p: p.name)
def test_reproduce_module_does_not_solve(path):
    found = violations(path.read_text(encoding="utf-8"), f"slamcli.reproduce.{path.stem}")
    assert not found, f"{path.name}: " + "; ".join(found) + " (run it as an experiment; render from its files)"
