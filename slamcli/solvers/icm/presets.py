"""Named settings of ICM-SLAM (``-p preset=NAME``): the value tables :data:`PRESETS` and :data:`WITH_IDS`.

``paper`` (the default) is Algorithm 2 as the paper runs it; ``real`` is the setting for real recordings, with
more values when the dataset carries sensor-reported ids (:data:`WITH_IDS`). Why each value was chosen, with the
measurements: ``benchmarks/results/icm_presets.md``.

A preset is a named constructor (``IcmParams.real(**given)``), resolved once before the solver runs
(:func:`resolve`): it fills only the keys the user left unset — a key given explicitly keeps its value, whatever
that value is. With sensor-reported ids the :data:`WITH_IDS` rule fills more unset keys; weight matrices given
explicitly (``R``, ``S``, ``Q`` or ``K``) keep ``weights=design`` and the result says so (:func:`weights_note`).
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

#: preset name -> the parameters it sets (``slamcli solvers icm`` lists them)
PRESETS: dict[str, dict[str, Any]] = {
    "paper": {},
    "real": {
        "accelerate": "joint",
        "accelerate_every": 1,
        "joint_iters": 20,
        "max_sweeps": 5,
        "merge": True,
        "weights": "design",
        "init": "gated",
        "gate_prob": 0.9999,
        "birth_prob": 0.999999,
    },
}


#: preset name -> what it sets in addition when the dataset has sensor-reported ids (resolved with the dataset
#: before the solve, :func:`resolve`; only keys left unset)
WITH_IDS: dict[str, dict[str, Any]] = {
    "paper": {},
    "real": {"correspondences": "reported", "init": "online", "weights": "information", "outlier_sigma": 7.0,
             "max_sweeps": 30, "polish_rtol": 1.0, "polish_iters": 6, "polish_extrapolate": True,
             "observation": "range_bearing", "odometry_only": True,
             "team_range_weights": True,
             "team_odometry_only": True},
}


def _kv(items: dict[str, Any]) -> str:
    return ", ".join(f"{k}={str(v).lower() if isinstance(v, bool) else f'{v:g}' if isinstance(v, float) else v}"
                     for k, v in items.items())


def expansion_text(name: str) -> str:
    """``"k=v, …"`` of one preset (the text ``slamcli solvers icm`` shows), its with-ids rule included."""
    text = _kv(PRESETS[name]) or "paper defaults"
    return text + (f"; with sensor-reported ids also {_kv(WITH_IDS[name])}" if WITH_IDS[name] else "")


#: the design weight matrices that ``weights=information`` replaces
WEIGHT_KEYS = ("R", "S", "Q", "K")

#: what ``observation=range_bearing`` needs (the solver refuses other values); a rule that would set it leaves
#: it, and ``odometry_only`` chosen with it, unset when one of these is given otherwise (:func:`range_bearing_note`)
RANGE_BEARING_NEEDS: dict[str, Any] = {"correspondences": "reported", "polish": "nls", "covariance": False,
                                       "surface": False, "range_bias": "none"}
RANGE_BEARING_KEYS = ("observation", "odometry_only")


def range_bearing_conflicts(values: Mapping[str, Any]) -> list[str]:
    """The keys of :data:`RANGE_BEARING_NEEDS` whose value in ``values`` is not the one it needs."""
    return [k for k, need in RANGE_BEARING_NEEDS.items() if k in values and str(values[k]).lower() != str(need).lower()]


def _range_bearing_conflicts(given: Mapping[str, Any]) -> list[str]:
    return [f"{k}={given[k]}" for k in range_bearing_conflicts(given)]


def check_name(name: str) -> None:
    """Raise ValueError (one line) for an unknown preset name."""
    if name not in PRESETS:
        raise ValueError(f"preset must be one of {', '.join(PRESETS)}, got {name!r}")


def resolve(name: str, given: Mapping[str, Any], has_ids: bool) -> dict[str, Any]:
    """The keyword arguments of the resolved parameters: preset ``name``'s values (and, with ``has_ids``, its
    :data:`WITH_IDS` rule over them) for every key not in ``given``, then ``given`` itself."""
    check_name(name)
    conflict = [k for k in WEIGHT_KEYS if k in given] if given.get("weights") == "information" else []
    if conflict:  # also when a value equals its default: given is given
        raise ValueError(f"{', '.join(conflict)} given with weights=information, which takes R, S, Q, K from the "
                         "dataset's noise model: drop them or use weights=design")
    filled = dict(PRESETS[name])
    if has_ids:
        rule = dict(WITH_IDS[name])
        if any(k in given for k in WEIGHT_KEYS) and rule.get("weights") == "information":
            del rule["weights"]  # the user's R, S, Q, K win over the dataset's noise model
        if rule.get("observation") == "range_bearing" and _range_bearing_conflicts(given):
            for k in RANGE_BEARING_KEYS:
                rule.pop(k, None)
        filled |= rule
    return {k: v for k, v in filled.items() if k not in given} | dict(given) | {"preset": name}


def range_bearing_note(name: str, given: Mapping[str, Any], has_ids: bool) -> str:
    """One line when the preset's data rule would have set ``observation=range_bearing`` but a value it cannot
    run with was given (:data:`RANGE_BEARING_NEEDS`); ``""`` otherwise."""
    bad = _range_bearing_conflicts(given)
    if not (has_ids and bad and "observation" not in given
            and WITH_IDS[name].get("observation") == "range_bearing"):
        return ""
    return f"preset={name}: observation=range_bearing, odometry_only=true not applied, {', '.join(bad)} given"


def weights_note(name: str, given: Mapping[str, Any], has_ids: bool) -> str:
    """One line when the preset's data rule would have set ``weights=information`` but explicit weight matrices
    kept ``weights=design``; ``""`` otherwise."""
    keys = [k for k in WEIGHT_KEYS if k in given]
    if not (has_ids and keys and "weights" not in given and WITH_IDS[name].get("weights") == "information"):
        return ""
    return f"preset={name}: weights=information not applied, {', '.join(keys)} given explicitly (weights=design uses them)"
