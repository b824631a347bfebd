"""mkdocs hooks: pages made at build time, so they never go stale.

* ``gallery.md``: simulates a small world, solves it, and runs every kind of ``slamcli plot`` on the results
  (in this process, through the CLI's own typer app); the figures become files of the site.
* ``measurements.md``: every ``benchmarks/results/*.md`` under its own heading, so a new results file appears
  on the next build.
* ``<!-- cli-help -->`` and ``<!-- solver-params -->`` in a page: the ``--help`` of every command and the
  ``slamcli solvers NAME`` text of every registered solver, from the installed CLI.
"""

from __future__ import annotations

import contextlib
import os
import re
import shlex
import tempfile
from pathlib import Path

from mkdocs.structure.files import File, Files

ROOT = Path(__file__).resolve().parent.parent
RESULTS = ROOT / "benchmarks" / "results"

#: the gallery's runs: (command, figure it writes or None, what the figure shows). Short worlds keep the
#: build to a few seconds; the figures look the same at full length.
GALLERY: list[tuple[str, str | None, str]] = [
    ("simulate -s loop --seed 1 --set n_steps=250 -o loop.h5", None, ""),
    ("solve loop.h5 -m icm -o icm.h5", None, ""),
    ("solve loop.h5 -m ekf -o ekf.h5", None, ""),
    ("solve loop.h5 -m graph -o graph.h5", None, ""),
    ("plot map ekf.h5 --ellipses -o map.png", "map.png",
     "`plot map`: true and estimated landmarks and paths, 2σ covariance ellipses (`--ellipses`), start ○ and end ◆."),
    ("plot map icm.h5 ekf.h5 graph.h5 --label ICM --label EKF --label Graph -o overlay.png", "overlay.png",
     "`plot map A B C`: several results of one dataset overlaid, one colour each."),
    ("plot errors icm.h5 -o errors-icm.png", "errors-icm.png",
     "`plot errors` on an iterative result: min / mean / max landmark error per iteration."),
    ("plot errors ekf.h5 -o errors-ekf.png", "errors-ekf.png",
     "`plot errors` on a filter result: per-step pose error (x, y, θ) with ±3σ bands of its own covariance."),
    ("plot mapchange icm.h5 graph.h5 --label ICM --label Graph -o mapchange.png", "mapchange.png",
     "`plot mapchange`: how far the map moves per iteration (log axis)."),
    ("simulate -s loop --seed 2 --set n_steps=250 -o loop2.h5", None, ""),
    ("simulate -s loop --seed 3 --set n_steps=250 -o loop3.h5", None, ""),
    ("solve loop2.h5 -m ekf -o ekf2.h5", None, ""),
    ("solve loop3.h5 -m ekf -o ekf3.h5", None, ""),
    ("plot nees ekf.h5 ekf2.h5 ekf3.h5 --label EKF -o nees.png", "nees.png",
     "`plot nees`: Monte-Carlo average pose NEES of N runs inside the two-sided 95 % χ² band."),
    ("sweep compare solver=odometry,ekf,graph replicates=3 scenario.n_steps=150 -o sweeps -q", None, ""),
    ("plot compare sweeps/compare --by solver -o compare.png", "compare.png",
     "`plot compare`: one metric per configuration of a sweep, box + strip plot."),
    ("simulate -s cuik-room --seed 0 -o room.h5", None, ""),
    ("solve room.h5 -m cuik -o cuik.h5", None, ""),
    ("plot boxes cuik.h5 -o boxes.png", "boxes.png",
     "`plot boxes`: CuikSLAM's guaranteed boxes for every pose (heading wedges) and landmark."),
]


@contextlib.contextmanager
def _cwd(path: Path):
    old = Path.cwd()
    os.chdir(path)
    try:
        yield
    finally:
        os.chdir(old)


def _cli(*args: str) -> str:
    """Output of ``slamcli ARGS`` run in this process (100 columns); a failure fails the build."""
    from typer.testing import CliRunner

    from slamcli.cli import app

    res = CliRunner().invoke(app, list(args), env={"COLUMNS": "100"}, terminal_width=100)
    if res.exit_code != 0:
        raise RuntimeError(f"`slamcli {' '.join(args)}` exited {res.exit_code}: {res.output.strip()}")
    return res.output.rstrip()


def _cli_help() -> str:
    """One section per command (and sub-command) with its ``--help`` text."""
    import typer

    from slamcli.cli import app

    group = typer.main.get_command(app)
    paths: list[tuple[str, ...]] = []
    for name, cmd in group.commands.items():
        paths.append((name,))
        paths += [(name, sub) for sub in getattr(cmd, "commands", {})]
    out = []
    for path in paths:
        out += [f"### slamcli {' '.join(path)}", "", "```text", _cli(*path, "--help"), "```", ""]
    return "\n".join(out)


def _solver_params() -> str:
    """One section per solver registered in the entry-point group with the text of ``slamcli solvers NAME``."""
    from importlib import metadata

    out = []
    for name in sorted({ep.name for ep in metadata.entry_points(group="slamcli.solvers")}):
        out += [f"### {name}", "", "```text", _cli("solvers", name), "```", ""]
    return "\n".join(out)


def on_page_markdown(markdown: str, page, config, files) -> str:
    """Fill the generated parts of the reference pages."""
    if "<!-- cli-help -->" in markdown:
        markdown = markdown.replace("<!-- cli-help -->", _cli_help())
    if "<!-- solver-params -->" in markdown:
        markdown = markdown.replace("<!-- solver-params -->", _solver_params())
    return markdown


def _run_gallery(folder: Path) -> None:
    """Run every gallery command in ``folder``; a failing command fails the build with its output."""
    from typer.testing import CliRunner

    from slamcli.cli import app

    runner = CliRunner()
    with _cwd(folder):
        for cmd, _fig, _caption in GALLERY:
            args = shlex.split(cmd)
            if args[0] in ("simulate", "solve", "plot"):
                args += ["-q"] if "-q" not in args else []
            if args[0] == "plot":
                args += ["--dpi", "110"]
            res = runner.invoke(app, args)
            if res.exit_code != 0:
                raise RuntimeError(f"gallery: `slamcli {cmd}` exited {res.exit_code}: {res.output.strip()}")


def _gallery_page() -> str:
    lines = ["# Gallery", "",
             "Every figure kind of `slamcli plot`, drawn while this site was built from a small simulated world "
             "(`loop`, 250 steps) and the bounded-noise room of CuikSLAM. The commands below are the ones the "
             "build ran, in this order; every figure is one column wide (3.5 in), the default.", "",
             "```console"]
    lines += [f"$ slamcli {cmd}" for cmd, _fig, _cap in GALLERY]
    lines += ["```", ""]
    for cmd, fig, caption in GALLERY:
        if fig:
            lines += [f"## {fig.removesuffix('.png')}", "", caption, "", f"`slamcli {cmd}`", "",
                      f"![{fig}](gallery/{fig})", ""]
    return "\n".join(lines)


def _demote(text: str, levels: int = 2) -> str:
    """Markdown headings one or more levels down (``# T`` → ``### T``), so each file nests under its own."""
    return re.sub(r"^(#{1,4}) ", lambda m: "#" * (len(m.group(1)) + levels) + " ", text, flags=re.M)


def _measurements_page() -> str:
    lines = ["# Measurements", "",
             "Every results file under `benchmarks/results/`, as committed: speed, memory and accuracy measured "
             "by `python -m benchmarks NAME` (or the command each file names) on the machine and load it "
             "states. Numbers live here and in those files, not in the code. `make bench` regenerates the "
             "CSV tables beside them.", ""]
    files = sorted(RESULTS.glob("*.md"))
    lines += [f"- [`{p.name}`](#{p.stem.replace('_', '-')})" for p in files] + [""]
    for p in files:
        lines += [f"## {p.stem.replace('_', '-')}" + " {#" + p.stem.replace("_", "-") + "}", "",
                  f"`benchmarks/results/{p.name}`", "", _demote(p.read_text()).strip(), ""]
    return "\n".join(lines)


def on_files(files: Files, config) -> Files:
    """Add the generated pages and the gallery's figures to the site."""
    files.append(File.generated(config, "measurements.md", content=_measurements_page()))
    with tempfile.TemporaryDirectory(prefix="slamcli-gallery-") as tmp:
        folder = Path(tmp)
        _run_gallery(folder)
        for _cmd, fig, _caption in GALLERY:
            if fig:
                files.append(File.generated(config, f"gallery/{fig}", content=(folder / fig).read_bytes()))
    files.append(File.generated(config, "gallery.md", content=_gallery_page()))
    return files
