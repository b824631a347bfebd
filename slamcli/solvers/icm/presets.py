"""Named settings of ICM-SLAM (``-p preset=NAME``; issue 22 item 3).

``paper`` (the default) is Algorithm 2 as the paper runs it (with the deviations listed in
:mod:`slamcli.solvers.icm.solver`). ``real`` is the one setting documented for real recordings; its values were
chosen by measurement (``slamcli reproduce --section real``, the real-data section of the report):

* ``accelerate=joint, accelerate_every=1, joint_iters=20`` — joint Gauss-Newton steps in every sweep until the
  step or the decrease is negligible: Gauss-Seidel sweeps alone leave a long chain where the init put it;
* ``max_sweeps=5`` — with the joint steps the energy test stops the run after 2-3 sweeps on the recordings;
* ``merge=true`` — the χ² label merge after each map step (:mod:`slamcli.solvers.icm.merge`);
* ``init=gated, gate_prob=0.9999, birth_prob=0.999999`` — the on-line init whose χ² gate follows a propagated pose
  covariance (:mod:`slamcli.solvers.icm.init_gated`), with a wide gate: GPS ATE on the car park 0.073 m (paper
  init 0.443 m; gate 0.99 / birth 0.9999: 1.007 m), on the whole Victoria Park run 2.75 m in 19 s of CPU (paper
  init 4.99 m), first 300 s of it 1.396 m (paper init 1.390 m);
* ``weights=design`` (R = Q = I) — on the car park the information weights ended at 0.83 m GPS ATE against
  0.44 m with the identity weights (paper init, joint steps); see the report for every recording.

* **with sensor-reported ids** (MRCLAM's barcodes; :data:`WITH_IDS`) — ``correspondences=reported, init=online,
  weights=information, outlier_sigma=7, max_sweeps=30``: the ids are used (the init has no association to
  gate: the paper's on-line init with the ids; the gated one ended robot 1 at 1.05 m), the energy is the MAP energy of the
  dataset's noise model (the same factors as ``graph``'s), and a sighting more than 7 σ from its id's map point
  takes the null matching (:mod:`slamcli.solvers.icm.gate`), the ICM counterpart of ``graph``'s robust kernel.
  Measured on MRCLAM Dataset 7, robots 1-5 solo (ATE, m): identity weights 0.73 / 0.70 / 1.43 / 0.65 / 3.80,
  information weights 1.04 / 0.37 / 0.28 / 0.36 / 0.22 (robot 1 follows misread barcodes, as ``graph`` without
  a kernel does: 1.62 m), information weights + the 7 σ null matching 0.26 / 0.37 / 0.30 / 0.39 / 0.18 against
  ``graph``'s 0.27 / 0.41 / 0.31 / 0.46 / 0.16. On a team (multi-robot solves only; a one-robot solve ignores
  them) also ``team_range_weights=true, team_odometry_only=true``: MRCLAM Dataset 7, five robots, mean ATE
  0.136 m → 0.124 m (7 sweeps; ``graph`` 0.115 m) — range weights alone 0.130 m, the odometry alone 0.136 m,
  ``graph``'s Cauchy kernel (``robust=cauchy``) 0.152 m. Without ids (Victoria Park, car park) the identity weights stay:
  with the nearest-point matching the information weights ended at 0.83 m on the car park against 0.44 m.

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
             "max_sweeps": 30, "team_range_weights": True, "team_odometry_only": True},
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


def check_name(name: str) -> None:
    """Raise ValueError (one line) for an unknown preset name."""
    if name not in PRESETS:
        raise ValueError(f"preset must be one of {', '.join(PRESETS)}, got {name!r}")


def resolve(name: str, given: Mapping[str, Any], has_ids: bool) -> dict[str, Any]:
    """The keyword arguments of the resolved parameters: preset ``name``'s values (and, with ``has_ids``, its
    :data:`WITH_IDS` rule over them) for every key not in ``given``, then ``given`` itself."""
    check_name(name)
    filled = dict(PRESETS[name])
    if has_ids:
        rule = dict(WITH_IDS[name])
        if any(k in given for k in WEIGHT_KEYS) and rule.get("weights") == "information":
            del rule["weights"]  # the user's R, S, Q, K win over the dataset's noise model
        filled |= rule
    return {k: v for k, v in filled.items() if k not in given} | dict(given) | {"preset": name}


def weights_note(name: str, given: Mapping[str, Any], has_ids: bool) -> str:
    """One line when the preset's data rule would have set ``weights=information`` but explicit weight matrices
    kept ``weights=design``; ``""`` otherwise."""
    keys = [k for k in WEIGHT_KEYS if k in given]
    if not (has_ids and keys and "weights" not in given and WITH_IDS[name].get("weights") == "information"):
        return ""
    return f"preset={name}: weights=information not applied, {', '.join(keys)} given explicitly (weights=design uses them)"
