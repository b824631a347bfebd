"""Simulate workflow: named scenario + overrides + seed → dataset file.

The scenario and every override are resolved and validated *before* anything is simulated or written, so a
bad ``--set`` leaves no file behind; the file itself is written atomically by :func:`slamcli.io.write_dataset`.
"""

from __future__ import annotations

import os
from typing import Any

from slamcli.errors import ConfigError
from slamcli.types import Dataset, ProgressFn


def parse_overrides(items: list[str] | dict[str, Any] | None) -> dict[str, Any]:
    """``["sensor.max_range=10", ...]`` → ``{"sensor.max_range": "10"}`` (dicts pass through).

    Raises ConfigError (one line) on an item without ``=`` or with an empty key.
    """
    if items is None:
        return {}
    if isinstance(items, dict):
        return dict(items)
    from slamcli.params import split_override

    out: dict[str, Any] = {}
    for text in items:
        key, value = split_override(text, "--set")
        out[key] = value
    return out


def simulate_to_file(
    scenario: str,
    seed: int,
    overrides: list[str] | dict[str, Any] | None,
    out_path: str | os.PathLike,
    progress: ProgressFn | None = None,
) -> Dataset:
    """Resolve ``scenario`` with ``overrides``, simulate with ``seed`` and write the dataset to ``out_path``.

    Returns the simulated :class:`~slamcli.types.Dataset` (what was written).
    """
    from slamcli.io import write_dataset
    from slamcli.sim import resolve_scenario, simulate

    if int(seed) < 0:
        raise ConfigError(f"--seed: must be >= 0, got {seed}")
    cfg = resolve_scenario(scenario, parse_overrides(overrides))
    dataset = simulate(cfg, int(seed), progress=progress)
    write_dataset(out_path, dataset)
    return dataset
