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


def main() -> None:
    app()


__all__ = ["app", "main"]
