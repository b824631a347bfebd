"""Experiment files (TOML) of the paper reproduction, shipped as package data.

``slamcli reproduce`` reads them from here; ``--experiments DIR`` (e.g. ``./experiments``) uses another
directory only when asked. :func:`path` gives the directory.
"""

from __future__ import annotations

from pathlib import Path


def path() -> Path:
    """Directory holding the packaged experiment files."""
    return Path(__file__).resolve().parent
