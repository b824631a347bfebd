"""Every command of the README and the tutorials runs and succeeds, as written.

The runnable commands are the lines starting with ``$ slamcli`` inside fenced ``console`` blocks; each page's
commands run in order, in the slamcli CLI (in this process), in a fresh folder, and each must exit 0 and write
the files it names with ``-o``/``--out``. Recordings come from the excerpts in ``tests/data`` laid out as a
``$SLAMCLI_DATASETS`` folder under their registry folders, so the registry names of the pages resolve as they
do for a user. What a page states the test does differently is done here and only here:

* real recordings: the Intel excerpt is copied in as ``intel-excerpt.g2o``;
* Dask: ``tcp://HOST:8786`` is the address of a scheduler with one worker started here on 127.0.0.1;
* a page's ``<!-- test-variant: COMMAND => SHORTER -->`` line: SHORTER runs in place of COMMAND (the page says
  so in its text);
* the plugin (its page and the suite's): the plugin page's ``mypkg/mine.py`` and the entry point of its ``pyproject.toml`` are written as the
  installed metadata ``pip install`` would write, on ``sys.path``.
"""

from __future__ import annotations

import re
import shlex
import shutil
import sys
import tomllib
from pathlib import Path

import pytest
from conftest import DATA, ROOT
from typer.testing import CliRunner

#: the pages whose commands a reader runs, in reading order
PAGES = ["README.md", "docs/tutorials/first-experiment.md", "docs/tutorials/real-recordings.md",
         "docs/tutorials/sweeps.md", "docs/tutorials/dask.md", "docs/tutorials/plugin.md",
         "docs/tutorials/reproduce.md", "docs/suite.md"]
#: registry folder → excerpt in tests/data (the recordings the pages name)
RECORDINGS = {"victoria_park": "victoria_park_excerpt", "acfr_carpark": "carpark_excerpt",
              "mrclam_dataset7": "mrclam_excerpt"}
SCHEDULER_PLACEHOLDER = "tcp://HOST:8786"
VARIANT = re.compile(r"^<!-- test-variant: (.+?) => (.+?) -->$", re.M)
PLUGIN_PAGE = "docs/tutorials/plugin.md"
FENCE = re.compile(r"^```(\w+)([^\n]*)\n(.*?)^```", re.M | re.S)


def blocks(page: str) -> list[tuple[str, str, str]]:
    """``(language, info after it, body)`` of every fenced block of a page."""
    return [(m.group(1), m.group(2).strip(), m.group(3)) for m in FENCE.finditer((ROOT / page).read_text())]


def commands(page: str) -> list[str]:
    """The ``$ `` lines of the page's ``console`` blocks, without the prompt, in page order."""
    return [line[2:].strip() for lang, _info, body in blocks(page) if lang == "console"
            for line in body.splitlines() if line.startswith("$ ")]


def variants(page: str) -> dict[str, str]:
    """``command → shorter command the test runs`` from the page's test-variant comments."""
    return dict(VARIANT.findall((ROOT / page).read_text()))


def outputs(args: list[str]) -> list[str]:
    """The files a command names with ``-o`` / ``--out`` / ``--output``."""
    return [args[i + 1] for i, a in enumerate(args[:-1]) if a in ("-o", "--out", "--output")]


@pytest.mark.parametrize("page", PAGES)
def test_every_console_line_is_a_slamcli_command(page):
    cmds = commands(page)
    assert cmds, f"{page}: no console block"
    assert all(c.startswith("slamcli ") for c in cmds), [c for c in cmds if not c.startswith("slamcli ")]
    assert set(variants(page)) <= set(cmds), set(variants(page)) - set(cmds)  # no variant of a gone command


def _plugin(page: str, folder: Path) -> None:
    """Lay out the page's plugin package as installed: its module and an entry point in installed metadata."""
    titled = {re.search(r'title="([^"]+)"', info).group(1): body
              for _lang, info, body in blocks(page) if 'title="' in info}
    module = folder / "mypkg" / "mine.py"
    module.parent.mkdir(parents=True)
    (module.parent / "__init__.py").write_text("")
    module.write_text(titled["mypkg/mine.py"])
    project = tomllib.loads(titled["pyproject.toml"])["project"]
    meta = folder / f"{project['name']}-{project['version']}.dist-info"
    meta.mkdir()
    (meta / "METADATA").write_text(f"Metadata-Version: 2.1\nName: {project['name']}\nVersion: {project['version']}\n")
    eps = project["entry-points"]["slamcli.solvers"]
    (meta / "entry_points.txt").write_text("[slamcli.solvers]\n" + "".join(f"{k} = {v}\n" for k, v in eps.items()))


def _clear_solver_caches() -> None:
    """Forget the entry points scanned so far (the registry caches them per process)."""
    from slamcli.solvers import registry

    for value in vars(registry).values():
        if callable(getattr(value, "cache_clear", None)):
            value.cache_clear()


def _forget_plugin() -> None:
    """After the plugin page: no ``mypkg`` module and no cached entry point of it stay behind."""
    for name in [m for m in sys.modules if m == "mypkg" or m.startswith("mypkg.")]:
        del sys.modules[name]
    _clear_solver_caches()


@pytest.fixture()
def scheduler():
    """A Dask scheduler with one single-threaded worker process on 127.0.0.1; its address."""
    distributed = pytest.importorskip("distributed")
    with distributed.LocalCluster(n_workers=1, threads_per_worker=1, processes=True, host="127.0.0.1",
                                  dashboard_address=":0") as cluster:
        yield cluster.scheduler_address


@pytest.mark.slow
@pytest.mark.parametrize("page", PAGES)
def test_page_commands_run(page, shared_datasets, tmp_path, monkeypatch, request):
    from slamcli.cli import app

    shared_datasets(RECORDINGS)
    work = tmp_path / "work"
    work.mkdir()
    monkeypatch.chdir(work)
    replace = {}
    if page.endswith("real-recordings.md"):
        shutil.copy(DATA / "intel_excerpt.g2o", work / "intel-excerpt.g2o")
    if page.endswith("dask.md"):
        replace[SCHEDULER_PLACEHOLDER] = request.getfixturevalue("scheduler")
    if page in (PLUGIN_PAGE, "docs/suite.md"):
        _plugin(PLUGIN_PAGE, tmp_path / "site-packages")
        monkeypatch.syspath_prepend(str(tmp_path / "site-packages"))
        _clear_solver_caches()
        request.addfinalizer(_forget_plugin)
    runner = CliRunner()
    shorter = variants(page)
    for cmd in commands(page):
        cmd = shorter.get(cmd, cmd)
        for old, new in replace.items():
            cmd = cmd.replace(old, new)
        args = shlex.split(cmd)[1:]
        res = runner.invoke(app, args)
        assert res.exit_code == 0, f"{page}: `{cmd}` exited {res.exit_code}:\n{res.output[-3000:]}"
        for out in outputs(args):
            assert (work / out).exists(), f"{page}: `{cmd}` did not write {out}"
