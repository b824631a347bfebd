"""``slamcli datasets``: the public recordings by name — list, fetch, locate, register a local copy, cite."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

from slamcli.cli.app import SlamcliTyper, app, handle_errors

datasets_app = SlamcliTyper(
    help="Public recordings by name: list, fetch NAME, path NAME, add NAME DIR, info NAME. Importers and "
         "reproduce accept the names (slamcli import mrclam mrclam7 --robot 1).",
    no_args_is_help=True,
)
app.add_typer(datasets_app, name="datasets")


@datasets_app.command("list")
def list_command() -> None:
    """One line per registered recording: name, importer, where it is on this machine (added / fetched /
    $SLAMCLI_DATASETS / missing), whether its sha256 is known, title."""
    with handle_errors():
        from slamcli.datasets import registry as r

        reg = r.registry()
        width = max(len(n) for n in reg)
        typer.echo(f"{'name':<{width}}  {'importer':<13} {'here':<18} {'checksum':<9}  title")
        for name in sorted(reg):
            e = reg[name]
            found = r.where(name)
            state = found[0] if found else "missing"
            sha = "sha256" if e.sha256_known else "no sha256"
            typer.echo(f"{name:<{width}}  {e.importer:<13} {state:<18} {sha:<9}  {e.title}")
        typer.echo(f"data folder: {r.data_dir()} (${r.ENV_DATA_DIR} overrides)")


@datasets_app.command("info")
def info_command(name: Annotated[str, typer.Argument(help="Dataset name (see `slamcli datasets list`).")]) -> None:
    """Title, homepage, licence, citation and files (URL, sha256) of one recording."""
    with handle_errors():
        from slamcli.datasets import registry as r

        e = r.entry(name)
        found = r.where(name)
        lines = [f"{e.name}: {e.title}", f"import with: slamcli import {e.importer} {e.name}",
                 f"homepage: {e.homepage}", f"licence: {e.licence}", f"cite: {e.citation}"]
        lines += [f"file: {f.path} <- {f.url} (sha256 {f.sha256 or 'unknown'})" for f in e.files]
        if e.note:
            lines.append(f"note: {e.note}")
        lines.append(f"here: {found[1]} ({found[0]})" if found else f"here: no (slamcli datasets fetch {e.name})")
        typer.echo("\n".join(lines))


@datasets_app.command("path")
def path_command(name: Annotated[str, typer.Argument(help="Dataset name.")]) -> None:
    """Print the path the importer reads (exit 1 with the fetch command when the recording is not here)."""
    with handle_errors():
        from slamcli.datasets import registry as r

        typer.echo(str(r.locate(name)))


@datasets_app.command("fetch")
def fetch_command(
    name: Annotated[str, typer.Argument(help="Dataset name.")],
    quiet: Annotated[bool, typer.Option("--quiet", "-q", help="Print only the path.")] = False,
) -> None:
    """Download a recording into the data folder (sha256-checked where known) and print its path."""
    with handle_errors():
        from slamcli.datasets import registry as r

        path, notes = r.fetch(name, progress=None if quiet else (lambda m: typer.echo(f"fetching {m}", err=True)))
        for note in notes:
            typer.echo(f"note: {note}", err=True)
        typer.echo(str(path))


@datasets_app.command("add")
def add_command(
    name: Annotated[str, typer.Argument(help="Dataset name.")],
    directory: Annotated[Path, typer.Argument(help="Folder of a local copy (e.g. a lab's shared datasets folder).")],
) -> None:
    """Register a local copy (checked: its files are there and match the known sha256) instead of fetching."""
    with handle_errors():
        from slamcli.datasets import registry as r

        path = r.add(name, directory)
        typer.echo(f"{name}: added {path}")
