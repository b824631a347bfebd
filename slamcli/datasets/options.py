"""Importer options named as the ``slamcli import <importer>`` flags without their dashes → one importer call.

Experiment files give a recording's import options this way (``robot = 3``, ``all-robots = true``,
``duration = 300``, ``range-std = 0.1``), plus ``solo = N`` beside ``robots``/``all-robots``: robot N of the
multi-robot import alone on the team's time grid (the file ``--solo-dir`` writes as ``robotN.h5``).
:func:`check_options` validates names and types (one line, "did you mean"), :func:`import_recording` runs the
importer. :data:`IMPORTER_VERSION` enters the content key of cached
imports: raise it whenever an importer's output for the same input changes.
"""

from __future__ import annotations

import re
from pathlib import Path
from typing import Any, Literal

from slamcli.errors import ConfigError

IMPORTER_VERSION = 1

_NOISE: dict[str, Any] = {"range-std": float | None, "bearing-std": float | None}
_CAR: dict[str, Any] = {"max-range": float, **_NOISE, "v-std": float | None, "steer-std": float | None}

#: importer → {option as its CLI flag without dashes: type}
OPTIONS: dict[str, dict[str, Any]] = {
    "mrclam": {"robot": int, "robots": tuple[int, ...] | None, "all-robots": bool, "dt": float, "start": float,
               "duration": float | None, "non-landmark": Literal["drop", "clutter"], "control-delay": float,
               "max-range": float, **_NOISE, "v-std": float | None, "omega-std": float | None, "no-truth": bool,
               "solo": int | None},
    "victoria-park": {"start": float, "duration": float | None, **_CAR},
    "carpark": _CAR,
    "g2o": {"dt": float, "forward": Literal["auto", "x", "y", "-x", "-y"], **_NOISE, "max-poses": int | None},
}


def check_options(importer: str, options: dict[str, Any], where: str) -> dict[str, Any]:
    """``options`` (flag names) coerced to their types, keyed by the flag name; one-line ConfigError
    ``"<where>.<flag>: ..."`` for an unknown option (with "did you mean") or a value of the wrong type."""
    from slamcli.params import convert, did_you_mean

    known = OPTIONS[importer]
    out = {}
    for key, value in options.items():
        if key not in known:
            raise ConfigError(f"{where}.{key}: not an option of `slamcli import {importer}`{did_you_mean(key, known)} "
                              f"(options: {', '.join(known)})")
        out[key] = convert(value, known[key], f"{where}.{key}")
    if importer == "mrclam" and out.get("solo") is not None and out.get("robots") is None \
            and not out.get("all-robots"):
        raise ConfigError(f"{where}.solo: needs a multi-robot import (robots = [...] or all-robots = true)")
    if importer == "mrclam" and (out.get("robots") is not None or out.get("all-robots")):
        team = "robots" if out.get("robots") is not None else "all-robots"
        clash = [k for k in ("robot", "no-truth", "non-landmark") if k in out]
        if team == "robots" and out.get("all-robots"):
            clash.insert(0, "all-robots")
        if clash:
            raise ConfigError(f"{where}.{clash[0]}: not an option of a multi-robot import ({team})")
    return out


def robot_numbers(directory: str | Path, robots: list[int] | tuple[int, ...] | None, all_robots: bool) -> list[int]:
    """The robots of a multi-robot MRCLAM import: ``robots`` as given, or (``all_robots``) every
    ``RobotN_Odometry.dat`` of ``directory`` in ascending N."""
    if not all_robots:
        return list(robots or ())
    return sorted(int(m.group(1)) for p in Path(directory).glob("Robot*_Odometry.dat")
                  if (m := re.fullmatch(r"Robot(\d+)_Odometry\.dat", p.name)))


def import_recording(importer: str, path: str | Path, options: dict[str, Any]):
    """Run ``importer`` on ``path`` with ``options`` (flag names, as :func:`check_options` returns them) →
    :class:`~slamcli.types.Dataset`. Importer failures are one-line :class:`DatasetImportError`."""
    o = {k.replace("-", "_"): v for k, v in options.items()}
    if importer == "g2o":
        from slamcli.datasets.g2o import import_graph

        return import_graph(path, **o)
    if importer in ("victoria-park", "carpark"):
        from slamcli.datasets import carpark, victoria_park

        mod = victoria_park if importer == "victoria-park" else carpark
        noise = mod.default_noise(**{k: o.pop(k) for k in ("range_std", "bearing_std", "v_std", "steer_std")
                                     if k in o})
        load = victoria_park.import_victoria_park if importer == "victoria-park" else carpark.import_carpark
        return load(path, noise=noise, **o)
    return _import_mrclam(path, o)


def _import_mrclam(path: str | Path, o: dict[str, Any]):
    from slamcli.datasets.mrclam import import_mrclam, import_mrclam_team, noise_from_options

    dt = o.pop("dt", 0.1)
    noise = noise_from_options(dt, *(o.pop(k, None) for k in ("range_std", "bearing_std", "v_std", "omega_std")))
    robots, all_robots, solo = o.pop("robots", None), o.pop("all_robots", False), o.pop("solo", None)
    if robots is None and not all_robots:
        return import_mrclam(path, o.pop("robot", 1), dt=dt, noise=noise, **o)
    team = import_mrclam_team(path, robot_numbers(path, robots, all_robots), dt=dt, noise=noise, **o)
    return team if solo is None else _solo(team, solo)


def _solo(team, number: int):
    """Robot ``number`` of a multi-robot import alone, on the team's time grid (``--solo-dir``'s robotN.h5)."""
    from slamcli.datasets import DatasetImportError
    from slamcli.datasets.team import solo_dataset

    numbers = [int(n) for n in team.inputs.robots.robot_number]
    if number not in numbers:
        raise DatasetImportError(f"solo = {number}: not one of the imported robots {numbers}")
    return solo_dataset(team, numbers.index(number))
