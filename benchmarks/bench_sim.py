"""Simulator speed: simulate + write ``paper-sim1`` (laser) and a 100 000-step ``loop`` world (point sensor).

Target (issue 2): ≥ 100 000 simulated steps per second with the point sensor. Each row reports the
simulation time (best of ``repeats``), steps/s (``meets_100k`` for the point sensor), the write time and file
size, the number of observations,
the peak traced memory of one simulation, and — as a reference measured in the same run —
``ref_integrate_s``: the shared dead-reckoning loop :func:`slamcli.models.motion.integrate` over the same
number of steps (the cheapest sequential DDMR recursion in the package); ``ratio_vs_ref`` =
sim / integrate time (< 1 means the whole simulator, controller and sensing included, is faster than that
bare loop).
"""

from __future__ import annotations

import os
import tempfile
import time
import tracemalloc
from pathlib import Path

import numpy as np

TARGET_STEPS_PER_S = 100_000


def _best(fn, repeats: int) -> tuple[float, object]:
    best, out = float("inf"), None
    for _ in range(repeats):
        t0 = time.perf_counter()
        out = fn()
        best = min(best, time.perf_counter() - t0)
    return best, out


def _row(label: str, scenario: str, overrides: dict, repeats: int, tmpdir: Path) -> dict:
    from slamcli.io import write_dataset
    from slamcli.models import motion
    from slamcli.sim import resolve_scenario, simulate

    cfg = resolve_scenario(scenario, overrides)
    sim_s, ds = _best(lambda: simulate(cfg, seed=1), repeats)
    path = tmpdir / f"{label}.h5"
    write_s, _ = _best(lambda: write_dataset(path, ds), max(1, repeats - 1))
    size_mb = os.path.getsize(path) / 1e6
    tracemalloc.start()
    simulate(cfg, seed=1)
    peak_mb = tracemalloc.get_traced_memory()[1] / 1e6
    tracemalloc.stop()
    T = cfg.n_steps
    ref_s, _ = _best(lambda: motion.integrate(ds.inputs.x0, ds.inputs.controls, cfg.dt), 1)
    return {
        "case": label,
        "steps": T,
        "landmarks": len(ds.truth.landmarks_xy),
        "observations": len(ds.inputs.observations),
        "simulate_s": sim_s,
        "steps_per_s": T / sim_s,
        "meets_100k": (T / sim_s >= TARGET_STEPS_PER_S) if cfg.sensor.kind == "point" else "",
        "write_s": write_s,
        "file_mb": size_mb,
        "peak_mem_mb": peak_mb,
        "ref_integrate_s": ref_s,
        "ratio_vs_ref": sim_s / ref_s,
    }


def run(quick: bool = False) -> list[dict]:
    n_big = 20_000 if quick else 100_000
    repeats = 1 if quick else 3
    with tempfile.TemporaryDirectory() as d:
        tmp = Path(d)
        rows = [
            _row("paper-sim1", "paper-sim1", {}, repeats, tmp),
            _row("paper-sim2", "paper-sim2", {}, repeats, tmp),
            _row("octagon", "octagon", {}, repeats, tmp),
            _row(f"loop-{n_big // 1000}k-point", "loop", {"n_steps": n_big}, repeats, tmp),
            _row(f"loop-{n_big // 1000}k-point-60lm", "loop",
                 {"n_steps": n_big, "world.n_landmarks": 60, "world.x_min": -20, "world.x_max": 40,
                  "world.y_min": -20, "world.y_max": 34, "world.min_separation": 1.5}, repeats, tmp),
        ]
    for r in rows:
        for k, v in r.items():
            if isinstance(v, (np.floating, np.integer)):
                r[k] = v.item()
    return rows


if __name__ == "__main__":
    for row in run():
        print(row)
