"""``slamcli solvers``: list the registered solver plugins; ``slamcli solvers NAME`` documents each parameter
(meaning, type, allowed values, default) from the solver's Params schema (each field's ``metadata["doc"]``),
read from its numpy-free params module."""

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
                # entry-point metadata + the numpy-free params modules: no solver (numpy/scipy) is imported
                params = ", ".join(f"{n}={d}" for n, _t, d in registry.describe(info.name))
                table.add_row(info.name, info.package, info.version, params or "—")
            stdout_console().print(table)
            return
        params_cls = registry.params_class(name)  # raises PluginError listing the names when unknown
        info = next(i for i in infos if i.name == name)
        typer.echo("\n".join(describe_solver(name, info, params_cls)))


def describe_solver(name: str, info, params_cls) -> list[str]:
    """Text lines (≤ 80 columns) documenting every parameter of ``params_cls``."""
    import textwrap
    import typing

    from slamcli.params import allowed_values, describe_params, param_docs

    docs = param_docs(params_cls)
    hints = typing.get_type_hints(params_cls)
    summary = " ".join((params_cls.__doc__ or "").strip().split("\n\n")[0].split())
    out = textwrap.wrap(f"{name} ({info.package} {info.version}): {summary}", WIDTH)
    out += ["", f"Parameters (slamcli solve -m {name} -p key=value; TOML [solver.params]):", ""]
    for pname, tname, default in describe_params(params_cls):
        text = docs.get(pname, ("", ""))[1]
        allowed = allowed_values(hints[pname])
        kind = " | ".join(allowed) if allowed else tname
        out += textwrap.wrap(f"{pname}  [{kind}]  default: {default}", WIDTH, subsequent_indent="    ")
        body = text.replace("``", "") or "(undocumented)"
        out += textwrap.wrap(body, WIDTH, initial_indent="    ", subsequent_indent="    ")
    return out
