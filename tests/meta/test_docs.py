"""The documentation site builds with strict warnings (a broken link, an unknown page, a docstring griffe
cannot parse, a failing gallery command all fail it), and its generated pages hold what they promise: every
figure kind of ``slamcli plot`` in the gallery, every ``benchmarks/results/*.md`` on the measurements page,
every command's help and every solver's parameters in the reference."""

from __future__ import annotations

import os
import subprocess
import sys
from importlib import metadata
from pathlib import Path

import pytest
from conftest import ROOT

PNG_MAGIC = b"\x89PNG\r\n\x1a\n"
#: the figure kinds `slamcli plot` accepts (its KIND argument)
PLOT_KINDS = ("map", "errors", "nees", "mapchange", "compare", "boxes")


@pytest.fixture(scope="module")
def site(tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("site")
    env = {**os.environ, "NO_MKDOCS_2_WARNING": "1"}
    res = subprocess.run([sys.executable, "-m", "mkdocs", "build", "--strict", "-f", str(ROOT / "mkdocs.yml"),
                          "-d", str(out)], capture_output=True, text=True, env=env, cwd=ROOT)
    assert res.returncode == 0, res.stderr[-4000:]
    return out


@pytest.mark.slow
def test_site_builds_strictly(site):
    for page in ("index.html", "install/index.html", "tutorials/first-experiment/index.html",
                 "reference/api/index.html", "schema/index.html", "experiments/index.html", "suite/index.html"):
        assert (site / page).is_file(), page
    api = (site / "reference" / "api" / "index.html").read_text()
    assert "slamcli.api.facade.solve" in api and "SlamInputs" in api  # mkdocstrings rendered the docstrings


@pytest.mark.slow
def test_gallery_has_every_plot_kind(site):
    gallery = (site / "gallery" / "index.html").read_text()
    for kind in PLOT_KINDS:
        assert f"slamcli plot {kind} " in gallery, kind
    figures = sorted((site / "gallery").glob("*.png"))
    assert len(figures) >= len(PLOT_KINDS)
    for fig in figures:
        assert fig.read_bytes()[:8] == PNG_MAGIC and fig.name in gallery


@pytest.mark.slow
def test_measurements_and_generated_reference(site):
    page = (site / "measurements" / "index.html").read_text()
    results = sorted((ROOT / "benchmarks" / "results").glob("*.md"))
    assert results
    for p in results:
        assert f"benchmarks/results/{p.name}" in page, p.name
    cli = (site / "reference" / "cli" / "index.html").read_text()
    for command in ("simulate", "solve", "evaluate", "plot", "sweep", "aggregate", "reproduce", "datasets add"):
        assert f"slamcli {command}" in cli and "Usage: slamcli" in cli
    solvers = (site / "reference" / "solvers" / "index.html").read_text()
    for ep in metadata.entry_points(group="slamcli.solvers"):
        assert f"{ep.name} (" in solvers, ep.name  # the head line of `slamcli solvers NAME`
