"""Command-line interface. Thin: parse arguments, call the library, render with rich."""

from __future__ import annotations

from slamcli.cli.app import app

# Each module registers its commands on ``app`` when imported; they import only typer at module level.
from slamcli.cli import solvers_cmd  # noqa: E402,F401
from slamcli.cli import simulate_cmd  # noqa: E402,F401
from slamcli.cli import solve_cmd  # noqa: E402,F401
from slamcli.cli import info_cmd  # noqa: E402,F401
from slamcli.cli import evaluate_cmd  # noqa: E402,F401
from slamcli.cli import plot_cmd  # noqa: E402,F401
from slamcli.cli import sweep_cmd  # noqa: E402,F401
from slamcli.cli import reproduce_cmd  # noqa: E402,F401
from slamcli.cli import import_cmd  # noqa: E402,F401


def main() -> None:
    app()


__all__ = ["app", "main"]
