"""Solver discovery through ``importlib.metadata.entry_points(group="slamcli.solvers")``."""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from importlib import metadata

from slamcli.errors import PluginError

GROUP = "slamcli.solvers"


@dataclass(frozen=True)
class SolverInfo:
    name: str
    target: str  # "module:Class"
    package: str
    version: str


def _entry_points() -> dict[str, metadata.EntryPoint]:
    eps = {}
    for ep in metadata.entry_points(group=GROUP):
        eps.setdefault(ep.name, ep)
    return eps


def available() -> list[SolverInfo]:
    """Every registered solver, sorted by name (loading none of them)."""
    out = []
    for name, ep in sorted(_entry_points().items()):
        dist = getattr(ep, "dist", None)
        out.append(
            SolverInfo(
                name=name,
                target=ep.value,
                package=dist.name if dist is not None else "?",
                version=dist.version if dist is not None else "?",
            )
        )
    return out


def names() -> list[str]:
    return [s.name for s in available()]


def load(name: str) -> type:
    """The solver class registered as ``name``; :class:`PluginError` lists the available names otherwise."""
    eps = _entry_points()
    if name not in eps:
        listing = ", ".join(sorted(eps)) or "none"
        raise PluginError(f"unknown solver {name!r}; available solvers: {listing}")
    listing = ", ".join(sorted(eps))
    try:
        cls = eps[name].load()
    except Exception as exc:  # noqa: BLE001 - any import failure of a plugin is reported the same way
        first = (str(exc).strip().splitlines() or [""])[0]
        raise PluginError(
            f"solver plugin {name!r} ({eps[name].value}) failed to load: {type(exc).__name__}: {first} "
            f"(available solvers: {listing})"
        ) from None
    params_cls = getattr(cls, "Params", None)
    if not (callable(getattr(cls, "solve", None)) and params_cls and dataclasses.is_dataclass(params_cls)):
        raise PluginError(
            f"solver plugin {name!r} ({eps[name].value}) does not follow the solver contract "
            f"(needs a Params dataclass and a solve() method; available solvers: {listing})"
        )
    return cls
