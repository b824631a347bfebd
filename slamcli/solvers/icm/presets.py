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
  weights=information, outlier_sigma=7, max_sweeps=30, polish_rtol=1, polish_iters=6``: the ids are used (the init has no association to
  gate: the paper's on-line init with the ids; the gated one ended robot 1 at 1.05 m), the energy is the MAP energy of the
  dataset's noise model (the same factors as ``graph``'s), and a sighting more than 7 σ from its id's map point
  takes the null matching (:mod:`slamcli.solvers.icm.gate`), the ICM counterpart of ``graph``'s robust kernel.
  Every sweep of a one-robot solve ends with the joint polish (``polish_rtol=1``), which then replaces the
  joint Gauss-Newton steps, and a polish stops after 6 LM iterations: the 7 σ gate re-matches after it, so
  the early polishes need not reach the optimum of matchings about to change; the run still stops only when
  a sweep and its polish move nothing (``benchmarks/results/icm_mrclam.md``).
  Measured on MRCLAM Dataset 7, robots 1-5 solo (ATE, m): identity weights 0.73 / 0.70 / 1.43 / 0.65 / 3.80,
  information weights 1.04 / 0.37 / 0.28 / 0.36 / 0.22 (robot 1 follows misread barcodes, as ``graph`` without
  a kernel does: 1.62 m), information weights + the 7 σ null matching 0.26 / 0.37 / 0.30 / 0.39 / 0.18 against
  ``graph``'s 0.27 / 0.41 / 0.31 / 0.46 / 0.16. On a team (multi-robot solves only; a one-robot solve ignores
  them) also ``team_range_weights=true, team_odometry_only=true``: MRCLAM Dataset 7, five robots, mean ATE
  0.136 m → 0.124 m (7 sweeps; ``graph`` 0.115 m) — range weights alone 0.130 m, the odometry alone 0.136 m,
  ``graph``'s Cauchy kernel (``robust=cauchy``) 0.152 m. Without ids (Victoria Park, car park) the identity weights stay:
  with the nearest-point matching the information weights ended at 0.83 m on the car park against 0.44 m.

A preset sets each of its keys that is still at its paper default; a key given explicitly with another value
wins (``-p preset=real -p weights=information``). A key set explicitly to its paper default cannot be told
apart from an unset one and takes the preset's value. Weight matrices given explicitly (``R``, ``S``, ``Q`` or
``K`` away from their defaults) keep ``weights=design``: the data rule's ``weights=information``, which would
replace them by the dataset's noise model, is then not applied, and the result says so
(:func:`weights_note`).
"""

from __future__ import annotations

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


#: preset name -> what it sets in addition when the dataset has sensor-reported ids (applied at solve time,
#: :func:`apply_data_rule`; the same "still at its paper default" rule)
WITH_IDS: dict[str, dict[str, Any]] = {
    "paper": {},
    "real": {"correspondences": "reported", "init": "online", "weights": "information", "outlier_sigma": 7.0,
             "max_sweeps": 30, "polish_rtol": 1.0, "polish_iters": 6, "team_range_weights": True,
             "team_odometry_only": True},
}


def _kv(items: dict[str, Any]) -> str:
    return ", ".join(f"{k}={str(v).lower() if isinstance(v, bool) else f'{v:g}' if isinstance(v, float) else v}"
                     for k, v in items.items())


def expansion_text(name: str) -> str:
    """``"k=v, …"`` of one preset (the text ``slamcli solvers icm`` shows), its with-ids rule included."""
    text = _kv(PRESETS[name]) or "paper defaults"
    return text + (f"; with sensor-reported ids also {_kv(WITH_IDS[name])}" if WITH_IDS[name] else "")


def apply_data_rule(params, defaults: dict[str, Any], has_ids: bool) -> dict[str, Any]:
    """The field values ``params`` takes from its preset's data rule: with ``has_ids``, each :data:`WITH_IDS`
    key whose current value equals its paper default ``defaults[key]`` or the value the preset itself gave it;
    nothing otherwise."""
    if not has_ids:
        return {}
    base = defaults | PRESETS[params.preset]
    out = {k: v for k, v in WITH_IDS[params.preset].items() if getattr(params, k) == base[k]}
    if explicit_weights(params, defaults) and out.get("weights") == "information":
        del out["weights"]  # the user's R, S, Q, K win over the dataset's noise model
    return out


#: the design weight matrices that ``weights=information`` replaces
WEIGHT_KEYS = ("R", "S", "Q", "K")


def explicit_weights(params, defaults: dict[str, Any]) -> list[str]:
    """The design weight matrices ``params`` holds away from their paper defaults (given explicitly)."""
    return [k for k in WEIGHT_KEYS if getattr(params, k) != defaults[k]]


def weights_note(params, defaults: dict[str, Any], has_ids: bool) -> str:
    """One line when the preset's data rule would have set ``weights=information`` but explicit weight matrices
    kept ``weights=design``; ``""`` otherwise."""
    given = explicit_weights(params, defaults)
    if not (has_ids and given and WITH_IDS[params.preset].get("weights") == "information"
            and params.weights == "design"):
        return ""
    return (f"preset={params.preset}: weights=information not applied, {', '.join(given)} given explicitly "
            "(weights=design uses them)")


def apply_preset(params, defaults: dict[str, Any]) -> dict[str, Any]:
    """The field values ``params`` takes from its preset: each preset key whose current value equals its paper
    default ``defaults[key]``. Raises ValueError for an unknown preset name."""
    name = params.preset
    if name not in PRESETS:
        raise ValueError(f"preset must be one of {', '.join(PRESETS)}, got {name!r}")
    return {k: v for k, v in PRESETS[name].items() if getattr(params, k) == defaults[k]}
