"""The typer application object and the helpers every command uses.

Commands live one per module in this package; each imports only typer at module level and everything heavy
inside the function body, so ``slamcli --help`` stays fast.
"""

from __future__ import annotations

import contextlib
import os
import re
import sys
from collections.abc import Callable, Iterator
from enum import StrEnum

import typer
from typer.core import TyperCommand, TyperGroup

#: click's placeholder names for typer's parameter types (typer's own help reads ``<str>``, ``{data}``)
_CLICK_METAVARS = {"str": "TEXT", "int": "INTEGER", "float": "FLOAT", "boolean": "BOOLEAN", "path": "PATH"}


def click_metavar(param) -> str:
    """The placeholder click would print for ``param``: ``TEXT``, ``INTEGER``, ``PATH``, ``[a|b|c]`` for a
    choice option, the upper-case name (``DATA``, ``RESULTS...``) for an argument."""
    if param.param_type_name == "argument":
        return param.name.upper() + ("..." if param.nargs != 1 else "")
    choices = getattr(param.type, "choices", None)
    if choices:
        return "[" + "|".join(str(getattr(c, "value", c)) for c in choices) + "]"
    return _CLICK_METAVARS.get(param.type.name, param.type.name.upper())


def choice(name: str, values: tuple[str, ...]) -> type[StrEnum]:
    """A string enumeration typer turns into a choice: help lists ``[a|b|c]``, shell completion offers the
    values, any other value is a usage error naming the option and the values. Members compare equal to (and
    format as) their value."""
    return StrEnum(name, {v: v for v in values})


class SlamcliCommand(TyperCommand):
    """A command whose help uses click's placeholders (``TEXT``, ``PATH``, ``[local|dask]``; usage
    ``[OPTIONS] DATA`` with ``[NAME]`` for an optional argument)."""

    def __init__(self, *args, **kwargs) -> None:
        super().__init__(*args, **kwargs)
        for param in self.params:
            if param.metavar is None and not getattr(param, "is_flag", False):
                param.metavar = click_metavar(param)

    def collect_usage_pieces(self, ctx) -> list[str]:
        pieces = [self.options_metavar] if self.options_metavar else []
        for param in self.get_params(ctx):
            if param.param_type_name == "argument":
                pieces.append(param.metavar if param.required else f"[{param.metavar}]")
        return pieces


class SlamcliTyper(typer.Typer):
    """``typer.Typer`` whose commands are :class:`SlamcliCommand` and answer ``-h`` as well as ``--help``."""

    def __init__(self, **kwargs) -> None:
        settings = {"help_option_names": ["-h", "--help"], **kwargs.pop("context_settings", {})}
        super().__init__(context_settings=settings, rich_markup_mode=None, **kwargs)

    def command(self, *args, cls=None, **kwargs):
        return super().command(*args, cls=cls or SlamcliCommand, **kwargs)


#: environment variable that asks the command for its shell-completion script or candidates
COMPLETE_VAR = "_SLAMCLI_COMPLETE"


class SlamcliGroup(TyperGroup):
    """The root command group: a usage error (unknown option, missing argument, bad value) prints one
    ``error:`` line and one hint line on stderr (exit status 2) instead of click's usage block."""

    def main(self, args=None, prog_name=None, complete_var=None, standalone_mode=True, **extra):
        if os.environ.get(complete_var or COMPLETE_VAR):
            # shell completion (README "Shell completion"): typer registers its bash/zsh/fish/powershell
            # scripts only when it adds --install-completion; register them for this call alone
            from typer.completion import completion_init

            completion_init()
        if not standalone_mode:
            return super().main(args, prog_name, complete_var, standalone_mode=False, **extra)
        try:
            rv = super().main(args, prog_name, complete_var, standalone_mode=False, **extra)
        except typer.Abort:
            typer.echo("aborted", err=True)
            sys.exit(1)
        except Exception as exc:  # click exceptions (typer may vendor click): matched by class name below
            names = {c.__name__ for c in type(exc).__mro__}
            if "ClickException" not in names:
                raise
            if "NoArgsIsHelpError" in names:  # a group called without a command: its help, as before
                exc.show()
                sys.exit(exc.exit_code)
            typer.echo(f"error: {exc.format_message().strip().splitlines()[0]}", err=True)
            if "UsageError" in names:
                ctx = getattr(exc, "ctx", None)
                typer.echo(f"hint: see '{ctx.command_path if ctx is not None else 'slamcli'} --help'", err=True)
            sys.exit(exc.exit_code)
        sys.exit(rv if isinstance(rv, int) else 0)


app = SlamcliTyper(
    name="slamcli",
    cls=SlamcliGroup,
    help="2-D SLAM experiment runner: simulate → solve → evaluate → plot, and parameter sweeps.",
    no_args_is_help=True,
    add_completion=False,
    pretty_exceptions_enable=False,
)


def _version_callback(value: bool) -> None:
    if value:
        import slamcli

        typer.echo(f"slamcli {slamcli.__version__}")
        raise typer.Exit()


@app.callback()
def _root(
    version: bool = typer.Option(False, "--version", callback=_version_callback, is_eager=True, help="Print the version."),
) -> None:
    """2-D SLAM experiment runner."""


#: columns of a console that is not a terminal (a file, a pipe): wide enough that no table or line of ours is
#: wrapped (rich would otherwise wrap at 80); ``COLUMNS`` in the environment still wins
UNWRAPPED_WIDTH = 10_000


def _console(stderr: bool):
    from rich.console import Console

    console = Console(stderr=stderr)
    if not console.is_terminal and "COLUMNS" not in os.environ:
        console.width = UNWRAPPED_WIDTH
    return console


def stderr_console():
    """A rich console on stderr; off a terminal it does not wrap lines (a log keeps each row on one line)."""
    return _console(stderr=True)


def stdout_console():
    """A rich console on stdout; off a terminal it does not wrap lines (a pipe gets each row on one line)."""
    return _console(stderr=False)


#: characters never printed as they are: C0 controls (ESC starts a terminal escape sequence), DEL, C1
#: controls, and the bidirectional overrides that reorder what a terminal shows
_UNPRINTABLE = re.compile("[\x00-\x1f\x7f-\x9f\u202a-\u202e\u2066-\u2069]")


def printable(text: str) -> str:
    """``text`` safe for a terminal: control characters (from file names, attributes or messages stored in a
    file) as ``\\xNN`` / ``\\uNNNN`` escapes, non-UTF-8 bytes of file names as ``\\udcNN``."""
    text = _UNPRINTABLE.sub(lambda m: ascii(m.group())[1:-1], text)
    return text.encode("utf-8", "backslashreplace").decode("utf-8")


def one_line(text: str) -> str:
    """First line of ``text``, :func:`printable` whatever the file names or stored strings in it."""
    return printable(text.splitlines()[0] if text.strip() else "")


@contextlib.contextmanager
def handle_errors(exit_code: int = 1) -> Iterator[None]:
    """Turn a :class:`~slamcli.errors.SlamcliError` (or an operating-system error the library did not
    anticipate, e.g. a read-only folder) into one line on stderr and exit status ``exit_code``.

    numpy's RuntimeWarnings (overflow, divide by zero, invalid value on bad numbers in user data) are
    collected and reported as ONE counted ``warning:`` line when the command succeeds; on an error only the
    error line is printed. Other warnings pass through unchanged.
    """
    import warnings
    from collections import Counter

    from slamcli.errors import SlamcliError

    ok = False
    # kind -> count, not a record per warning: a long command (reproduce) raises millions of RuntimeWarnings,
    # and recording each one grew a test worker to 15 GB
    numeric: Counter[str] = Counter()
    with warnings.catch_warnings():
        warnings.simplefilter("always", RuntimeWarning)
        passthrough = warnings.showwarning

        def count_numeric(message, category, filename, lineno, file=None, line=None):
            if issubclass(category, RuntimeWarning):
                numeric[str(message).split(" encountered")[0]] += 1
            else:
                passthrough(message, category, filename, lineno, file, line)

        warnings.showwarning = count_numeric  # catch_warnings restores it
        try:
            yield
            ok = True
        except SlamcliError as exc:
            msg = one_line(str(exc)) or type(exc).__name__
            typer.echo(f"error: {msg}", err=True)
            raise typer.Exit(getattr(exc, "exit_code", exit_code)) from None  # OutputRefused: 2
        except BrokenPipeError:
            # the reader of our output stopped (`slamcli datasets list | head -1`): not an error worth a line;
            # stdout goes to devnull so the interpreter's last flush does not fail again
            os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
            raise typer.Exit(exit_code) from None
        except OSError as exc:
            where = f"{exc.filename}: " if exc.filename is not None else ""
            typer.echo(f"error: {one_line(where + (exc.strerror or str(exc) or type(exc).__name__))}", err=True)
            raise typer.Exit(exit_code) from None
        except MemoryError:
            typer.echo("error: out of memory (a parameter or an input too large for this machine)", err=True)
            raise typer.Exit(exit_code) from None
        except KeyboardInterrupt:
            typer.echo("interrupted", err=True)
            raise typer.Exit(130) from None
        finally:
            if numeric and ok:
                kinds = sorted(numeric)
                typer.echo(f"warning: {sum(numeric.values())} numeric warning(s) on this input "
                           f"({'; '.join(kinds)[:160]}); "
                           "the result may hold inf/nan", err=True)


def rich_progress(*status_columns):
    """The one progress-bar layout of the CLI, on stderr: description, bar, done/total, ``status_columns``
    (e.g. the sweep's done/failed/skipped counts), elapsed time, ETA. A ``rich.progress.Progress``."""
    from rich.progress import (
        BarColumn,
        MofNCompleteColumn,
        Progress,
        TextColumn,
        TimeElapsedColumn,
        TimeRemainingColumn,
    )

    return Progress(
        TextColumn("{task.description}"),
        BarColumn(),
        MofNCompleteColumn(),
        *status_columns,
        TimeElapsedColumn(),
        TextColumn("ETA"),
        TimeRemainingColumn(),
        console=stderr_console(),
        transient=False,
    )


@contextlib.contextmanager
def progress_bar(description: str, *, quiet: bool = False) -> Iterator[Callable[[int, int], None]]:
    """A rich progress bar on stderr, exposed as a ``progress(done, total)`` callback.

    When stderr is not a terminal (a log file, a pipe), plain lines at a bounded rate instead
    (:class:`slamcli.progress.ProgressLines`); with ``quiet`` the callback does nothing.
    """
    if quiet:
        yield lambda done, total: None
        return
    if not stderr_is_terminal():
        from slamcli.progress import ProgressLines

        yield ProgressLines(description, echo_stderr)
        return
    with rich_progress() as prog:
        task = prog.add_task(description, total=None)

        def update(done: int, total: int) -> None:
            prog.update(task, completed=done, total=total)

        yield update


def fail(message: str) -> None:
    """Print a one-line error and exit 1 (for CLI-level argument problems)."""
    typer.echo(f"error: {one_line(message)}", err=True)
    raise typer.Exit(1)


def stderr_is_terminal() -> bool:
    """Whether a progress bar on stderr would be redrawn in place (rich's test: a TTY, or forced by the
    environment); otherwise long work reports plain lines."""
    return stderr_console().is_terminal


def echo_stderr(line: str) -> None:
    """Write ``line`` to stderr and flush it (a log read while the work runs sees it at once)."""
    typer.echo(line, err=True)


def check_output(path, *, folder: bool = False, option: str = "-o", inputs=(), replaces_folder: bool = False,
                 kind: str | None = None, force: bool = False) -> None:
    """Refuse an output path that cannot be written, before any work is done (one line, exit 1).

    A symbolic-link loop on the path, a directory where a file is expected (or a file where a folder is
    expected), a name longer than the file system allows, a parent that is a file, or a parent folder this
    process may not write into. Then the output guard (:func:`slamcli.io.guard.guard_output`, exit 2) with
    every file the command reads (:func:`files_read` of ``inputs``): an output that is one of them or a file
    inside an input folder, a device or FIFO, a path inside a running sweep's results folder, or (with
    ``kind``, unless ``force``) an existing file of another kind.
    """
    import errno
    from pathlib import Path

    p = Path(path)
    for q in reversed((p, *p.parents)):  # a symbolic link loop on the way (a later resolve() would raise)
        try:
            os.stat(q)
        except OSError as exc:
            if exc.errno == errno.ELOOP:
                fail(f"{option} {p}: {q} is a loop of symbolic links")
    for part in p.parts:
        if len(os.fsencode(part)) > 255:
            fail(f"{option} {p}: a name is too long ({len(os.fsencode(part))} bytes, limit 255)")
    if not folder and p.is_dir():
        fail(f"{option} {p}: is a directory, expected a file name")
    if folder and (p.is_symlink() or (p.exists() and not p.is_dir())):
        fail(f"{option} {p}: exists and is not a folder")
    anc = p.parent
    while not anc.exists() and anc != anc.parent:
        anc = anc.parent
    if anc.exists() and not anc.is_dir():
        fail(f"{option} {p}: {anc} is a file, not a folder")
    if not os.access(anc, os.W_OK | os.X_OK):
        fail(f"{option} {p}: folder {anc} is not writable")
    from slamcli.io.guard import guard_output

    guard_output(p, files_read(inputs), folder=folder, replaces_folder=replaces_folder, option=option, kind=kind,
                 force=force)


def files_read(named) -> list:
    """Every file and folder a command with the inputs ``named`` may read: the named paths, the dataset each
    named result records (read when ``--data`` is not given), and every registry recording's folder on this
    machine (an importer reads them by name)."""
    from pathlib import Path

    from slamcli.api.evaluate import recorded_dataset
    from slamcli.datasets.registry import recording_folders

    out = [Path(p) for p in named if p is not None]
    out += [d for p in out if p.is_file() and (d := recorded_dataset(p)) is not None]
    return out + recording_folders()


def iteration_count(result) -> int | None:
    """Iterations of an iterative solve, as the solver counts them: ``extra["iterations"]`` when the solver
    records it, else the trace length minus its row 0 (the initialisation); None without a trace."""
    if "iterations" in result.extra:
        return int(result.extra["iterations"])
    if result.trace is None:
        return None
    return max(len(result.trace) - 1, 0)


#: abbreviations whose full stop does not end the first sentence of a help text
_ABBREV = re.compile(r"(?:\b(?:Figs?|Eqs?|e\.g|i\.e|cf|vs|etc|approx)\.)$")


def short_help(doc: str | None, limit: int = 60) -> str:
    """One-line command summary for ``slamcli --help``: the first clause of the docstring's first paragraph
    (up to a sentence end, ``:`` or ``;``), shortened at a word boundary with "…" when longer than ``limit``
    — never cut inside a word or after an abbreviation's full stop."""
    text = " ".join((doc or "").strip().split("\n\n")[0].split())
    for m in re.finditer(r"[.:;](?=\s|$)", text):
        if m.group() == "." and _ABBREV.search(text[: m.end()]):
            continue
        text = text[: m.start()]
        break
    if len(text) <= limit:
        return text
    cut = text[: limit].rsplit(" ", 1)[0].rstrip(" ,(-—")
    return cut + " …"


def polish_help(typer_app: typer.Typer) -> None:
    """Give every command and sub-group an explicit summary (:func:`short_help`), recursively."""
    import inspect

    for info in typer_app.registered_commands:
        if not isinstance(info.short_help, str):
            info.short_help = short_help(info.help or inspect.getdoc(info.callback))
    for group in typer_app.registered_groups:
        sub = group.typer_instance
        if not isinstance(group.short_help, str):  # typer's Default(None) placeholder
            text = group.help if isinstance(group.help, str) else sub.info.help
            group.short_help = sub.info.short_help = short_help(text if isinstance(text, str) else "")
        polish_help(sub)
