"""Reproduction section for paper 001 (Chakravorty & Saha, hybrid Bayesian/frequentist SLAM), Figs. 2-9.

``run_section(out_dir, quick, progress) -> (markdown, ok)`` simulates the paper's maps, runs the ``hybrid``
solver (which also builds the log-odds baseline of eq. 24 from the same belief mean), draws subfigures (a)-(h)
per run and the §II.D counterexample (Fig. 2), and writes a markdown section whose every outcome sentence is
computed from the run's own numbers. Finished runs are reused (the result file is kept under ``out_dir``).

Two sections, so that the long Map 4 run comes last in ``make reproduce`` and can be run on its own:
``run_section`` (key ``paper001``) — Maps 1-3 with both sensors, the Map 3 posts variant and Fig. 2;
``run_section_map4`` (key ``paper001-map4``) — Map 4 with the laser, 2 laps, as the paper. Quick mode: a small
Map 1 (40 m square, 8 m corridor, 1 m cells, 60 beams) with both sensors, and the first 120 steps of Map 4 —
smoke checks, named as such. Each section states every run's wall and CPU time.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from slamcli.types import LogFn

_QUICK_OVERRIDES = {"walls.width": 40.0, "walls.height": 40.0, "walls.corridor": 8.0, "walls.resolution": 1.0,
                    "sensor.n_beams": 60, "walls.laps": 2}
_QUICK_MAP4 = {"walls.laps": 0, "n_steps": 120, "walls.resolution": 1.0, "sensor.n_beams": 60}


@dataclass
class Run:
    label: str
    scenario: str
    sensor: str
    map_no: int
    overrides: dict = field(default_factory=dict)
    params: dict = field(default_factory=dict)


def planned_runs(quick: bool, part: str = "all") -> list[Run]:
    """The runs (paper §III: Maps 1-3 with both sensors, Map 4 with the laser, 2 laps); ``part`` = ``"maps"``
    (Maps 1-3 and the posts variant), ``"map4"`` or ``"all"``."""
    if quick:
        runs = [Run("Map 1 (small) laser", "hybrid-map1", "laser", 1, dict(_QUICK_OVERRIDES), {"resolution": 1.0}),
                Run("Map 1 (small) noisy", "hybrid-map1-noisy", "noisy", 1, dict(_QUICK_OVERRIDES),
                    {"resolution": 1.0})]
        map4 = [Run("Map 4 laser, first 120 steps", "hybrid-map4", "laser", 4, dict(_QUICK_MAP4),
                    {"resolution": 1.0, "n_snapshots": 2})]
    else:
        runs = []
        for k in (1, 2, 3):
            runs.append(Run(f"Map {k} laser", f"hybrid-map{k}", "laser", k))
            runs.append(Run(f"Map {k} noisy", f"hybrid-map{k}-noisy", "noisy", k))
        runs.append(Run("Map 3 posts, laser", "hybrid-map3-posts", "laser", 3))
        map4 = [Run("Map 4 laser", "hybrid-map4", "laser", 4, {"walls.laps": 2}, {"n_snapshots": 8})]
    return {"maps": runs, "map4": map4, "all": runs + map4}[part]


def _slug(s: str) -> str:
    return "".join(c if c.isalnum() else "-" for c in s.lower()).strip("-")


def _execute(run: Run, out: Path, seed: int = 1) -> tuple[Path, Path]:
    """Simulate + solve (reusing finished files); returns (dataset path, result path)."""
    from slamcli.io import dataset_hash, read_result, write_dataset, write_result
    from slamcli.sim.simulate import simulate_scenario
    from slamcli.solvers.hybrid import HybridParams, HybridSlam

    d = out / _slug(run.label)
    d.mkdir(parents=True, exist_ok=True)
    dpath, rpath = d / "data.h5", d / "result.h5"
    if dpath.is_file() and rpath.is_file():
        from slamcli.errors import SlamcliError

        try:
            read_result(rpath)
            return dpath, rpath
        except SlamcliError:  # a broken file is simply redone
            rpath.unlink()
    ds = simulate_scenario(run.scenario, seed, run.overrides)
    write_dataset(dpath, ds)
    import time

    cpu0 = time.process_time()
    res = HybridSlam(HybridParams(**run.params)).solve(ds.inputs, rng=np.random.default_rng([1, seed]))
    cpu = time.process_time() - cpu0
    import dataclasses

    res = dataclasses.replace(res, dataset_hash=dataset_hash(ds),
                              extra={**res.extra, "dataset_path": "data.h5", "cpu_time_s": cpu})
    write_result(rpath, res)
    return dpath, rpath


def _metrics(dpath: Path, rpath: Path) -> dict:
    from slamcli.io import read_dataset, read_result
    from slamcli.metrics.occupancy import common_mask, error_at_lap_ends, pose_errors_3sigma, snapshot_errors

    ds, res = read_dataset(dpath), read_result(rpath)
    tr = ds.truth
    mask = common_mask(res.grids, tr.occupancy)
    out: dict = {"ds": ds, "res": res, "laps": tr.lap_end_step}
    for name, g in res.grids.items():
        df = snapshot_errors(g, tr.occupancy, tr.lap_end_step, mask)
        out[f"{name}_df"] = df
        out[f"{name}_lap"] = error_at_lap_ends(df, tr.lap_end_step)
        out[f"{name}_lap_mean"] = error_at_lap_ends(df, tr.lap_end_step, "mean_abs_error")
        out[f"{name}_final"] = df.iloc[-1].to_dict()
    pe = pose_errors_3sigma(res.poses_xyt, tr.poses_xyt, res.pose_cov)
    out["pose"] = pe
    out["nees_mean"] = float(np.nanmean(pe["nees"].to_numpy()[1:]))
    out["inside_3sigma"] = float(np.mean(np.all(np.abs(pe[["err_x", "err_y", "err_theta"]].to_numpy())
                                                <= pe[["bound3_x", "bound3_y", "bound3_theta"]].to_numpy(), axis=1)))
    out["odo_err_max"] = float(np.max(np.hypot(*(ds.inputs.odometry_xyt[:, :2] - tr.poses_xyt[:, :2]).T)))
    out["pos_err_mean"] = float(np.mean(np.hypot(*(res.poses_xyt[:, :2] - tr.poses_xyt[:, :2]).T)))
    out["n_steps"] = ds.inputs.n_poses - 1
    out["wall_time_s"] = float(res.wall_time_s)
    out["cpu_time_s"] = float(res.extra.get("cpu_time_s", float("nan")))
    return out


def _figure(run: Run, m: dict, path: Path) -> None:
    """Subfigures (a)-(h) of paper 001 Figs. 3-9 for one run."""
    from matplotlib.figure import Figure

    from slamcli.plots import save_figure
    from slamcli.plots.grids import draw_grid, draw_walls, plot_map_error_vs_laps, plot_pose_error_3sigma

    ds, res = m["ds"], m["res"]
    tr = ds.truth
    g = res.grids["frequentist"]
    fig = Figure(figsize=(17, 8))
    axs = fig.subplots(2, 4)
    ax = axs[0, 0]
    draw_walls(ax, tr.walls_xyxy)
    ax.plot(tr.landmarks_xy[:, 0], tr.landmarks_xy[:, 1], "s", mfc="none", mec="k", ms=4, ls="none",
            label="features")
    ax.set_title("(a) map and features")
    ax.set_aspect("equal")
    ax = axs[0, 1]
    ax.plot(tr.poses_xyt[:, 0], tr.poses_xyt[:, 1], "k-", lw=0.6, label="true")
    ax.plot(ds.inputs.odometry_xyt[:, 0], ds.inputs.odometry_xyt[:, 1], "--", color="0.5", lw=0.6, label="odometry")
    ax.set_title("(b) raw odometry")
    ax.set_aspect("equal", adjustable="datalim")
    ax.legend(fontsize=7)
    steps = g.snapshot_step
    laps = m["laps"]
    first = int(np.argmin(np.abs(steps - laps[0]))) if len(laps) else 0
    for ax, k, name in ((axs[0, 2], first, "(c) after lap 1"), (axs[0, 3], len(steps) - 1, f"(d) after lap {len(laps)}")):
        draw_grid(ax, g, snapshot=k)
        t = int(steps[k])
        ax.plot(res.poses_xyt[: t + 1, 0], res.poses_xyt[: t + 1, 1], "-", color="tab:blue", lw=0.5)
        ax.plot(tr.landmarks_xy[:, 0], tr.landmarks_xy[:, 1], "s", mfc="none", mec="tab:green", ms=4, ls="none")
        ax.plot(res.landmarks_xy[:, 0], res.landmarks_xy[:, 1], "*", color="tab:red", ms=4, ls="none")
        ax.set_title(name)
        ax.set_aspect("equal")
        wx, wy = tr.walls_xyxy[:, [0, 2]], tr.walls_xyxy[:, [1, 3]]
        ax.set_xlim(wx.min() - 3, wx.max() + 3)
        ax.set_ylim(wy.min() - 3, wy.max() + 3)
    curves = {name: (m[f"{name}_df"]["lap"].to_numpy(), m[f"{name}_df"]["total_abs_error"].to_numpy())
              for name in res.grids}
    plot_map_error_vs_laps(axs[1, 0], curves, title="(e) total map error")
    plot_pose_error_3sigma([axs[1, 1], axs[1, 2], axs[1, 3]], m["pose"], ds.inputs.dt)
    axs[1, 1].set_title("(f)-(h) pose error and 3σ")
    fig.suptitle(run.label)
    fig.tight_layout()
    save_figure(fig, path, dpi=110)


#: Fig. 2's step size γ_t = 1/(a·t): a > 1 so the first update does not jump all the way to c_i (a = 1 gives
#: γ₁ = 1 and straight jumps); with a = 1.5 the error decays like t^(−1/a), hence the 30 000 updates
FIG2_A, FIG2_STEPS = 1.5, 30_000


def counterexample_figure(path: Path) -> dict:
    """Fig. 2: eq. (23) trajectories in the p1-p2 plane from a grid of starts, b = (0.4, 0.6), p3 = 0.5,
    γ_t = 1/(a·t) with a = :data:`FIG2_A`. Returns ``{"max_final_dist": …, "n_starts": …, "a": …,
    "n_steps": …}`` (distance of each end point to the true map (0, 1))."""
    from matplotlib.figure import Figure

    from slamcli.plots import save_figure
    from slamcli.solvers.hybrid.counterexample import run_frequentist

    fig = Figure(figsize=(5, 5))
    ax = fig.subplots()
    starts = [(p1, p2) for p1 in np.linspace(0.05, 0.95, 5) for p2 in np.linspace(0.05, 0.95, 5)]
    d = []
    for k, p0 in enumerate(starts):
        tr = run_frequentist(p0, FIG2_STEPS, np.random.default_rng(k), a=FIG2_A)
        ax.plot(tr[:, 0], tr[:, 1], "-", lw=0.7)
        ax.plot(*p0, "o", ms=3, color="k")
        d.append(math.hypot(tr[-1, 0], 1 - tr[-1, 1]))
    ax.plot(0, 1, "r*", ms=12, label="true map (0, 1)")
    ax.set_xlabel("p1")
    ax.set_ylabel("p2")
    ax.set_title(f"Fig. 2: frequentist update (eq. 23), b = (0.4, 0.6), a = {FIG2_A:g}")
    ax.legend()
    save_figure(fig, path, dpi=110)
    return {"max_final_dist": float(max(d)), "n_starts": len(starts), "a": FIG2_A, "n_steps": FIG2_STEPS}


def _fmt(x, digits: int = 3) -> str:
    if x is None or (isinstance(x, float) and not math.isfinite(x)):
        return "n/a"
    return f"{x:.{digits}g}"


#: the paper's claims (§I, §III, §IV), in the order of the verdict table
CLAIMS = ("convergence over laps", "laser better than noisy", "frequentist vs Bayesian map", "consistency",
          "linear complexity", "robustness to association")
#: a two-sided 95 % band of the mean NEES over N independent seeds (χ²(3N)/N quantiles, d = 3)
NEES_BAND_PROB = 0.95
#: seeds a run needs before its mean NEES is judged against the band
NEES_MIN_SEEDS = 20
#: per-step time over map cells counts as linear when the log-log slope is at most this
LINEAR_SLOPE_MAX = 1.2


def nees_band(n_seeds: int, dof: int = 3, prob: float = NEES_BAND_PROB) -> tuple[float, float]:
    """``[lo, hi]`` of the mean NEES over ``n_seeds`` calibrated runs (χ²(dof·N)/N quantiles)."""
    from scipy.stats import chi2

    k = dof * max(int(n_seeds), 1)
    return float(chi2.ppf((1 - prob) / 2, k) / max(n_seeds, 1)), float(chi2.ppf((1 + prob) / 2, k) / max(n_seeds, 1))


def claim_verdicts(runs: list[dict], complexity: list[tuple[float, float]] | None = None,
                   association: list[dict] | None = None) -> list[tuple[str, str, str]]:
    """One verdict per paper claim (:data:`CLAIMS`), computed from the numbers only.

    Parameters
    ----------
    runs : list of dict        per run: ``map`` (int), ``sensor`` ("laser" | "noisy"), ``lap_errors`` (per-cell
                               error of the frequentist map at each lap end), ``final_freq`` / ``final_logodds``
                               (final per-cell errors) and ``nees`` (mean pose NEES per seed, list).
    complexity : list of (map cells, CPU s per step), or None when not measured.
    association : list of dict, or None when not run: per experiment ``label``, ``error_known`` and ``error``
                               (final per-cell error with reported ids and with the perturbed association).

    Returns
    -------
    list of (claim, verdict, evidence): verdict ∈ {"holds", "does NOT hold", "partly", "not tested"}.
    """
    out = []
    laps = [r for r in runs if len(r.get("lap_errors", ())) >= 2]
    falls = [bool(np.all(np.diff(r["lap_errors"]) < 0)) for r in laps]
    out.append((CLAIMS[0], _all_any(falls), f"map error falls at every lap end in {sum(falls)} of {len(falls)} runs"))
    pairs = {}
    for r in runs:
        pairs.setdefault(r["map"], {})[r["sensor"]] = r["final_freq"]
    both = [(k, v["laser"], v["noisy"]) for k, v in sorted(pairs.items()) if {"laser", "noisy"} <= set(v)]
    better = [el < en for _k, el, en in both]
    out.append((CLAIMS[1], _all_any(better), "; ".join(f"Map {k}: {_fmt(el)} vs {_fmt(en)}" for k, el, en in both)
                or "no map with both sensors"))
    fb = [r["final_freq"] < r["final_logodds"] for r in runs if r.get("final_logodds") is not None]
    out.append((CLAIMS[2], _all_any(fb), f"frequentist map below log-odds in {sum(fb)} of {len(fb)} runs"))
    cons, ev = [], []
    for r in runs:
        nees = [x for x in r.get("nees", []) if math.isfinite(x)]
        if 0 < len(nees) < NEES_MIN_SEEDS:  # the time average of one run is no χ² sample: no verdict
            ev.append(f"Map {r['map']} {r['sensor']}: {_fmt(float(np.mean(nees)))} over {len(nees)} seed(s) "
                      f"(< {NEES_MIN_SEEDS}, not judged)")
        elif nees:
            lo, hi = nees_band(len(nees))
            m = float(np.mean(nees))
            cons.append(lo <= m <= hi)
            ev.append(f"Map {r['map']} {r['sensor']}: {_fmt(m)} over {len(nees)} seed(s), band [{_fmt(lo)}, {_fmt(hi)}]")
    out.append((CLAIMS[3], _all_any(cons), "; ".join(ev) or "no NEES"))
    if complexity and len(complexity) >= 2:
        cells, sec = np.log(np.asarray(complexity, float)).T
        slope = float(np.polyfit(cells, sec, 1)[0])
        out.append((CLAIMS[4], "holds" if slope <= LINEAR_SLOPE_MAX else "does NOT hold",
                    f"log-log slope of CPU per step vs map cells {slope:.2f} over {len(complexity)} maps "
                    f"(linear ⇔ ≤ {LINEAR_SLOPE_MAX})"))
    else:
        out.append((CLAIMS[4], "not tested", "no stored per-step time vs map cells"))
    if association:
        robust = [a["error"] <= 1.5 * a["error_known"] for a in association]
        out.append((CLAIMS[5], _all_any(robust), "; ".join(f"{a['label']}: {_fmt(a['error'])} vs "
                                                           f"{_fmt(a['error_known'])} with ids" for a in association)))
    else:
        out.append((CLAIMS[5], "not tested", "features always use their reported ids; no ML / clutter / wrong-id run"))
    return out


def _all_any(flags: list[bool]) -> str:
    if not flags:
        return "not tested"
    return "holds" if all(flags) else "partly" if any(flags) else "does NOT hold"


#: every way our runs differ from paper 001 (the section's "Setting" line)
DEVIATIONS = (
    "wall worlds approximating the paper's maps (corridor widths, beam count, feature set and route are ours)",
    "observation matrices conditional on the cell being observed; crossed cells count as empty only ≥ 3 m before "
    "the reading (`free_margin`)",
    "the thin-wall scan likelihood p(z|s,P) for the sample weights instead of eqs. (32)-(34) as is",
    "the per-cell clock of γ = a·n^(−α) advances by min(1, W_i) (weighted clock) instead of 1",
    "A is averaged with the posterior weights p(z|s)b(s) instead of b(s) (eq. 19)",
    "EKF stabilising noise 3× σ_r, σ_θ instead of the paper's ≈10×",
    "one seed per run",
)


def run_section(out_dir: Path, quick: bool, progress: LogFn | None = None) -> tuple[str, bool]:
    """Section ``paper001``: Maps 1-3 (both sensors), the posts variant and Fig. 2 (see :func:`_run_part`)."""
    return _run_part(out_dir, quick, progress, "maps")


def run_section_map4(out_dir: Path, quick: bool, progress: LogFn | None = None) -> tuple[str, bool]:
    """Section ``paper001-map4``: Map 4 with the laser, 2 laps (the longest run; last in ``make reproduce``)."""
    return _run_part(out_dir, quick, progress, "map4")


def _claim_row(run: Run, m: dict) -> dict:
    """The numbers :func:`claim_verdicts` reads, from one run's metrics."""
    lf = m.get("logodds_final")
    return {"map": run.map_no, "sensor": run.sensor, "lap_errors": np.asarray(m["frequentist_lap_mean"], float),
            "final_freq": float(m["frequentist_final"]["mean_abs_error"]),
            "final_logodds": None if not lf else float(lf["mean_abs_error"]), "nees": [m["nees_mean"]]}


def _claim_lines(results: list, ce: dict | None, part: str, quick: bool, rel: str) -> list[str]:
    """The claims subsection: the verdict table (:func:`claim_verdicts`) and one sentence per run and claim,
    each computed from the numbers."""
    lines = ["### The paper's claims beside our numbers", ""]
    if part != "map4":
        verdicts = claim_verdicts([_claim_row(r, m) for r, m in results if "posts" not in r.label])
        lines += ["| claim | verdict | evidence |", "|---|---|---|"]
        lines += [f"| {c} | {v} | {e} |" for c, v, e in verdicts] + [""]
    by = {(r.map_no, r.sensor): m for r, m in results if "posts" not in r.label}
    for k in sorted({mk for mk, _ in by}):
        if (k, "laser") in by and (k, "noisy") in by:
            el = by[(k, "laser")]["frequentist_final"]["mean_abs_error"]
            en = by[(k, "noisy")]["frequentist_final"]["mean_abs_error"]
            verdict = "holds" if el < en else "does NOT hold"
            lines.append(f"- *The laser maps better than the noisy sensor* — Map {k}: final per-cell error "
                         f"{_fmt(el)} (laser) vs {_fmt(en)} (noisy): the claim {verdict} here (condition: laser < noisy).")
    for run, m in results:
        e = m["frequentist_lap"]
        if len(e) >= 2 and np.all(np.isfinite(e)):
            falls = bool(np.all(np.diff(e) < 0))
            ratios = e[1:] / e[:-1]
            geo = bool(falls and len(ratios) >= 2 and np.ptp(ratios) < 0.5 * np.mean(ratios))
            lines.append(
                f"- *Map error falls roughly exponentially with laps* — {run.label}: total error at the lap ends "
                + " → ".join(_fmt(x, 4) for x in e) + f" (ratios {', '.join(_fmt(x) for x in ratios)}): "
                + ("falls every lap" if falls else "does NOT fall every lap")
                + ("; roughly geometric (ratios within ±25 % of their mean)." if geo else
                   ("; one ratio only, the shape of the decay cannot be judged." if falls and len(ratios) < 2 else
                    ("; the per-lap ratios are not constant, so not clearly exponential." if falls else "."))))
    for run, m in results:
        ff, lf = m["frequentist_final"], m.get("logodds_final")
        if lf:
            better = ff["mean_abs_error"] < lf["mean_abs_error"]
            lines.append(f"- *The frequentist map is consistent where the log-odds map with the same belief mean "
                         f"is not* — {run.label}: final per-cell error {_fmt(ff['mean_abs_error'])} (frequentist) vs "
                         f"{_fmt(lf['mean_abs_error'])} (log-odds): the frequentist map is "
                         + ("better" if better else "NOT better") + " on this run.")
    for run, m in results:
        lines.append(f"- *The EKF with stabilising noise stays consistent* — {run.label}: mean pose NEES "
                     f"{_fmt(m['nees_mean'])} (3 = calibrated; below 3 = conservative), "
                     f"{100 * m['inside_3sigma']:.0f} % of steps have all three errors inside ±3σ.")
    if ce is not None:
        lines.append(f"- *Fig. 2: the frequentist update converges to the true map from every start* — "
                     f"{ce['n_starts']} starts, γ_t = 1/({ce['a']:g}·t), largest final distance to (0, 1) after "
                     f"{ce['n_steps']} updates: "
                     f"{_fmt(ce['max_final_dist'])}: "
                     + ("converged (< 0.05)." if ce["max_final_dist"] < 0.05 else "NOT converged within 0.05.")
                     + f" Figure: `{rel}/fig2_counterexample.png`.")
    if part == "map4":
        for run, m in results:
            if not quick:
                within = m["cpu_time_s"] < 900.0
                lines.append(f"- *Map 4 with the laser, 2 laps, in under 15 min* (our target, on 2 cores) — "
                             f"{run.label}: {m['n_steps']} steps, solve {m['cpu_time_s']:.0f} s CPU "
                             f"({m['wall_time_s']:.0f} s wall): " + ("within" if within else "NOT within")
                             + " 900 s of CPU time.")
    return lines


def _run_part(out_dir: Path, quick: bool, progress: LogFn | None, part: str) -> tuple[str, bool]:
    """Run the paper 001 experiments of ``part`` into ``out_dir``; return the markdown section (figure paths
    relative to ``out_dir``'s parent, where the report lives) and whether every run completed.

    ``progress`` gets one status line per finished run (the reproduce driver passes its line logger)."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    rel = out.name

    def report(done: int, total: int) -> None:
        if progress is not None:
            progress(f"paper001: {done}/{total} runs")

    runs = planned_runs(quick, part)
    if part == "map4":
        lines = ["## Paper 001, Map 4: hybrid SLAM on a 1 km × 200 m city-block map (Fig. 9)", ""]
        if quick:
            lines += ["> **QUICK MODE**: the first 120 steps of Map 4 at 1 m cells, 60 beams — a smoke check, "
                      "not the paper's run.", ""]
    else:
        lines = ["## Paper 001: hybrid Bayesian/frequentist SLAM (Figs. 2-8)", ""]
        if quick:
            lines += ["> **QUICK MODE**: a small Map 1 (40 m square, 8 m corridors, 1 m cells, 60 beams), both "
                      "sensors — a smoke check, not the paper's maps.", ""]
    ok = True
    results: list[tuple[Run, dict]] = []
    total = len(runs) + 1
    for i, run in enumerate(runs):
        report(i, total)
        try:
            dpath, rpath = _execute(run, out)
            m = _metrics(dpath, rpath)
            _figure(run, m, out / f"{_slug(run.label)}.png")
            results.append((run, m))
        except Exception as exc:  # noqa: BLE001 - a failed run is reported, the section goes on
            ok = False
            lines.append(f"- **{run.label}: failed** — {str(exc).splitlines()[0] if str(exc) else type(exc).__name__}")
    ce = counterexample_figure(out / "fig2_counterexample.png") if part != "map4" else None
    report(total, total)

    # ---- table ----
    hdr = ["run", "steps", "laps", "odometry max err (m)", "EKF mean pos err (m)", "pose NEES (mean, d=3)",
           "steps inside 3σ", "per-cell err lap 1 → last (freq.)", "final per-cell err freq. / log-odds",
           "accuracy freq. / log-odds", "solve wall / CPU (s)"]
    rows = []
    for run, m in results:
        fl, ff, lf = m["frequentist_lap_mean"], m["frequentist_final"], m.get("logodds_final", {})
        rows.append([run.label, m["n_steps"], len(m["laps"]), _fmt(m["odo_err_max"]), _fmt(m["pos_err_mean"]),
                     _fmt(m["nees_mean"]), f"{100 * m['inside_3sigma']:.0f} %",
                     f"{_fmt(fl[0])} → {_fmt(fl[-1])}" if len(fl) else "n/a",
                     f"{_fmt(ff['mean_abs_error'])} / {_fmt(lf.get('mean_abs_error'))}",
                     f"{_fmt(ff['accuracy'])} / {_fmt(lf.get('accuracy'))}",
                     f"{m['wall_time_s']:.0f} / {m['cpu_time_s']:.0f}"])
    lines += ["| " + " | ".join(hdr) + " |", "|" + "---|" * len(hdr)]
    lines += ["| " + " | ".join(str(c) for c in r) + " |" for r in rows]
    lines += ["", "Per-cell error = Σ|P − P*| / n over the cells both maps observed; the total error per lap is drawn in subfigure (e) of each run's figure "
              + ", ".join(f"`{rel}/{_slug(r.label)}.png`" for r, _ in results) + ".", ""]
    if results:
        walls = [m["wall_time_s"] for _, m in results]
        cpus = [m["cpu_time_s"] for _, m in results]
        lines += ["Run times (solve, this machine; wall time depends on the load, CPU time much less): "
                  + "; ".join(f"{r.label} {m['wall_time_s']:.0f} s wall / {m['cpu_time_s']:.0f} s CPU "
                              f"({1000 * m['cpu_time_s'] / max(m['n_steps'] + 1, 1):.1f} ms CPU per step)"
                              for r, m in results)
                  + f"; total {sum(walls):.0f} s wall / {np.nansum(cpus):.0f} s CPU. Finished runs are reused.", ""]

    lines += _claim_lines(results, ce, part, quick, rel)
    lines += ["", "Setting (the paper gives the sizes, robot, noise levels, 40 m range and laps); our deviations: "
              + "; ".join(DEVIATIONS) + " (see docs and `slamcli solvers hybrid`).", ""]
    return "\n".join(lines), ok and len(results) == len(runs)
