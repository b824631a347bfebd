"""Solver discovery through ``importlib.metadata.entry_points(group="slamcli.solvers")`` — the package
metadata is the one table of solvers (slamcli's own are declared in its ``pyproject.toml`` like any plug-in).

:func:`available` reads entry-point metadata only. :func:`describe` reads a solver's ``Params`` from its
numpy-free params module (:func:`params_module`), so ``slamcli solvers NAME`` imports neither numpy nor the
solver; a plug-in without such a module is imported and asked. :func:`load` imports the solver to run it.
Scanning every installed distribution's entry points is done once per process.
"""

from __future__ import annotations

import dataclasses
import functools
import importlib
from dataclasses import dataclass
from typing import TYPE_CHECKING

from slamcli.errors import PluginError

if TYPE_CHECKING:
    from importlib import metadata

GROUP = "slamcli.solvers"


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
    """The group's entry points, slamcli's own or else the first of each name (scanning every installed
    distribution's metadata is done once per process)."""
    from importlib import metadata

    eps: dict[str, metadata.EntryPoint] = {}
    for ep in metadata.entry_points(group=GROUP):
        if ep.name not in eps or getattr(ep.dist, "name", None) == "slamcli":  # a plug-in cannot replace ours
            eps[ep.name] = ep
    return tuple(eps.items())


def _targets() -> dict[str, str]:
    """``name → "module:Class"`` of every registered solver (slamcli's own and the plug-ins')."""
    return {name: ep.value for name, ep in _entry_points().items()}


def _listing() -> str:
    return ", ".join(sorted(_targets())) or "none"


def available() -> list[SolverInfo]:
    """Every registered solver, sorted by name (loading none of them)."""
    eps = _entry_points()
    out = []
    for name, target in sorted(_targets().items()):
        dist = getattr(eps[name], "dist", None)
        package, version = (dist.name, dist.version) if dist is not None else ("?", "?")
        out.append(SolverInfo(name=name, target=target, package=package, version=version))
    return out


def names() -> list[str]:
    return [s.name for s in available()]


def _target(name: str) -> str | None:
    """``"module:Class"`` registered as ``name``, or None."""
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


def params_module(target: str) -> str:
    """The numpy-free module that holds the ``Params`` of the solver at ``target`` (``"module:Class"``), by
    convention: ``pkg.params`` beside ``pkg.solver`` or inside a package ``pkg``, else ``<module>_params``."""
    import importlib.util

    modname = target.partition(":")[0].strip()
    if modname.endswith(".solver"):
        return modname.rpartition(".")[0] + ".params"
    spec = importlib.util.find_spec(modname)  # imports the parent packages only, never the solver module
    return f"{modname}.params" if spec is not None and spec.submodule_search_locations else f"{modname}_params"


def params_class(name: str) -> type:
    """Solver ``name``'s ``Params`` dataclass from its params module (:func:`params_module`; no numpy), or
    from the solver itself for a plug-in without one. Raises :class:`PluginError` like :func:`load`."""
    import importlib.util

    target = _target(name)
    if target is None:
        raise PluginError(f"unknown solver {name!r}; available solvers: {_listing()}")
    try:
        modname = params_module(target)
        found = importlib.util.find_spec(modname) is not None
    except (ImportError, ValueError):
        found = False
    params = getattr(importlib.import_module(modname), "Params", None) if found else None
    if params is None or not dataclasses.is_dataclass(params):
        params = load(name).Params
    return params


def describe(name: str) -> list[tuple[str, str, str]]:
    """``[(field, type, default)]`` of solver ``name``'s parameters, from :func:`params_class` (no numpy for
    the solvers slamcli ships). Raises :class:`PluginError` (unknown name, broken plugin) like :func:`load`."""
    from slamcli.params import describe_params

    return describe_params(params_class(name))
