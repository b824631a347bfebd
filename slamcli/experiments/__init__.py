"""The experiment files (TOML) of the paper reproduction and the sweeps, by name.

They live in the repository's top-level ``experiments/`` folder; a wheel carries copies inside this package
(``setup.py`` copies them at build time). :func:`path` gives whichever holds them: this package's folder when it
has TOML files (a wheel install), else ``experiments/`` beside the package (a checkout or editable install).
``slamcli reproduce`` and ``slamcli sweep NAME`` read them from there.
"""

from __future__ import annotations

from pathlib import Path


def path() -> Path:
    """Directory holding the shipped experiment files."""
    here = Path(__file__).resolve().parent
    if any(here.glob("*.toml")):
        return here
    return here.parents[1] / "experiments"


def names() -> list[str]:
    """Names of the shipped experiments (file stems), sorted."""
    return sorted(p.stem for p in path().glob("*.toml"))


def find(name: str) -> Path | None:
    """The shipped experiment file called ``name`` (with or without ``.toml``), or None."""
    stem = name[:-5] if name.endswith(".toml") else name
    if "/" in stem or "\\" in stem or stem not in names():
        return None
    return path() / f"{stem}.toml"
