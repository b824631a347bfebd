"""``slamcli solvers``: list the registered solver plugins and their parameters."""

from __future__ import annotations

import typer

from slamcli.cli.app import app, handle_errors, stdout_console


@app.command("solvers")
def solvers_command(
    name: str = typer.Argument(None, help="Show the parameters of this solver only."),
) -> None:
    """List registered solvers (entry-point group ``slamcli.solvers``): name, package, version, parameters."""
    with handle_errors():
        from rich.table import Table

        from slamcli.solvers import registry

        infos = registry.available()
        if name is not None:
            if name not in {i.name for i in infos}:
                registry.load(name)  # raises PluginError listing the names
            infos = [i for i in infos if i.name == name]
        table = Table(title="slamcli solvers")
        for col in ("name", "package", "version", "parameters (default)"):
            table.add_column(col)
        for info in infos:
            # read from entry-point metadata and the Params source: no solver (numpy/scipy) is imported
            params = ", ".join(f"{n}={d}" for n, _t, d in registry.describe(info.name))
            table.add_row(info.name, info.package, info.version, params or "—")
        stdout_console().print(table)
