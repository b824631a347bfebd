"""``slamcli solvers``: list the registered solver plugins; ``slamcli solvers NAME`` documents each parameter
(meaning, type, allowed values, default) from the solver's Params docstring — the one source."""

from __future__ import annotations

import typer

from slamcli.cli.app import app, handle_errors, stdout_console

WIDTH = 80


@app.command("solvers")
def solvers_command(
    name: str = typer.Argument(None, help="Document the parameters of this solver."),
) -> None:
    """List registered solvers (entry-point group slamcli.solvers); with NAME, explain its parameters."""
    with handle_errors():
        from slamcli.solvers import registry

        infos = registry.available()
        if name is None:
            from rich.table import Table

            table = Table(title="slamcli solvers (slamcli solvers NAME explains the parameters)",
                          title_justify="left")
            for col in ("name", "package", "version", "parameters (default)"):
                table.add_column(col, overflow="fold")
            for info in infos:
                # entry-point metadata + the Params read from source: no solver (numpy/scipy) is imported
                params = ", ".join(f"{n}={d}" for n, _t, d in registry.describe(info.name))
                table.add_row(info.name, info.package, info.version, params or "—")
            stdout_console().print(table)
            return
        cls = registry.load(name)  # raises PluginError listing the names when unknown
        info = next(i for i in infos if i.name == name)
        typer.echo("\n".join(describe_solver(name, info, cls)))


def describe_solver(name: str, info, cls) -> list[str]:
    """Text lines (≤ 80 columns) documenting every parameter of ``cls.Params``."""
    import textwrap
    import typing

    from slamcli.params import allowed_values, describe_params, param_docs

    docs = param_docs(cls.Params)
    hints = typing.get_type_hints(cls.Params)
    summary = (cls.__doc__ or "").strip().splitlines()[0] if cls.__doc__ else ""
    out = textwrap.wrap(f"{name} ({info.package} {info.version}): {summary}", WIDTH)
    out += ["", f"Parameters (slamcli solve -m {name} -p key=value; TOML [solver.params]):", ""]
    for pname, tname, default in describe_params(cls.Params):
        doc_type, text = docs.get(pname, ("", ""))
        allowed = allowed_values(hints[pname])
        kind = " | ".join(allowed) if allowed else (doc_type.split(",")[0].strip() or tname)
        out += textwrap.wrap(f"{pname}  [{kind}]  default: {default}", WIDTH, subsequent_indent="    ")
        body = text.replace("``", "") or "(undocumented)"
        out += textwrap.wrap(body, WIDTH, initial_indent="    ", subsequent_indent="    ")
    return out
