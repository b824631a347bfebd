"""Is the Victoria Park importer's default noise calibrated? Variance-component estimation (VCE) at the batch
optimum of the incremental smoother's association — the GPS is used nowhere in it.

Per window (the first 300 s; without ``--quick`` also the full run): ``isam`` with its defaults on the
default-noise import gives the association (which detection is which landmark) and a starting estimate.
Then, round by round, ``graph``'s factor graph of that association (laser frame, every pose: per-step odometry
between factors, range-bearing factors, no kernel) is solved by LM from the previous optimum, and
:func:`slamcli.solvers.nls.variance.variance_components` gives each factor group's variance factor
``r_g = Σ whitened residual² / redundancy`` (exact redundancy ``n_g − tr(J_g H⁻¹ J_gᵀ)`` through the selected
inverse of ``H``; the common approximation ``n_g (1 − n/m)`` beside it). Groups: odometry x (along the
heading), odometry lateral, odometry heading, range, bearing — the importer's ``odometry_std`` (x, lateral,
θ) and ``range_std`` / ``bearing_std``. Every σ is scaled by ``√r_g`` and the next round re-solves, until
every ``|r_g − 1| ≤ TOL`` (the simple iterated estimator; Förstner 1979) — the rounds are
:func:`slamcli.solvers.graph.calibrate_noise`, the estimator of ``isam -p noise=vce``, here to a tighter TOL.
``σ_*`` columns are the σ the round *assumed*, ``r_*`` what it measured; the last round's ``σ·√r`` is the
calibrated noise.

Then, per window: (a) a synthetic check of the estimator on this very problem — measurements drawn with the
calibrated σ around isam's estimate (same steps, association and geometry, seeded), VCE from the defaults
again: the table gives recovered / true σ; (b) ``isam`` on the import with the calibrated noise (odometry
and laser σ; the control σ, unused by ``graph`` and ``isam``, stay), at its default gate and at
``gate_prob`` :data:`WIDE_GATE`; (c) VCE again on the wide gate's association (does the calibration hold on
the association its own noise gives?).

The ``gps_ate_m`` / ``isam_gps_ate_m`` columns (``slamcli evaluate``'s aligned GPS ATE, glitch gate on)
describe each optimum; they take no part in the estimate.

Run: ``OMP_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1 python -m benchmarks vp_noise [--quick]``; writes
``benchmarks/results/vp_noise.csv`` and ``benchmarks/results/vp_noise.md``.
"""

from __future__ import annotations

import dataclasses
import os
import time
from pathlib import Path

os.environ.setdefault("OMP_NUM_THREADS", "1")
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import numpy as np

from benchmarks.bench_isam import _victoria
from slamcli.solvers.graph.variance import NOISE_GROUPS

HERE = Path(__file__).resolve().parent
GROUPS = NOISE_GROUPS
#: converged when every variance factor is within this of 1
TOL = 0.002
MAX_ROUNDS = 20
#: the wide χ² gate probability tried with the calibrated noise (χ²₂ threshold 41.4 against 13.8 at isam's 0.999)
WIDE_GATE = 1 - 1e-9
#: seed of the synthetic check's draws
SEED = 2026


def isam_run(dataset, gate_prob: float | None = None):
    """``isam`` (defaults, or another ``gate_prob``) on ``dataset``: ``(inputs in the laser frame, association
    (N,), laser-frame poses (T+1, 3), landmarks (L, 2), summary row)``."""
    from benchmarks.bench_isam import _ate, _to_body, run_smoother
    from slamcli.solvers import frontend
    from slamcli.solvers.isam import IsamParams

    p = IsamParams() if gate_prob is None else IsamParams(gate_prob=gate_prob)
    inp, sm, cpu = run_smoother(dataset, p)  # Victoria Park reports no ids: nearest-neighbour association
    assoc, old_of_new = frontend.compact_labels(sm.assoc)
    ate, raw = _ate(dataset, _to_body(sm.poses(), dataset.inputs))
    summary = {"gate_prob": p.gate_prob, "isam_landmarks": int(old_of_new.size), "isam_cpu_s": cpu,
               "isam_gps_ate_m": ate, "isam_gps_ate_raw_m": raw}
    return inp, assoc, sm.poses(), sm.landmarks()[old_of_new], summary


def vce(name: str, stage: str, dataset, inp, assoc, poses, lms) -> list[dict]:
    """The iterated VCE rounds (module docstring; :func:`slamcli.solvers.graph.calibrate_noise`, the estimator
    of ``isam -p noise=vce``) from the import's noise on one association; one row per round (``dataset``
    None: no GPS ATE column)."""
    from benchmarks.bench_isam import _ate, _to_body
    from slamcli.solvers.graph import calibrate_noise, noise_sigmas

    sig0 = noise_sigmas(inp.noise)
    rows = []
    clock = [time.process_time()]

    def record(rnd, gp, res):
        vc, sig = rnd.components, sig0 * rnd.scale
        n = gp.problem.n_vars
        poses_r, _ = gp.unpack(res.x)
        row = {"window": name, "stage": stage, "round": len(rows), "n_vars": n,
               "n_rows": int(sum(b.n_factors * np.shape(b.sqrt_info)[-1] for b in gp.problem.blocks)),
               "landmarks": gp.n_landmarks, "lm_message": res.message, "cpu_s": time.process_time() - clock[0],
               "gps_ate_m": float("nan") if dataset is None else _ate(dataset, _to_body(poses_r, dataset.inputs))[0]}
        approx = vc.ssr / (vc.n_obs * (1.0 - n / row["n_rows"]))  # ρ_g ≈ n_g (1 − n/m), m over every row
        for i, g in enumerate(GROUPS):
            row.update({f"sigma_{g}": sig[i], f"n_{g}": int(vc.n_obs[i]), f"redundancy_{g}": vc.redundancy[i],
                        f"r_{g}": vc.ratio[i], f"r_approx_{g}": approx[i]})
        rows.append(row)
        print(f"{name} / {stage} round {row['round']}: " + " ".join(
            f"{g} σ {sig[i]:.4g} r {vc.ratio[i]:.4f}" for i, g in enumerate(GROUPS))
            + f"  ATE {row['gps_ate_m']:.3f}", flush=True)
        clock[0] = time.process_time()

    calibrate_noise(inp, assoc, poses, lms, tol=TOL, max_reweights=MAX_ROUNDS - 1, on_round=record)
    return rows


def synthetic(inp, assoc, poses, lms, sigma, seed: int):
    """The same problem (steps, association, geometry) with measurements drawn around ``poses (T+1, 3)`` and
    ``lms (L, 2)`` with known σ = ``sigma`` (odometry x, lateral, heading per step, range, bearing): per-step
    odometry ``d_t = (x_t⁻¹ ⊕ x_{t+1}) ⊕ Exp(−ε_t)``, ε_t ~ N(0, diag σ²) (so ``graph``'s between error at
    the generating poses is ε_t), integrated from ``x_0``; associated sightings ``h(x, m) + N(0, σ²)``."""
    from slamcli.models import se2
    from slamcli.models.angles import wrap_angle
    from slamcli.models.observation import range_bearing

    rng = np.random.default_rng(seed)
    sigma = np.asarray(sigma, float)
    eps = rng.normal(size=(poses.shape[0] - 1, 3)) * sigma[:3]
    d = se2.compose(se2.between(poses[:-1], poses[1:]), se2.exp(-eps))
    th = poses[0, 2] + np.concatenate([[0.0], np.cumsum(d[:, 2])])
    c, s = np.cos(th[:-1]), np.sin(th[:-1])
    step_xy = np.stack([c * d[:, 0] - s * d[:, 1], s * d[:, 0] + c * d[:, 1]], -1)
    odo = np.column_stack([poses[0, :2] + np.vstack([[0.0, 0.0], np.cumsum(step_xy, 0)]), wrap_angle(th)])
    obs = inp.observations
    z = np.array(obs.z, float)
    rows = np.flatnonzero(assoc >= 0)
    zt = range_bearing(poses[np.asarray(obs.step)[rows]], lms[assoc[rows]])
    z[rows, 0] = zt[:, 0] + sigma[3] * rng.normal(size=rows.size)
    z[rows, 1] = wrap_angle(zt[:, 1] + sigma[4] * rng.normal(size=rows.size))
    return dataclasses.replace(inp, x0=np.array(poses[0], float), odometry_xyt=odo,
                               observations=dataclasses.replace(obs, range_m=z[:, 0], bearing_rad=z[:, 1]))


def calibrated(rows: list[dict], window: str, stage: str) -> dict:
    """The calibrated σ of a window and stage (its last round's σ·√r) and their ratios to the import's
    defaults."""
    from slamcli.datasets.victoria_park import default_noise
    from slamcli.solvers.graph import noise_sigmas

    last = [r for r in rows if r["window"] == window and r["stage"] == stage][-1]
    default = dict(zip(GROUPS, noise_sigmas(default_noise())))
    out = {"window": window, "stage": stage, "rounds": last["round"] + 1}
    for g in GROUPS:
        s = last[f"sigma_{g}"] * np.sqrt(last[f"r_{g}"])
        out[f"sigma_{g}"] = s
        out[f"factor_{g}"] = s / default[g]
        out[f"redundancy_share_{g}"] = last[f"redundancy_{g}"] / last[f"n_{g}"]
        out[f"rel_sd_{g}"] = 1.0 / np.sqrt(2.0 * last[f"redundancy_{g}"])  # of σ̂ (a χ²_ρ variance estimate)
    return out


def calibrated_noise(cal: dict):
    """The importer's default :class:`NoiseSpec` with the calibrated odometry and laser σ (the control σ, which
    ``graph`` and ``isam`` do not use, stay the defaults)."""
    from slamcli.datasets.victoria_park import default_noise
    from slamcli.solvers.graph import noise_with_sigmas

    return noise_with_sigmas(default_noise(), [cal[f"sigma_{g}"] for g in GROUPS])


def write_markdown(rows: list[dict], isam_rows: list[dict]) -> Path:
    lines = ["# Victoria Park noise: iterated variance-component estimation",
             "", "Generated by `python -m benchmarks vp_noise` (module docstring: method).", "",
             "| window | association | round | " + " | ".join(f"σ {g} | r {g}" for g in GROUPS)
             + " | r≈ range | r≈ bearing | GPS ATE m |", "|" + "---|" * (5 + 2 * len(GROUPS) + 1)]
    for r in rows:
        cells = [r["window"], r["stage"], str(r["round"])]
        for g in GROUPS:
            cells += [f"{r[f'sigma_{g}']:.4g}", f"{r[f'r_{g}']:.3f}"]
        cells += [f"{r['r_approx_range']:.3f}", f"{r['r_approx_bearing']:.3f}", f"{r['gps_ate_m']:.3f}"]
        lines.append("| " + " | ".join(cells) + " |")
    lines += ["", "Calibrated σ (last round's σ·√r), its factor against the import's defaults (×), the group's "
              "redundancy share ρ/n and the σ estimate's relative standard deviation 1/√(2ρ):", "",
              "| window | association | rounds | " + " | ".join(f"σ {g} (×; ρ/n; sd)" for g in GROUPS) + " |",
              "|" + "---|" * (3 + len(GROUPS))]
    for w, st in dict.fromkeys((r["window"], r["stage"]) for r in rows):
        c = calibrated(rows, w, st)
        lines.append(f"| {w} | {st} | {c['rounds']} | " + " | ".join(
            f"{c[f'sigma_{g}']:.4g} (×{c[f'factor_{g}']:.2f}; {c[f'redundancy_share_{g}']:.3f}; "
            f"{100 * c[f'rel_sd_{g}']:.1f} %)" for g in GROUPS) + " |")
    lines += ["", "Synthetic check (measurements drawn with the first association's calibrated σ, VCE from the "
              "defaults): recovered σ / true σ, and that ratio's distance from 1 in standard deviations "
              "1/√(2ρ):", "", "| window | " + " | ".join(GROUPS) + " |", "|" + "---|" * (1 + len(GROUPS))]
    for w in dict.fromkeys(r["window"] for r in rows if r["stage"] == "synthetic, σ known"):
        c = calibrated(rows, w, "synthetic, σ known")
        last = [r for r in rows if r["window"] == w and r["stage"] == "synthetic, σ known"][-1]
        q = [c[f"sigma_{g}"] / last[f"true_sigma_{g}"] for g in GROUPS]
        lines.append(f"| {w} | " + " | ".join(f"{v:.4f} ({(v - 1) / c[f'rel_sd_{g}']:+.1f} sd)"
                                              for v, g in zip(q, GROUPS)) + " |")
    lines += ["", "`isam` on the default import and on the VCE-calibrated one (calibrated on the default "
              "association of the same window):", "",
              "| window | noise | gate_prob | landmarks | GPS ATE m | raw ATE m | CPU s |", "|" + "---|" * 7]
    for r in isam_rows:
        lines.append(f"| {r['window']} | {r['noise']} | {r['gate_prob']:.10g} | {r['isam_landmarks']} | "
                     f"{r['isam_gps_ate_m']:.3f} | {r['isam_gps_ate_raw_m']:.3f} | {r['isam_cpu_s']:.1f} |")
    path = HERE / "results" / "vp_noise.md"
    path.parent.mkdir(exist_ok=True)
    tmp = path.with_suffix(".md.tmp")
    tmp.write_text("\n".join(lines) + "\n", encoding="utf-8")
    tmp.replace(path)
    return path


def run(quick: bool = False) -> list[dict]:
    rows: list[dict] = []
    isam_rows: list[dict] = []
    for name, duration in [("first 300 s", 300.0)] + ([] if quick else [("full", None)]):
        ds = _victoria(duration)
        inp, assoc, poses, lms, summary = isam_run(ds)
        isam_rows.append({"window": name, "noise": "defaults", **summary})
        rows += vce(name, "isam, defaults", ds, inp, assoc, poses, lms)
        cal = calibrated(rows, name, "isam, defaults")
        # the estimator's check: measurements drawn with the calibrated σ around isam's estimate, same
        # association and geometry, VCE from the defaults again — does it recover the σ it was given?
        truth = [cal[f"sigma_{g}"] for g in GROUPS]
        syn = vce(name, "synthetic, σ known", None, synthetic(inp, assoc, poses, lms, truth, SEED), assoc,
                  poses, lms)
        rows += [{**r, **{f"true_sigma_{g}": t for g, t in zip(GROUPS, truth)}} for r in syn]
        # the same recording with the calibrated noise (the importer only stores the noise: no re-read)
        ds_cal = dataclasses.replace(ds, inputs=dataclasses.replace(ds.inputs, noise=calibrated_noise(cal)))
        for gate in (None, WIDE_GATE):
            inp, assoc, poses, lms, summary = isam_run(ds_cal, gate)
            isam_rows.append({"window": name, "noise": "VCE", **summary})
        # does the calibration hold on the association its own noise gives? (the wide gate's)
        rows += vce(name, "isam, VCE noise, wide gate", ds_cal, inp, assoc, poses, lms)
    write_markdown(rows, isam_rows)
    return rows + isam_rows
