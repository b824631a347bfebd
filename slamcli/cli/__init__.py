"""Command-line interface. Thin: parse arguments, call the library, render with rich."""

from __future__ import annotations

# Each module registers its commands on ``app`` when imported; they import only typer at module level.
from slamcli.cli import (
    aggregate_cmd,  # noqa: F401
    datasets_cmd,  # noqa: F401
    diff_cmd,  # noqa: F401
    evaluate_cmd,  # noqa: F401
    export_cmd,  # noqa: F401
    import_cmd,  # noqa: F401
    import_trajectory_cmd,  # noqa: F401
    info_cmd,  # noqa: F401
    plot_cmd,  # noqa: F401
    reproduce_cmd,  # noqa: F401
    simulate_cmd,  # noqa: F401
    solve_cmd,  # noqa: F401
    solvers_cmd,  # noqa: F401
    sweep_cmd,  # noqa: F401
)
from slamcli.cli.app import app, polish_help

polish_help(app)  # one-line command summaries that are never cut mid-word


def app_for(argv: list[str]):
    """``app`` with only the command (or command group) that ``argv`` names first, or ``app`` itself when
    ``argv`` starts with anything else (an option, an unknown or mistyped name, nothing).

    typer turns every registered command into a click command (signature, type hints, parameters) before it
    parses anything, which costs CPU for every command although one is run. Every command parses, helps and
    fails the same either way (``tests/cli/test_cli_startup.py``).
    """
    import copy

    name = argv[0] if argv else ""
    commands = [c for c in app.registered_commands if c.name == name]
    groups = [g for g in app.registered_groups if g.name == name]
    if not commands and not groups:
        return app
    narrow = copy.copy(app)
    narrow.registered_commands, narrow.registered_groups = commands, groups
    return narrow


#: allocations between two young-generation collections in a command process (CPython's default is 700)
GC_THRESHOLD0 = 100_000


def main() -> None:
    """The ``slamcli`` console script and ``python -m slamcli``.

    A command first imports numpy/SciPy/h5py/typer: tens of thousands of objects that live as long as the
    process, which CPython's default collector threshold (700 net allocations) walks many times before any
    work starts. The young generation is collected every :data:`GC_THRESHOLD0` net allocations instead
    (chosen by measurement: benchmarks/results/design_notes.md); the older generations keep their ratios, so
    cyclic garbage is still collected (the library API leaves the threshold alone).
    NumPy submodules that ``import scipy.sparse`` would execute and no command uses (``numpy.f2py``,
    ``numpy.testing``, …) are registered as lazily executed modules first
    (:func:`slamcli.api.startup.defer_unused_numpy_submodules`).
    """
    import gc
    import sys

    from slamcli.api.startup import defer_unused_numpy_submodules

    defer_unused_numpy_submodules()
    gc.set_threshold(max(GC_THRESHOLD0, gc.get_threshold()[0]), *gc.get_threshold()[1:])
    app_for(sys.argv[1:])()


__all__ = ["GC_THRESHOLD0", "app", "app_for", "main"]
