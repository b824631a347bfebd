"""Every arrow points down: no import cycle and no import from a higher layer, at module level or inside a
function body (issue 21).

The checker reads each module's imports from its AST (``import a.b``, ``from a import b``, ``from . import b``,
``from ..x import y``, wherever they stand: module level, function bodies, ``if TYPE_CHECKING:`` blocks) and
builds the graph of slamcli modules. An import ``from slamcli.pkg import name`` counts as an edge to the
submodule ``slamcli.pkg.name`` when that submodule exists, and to the package ``slamcli.pkg`` otherwise. A
package's ``__init__`` is a module like any other: ``from slamcli.sim import X`` inside ``slamcli.sim.bounded``
is an edge to ``slamcli.sim``, a cycle if that ``__init__`` imports ``bounded``. The package ``__init__`` that
Python runs before any submodule is not an edge the importer wrote, so it is not counted.

Layers (rank: packages, top-level modules or, as an exception, one module; the longest matching name wins).
Lower ranks are imported by higher ones, never the reverse; modules of the same rank may import each other, but
not in a cycle:

====  ==================================================================================================
rank  members
====  ==================================================================================================
0     ``slamcli`` (the package ``__init__``, version only), ``errors``, ``types``, ``params``, ``numerics``,
      ``progress`` (plain progress lines for logs, standard library only),
      ``models.angles`` (the one angle-wrap helper, numpy only; ``types`` wraps bearings with it),
      ``experiments`` (package data: the TOML files and a function returning their folder)
1     ``models``
2     ``sim``, ``solvers``
3     ``io``, ``datasets``, ``metrics``
4     ``plots``
5     ``api``
6     ``sweep``
7     ``reproduce``
8     ``cli``, ``__main__``
====  ==================================================================================================

``io`` sits above ``sim`` and ``solvers`` because it writes their dataset and result types (the types
themselves live in rank 0, so in practice io imports only base modules and models); ``datasets`` (the
importers) write through io and so sit beside it; ``metrics`` reads results beside io.
"""

from __future__ import annotations

import ast
from collections.abc import Iterable
from pathlib import Path

import pytest

import slamcli

PACKAGE_ROOT = Path(slamcli.__file__).resolve().parent

RANKS: dict[str, int] = {
    "slamcli": 0,
    "errors": 0,
    "types": 0,
    "params": 0,
    "numerics": 0,
    "progress": 0,
    "models.angles": 0,
    "experiments": 0,
    "models": 1,
    "sim": 2,
    "solvers": 2,
    "io": 3,
    "datasets": 3,
    "metrics": 3,
    "plots": 4,
    "api": 5,
    "sweep": 6,
    "reproduce": 7,
    "cli": 8,
    "__main__": 8,
}


# ------------------------------------------------------------------------------------------------ the checker
def module_names(root: Path, top: str) -> dict[str, Path]:
    """``{dotted module name: file}`` of every ``.py`` file below ``root`` (the package directory of ``top``)."""
    out: dict[str, Path] = {}
    for path in sorted(root.rglob("*.py")):
        parts = list(path.relative_to(root).with_suffix("").parts)
        if parts[-1] == "__init__":
            parts = parts[:-1]
        out[".".join([top, *parts])] = path
    return out


def _resolve_relative(module: str, is_package: bool, level: int, name: str | None) -> str:
    """The absolute module named by ``from <level dots><name> import ...`` inside ``module``."""
    base = module.split(".") if is_package else module.split(".")[:-1]
    if level > 1:
        base = base[: len(base) - (level - 1)]
    return ".".join([*base, name] if name else base)


def imported_modules(source: str, module: str, is_package: bool, known: Iterable[str]) -> set[tuple[str, int]]:
    """``{(imported module, line)}``: every import statement anywhere in ``source`` (any nesting), resolved to
    the longest known module name it names."""
    known = set(known)
    out: set[tuple[str, int]] = set()

    def longest_known(dotted: str) -> str | None:
        parts = dotted.split(".")
        for k in range(len(parts), 0, -1):
            cand = ".".join(parts[:k])
            if cand in known:
                return cand
        return None

    for node in ast.walk(ast.parse(source)):
        if isinstance(node, ast.Import):
            for alias in node.names:
                target = longest_known(alias.name)
                if target:
                    out.add((target, node.lineno))
        elif isinstance(node, ast.ImportFrom):
            base = (_resolve_relative(module, is_package, node.level, node.module) if node.level
                    else node.module or "")
            for alias in node.names:
                target = longest_known(f"{base}.{alias.name}") or longest_known(base)
                if target:
                    out.add((target, node.lineno))
    return out


def import_graph(root: Path, top: str) -> dict[str, dict[str, int]]:
    """``{module: {imported module: first line}}`` over the package tree at ``root`` (self-edges left out)."""
    mods = module_names(root, top)
    graph: dict[str, dict[str, int]] = {}
    for mod, path in mods.items():
        is_pkg = path.name == "__init__.py"
        edges: dict[str, int] = {}
        for target, line in sorted(imported_modules(path.read_text(), mod, is_pkg, mods), key=lambda e: e[1]):
            if target == mod:
                continue
            edges.setdefault(target, line)
        graph[mod] = edges
    return graph


def find_cycles(graph: dict[str, dict[str, int]]) -> list[list[str]]:
    """The non-trivial strongly connected components of ``graph`` (Tarjan), each as a sorted module list."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    out: list[list[str]] = []
    counter = 0

    def visit(v: str) -> None:  # recursion depth ≤ number of modules (~200)
        nonlocal counter
        index[v] = low[v] = counter
        counter += 1
        stack.append(v)
        on_stack.add(v)
        for w in graph.get(v, {}):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on_stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = []
            while True:
                w = stack.pop()
                on_stack.discard(w)
                comp.append(w)
                if w == v:
                    break
            if len(comp) > 1:
                out.append(sorted(comp))

    for v in sorted(graph):
        if v not in index:
            visit(v)
    return out


def layer_of(module: str, top: str, ranks: dict[str, int]) -> int:
    """The rank of the longest key of ``ranks`` that is a prefix of ``module`` (without ``top.``)."""
    parts = module.split(".")[1:]
    for k in range(len(parts), 0, -1):
        key = ".".join(parts[:k])
        if key in ranks:
            return ranks[key]
    if not parts:
        return ranks[top]
    raise KeyError(f"{module}: no layer rank; add its package to RANKS")


def upward_imports(graph: dict[str, dict[str, int]], top: str, ranks: dict[str, int]) -> list[str]:
    """``"a:line imports b"`` for every edge from a module to a module of a higher layer."""
    out = []
    for mod, edges in sorted(graph.items()):
        for target, line in sorted(edges.items()):
            if layer_of(target, top, ranks) > layer_of(mod, top, ranks):
                out.append(f"{mod}:{line} imports {target} "
                           f"(layer {layer_of(target, top, ranks)} > {layer_of(mod, top, ranks)})")
    return out


# ------------------------------------------------------------------------------------------------- the tests
@pytest.fixture(scope="module")
def graph() -> dict[str, dict[str, int]]:
    return import_graph(PACKAGE_ROOT, "slamcli")


@pytest.mark.slow
def test_every_package_has_a_rank(graph):
    assert graph, "no slamcli module found"
    unranked = []
    for mod in graph:
        try:
            layer_of(mod, "slamcli", RANKS)
        except KeyError:
            unranked.append(mod)
    assert unranked == []


def test_no_import_cycle(graph):
    assert find_cycles(graph) == []


def test_no_upward_import(graph):
    assert upward_imports(graph, "slamcli", RANKS) == []


def _first_line_with(module: str, text: str) -> int:
    lines = (PACKAGE_ROOT.parent / (module.replace(".", "/") + ".py")).read_text().splitlines()
    return next(i for i, ln in enumerate(lines, 1) if text in ln)


def test_checker_sees_function_level_imports_of_the_real_tree(graph):
    # located by plain text search, independently of the AST: imports inside function bodies
    assert graph["slamcli.sweep.runner"]["slamcli.api.simulate"] == _first_line_with(
        "slamcli.sweep.runner", "from slamcli.api.simulate import")
    assert graph["slamcli.sim.simulate"]["slamcli.sim.wallworld"] == _first_line_with(
        "slamcli.sim.simulate", "from slamcli.sim.wallworld import")


def _write_tree(root: Path, files: dict[str, str]) -> None:
    for rel, text in files.items():
        p = root / rel
        p.parent.mkdir(parents=True, exist_ok=True)
        p.write_text(text)


def test_planted_violations_are_flagged(tmp_path):
    """A synthetic package: ``low.a`` imports ``high`` inside a function body (upward), and ``low.b`` ↔
    ``low.c`` import each other, one of them relatively and inside a function (a hidden cycle)."""
    pkg = tmp_path / "pkg"
    _write_tree(pkg, {
        "__init__.py": "",
        "base.py": "X = 1\n",
        "low/__init__.py": "",
        "low/a.py": "from pkg.base import X\n\ndef f():\n    from pkg.high import g\n    return g\n",
        "low/b.py": "import pkg.low.c\n",
        "low/c.py": "def h():\n    from . import b\n    return b\n",
        "high.py": "from pkg.low.a import f\n\ndef g():\n    return f\n",
    })
    ranks = {"pkg": 0, "base": 0, "low": 1, "high": 2}
    g = import_graph(pkg, "pkg")
    assert g["pkg.low.a"] == {"pkg.base": 1, "pkg.high": 4}
    assert g["pkg.low.c"] == {"pkg.low.b": 2}
    assert find_cycles(g) == [["pkg.high", "pkg.low.a"], ["pkg.low.b", "pkg.low.c"]]
    assert upward_imports(g, "pkg", ranks) == ["pkg.low.a:4 imports pkg.high (layer 2 > 1)"]


def test_clean_synthetic_tree_passes(tmp_path):
    pkg = tmp_path / "pkg"
    _write_tree(pkg, {
        "__init__.py": "",
        "base.py": "X = 1\n",
        "low/__init__.py": "from .a import f\n",
        "low/a.py": "from ..base import X\n\ndef f():\n    return X\n",
        "high.py": "def g():\n    from pkg.low import f\n    return f\n",
    })
    g = import_graph(pkg, "pkg")
    assert g["pkg.high"] == {"pkg.low": 2}
    assert find_cycles(g) == []
    assert upward_imports(g, "pkg", {"pkg": 0, "base": 0, "low": 1, "high": 2}) == []
