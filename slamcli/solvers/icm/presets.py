"""Named settings of ICM-SLAM (``-p preset=NAME``; issue 22 item 3).

``paper`` (the default) is Algorithm 2 as the paper runs it (with the deviations listed in
:mod:`slamcli.solvers.icm.solver`). ``real`` is the one setting documented for real recordings; its values were
chosen by measurement (``slamcli reproduce --section real``, the real-data section of the report):

* ``accelerate=joint, accelerate_every=1, joint_iters=20`` — joint Gauss-Newton steps in every sweep until the
  step or the decrease is negligible: Gauss-Seidel sweeps alone leave a long chain where the init put it;
* ``max_sweeps=5`` — with the joint steps the energy test stops the run after 2-3 sweeps on the recordings;
* ``merge=true`` — the χ² label merge after each map step (:mod:`slamcli.solvers.icm.merge`);
* ``weights=design`` (R = Q = I) — on the car park the information weights ended at 0.83 m GPS ATE against
  0.44 m with the identity weights (paper init, joint steps); see the report for every recording.

A preset sets each of its keys that is still at its paper default; a key given explicitly with another value
wins (``-p preset=real -p weights=information``). A key set explicitly to its paper default cannot be told
apart from an unset one and takes the preset's value.
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
    },
}


def expansion_text(name: str) -> str:
    """``"k=v, …"`` of one preset (the text ``slamcli solvers icm`` shows)."""
    items = PRESETS[name]
    return ", ".join(f"{k}={str(v).lower() if isinstance(v, bool) else v}" for k, v in items.items()) or "paper defaults"


def apply_preset(params, defaults: dict[str, Any]) -> dict[str, Any]:
    """The field values ``params`` takes from its preset: each preset key whose current value equals its paper
    default ``defaults[key]``. Raises ValueError for an unknown preset name."""
    name = params.preset
    if name not in PRESETS:
        raise ValueError(f"preset must be one of {', '.join(PRESETS)}, got {name!r}")
    return {k: v for k, v in PRESETS[name].items() if getattr(params, k) == defaults[k]}
