"""cuik (paper 004) throughput: contractions/s, propagations/s, live hypotheses per step and total time.

Rows (seed 1 unless said otherwise):

* ``cuik-room`` with unknown correspondence (types only): the scenario default (full set: θ narrowing,
  closest-landmark negative information, declared 5 m landmark separation), the same without the separation
  prior (``bounded.declared_separation=0``), and the paper operator set without it; the full set with the
  final 3B shaving (4 slices) + bisection (64 leaves) pass; and the unique correspondence (true association,
  one graph) as the reference for the cost of branching; the unique correspondence with the branch-and-bound
  hull pass (``hull_leaves``, 10 quick / 100 full), the same with the LP contractor (``lp_rounds=2``) and the
  LP-bounded hull pass (``hull_lp``), the unknown correspondence with ``lp_rounds=2``, and in Porta's setting
  (``cuik-room-porta``) — ``ratio`` = seconds of the row / seconds of the unique-correspondence full-set run in
  the same process.
* ``cuik-corridors`` (14 typed landmarks, 45 legs, declared 4 m separation) with the hypothesis cap 16 and the
  two cap rankings ``parsimony_volume`` (default: fewest landmarks, then largest box volume) and
  ``parsimony_area`` (fewest landmarks, then smallest landmark box area); full mode also runs seeds 0-4 with
  the default ranking (survival rate over seeds): status, whether the true correspondence survived the cap,
  and the live hypotheses after each pose (as a ``;``-separated list).

``contractions`` counts narrowing-operator applications, ``propagations`` fixpoint runs (one per new edge
per hypothesis, plus the 3B/bisection trials). Times are the best of ``repeats`` solves.
"""

from __future__ import annotations

import dataclasses
import time

import numpy as np

from slamcli.api.solve import solve_dataset
from slamcli.metrics import sets
from slamcli.sim import simulate_scenario


def _known(ds):
    obs = dataclasses.replace(ds.inputs.observations, reported_id=ds.truth.obs_landmark.copy())
    return dataclasses.replace(ds.inputs, observations=obs)


def _row(name, inputs, ds, params, repeats):
    best, r = float("inf"), None
    for _ in range(repeats):
        t0 = time.perf_counter()
        r = solve_dataset(inputs, "cuik", params)
        best = min(best, time.perf_counter() - t0)
    m = (sets.set_metrics(r.hypotheses, ds.truth.poses_xyt, ds.truth.landmarks_xy, ds.truth.obs_landmark)
         if r.hypotheses is not None else {})
    live = r.extra.get("live_hypotheses_per_step", [])
    return {
        "run": name,
        "params": " ".join(f"{k}={v}" for k, v in params.items()) or "defaults",
        "status": r.status.value,
        "seconds": best,
        "contractions": r.extra["contractions"],
        "propagations": r.extra["propagations"],
        "contractions_per_s": r.extra["contractions"] / best,
        "propagations_per_s": r.extra["propagations"] / best,
        "hypotheses_final": len(r.hypotheses) if r.hypotheses is not None else 0,
        "live_max": max(live) if live else 0,
        "live_per_step": ";".join(str(x) for x in live),
        "true_correspondence_survived": m.get("true_correspondence_survived"),
        "soundness": m.get("soundness"),
        "landmark_width_mean_m": m.get("true_landmark_width_mean", m.get("best_landmark_width_mean")),
    }


def run(quick: bool = False) -> list[dict]:
    repeats = 1 if quick else 3
    room = simulate_scenario("cuik-room", 1)
    room0 = simulate_scenario("cuik-room", 1, {"bounded.declared_separation": 0.0})
    rows = [_row("cuik-room/unique", _known(room), room, {"association": "reported"}, repeats)]
    ref = rows[0]["seconds"]
    rows.append(_row("cuik-room/unknown", room.inputs, room, {}, repeats))
    rows.append(_row("cuik-room/unknown-no-separation", room0.inputs, room0, {}, repeats))
    rows.append(_row("cuik-room/unknown-no-separation", room0.inputs, room0,
                     {"narrow_theta": False, "negative_information": False}, repeats))
    rows.append(_row("cuik-room/unique", _known(room), room,
                     {"association": "reported", "shave_slices": 4, "bisect_leaves": 64}, repeats))
    rows.append(_row("cuik-room/unique", _known(room), room,
                     {"association": "reported", "shave_slices": 4, "bisect_leaves": 64,
                      "hull_leaves": 10 if quick else 100}, 1))
    rows.append(_row("cuik-room/unique", _known(room), room,
                     {"association": "reported", "shave_slices": 4, "bisect_leaves": 64, "lp_rounds": 2,
                      "hull_leaves": 10 if quick else 100, "hull_lp": True}, 1))
    rows.append(_row("cuik-room/unknown", room.inputs, room, {"lp_rounds": 2}, 1))
    porta = simulate_scenario("cuik-room-porta", 1)
    rows.append(_row("cuik-room-porta/unique", porta.inputs, porta, {"association": "reported"}, repeats))
    corr = simulate_scenario("cuik-corridors", 1)
    for rank in ("parsimony_volume",) if quick else ("parsimony_volume", "parsimony_area"):
        rows.append(_row("cuik-corridors/unknown", corr.inputs, corr, {"max_hypotheses": 16, "rank": rank}, 1))
    if not quick:
        for seed in (0, 2, 3, 4):
            ds = simulate_scenario("cuik-corridors", seed)
            rows.append(_row(f"cuik-corridors/unknown seed {seed}", ds.inputs, ds, {"max_hypotheses": 16}, 1))
    rows.append(_row("cuik-corridors/unique", _known(corr), corr, {"association": "reported"}, 1))
    for r in rows:
        r["ratio_vs_room_unique"] = r["seconds"] / ref if ref > 0 else np.nan
    return rows
