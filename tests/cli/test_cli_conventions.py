"""Command-line conventions read from the help of every command: ``-h`` is ``--help``, placeholders are click's
(``TEXT``, ``PATH``, ``DATA``), and every enumerated option is a choice its help lists and its parser enforces."""

from __future__ import annotations

import re
import typing
from pathlib import Path

import pytest
import typer
from typer.testing import CliRunner

from slamcli.cli import app

runner = CliRunner()
#: a click placeholder: an upper-case word (TEXT, INTEGER, PATH, DATA, OVERRIDES...) or a choice [a|b|c]
CLICK_METAVAR = re.compile(r"^(?:[A-Z][A-Z_]*(?:\.\.\.)?|\[[^\[\]]+(?:\|[^\[\]]+)+\])$")


def _commands(cmd=None, path=()) -> typing.Iterator[tuple[tuple[str, ...], typing.Any]]:
    """Every (sub)command of the application with its path of names."""
    cmd = cmd or typer.main.get_command(app)
    yield path, cmd
    for name, sub in getattr(cmd, "commands", {}).items():
        yield from _commands(sub, (*path, name))


ALL = list(_commands())


def test_every_command_is_listed():
    names = {" ".join(p) for p, _ in ALL}
    assert {"", "solve", "sweep", "plot", "import", "import g2o", "import trajectory", "datasets fetch"} <= names


@pytest.mark.parametrize("path", [p for p, _ in ALL], ids=lambda p: " ".join(p) or "slamcli")
@pytest.mark.slow
def test_dash_h_is_help_and_placeholders_are_click_style(path):
    long = runner.invoke(app, [*path, "--help"])
    short = runner.invoke(app, [*path, "-h"])
    assert long.exit_code == 0 and short.exit_code == 0, short.output
    assert short.output == long.output
    usage = long.output.split("\n\n")[0]
    assert "<" not in usage and "{" not in usage, usage
    assert re.search(r"^\s+-h, --help\s", long.output, re.M), long.output
    cmd = dict(ALL)[path]
    with typer.Context(cmd) as ctx:
        for param in cmd.params:
            if not getattr(param, "is_flag", False) and not param.hidden:
                assert CLICK_METAVAR.match(param.make_metavar(ctx)), (param.name, param.make_metavar(ctx))


#: (command, option, values the command accepts): the values the library behind each option accepts
CHOICES = [
    (("sweep",), "--executor", ("local", "dask")),
    (("export",), "--format", ("tum", "kitti", "g2o", "gtsam", "csv")),
    (("evaluate",), "--rpe-unit", ("steps", "m")),
    (("import", "mrclam"), "--non-landmark", ("drop", "clutter")),
    (("import", "g2o"), "--forward", ("auto", "x", "y", "-x", "-y")),
    (("import", "trajectory"), "--format", ("tum", "kitti", "auto")),
    (("import", "trajectory"), "--extrapolate", ("error", "hold")),
]


@pytest.mark.parametrize(("path", "option", "values"), CHOICES, ids=lambda x: " ".join(x) if isinstance(x, tuple) else x)
def test_enumerated_options_are_choices_listed_in_the_help(path, option, values):
    help_text = runner.invoke(app, [*path, "--help"]).output
    assert re.search(rf"{re.escape(option)} \[{re.escape('|'.join(values))}\]", help_text), help_text
    bad = runner.invoke(app, [*path, option, "parsecs"])
    assert bad.exit_code == 2 and "Traceback" not in bad.output
    first = bad.stderr.splitlines()[0]
    assert first.startswith("error: ") and option in first and all(f"'{v}'" in first for v in values), first


def test_library_accepts_what_the_help_lists():
    """The choices of the CLI are the values the library takes (an independent list for each)."""
    from slamcli.api.evaluate import check_evaluation_options
    from slamcli.datasets.g2o import import_graph
    from slamcli.datasets.mrclam import import_mrclam
    from slamcli.io.export import FORMATS

    assert dict((o, v) for p, o, v in CHOICES if p == ("export",))["--format"] == FORMATS
    for unit in ("steps", "m"):
        check_evaluation_options(cutoff=1.0, ospa_order=2.0, near_path_m=None, rpe_delta=1.0, rpe_unit=unit)
    hints = {"forward": import_graph, "non_landmark": import_mrclam}
    listed = {"forward": CHOICES[4][2], "non_landmark": CHOICES[3][2]}
    for name, fn in hints.items():
        assert typing.get_args(typing.get_type_hints(fn)[name]) == listed[name]


@pytest.mark.slow
def test_shell_completion_offers_the_choices():
    """The bash completion protocol (README "Shell completion") answers with an option's choices."""
    import os
    import subprocess
    import sys

    script = Path(sys.executable).with_name("slamcli")  # the console script: completion keys on its name
    if not script.exists():
        pytest.skip("the slamcli console script is not installed beside this interpreter")

    def complete(words: str) -> list[str]:
        cword = len(words.split()) - (not words.endswith(" "))  # index of the word being completed
        env = dict(os.environ, COMP_WORDS=words, COMP_CWORD=str(cword), _SLAMCLI_COMPLETE="complete_bash")
        return subprocess.run([script], env=env, capture_output=True, text=True, timeout=60).stdout.split()

    assert complete("slamcli sweep exp.toml --executor ") == ["local", "dask"]
    assert "solve" in complete("slamcli so") and "sweep" not in complete("slamcli so")
    source = subprocess.run([script], env=dict(os.environ, _SLAMCLI_COMPLETE="source_bash"),
                            capture_output=True, text=True, timeout=60).stdout
    assert "complete -o default -F _slamcli_completion slamcli" in source


def test_a_reader_that_stops_early_gets_no_error_line(tmp_path):
    """``slamcli datasets list | head -1``: the pipe's reader is gone before the command writes (closed here
    before the command has even started), which is no error to report."""
    import os
    import subprocess
    import sys

    proc = subprocess.Popen([sys.executable, "-m", "slamcli", "datasets", "list"], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, env={**os.environ, "SLAMCLI_DATA_DIR": str(tmp_path)})
    proc.stdout.close()
    err = proc.stderr.read().decode()
    assert proc.wait(timeout=60) == 1 and err == "", err
