"""``make install`` needs no system package manager and no system headers: with apt-get/dpkg absent from PATH the
recipe make would run names neither, and its extras do not depend on what headers the machine holds. CI itself
runs the real ``make install`` with apt-get hidden and wheels only (``.ci/run``); this test checks the Makefile's
recipe (no download) and that the installed environment has CHOLMOD."""

from __future__ import annotations

import os
import re
import shutil
import subprocess
from pathlib import Path

import pytest
from conftest import ROOT

HIDDEN = re.compile(r"^(apt|apt-get|apt-cache|aptitude|dpkg.*)$")
pytestmark = pytest.mark.skipif(shutil.which("make") is None, reason="needs make")


def _path_without_package_managers(tmp_path: Path) -> str:
    """A PATH of one folder with links to every executable of the current PATH except apt*/dpkg*."""
    shadow = tmp_path / "bin"
    shadow.mkdir()
    for d in os.environ.get("PATH", "").split(os.pathsep):
        if not os.path.isdir(d):
            continue
        for name in os.listdir(d):
            f = os.path.join(d, name)
            if HIDDEN.match(name) or (shadow / name).exists() or not os.access(f, os.X_OK):
                continue
            (shadow / name).symlink_to(f)
    return str(shadow)


def _install_recipe(tmp_path: Path, include_dirs: Path) -> list[str]:
    path = _path_without_package_managers(tmp_path)
    assert shutil.which("apt-get", path=path) is None and shutil.which("dpkg", path=path) is None
    out = subprocess.run(["make", "-n", "install", f"INCLUDE_DIRS={include_dirs}"], cwd=ROOT, capture_output=True,
                         text=True, env={**os.environ, "PATH": path}, check=True, timeout=60).stdout
    return out.splitlines()


def _extras(lines: list[str]) -> set[str]:
    (line,) = [x for x in lines if "pip install" in x and " -e " in x]
    return set(re.search(r'"\.\[([^\]]*)\]"', line).group(1).split(","))


EXTRAS = {"test", "gtsam", "dask", "parquet", "dev", "interval", "fast", "docs"}


def test_install_names_no_package_manager(tmp_path):
    lines = _install_recipe(tmp_path, tmp_path / "no-include")
    assert not any(re.search(r"\b(apt-get|apt|dpkg|sudo|brew)\b", x) for x in lines), lines
    assert _extras(lines) == EXTRAS
    assert any("linear solver: " in x for x in lines)


def test_install_is_the_same_whatever_headers_the_machine_has(tmp_path):
    inc = tmp_path / "include"
    (inc / "suitesparse").mkdir(parents=True)
    (inc / "suitesparse" / "cholmod.h").write_text("/* stand-in */\n")
    (tmp_path / "a").mkdir()
    (tmp_path / "b").mkdir()
    assert _install_recipe(tmp_path / "a", inc) == _install_recipe(tmp_path / "b", tmp_path / "no-include")


def test_the_installed_environment_has_cholmod():
    # a core dependency (CVXOPT's wheel ships SuiteSparse): the graph path and the selected inverse are the
    # default everywhere, so their tests run on every install
    from slamcli.solvers import nls

    assert nls.cholmod_available()


def test_license_matches_pyproject():
    import tomllib

    meta = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]
    assert meta["license"] == "MIT" and "LICENSE" in meta["license-files"]
    assert (ROOT / "LICENSE").read_text().startswith("MIT License")
