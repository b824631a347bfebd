"""Which robust kernel should ``graph`` use by default on real data? (issue 10 item 3)

Cases, each solved with ``robust = none | huber | cauchy | geman_mcclure`` (GTSAM's m-estimators, default
widths 1.345 / 2.3849 / 1.0; the kernel acts on the observation factors, never on odometry or the prior):

* **MRCLAM Dataset 7, robots 1-5** — imported with ``slamcli import mrclam DIR --robot N`` (defaults: rows that
  see another robot or an unknown barcode dropped), sensor-reported barcode ids as the association
  (``association = auto`` → ``reported``). Misread barcodes are the outliers.
* **Simulator with clutter** — scenario ``loop`` with ``clutter.rate = 0.5`` false returns per scan, no reported
  ids (gated nearest-neighbour association, ``association = auto`` → ``nn``), seeds 1-3.

Per row: unaligned and SE(2)-aligned ATE RMSE against the ground truth (benchmark only; solvers never see it),
landmark RMSE (each estimated landmark against the true landmark most of its rows belong to), final cost,
iterations, wall time, and the χ² outlier counts of the observation factors at the estimate (whitened squared
residual above ``χ²₂(0.95) = 5.99`` / ``χ²₂(0.99) = 9.21``), as ``graph`` now reports them in
``extra["chi2_outliers"]``.

The decision is computed from the rows (:func:`decide`) and printed by ``python -m benchmarks.bench_robust_study``;
``--quick`` runs robots 1-2 and seed 1 only. Results: ``benchmarks/results/robust_study.csv``.
"""

from __future__ import annotations

import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

MRCLAM = Path(__file__).resolve().parent.parent.parent.parent / "shared" / "datasets" / "mrclam_dataset7"
if not MRCLAM.is_dir():
    MRCLAM = Path("/work/shared/datasets/mrclam_dataset7")
KERNELS = ("none", "huber", "cauchy", "geman_mcclure")
CLUTTER_RATE = 0.5


def _import_mrclam(robot: int, out: Path):
    from slamcli.io import read_dataset

    cli = Path(sys.executable).with_name("slamcli")
    cmd = [str(cli), "import", "mrclam", str(MRCLAM), "--robot", str(robot), "-q", "-o", str(out)]
    subprocess.run(cmd, check=True, capture_output=True, text=True)
    return read_dataset(out)


def _simulate(seed: int):
    from slamcli.sim import simulate_scenario

    return simulate_scenario("loop", seed=seed, overrides={"clutter.rate": CLUTTER_RATE, "sensor.report_ids": False})


def _map_rmse(res, truth) -> float:
    """RMSE of each estimated landmark against the true landmark most of its associated rows belong to."""
    errs = []
    for lab in range(len(res.landmarks_xy)):
        rows = np.flatnonzero(res.assoc == lab)
        true = truth.obs_landmark[rows]
        true = true[true >= 0]
        if not true.size:  # a landmark built only from clutter
            continue
        j = np.bincount(true).argmax()
        errs.append(np.linalg.norm(res.landmarks_xy[lab] - truth.landmarks_xy[j]))
    return float(np.sqrt(np.mean(np.square(errs)))) if errs else float("nan")


def _row(case: str, ds, kernel: str) -> dict:
    from slamcli.api.solve import solve_dataset
    from slamcli.metrics.trajectory import ate

    t0 = time.perf_counter()
    res = solve_dataset(ds.inputs, "graph", {"robust": kernel, "covariance": False})
    wall = time.perf_counter() - t0
    obs_counts = {k: v for k, v in res.extra["chi2_outliers"].items() if k in ("bearing_range", "landmark_xy")}
    o = next(iter(obs_counts.values()), {"factors": 0, "over_95": 0, "over_99": 0})
    return {
        "case": case,
        "robust": kernel,
        "status": res.status.value,
        "association": res.extra["association"],
        "ate_rmse_m": ate(res.poses_xyt, ds.truth.poses_xyt)["ate_rmse_m"],
        "ate_aligned_rmse_m": ate(res.poses_xyt, ds.truth.poses_xyt, align=True)["ate_rmse_m"],
        "map_rmse_m": _map_rmse(res, ds.truth),
        "n_landmarks": int(res.extra["n_landmarks"]),
        "final_cost": float(res.extra["final_cost"]),
        "iterations": int(res.extra["iterations"]),
        "wall_s": round(wall, 2),
        "obs_factors": int(o["factors"]),
        "obs_over_chi2_95": int(o["over_95"]),
        "obs_over_chi2_99": int(o["over_99"]),
        "odometry_over_chi2_99": int(res.extra["chi2_outliers"].get("odometry", {}).get("over_99", 0)),
    }


def run(quick: bool = False) -> list[dict]:
    """Measured in a child process with single-threaded BLAS (see bench_graph: a multi-threaded OpenBLAS on a
    loaded machine makes the dense Schur complements of ``graph`` up to ~100× slower); also writes
    ``results/robust_study.md`` with the decision and the table."""
    import json
    import os

    env = dict(os.environ, OPENBLAS_NUM_THREADS="1", OMP_NUM_THREADS="1", MKL_NUM_THREADS="1")
    cmd = [sys.executable, "-m", "benchmarks.bench_robust_study", "--rows"] + (["--quick"] if quick else [])
    out = subprocess.run(cmd, env=env, cwd=Path(__file__).resolve().parent.parent, capture_output=True, text=True,
                         check=True)
    rows = [json.loads(ln) for ln in out.stdout.splitlines() if ln.startswith("{")]
    write_report(rows, Path(__file__).resolve().parent / "results" / "robust_study.md")
    return rows


def write_report(rows: list[dict], path: Path) -> None:
    cols = ["case", "robust", "ate_rmse_m", "ate_aligned_rmse_m", "map_rmse_m", "n_landmarks", "iterations", "wall_s",
            "obs_factors", "obs_over_chi2_95", "obs_over_chi2_99"]
    lines = ["# Robust kernel study (benchmarks/bench_robust_study.py)", ""]
    lines += [f"* {s}" for s in decide(rows)]
    lines += ["", "| " + " | ".join(cols) + " |", "|" + "---|" * len(cols)]
    for r in rows:
        lines.append("| " + " | ".join(f"{r[c]:.4g}" if isinstance(r[c], float) else str(r[c]) for c in cols) + " |")
    path.parent.mkdir(exist_ok=True)
    tmp = path.with_suffix(".md.tmp")
    tmp.write_text("\n".join(lines) + "\n")
    tmp.replace(path)


def measure(quick: bool = False) -> list[dict]:
    rows = []
    robots = (1, 2) if quick else (1, 2, 3, 4, 5)
    seeds = (1,) if quick else (1, 2, 3)
    with tempfile.TemporaryDirectory() as tmp:
        for r in robots:
            ds = _import_mrclam(r, Path(tmp) / f"mrclam7_r{r}.h5")
            rows += [_row(f"mrclam7/robot{r}", ds, k) for k in KERNELS]
    for s in seeds:
        ds = _simulate(s)
        rows += [_row(f"sim-loop-clutter{CLUTTER_RATE:g}/seed{s}", ds, k) for k in KERNELS]
    return rows


def decide(rows: list[dict]) -> list[str]:
    """The default-kernel decision, every sentence computed from ``rows`` with the condition that makes it true."""
    out = []
    kinds = {"real": [r for r in rows if r["case"].startswith("mrclam")],
             "sim": [r for r in rows if r["case"].startswith("sim")]}

    def mean_ate(rs, k):
        v = [r["ate_rmse_m"] for r in rs if r["robust"] == k]
        return float(np.mean(v)) if v else float("nan")

    def worst_ratio(rs, k):
        """max over cases of ATE(k) / ATE(none)."""
        cases = sorted({r["case"] for r in rs})
        ratios = []
        for c in cases:
            a = {r["robust"]: r["ate_rmse_m"] for r in rs if r["case"] == c}
            if k in a and "none" in a and a["none"] > 0:
                ratios.append(a[k] / a["none"])
        return max(ratios) if ratios else float("nan")

    real, sim = kinds["real"], kinds["sim"]
    means = {k: mean_ate(real, k) for k in KERNELS}
    best = min((k for k in KERNELS if np.isfinite(means[k])), key=lambda k: means[k])
    out.append("mean unaligned ATE over the MRCLAM robots: " + ", ".join(f"{k} {means[k]:.3f} m" for k in KERNELS))
    out.append(f"lowest on real data: {best} ({means[best]:.3f} m vs none {means['none']:.3f} m, "
               f"worst case ratio to none {worst_ratio(real, best):.2f})")
    if sim:
        sm = {k: mean_ate(sim, k) for k in KERNELS}
        out.append("mean unaligned ATE on the simulator with clutter: " + ", ".join(f"{k} {sm[k]:.3f} m" for k in KERNELS))
        out.append(f"{best} on the simulator: worst case ratio to none {worst_ratio(sim, best):.3f} "
                   f"({'no case worse than 5 %' if worst_ratio(sim, best) <= 1.05 else 'worse than none by > 5 % in some case'})")
    # the rule: a kernel becomes the real-data default if it lowers the mean ATE by ≥ 10 % and is never worse
    # than none by more than 5 % in any real or simulated case
    ok = (means[best] <= 0.9 * means["none"] and worst_ratio(real, best) <= 1.05
          and (not sim or worst_ratio(sim, best) <= 1.05))
    out.append(f"decision: {'default robust=' + best + ' for sensor-reported ids' if ok and best != 'none' else 'keep robust=none'}"
               f" (rule: ≥ 10 % lower mean real-data ATE than none and never > 5 % worse in any case; "
               f"{'met' if ok else 'not met'})")
    return out


if __name__ == "__main__":  # pragma: no cover
    import json

    if "--rows" in sys.argv:  # the child process of run()
        for r in measure(quick="--quick" in sys.argv):
            print(json.dumps(r), flush=True)
    else:
        rows = run(quick="--quick" in sys.argv)
        for line in decide(rows):
            print(line)
