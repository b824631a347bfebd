"""Solver discovery through ``importlib.metadata.entry_points(group="slamcli.solvers")``.

Listing is cheap on purpose: :func:`available` reads entry-point metadata only, and :func:`describe` reads a
solver's ``Params`` dataclass *statically* — it parses the solver module's source with :mod:`ast` (located
with the import system's finders, executing nothing) and folds each field's default as a constant
expression — so ``slamcli solvers`` imports neither numpy nor scipy nor any solver (start-up budget 0.5 s,
issue 17; ``slamcli.solvers.nls`` alone takes ≈ 0.2-0.8 s to import). Whatever the static reader cannot
prove (a ``Params`` inherited or built at import time, a default computed by a function call, an enum
default) makes it fall back to importing the solver and asking the real dataclass, so the listing is never
guessed; ``tests/test_startup.py`` checks that both ways agree for every registered solver.
Running a solver (:func:`load`) always imports it.

The solvers slamcli ships (:data:`BUILTIN`) are resolved from that table: solving with one of them reads no
distribution's metadata. Scanning the entry points of every installed distribution (``importlib.metadata``,
≈ 5-15 ms CPU) happens only for a name that is not built in (a plug-in), for an error message that lists every
name, and for :func:`available`. A plug-in cannot replace a built-in name.
"""

from __future__ import annotations

import ast
import dataclasses
import functools
import importlib
import math
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

from slamcli.errors import PluginError

if TYPE_CHECKING:
    from importlib import metadata

GROUP = "slamcli.solvers"
#: slamcli's own solvers, ``name → "module:Class"``: the same table as ``[project.entry-points."slamcli.solvers"]``
#: in pyproject.toml (``tests/test_cli_startup.py`` checks the two agree on the installed distribution)
BUILTIN = {
    "odometry": "slamcli.solvers.odometry:OdometrySolver",
    "ekf": "slamcli.solvers.ekf:EkfSlam",
    "graph": "slamcli.solvers.graph.solver:GraphSlam",
    "isam": "slamcli.solvers.isam.solver:IsamSlam",
    "icm": "slamcli.solvers.icm.solver:IcmSlam",
    "fastslam": "slamcli.solvers.fastslam:FastSlam",
    "hybrid": "slamcli.solvers.hybrid:HybridSlam",
    "cuik": "slamcli.solvers.cuik:CuikSlam",
}


@dataclass(frozen=True)
class SolverInfo:
    name: str
    target: str  # "module:Class"
    package: str
    version: str


def _entry_points() -> dict[str, metadata.EntryPoint]:
    return dict(_scan_entry_points())


@functools.cache
def _scan_entry_points() -> tuple[tuple[str, metadata.EntryPoint], ...]:
    """The group's entry points, first of each name (scanning every installed distribution's metadata
    costs ≈ 10 ms, so it is done once per process)."""
    from importlib import metadata

    eps: dict[str, metadata.EntryPoint] = {}
    for ep in metadata.entry_points(group=GROUP):
        eps.setdefault(ep.name, ep)
    return tuple(eps.items())


def _targets() -> dict[str, str]:
    """``name → "module:Class"`` of every solver: the plug-ins' entry points, then :data:`BUILTIN` over them."""
    return {**{name: ep.value for name, ep in _entry_points().items()}, **BUILTIN}


def _listing() -> str:
    return ", ".join(sorted(_targets())) or "none"


def available() -> list[SolverInfo]:
    """Every registered solver, sorted by name (loading none of them)."""
    import slamcli

    eps = _entry_points()
    out = []
    for name, target in sorted(_targets().items()):
        if name in BUILTIN:
            package, version = "slamcli", slamcli.__version__
        else:
            dist = getattr(eps[name], "dist", None)
            package, version = (dist.name, dist.version) if dist is not None else ("?", "?")
        out.append(SolverInfo(name=name, target=target, package=package, version=version))
    return out


def names() -> list[str]:
    return [s.name for s in available()]


def _target(name: str) -> str | None:
    """``"module:Class"`` registered as ``name`` (a built-in without reading any metadata), or None."""
    if name in BUILTIN:
        return BUILTIN[name]
    ep = _entry_points().get(name)
    return None if ep is None else ep.value


def _load_target(target: str) -> type:
    """The object ``"module:attr.path"`` names (what ``EntryPoint.load`` does)."""
    modname, _, attr = target.partition(":")
    obj = importlib.import_module(modname.strip())
    for part in filter(None, attr.strip().split(".")):
        obj = getattr(obj, part)
    return obj


def load(name: str) -> type:
    """The solver class registered as ``name``; :class:`PluginError` lists the available names otherwise."""
    target = _target(name)
    if target is None:
        raise PluginError(f"unknown solver {name!r}; available solvers: {_listing()}")
    try:
        cls = _load_target(target)
    except Exception as exc:  # noqa: BLE001 - any import failure of a plugin is reported the same way
        first = (str(exc).strip().splitlines() or [""])[0]
        raise PluginError(
            f"solver plugin {name!r} ({target}) failed to load: {type(exc).__name__}: {first} "
            f"(available solvers: {_listing()})"
        ) from None
    params_cls = getattr(cls, "Params", None)
    if not (callable(getattr(cls, "solve", None)) and params_cls and dataclasses.is_dataclass(params_cls)):
        raise PluginError(
            f"solver plugin {name!r} ({target}) does not follow the solver contract "
            f"(needs a Params dataclass and a solve() method; available solvers: {_listing()})"
        )
    return cls


# --------------------------------------------------------------------------------------------------------
# static description of a solver's Params (no import of the solver)
# --------------------------------------------------------------------------------------------------------
class _NotStatic(Exception):
    """The source does not determine the answer without running code."""


_CONSTANTS = {"pi": math.pi, "tau": math.tau, "e": math.e, "inf": math.inf}
_BINOPS = {ast.Add: lambda a, b: a + b, ast.Sub: lambda a, b: a - b, ast.Mult: lambda a, b: a * b,
           ast.Div: lambda a, b: a / b, ast.FloorDiv: lambda a, b: a // b, ast.Pow: lambda a, b: a**b}
_FACTORIES = {"tuple": tuple, "list": list, "dict": dict}


def _const(node: ast.AST):
    """Value of a constant expression: literals, tuples/lists, ±, + − × / // **, ``math.pi``-style constants
    (also via ``np``/``numpy``), ``float("inf")``. Anything else raises :class:`_NotStatic`."""
    if isinstance(node, ast.Constant):
        return node.value
    if isinstance(node, (ast.Tuple, ast.List)):
        vals = [_const(e) for e in node.elts]
        return tuple(vals) if isinstance(node, ast.Tuple) else vals
    if isinstance(node, ast.UnaryOp) and isinstance(node.op, (ast.USub, ast.UAdd)):
        v = _const(node.operand)
        if isinstance(v, (int, float)) and not isinstance(v, bool):
            return -v if isinstance(node.op, ast.USub) else +v
    if isinstance(node, ast.BinOp) and type(node.op) in _BINOPS:
        a, b = _const(node.left), _const(node.right)
        if all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in (a, b)):
            return _BINOPS[type(node.op)](a, b)
    if (isinstance(node, ast.Attribute) and isinstance(node.value, ast.Name)
            and node.value.id in ("math", "np", "numpy") and node.attr in _CONSTANTS):
        return _CONSTANTS[node.attr]
    if (isinstance(node, ast.Call) and isinstance(node.func, ast.Name) and node.func.id == "float"
            and len(node.args) == 1 and not node.keywords and isinstance(node.args[0], ast.Constant)
            and isinstance(node.args[0].value, str)):
        return float(node.args[0].value)
    raise _NotStatic(ast.unparse(node))


@functools.cache
def _module_source(modname: str) -> tuple[ast.Module, bool]:
    """Top-level statements of ``modname`` (module-level functions left out, see :func:`_without_functions`)
    and whether it is a package, found without executing any module."""
    import importlib.machinery
    import importlib.util

    parts = modname.split(".")
    spec = importlib.util.find_spec(parts[0])  # a top-level name: found, not imported
    for i in range(1, len(parts)):
        if spec is None or not spec.submodule_search_locations:
            raise _NotStatic(modname)
        spec = importlib.machinery.PathFinder.find_spec(".".join(parts[: i + 1]), spec.submodule_search_locations)
    if spec is None or not spec.origin or not spec.origin.endswith(".py"):
        raise _NotStatic(modname)
    path = Path(spec.origin)
    src = path.read_text(encoding="utf-8")
    try:
        tree = ast.parse(_without_functions(src), str(path))
    except SyntaxError:  # the line cut met an unusual layout: parse everything (same answer, slower)
        tree = ast.parse(src, str(path))
    return tree, path.name == "__init__.py"


def _without_functions(src: str) -> str:
    """``src`` without its module-level ``def`` blocks (and their decorators): the static reader needs only
    classes, imports and assignments, and the functions are most of a solver module's text — parsing all
    five built-in solver modules whole costs ≈ 50 ms of CPU, this cut ≈ 5× less.

    A block runs from a column-0 ``def`` to the next column-0 code line. Should a column-0 line inside a
    function (a multi-line string) end the cut early, the rest of the body is left indented at top level,
    which is a SyntaxError, and :func:`_module_source` parses the whole text instead.
    """
    out: list[str] = []
    decorators: list[str] = []
    skipping = False
    for line in src.splitlines(keepends=True):
        if line[:1] not in ("", " ", "\t", "\r", "\n", "#", ")", "]", "}"):  # column-0 code: a new statement
            if line.startswith("@"):
                decorators.append(line)
                continue
            skipping = line.startswith(("def ", "async def "))
            if not skipping:
                out += decorators
            decorators = []
        elif decorators:  # a decorator's continuation lines
            decorators.append(line)
            continue
        if not skipping:
            out.append(line)
    return "".join(out + decorators)


def _import_target(modname: str, is_pkg: bool, node: ast.ImportFrom) -> str:
    """Absolute module name of a ``from … import`` statement found in ``modname``."""
    if not node.level:
        return node.module or ""
    pkg = modname.split(".") if is_pkg else modname.split(".")[:-1]
    pkg = pkg[: len(pkg) - (node.level - 1)]
    return ".".join(pkg + ([node.module] if node.module else []))


def _find_class(modname: str, name: str, depth: int = 0) -> tuple[str, ast.ClassDef]:
    """``(module, class statement)`` that binds ``name`` in ``modname``, following ``from … import`` and
    ``A = B`` aliases at module level."""
    if depth > 8:
        raise _NotStatic(f"{modname}.{name}")
    tree, is_pkg = _module_source(modname)
    found, star = None, []
    for node in tree.body:  # top-level statements only; the last binding wins, as at run time
        if isinstance(node, ast.ClassDef) and node.name == name:
            found = ("class", node)
        elif isinstance(node, ast.ImportFrom):
            for alias in node.names:
                if (alias.asname or alias.name) == name:
                    found = ("import", (_import_target(modname, is_pkg, node), alias.name))
                elif alias.name == "*":
                    star.append(_import_target(modname, is_pkg, node))
        elif (isinstance(node, ast.Assign) and len(node.targets) == 1 and isinstance(node.targets[0], ast.Name)
              and node.targets[0].id == name):
            found = ("alias", node.value)
    if found is None:
        for target in reversed(star):  # ``from .solver import *``
            try:
                return _find_class(target, name, depth + 1)
            except _NotStatic:
                continue
        raise _NotStatic(f"{modname}.{name}")
    kind, what = found
    if kind == "class":
        return modname, what
    if kind == "import":
        return _find_class(what[0], what[1], depth + 1)
    if isinstance(what, ast.Name):
        return _find_class(modname, what.id, depth + 1)
    raise _NotStatic(f"{modname}.{name}")


def _is_dataclass_decorator(d: ast.AST) -> bool:
    d = d.func if isinstance(d, ast.Call) else d
    return (isinstance(d, ast.Name) and d.id == "dataclass") or (
        isinstance(d, ast.Attribute) and d.attr == "dataclass")


def _field_default(value: ast.AST | None):
    """Default of one dataclass field statement (``x: T = v`` or ``x: T = field(...)``)."""
    if value is None:
        return "required"
    if isinstance(value, ast.Call) and (
        (isinstance(value.func, ast.Name) and value.func.id == "field")
        or (isinstance(value.func, ast.Attribute) and value.func.attr == "field")
    ):
        kw = {k.arg: k.value for k in value.keywords}
        if "default" in kw:
            return _const(kw["default"])
        fac = kw.get("default_factory")
        if isinstance(fac, ast.Name) and fac.id in _FACTORIES:
            return _FACTORIES[fac.id]()
        if isinstance(fac, ast.Lambda) and not fac.args.args:
            return _const(fac.body)
        raise _NotStatic(ast.unparse(value))
    return _const(value)


def describe_static(name: str) -> list[tuple[str, str, str]]:
    """``[(field, annotation, default)]`` of solver ``name``'s ``Params``, read from source without importing.

    Raises :class:`_NotStatic` when the source alone does not determine it (see the module docstring).
    """
    target = _target(name)
    if target is None:
        raise _NotStatic(name)
    modname, _, attr = target.partition(":")
    if not attr or "." in attr:
        raise _NotStatic(target)
    owner, solver = _find_class(modname.strip(), attr.strip())
    params_expr = None
    for node in solver.body:
        if isinstance(node, ast.Assign) and any(isinstance(t, ast.Name) and t.id == "Params" for t in node.targets):
            params_expr = node.value
        elif isinstance(node, ast.AnnAssign) and isinstance(node.target, ast.Name) and node.target.id == "Params":
            params_expr = node.value
    if not isinstance(params_expr, ast.Name):
        raise _NotStatic(f"{name}: Params")
    _, cls = _find_class(owner, params_expr.id)  # resolved where the solver class statement lives
    if cls.bases or cls.keywords or not any(_is_dataclass_decorator(d) for d in cls.decorator_list):
        raise _NotStatic(f"{name}: {cls.name} is not a plain dataclass")
    out = []
    for node in cls.body:
        if isinstance(node, ast.AnnAssign) and isinstance(node.target, ast.Name):
            ann = ast.unparse(node.annotation)
            if ann.split("[")[0].split(".")[-1] in ("ClassVar", "InitVar"):
                continue
            default = _field_default(node.value)
            out.append((node.target.id, ann, str(default)))
    return out


def describe(name: str) -> list[tuple[str, str, str]]:
    """``[(field, type, default)]`` of solver ``name``'s parameters: statically when the source determines
    them (no import), else from the imported ``Params`` (:func:`slamcli.params.describe_params`).

    Raises :class:`PluginError` (unknown name, broken plugin) like :func:`load`.
    """
    try:
        return describe_static(name)
    except (_NotStatic, OSError, SyntaxError, ValueError, ImportError):
        from slamcli.params import describe_params

        return describe_params(load(name).Params)
