"""Reproduction sections for paper 001 (Chakravorty & Saha, hybrid Bayesian/frequentist SLAM), Figs. 2-9.

The runs are shipped experiments (``experiments/paper001-*.toml``, each runnable with ``slamcli sweep NAME``):
the ``hybrid`` solver (which also builds the log-odds baseline of eq. 24 from the same belief mean) on the
paper's maps. :func:`section` and :func:`section_map4` run them through the sweep engine; :func:`render` and
:func:`render_map4` write the markdown from the sweep folders alone (``results.csv``, each run's ``dataset.h5``
and ``result.h5``) — they never solve: subfigures (a)-(h) per run, the §II.D counterexample (Fig. 2, a model
calculation) and outcome sentences computed from the runs' own numbers.

Two sections, so that the long Map 4 run comes last in ``make reproduce`` and can be run on its own:
``paper001`` — Maps 1-3 with both sensors, the Map 3 posts variant, Fig. 2 and the claim studies;
``paper001-map4`` — Map 4 with the laser, 2 laps, as the paper. Quick mode (the files' ``[quick]`` tables): a
small Map 1 (40 m square, 8 m corridor, 1 m cells, 60 beams) with both sensors, and the first 120 steps of Map 4 —
smoke checks, named as such. Each section states every run's wall and CPU time.

The claim studies (:func:`study_runs`, :func:`consistency_study`, :func:`plateau_study`; helpers in
:mod:`slamcli.reproduce.paper001_studies`) feed :func:`claim_verdicts`: association faults (1 lap per map), the
20-seed NEES Monte-Carlo of the Bayesian part (quick: 5 seeds on the small map, not judged), the plain-likelihood
ablation, the paper's 10× stabilising noise, the noisy plateau (maps from given poses) and the stored complexity
table.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from slamcli.reproduce.paper001_studies import (
    COMPLEXITY_CSV,
    NEES_MIN_SEEDS,
    gamma_from_median,
    loglog_slope,
    nees_class,
    nees_summary,
    read_complexity,
)

TITLE = "Paper 001: hybrid Bayesian/frequentist SLAM (Figs. 2-8)"
#: section ``paper001-map4``: its shipped experiment (``experiments/paper001-map4.toml``), the data entry and
#: solver label of its one run, and the run's label in the report (full, quick)
MAP4_EXPERIMENT, MAP4_DATA, MAP4_SOLVER = "paper001-map4", "map4-laser", "hybrid"
MAP4_LABELS = ("Map 4 laser", "Map 4 laser, first 120 steps")
MAP4_TITLE = "Paper 001, Map 4: hybrid SLAM on a 1 km × 200 m city-block map (Fig. 9)"
#: the plateau study's experiment; its solver label and data entries (the EKF mean's map, the true poses', the
#: true poses' with a bearing-noise-free scan)
PLATEAU_EXPERIMENT, PLATEAU_SOLVER = "paper001-plateau", "mapper"
PLATEAU_DATA = ("noisy", "true-poses", "true-poses-no-bearing")
#: the NEES Monte-Carlo's solver label (``mapping = false``) and its swept column in ``results.csv``
NEES_SOLVER = "ekf"
NEES_SCALE_COLUMN = f"solver.{NEES_SOLVER}.stabilising_scale"


@dataclass
class Run:
    """One run as the report names it, and where the sweeps hold it: experiment, data entry, solver label."""

    label: str
    sensor: str
    map_no: int
    experiment: str
    data: str
    solver: str = "hybrid"
    study: str = ""  # "" = a figure run; "association", "ablation", "stabilising": the claim studies


def _maps(quick: bool) -> list[tuple[int, str]]:
    """(map number, name in the report) of the maps a mode runs (quick: the small Map 1)."""
    return [(1, "Map 1 (small)")] if quick else [(k, f"Map {k}") for k in (1, 2, 3)]


def experiments(quick: bool) -> list[str]:
    """The shipped experiments (``experiments/<name>.toml``) of section ``paper001``: per map its figure runs,
    association study and NEES Monte-Carlo, then the plateau study (quick: Map 1's, whose ``[quick]`` tables
    make it the small map)."""
    ks = [k for k, _ in _maps(quick)]
    return [f"paper001-{kind}map{k}" for kind in ("", "assoc-", "nees-") for k in ks] + [PLATEAU_EXPERIMENT]


def planned_runs(quick: bool) -> list[Run]:
    """The figure runs of section ``paper001`` (paper §III: Maps 1-3 with both sensors and the Map 3 posts
    variant); Map 4 is the experiment :data:`MAP4_EXPERIMENT`."""
    runs = [Run(f"{name} {sens}", sens, k, f"paper001-map{k}", f"map{k}-{sens}")
            for k, name in _maps(quick) for sens in ("laser", "noisy")]
    if not quick:
        runs.append(Run("Map 3 posts, laser", "laser", 3, "paper001-map3", "map3-posts"))
    return runs


#: the association study's perturbations: (label, data entry, solver label, also on Map 3) of the
#: ``paper001-assoc-map<k>`` experiments
ASSOCIATION_CASES = (
    ("ML association", "ids", "ml", False),
    ("ML association + clutter 0.5/step", "clutter", "ml", False),
    ("reported ids + clutter 0.5/step", "clutter", "ids", True),
    ("1 % wrong ids", "wrong-ids", "ids", True),
)
#: the paper's stabilising noise (§III: the sensor noise "pumped up by a factor of approximately 10") beside our 3
PAPER_STABILISING = 10.0


def study_runs(quick: bool) -> list[Run]:
    """The runs of the claim studies (no figures): association (1 lap per map: the reported-id run and each of
    :data:`ASSOCIATION_CASES`), the plain-likelihood ablation and the paper's 10× stabilising noise (Map 1).

    ML association is not run on Map 3: it loses the track on Maps 1-2 (the first mis-association comes when the
    heading jumps by more than the angular gap of two features) and the lost filter then adds a landmark for
    almost every row — on Map 3's 108 features the EKF's cost grows past the section's time budget."""
    runs = []
    for k, name in _maps(quick):
        exp = f"paper001-assoc-map{k}"
        runs.append(Run(f"{name} laser, 1 lap, reported ids", "laser", k, exp, "ids", "ids", "association"))
        runs += [Run(f"{name} laser, 1 lap, {lab}", "laser", k, exp, data, solver, "association")
                 for lab, data, solver, on3 in ASSOCIATION_CASES if k != 3 or on3]
    k, name = _maps(quick)[0]
    runs.append(Run(f"{name} laser, plain scan likelihood", "laser", k, "paper001-map1", "map1-laser", "plain",
                    "ablation"))
    runs += [Run(f"{name} {sens}, {PAPER_STABILISING:g}× stabilising noise", sens, k, "paper001-map1",
                 f"map1-{sens}", "noise10", "stabilising") for sens in ("laser", "noisy")]
    return runs


def _slug(s: str) -> str:
    return "".join(c if c.isalnum() else "-" for c in s.lower()).strip("-")


def _load_runs(runs: list[Run], sweeps: dict, lines: list[str]) -> tuple[list[tuple[Run, dict]], bool]:
    """:func:`_metrics` of every run from its sweep folder (``sweeps``: experiment name → :class:`SweepRuns`);
    a run without a completed row gets a line in ``lines`` and makes the flag False."""
    out, ok = [], True
    for run in runs:
        try:
            row = sweeps[run.experiment].one(run.solver, run.data)
        except KeyError:
            ok = False
            lines.append(f"- **{run.label}: failed** — no completed run `{run.solver}` on `{run.data}` in "
                         f"`{run.experiment}/results.csv`")
            continue
        d = Path(row["path"])
        out.append((run, _metrics(d / "dataset.h5", d / "result.h5", float(row["solve_cpu_s"]))))
    return out, ok


def _metrics(dpath: Path, rpath: Path, cpu_time_s: float | None = None) -> dict:
    """One run's numbers from its dataset and result files; ``cpu_time_s``: the solve's CPU time (the sweep's
    ``solve_cpu_s``; default: the result's ``cpu_time_s`` extra)."""
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
    out["cpu_time_s"] = float(res.extra.get("cpu_time_s", float("nan")) if cpu_time_s is None else cpu_time_s)
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

    from slamcli.models.hybrid_counterexample import run_frequentist
    from slamcli.plots import save_figure

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
#: per-step time over map cells counts as linear when the log-log slope is at most this
LINEAR_SLOPE_MAX = 1.2
#: a perturbed association counts as robust when its final per-cell map error is at most this × the error with
#: the reported ids (same map, same seed, same number of laps)
ROBUST_ERROR_RATIO = 1.5


def claim_verdicts(runs: list[dict], complexity: list[tuple[float, float]] | None = None,
                   association: list[dict] | None = None,
                   consistency: list[dict] | None = None) -> list[tuple[str, str, str]]:
    """One verdict per paper claim (:data:`CLAIMS`), computed from the numbers only.

    Parameters
    ----------
    runs : list of dict        per run: ``map`` (int), ``sensor`` ("laser" | "noisy"), ``lap_errors`` (per-cell
                               error of the frequentist map at each lap end), ``final_freq`` / ``final_logodds``
                               (final per-cell errors).
    complexity : list of (map cells, CPU time per step), or None when not measured.
    association : list of dict, or None when not run: per experiment ``label``, ``error_known`` and ``error``
                               (final per-cell error with reported ids and with the perturbed association),
                               optionally ``pos_err_known`` / ``pos_err`` (mean position error, m).
    consistency : list of :func:`~slamcli.reproduce.paper001_studies.nees_summary` dicts (per configuration,
                               ANEES over seeds per step against the χ² band), or None when not run. Holds when
                               every judged configuration is calibrated; does NOT hold when one is optimistic
                               (ANEES above the band on > 5 % of the steps); partly when the rest are
                               conservative (below the band: consistent, not tight).

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
    out.append(_consistency_verdict(consistency or []))
    if complexity and len(complexity) >= 2:
        cells, sec = np.asarray(complexity, float).T
        slope = loglog_slope(cells, sec)
        out.append((CLAIMS[4], "holds" if slope <= LINEAR_SLOPE_MAX else "does NOT hold",
                    f"log-log slope of CPU per step vs map cells {slope:.2f} over {len(complexity)} grids "
                    f"({_fmt(float(cells.min()))} to {_fmt(float(cells.max()))} cells; linear ⇔ ≤ {LINEAR_SLOPE_MAX})"))
    else:
        out.append((CLAIMS[4], "not tested", "no stored per-step time vs map cells (`python -m benchmarks hybrid`)"))
    if association:
        robust = [a["error"] <= ROBUST_ERROR_RATIO * a["error_known"] for a in association]
        ev = []
        for a in association:
            pos = (f", pose {_fmt(a['pos_err'])} vs {_fmt(a['pos_err_known'])} m" if a.get("pos_err") is not None
                   and a.get("pos_err_known") is not None else "")
            ev.append(f"{a['label']}: {_fmt(a['error'])} vs {_fmt(a['error_known'])} with ids{pos}")
        out.append((CLAIMS[5], _all_any(robust), "; ".join(ev) + f" (robust ⇔ map error ≤ {ROBUST_ERROR_RATIO}× "
                                                                "the reported-id run's)"))
    else:
        out.append((CLAIMS[5], "not tested", "features always use their reported ids; no ML / clutter / wrong-id run"))
    return out


def _consistency_verdict(consistency: list[dict]) -> tuple[str, str, str]:
    ev, classes = [], []
    for c in consistency:
        k = nees_class(c)
        ev.append(f"{c['label']}: ANEES {_fmt(c['anees_mean'])} over {c['n_seeds']} seeds, "
                  f"{100 * c['inside']:.0f} % of steps inside [{_fmt(c['lo'])}, {_fmt(c['hi'])}], "
                  f"{100 * c['above']:.0f} % above → {k}")
        if k != "not judged":
            classes.append(k)
    if not classes:
        verdict = "not tested"
    elif all(k == "calibrated" for k in classes):
        verdict = "holds"
    elif "optimistic" in classes:
        verdict = "does NOT hold"
    else:
        verdict = "partly"
    note = f" (judged from ≥ {NEES_MIN_SEEDS} seeds)" if consistency else ""
    return CLAIMS[3], verdict, ("; ".join(ev) + note) if ev else "no Monte-Carlo of the NEES"


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
    "EKF stabilising noise 3× σ_r, σ_θ instead of the paper's ≈10× (the 10× runs are shown beside)",
    "one seed per map run; the consistency claim is judged from a 20-seed Monte-Carlo of the EKF part",
)


def render(exp_dirs: dict[str, Path], out_dir: Path, quick: bool) -> tuple[str, bool]:
    """Section ``paper001``'s markdown (without its heading) and whether every run completed, from the finished
    sweep folders ``{experiment name: folder}`` of :func:`experiments` alone (``results.csv``, each run's
    ``dataset.h5`` and ``result.h5``); figures go to ``out_dir`` (named relative to the report as
    ``out_dir.name``). Fig. 2 is a model calculation (:mod:`slamcli.models.hybrid_counterexample`), the
    complexity table the stored benchmark file."""
    from slamcli.reproduce.sweep_runs import SweepRuns

    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    sweeps = {name: SweepRuns(Path(d)) for name, d in exp_dirs.items() if (Path(d) / "results.csv").is_file()}
    lines = _quick_note("maps", quick)
    results, ok = _load_runs(planned_runs(quick), sweeps, lines)
    for run, m in results:
        _figure(run, m, out / f"{_slug(run.label)}.png")
    ce = counterexample_figure(out / "fig2_counterexample.png")
    study_lines, verdict_kw, ok_s = _render_studies(sweeps, quick, results)
    lines += _body(results, ce, "maps", quick, out.name, study_lines, verdict_kw)
    return "\n".join(lines), ok and ok_s


def section(rep):
    """Section ``paper001``: Maps 1-3 (both sensors), the posts variant, Fig. 2 and the claim studies, run as
    the experiments :func:`experiments` through the sweep engine (``rep.run``: resumable, ``-j N``) and rendered
    by :func:`render`; ``rep`` is the :class:`~slamcli.reproduce.report.Reproduction`."""
    return _swept_section(rep, "paper001", TITLE, experiments(rep.quick), render)


def _swept_section(rep, key: str, title: str, names: list[str], render_fn):
    """Run the experiments ``names`` with ``rep.run`` and render their folders with ``render_fn(dirs, out_dir,
    quick)`` into a :class:`~slamcli.reproduce.report.Section` ``key`` (figures under ``<report>/<key>``)."""
    from slamcli.reproduce.report import Section
    from slamcli.reproduce.sweep_runs import finish_section, run_experiments

    sec = Section(key, title)
    text, ok = render_fn(run_experiments(rep, sec, names), rep.out / key, rep.quick)
    return finish_section(sec, text, ok, "runs did not complete")


def render_map4(exp_dirs: dict[str, Path], out_dir: Path, quick: bool) -> tuple[str, bool]:
    """Section ``paper001-map4``'s markdown (without its heading) and whether its run completed, from the sweep
    folder of :data:`MAP4_EXPERIMENT` in ``exp_dirs`` alone (``results.csv``: status and ``solve_cpu_s``; the
    run's ``dataset.h5`` and ``result.h5``); the figure goes to ``out_dir`` (named relative to the report as
    ``out_dir.name``)."""
    from slamcli.reproduce.sweep_runs import SweepRuns

    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    lines = _quick_note("map4", quick)
    run = Run(MAP4_LABELS[bool(quick)], "laser", 4, MAP4_EXPERIMENT, MAP4_DATA, MAP4_SOLVER)
    results, ok = _load_runs([run], {MAP4_EXPERIMENT: SweepRuns(Path(exp_dirs[MAP4_EXPERIMENT]))}, lines)
    for r, m in results:
        _figure(r, m, out_dir / f"{_slug(r.label)}.png")
    lines += _body(results, None, "map4", quick, out_dir.name, [], None)
    return "\n".join(lines), ok


def section_map4(rep):
    """Section ``paper001-map4``: Map 4 with the laser, 2 laps (the longest run; last in ``make reproduce``), run
    through the sweep engine (``rep.run``: resumable, ``-j N``) and rendered by :func:`render_map4`."""
    return _swept_section(rep, "paper001-map4", MAP4_TITLE, [MAP4_EXPERIMENT], render_map4)


def _claim_row(run: Run, m: dict) -> dict:
    """The numbers :func:`claim_verdicts` reads, from one run's metrics."""
    lf = m.get("logodds_final")
    return {"map": run.map_no, "sensor": run.sensor, "lap_errors": np.asarray(m["frequentist_lap_mean"], float),
            "final_freq": float(m["frequentist_final"]["mean_abs_error"]),
            "final_logodds": None if not lf else float(lf["mean_abs_error"])}


def _claim_lines(results: list, ce: dict | None, part: str, quick: bool, rel: str,
                 verdict_kw: dict | None = None) -> list[str]:
    """The claims subsection: the verdict table (:func:`claim_verdicts`, with the studies' numbers
    ``verdict_kw``) and one sentence per run and claim, each computed from the numbers."""
    lines = ["### The paper's claims beside our numbers", ""]
    if part != "map4":
        verdicts = claim_verdicts([_claim_row(r, m) for r, m in results if "posts" not in r.label],
                                  **(verdict_kw or {}))
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


def _mc_configs(quick: bool) -> list[tuple[str, str, str, float]]:
    """(label, experiment, data entry, stabilising scale) of the NEES Monte-Carlo: every map and sensor with our
    3× and the paper's 10× stabilising noise, and without any (1×: the paper says the filter then "rapidly becomes
    overconfident") (quick: the small Map 1)."""
    return [(f"{name} {sens}, {scale:g}×", f"paper001-nees-map{k}", sens, scale)
            for scale in (3.0, PAPER_STABILISING, 1.0) for k, name in _maps(quick) for sens in ("laser", "noisy")]


def consistency_study(sweeps: dict, quick: bool) -> list[dict]:
    """:func:`nees_summary` per :func:`_mc_configs` entry over its completed seeds: the pose NEES of each run's
    result against its dataset's truth, every seed cut to the shortest run (runs that end at a lap end differ
    in length by a few steps); a configuration without a completed run is left out."""
    from slamcli.io import read_dataset, read_result
    from slamcli.metrics.consistency import pose_nees

    rows = []
    for label, exp, data, scale in _mc_configs(quick):
        if exp not in sweeps:
            continue
        t = sweeps[exp].rows(NEES_SOLVER, data)
        t = t[np.isclose(t[NEES_SCALE_COLUMN].astype(float), scale)]
        nees = []
        for path in t["path"]:
            res, ds = read_result(Path(path) / "result.h5"), read_dataset(Path(path) / "dataset.h5")
            nees.append(pose_nees(res.poses_xyt, ds.truth.poses_xyt, res.pose_cov))
        if nees:
            n = min(len(r) for r in nees)
            rows.append(nees_summary(np.stack([r[:n] for r in nees]), label))
    return rows


def _association_rows(studied: list[tuple[Run, dict]]) -> list[dict]:
    ref = {r.map_no: m for r, m in studied if r.study == "association" and r.label.endswith("reported ids")}
    rows = []
    for r, m in studied:
        if r.study != "association" or r.label.endswith("reported ids") or r.map_no not in ref:
            continue
        k = ref[r.map_no]
        rows.append({"label": r.label.replace(" laser, 1 lap,", ":"),
                     "error": float(m["frequentist_final"]["mean_abs_error"]),
                     "error_known": float(k["frequentist_final"]["mean_abs_error"]),
                     "pos_err": m["pos_err_mean"], "pos_err_known": k["pos_err_mean"],
                     "n_landmarks": int(len(m["res"].landmarks_xy)), "first_wrong_step": first_wrong_step(m)})
    return rows


def first_wrong_step(m: dict) -> int | None:
    """The first step at which a row is fused into a landmark that rows of another source built (another true
    feature, or a false return: id −1), from the result's row association and the truth's (a metric)."""
    assoc = np.asarray(m["res"].assoc, np.int64)
    truth = np.asarray(m["ds"].truth.obs_landmark, np.int64)
    steps = np.asarray(m["ds"].inputs.observations.step, np.int64)
    owner: dict[int, int] = {}
    for i in np.flatnonzero(assoc >= 0):
        j = int(assoc[i])
        if owner.setdefault(j, int(truth[i])) != truth[i]:
            return int(steps[i])
    return None


def _complexity_pairs() -> tuple[list[tuple[float, float]] | None, list[dict] | None]:
    rows = read_complexity(Path(__file__).resolve().parents[2] / COMPLEXITY_CSV)
    if not rows:
        return None, rows
    return [(r["grid_cells"], r["cpu_ms_per_map_step"]) for r in rows], rows


def plateau_study(results: list[tuple[Run, dict]], sweeps: dict) -> dict | None:
    """Map 1 with the noisy sensor, mapped again from one pose per step (:data:`PLATEAU_EXPERIMENT`: the EKF
    mean, the true pose and the true pose with a bearing-noise-free scan). Per-cell error at each lap end on the
    cells every one of these maps observed; γ of the median cell at the lap ends; the noisy sensor's effective
    range σ at 40 m beside the cell size. None when a run is missing."""
    from slamcli.metrics.occupancy import common_mask, error_at_lap_ends, snapshot_errors

    by = {(r.map_no, r.sensor): m for r, m in results if not r.study and "posts" not in r.label}
    if (1, "noisy") not in by or PLATEAU_EXPERIMENT not in sweeps:
        return None
    m = by[(1, "noisy")]
    ds, res = m["ds"], m["res"]
    tr = ds.truth
    laps = np.asarray(tr.lap_end_step, np.int64)
    try:
        mean, true, nob = (sweeps[PLATEAU_EXPERIMENT].result(PLATEAU_SOLVER, d) for d in PLATEAU_DATA)
    except KeyError:
        return None
    grids = {"EKF belief, 7 weighted sigma points (the run)": res.grids["frequentist"],
             "EKF mean only": mean.grids["frequentist"], "true poses": true.grids["frequentist"],
             "true poses, scan bearing σ = 0": nob.grids["frequentist"]}
    at_laps = all(np.array_equal(r.grids["frequentist"].snapshot_step, laps) for r in (mean, true, nob))
    mask = common_mask(grids, tr.occupancy)
    errors = {k: error_at_lap_ends(snapshot_errors(g, tr.occupancy, laps, mask), laps, "mean_abs_error")
              for k, g in grids.items()}
    par = res.params
    nz = ds.inputs.noise
    return {"errors": errors, "laps": len(laps), "n_cells": int(mask.sum()), "snapshots_at_laps": at_laps,
            "gamma": gamma_from_median(true.extra.get("clock_median"), len(laps), par["a"], par["alpha"]),
            "sigma_eff": float(math.hypot(nz.range_std, ds.inputs.max_range * nz.bearing_std)),
            "range_std": float(nz.range_std), "bearing_std": float(nz.bearing_std),
            "max_range": float(ds.inputs.max_range), "resolution": float(par["resolution"])}


#: a map error counts as a plateau when the last lap end gains less than this fraction on lap 1's
PLATEAU_GAIN = 0.05


def plateaued(lap_errors) -> bool:
    """True when the error at the last lap end is within :data:`PLATEAU_GAIN` of lap 1's (≥ 2 laps)."""
    v = np.asarray(lap_errors, float)
    return bool(len(v) >= 2 and v[-1] >= (1 - PLATEAU_GAIN) * v[0])


def _plateau_lines(pl: dict) -> list[str]:
    e = pl["errors"]
    lines = ["#### The noisy-sensor plateau, measured", "",
             f"Map 1 noisy, per-cell error at the lap ends on the {pl['n_cells']} cells every map below observed "
             "(E2 from one pose per step unless stated; the run's own map: its snapshot nearest each lap end):", "",
             "| poses given to the mapper | " + " | ".join(f"lap {k + 1}" for k in range(pl["laps"])) + " |",
             "|---|" + "---|" * pl["laps"]]
    lines += [f"| {k} | " + " | ".join(_fmt(float(x), 3) for x in v) + " |" for k, v in e.items()]
    run = e["EKF belief, 7 weighted sigma points (the run)"]
    mean, true = e["EKF mean only"], e["true poses"]
    nob = e["true poses, scan bearing σ = 0"]
    if not pl.get("snapshots_at_laps", True):
        lines += ["", "- The given-pose maps' snapshots are not at this dataset's lap ends (the experiment's "
                  "`snapshot_steps`): their errors are those of the nearest snapshot."]
    if len(true) < 2:
        return lines + ["", "- One lap only: the plateau cannot be judged.", ""]
    lines += ["", f"- The run: {_fmt(run[0])} → {_fmt(run[-1])} ("
              + ("a plateau" if plateaued(run) else "still falling") + f"); with the true poses: {_fmt(true[0])} → "
              f"{_fmt(true[-1])} (" + ("flat after lap 1: the floor of E2 with this sensor" if plateaued(true)
                                      else "still falling") + ").",
              f"- Of the run's final error {_fmt(run[-1])}: {_fmt(true[-1])} remains with the true poses (the sensor), "
              f"{_fmt(mean[-1] - true[-1])} comes with the EKF mean's pose error, and {_fmt(run[-1] - mean[-1])} with "
              "spreading each scan over the 7 weighted sigma points instead of the mean.",
              f"- Without the scan's bearing noise the floor is {_fmt(nob[-1])} (true poses): the bearing noise "
              f"accounts for {_fmt(true[-1] - nob[-1])} of it.",
              f"- The noisy sensor's range σ at {pl['max_range']:g} m with its bearing error folded in: "
              f"√(σ_r² + (r σ_θ)²) = √({pl['range_std']:g}² + ({pl['max_range']:g}·{pl['bearing_std']:.4g})²) = "
              f"{pl['sigma_eff']:.3f} m against {pl['resolution']:g} m cells "
              f"({pl['sigma_eff'] / pl['resolution']:.2f} cells).",
              "- Step size γ = a·n^(−α) of the median updated cell at the lap ends (true poses): "
              + " → ".join(_fmt(g) for g in pl["gamma"]) + ".", ""]
    return lines


def _study_lines(studied: list, results: list, mc: list[dict], assoc: list[dict], cx_rows) -> list[str]:
    """Tables of the association runs, the ablation and 10× runs, the NEES Monte-Carlo and the stored
    complexity table."""
    lines = ["", "### Claim studies", "", "| run | steps | final per-cell err (freq.) | EKF mean pos err (m) | "
             "EKF landmarks | first wrong association (step) | solve CPU (s) |", "|---|---|---|---|---|---|---|"]
    lines += [f"| {r.label} | {m['n_steps']} | {_fmt(m['frequentist_final']['mean_abs_error'])} | "
              f"{_fmt(m['pos_err_mean'])} | {len(m['res'].landmarks_xy)} | {_wrong(m) if r.study == 'association' else ''} | "
              f"{m['cpu_time_s']:.0f} |" for r, m in studied]
    lines.append("")
    base = {(r.map_no, r.sensor): m for r, m in results if not r.study and "posts" not in r.label}
    for r, m in studied:
        if r.study in ("ablation", "stabilising") and (r.map_no, r.sensor) in base:
            b = base[(r.map_no, r.sensor)]["frequentist_final"]["mean_abs_error"]
            e = m["frequentist_final"]["mean_abs_error"]
            what = ("the thin-wall likelihood (our default)" if r.study == "ablation"
                    else "our 3× stabilising noise")
            lines.append(f"- {r.label}: final per-cell error {_fmt(e)} vs {_fmt(b)} with {what}: "
                         + ("ours is better." if b < e else "ours is NOT better."))
    lines += ["", "NEES Monte-Carlo of the Bayesian part (ANEES per step over the seeds against the two-sided 95 % "
              "χ²(3N)/N band):", "", "| configuration | seeds | ANEES mean | steps inside band | above | below | "
              "class |", "|---|---|---|---|---|---|---|"]
    lines += [f"| {c['label']} | {c['n_seeds']} | {_fmt(c['anees_mean'])} | {100 * c['inside']:.0f} % | "
              f"{100 * c['above']:.0f} % | {100 * c['below']:.0f} % | {nees_class(c)} |" for c in mc]
    lines.append("")
    bare = [c for c in mc if c["label"].endswith(" 1×") and nees_class(c) != "not judged"]
    if bare:
        over = [c["label"] for c in bare if nees_class(c) == "optimistic"]
        lines.append(f"- Without stabilising noise (1×) the filter is optimistic in {len(over)} of {len(bare)} "
                     "configurations: the paper's \"otherwise the filter rapidly becomes overconfident\" "
                     + ("holds here." if len(over) == len(bare) else "holds in part here." if over
                        else "does NOT hold here (with reported ids)."))
    if cx_rows:
        lines += ["", f"Stored complexity results (`{COMPLEXITY_CSV.as_posix()}`, `python -m benchmarks hybrid`: CPU "
                  "time per mapping step, single-threaded):", "", "| world | grid cells | CPU ms / step |",
                  "|---|---|---|"]
        lines += [f"| {r['world']} | {r['grid_cells']:.0f} | {_fmt(r['cpu_ms_per_map_step'])} |" for r in cx_rows]
    return lines + [""]


def _wrong(m: dict) -> str:
    t = first_wrong_step(m)
    if t is None:
        return "none"
    err = m["pose"]["err_theta"].to_numpy()
    return f"{t} (heading error of the estimate after it {abs(float(err[t])):.2f} rad)"


def _render_studies(sweeps: dict, quick: bool, results: list) -> tuple[list[str], dict, bool]:
    """The claim studies from their sweep folders; returns (markdown lines, keyword arguments of
    :func:`claim_verdicts`, whether every study run completed)."""
    lines: list[str] = []
    studied, ok = _load_runs(study_runs(quick), sweeps, lines)
    mc = consistency_study(sweeps, quick)
    assoc = _association_rows(studied)
    pairs, cx_rows = _complexity_pairs()
    lines += _study_lines(studied, results, mc, assoc, cx_rows)
    pl = plateau_study(results, sweeps)
    if pl is not None:
        lines += _plateau_lines(pl)
    ours = [c for c in mc if c["label"].endswith(" 3×")]
    return lines, {"complexity": pairs, "association": assoc or None, "consistency": ours}, ok


def _quick_note(part: str, quick: bool) -> list[str]:
    """The QUICK MODE banner of a part (none in full mode)."""
    if not quick:
        return []
    if part == "map4":
        return ["> **QUICK MODE**: the first 120 steps of Map 4 at 1 m cells, 60 beams — a smoke check, "
                "not the paper's run.", ""]
    return ["> **QUICK MODE**: a small Map 1 (40 m square, 8 m corridors, 1 m cells, 60 beams), both "
            "sensors — a smoke check, not the paper's maps.", ""]


def _body(results: list[tuple[Run, dict]], ce: dict | None, part: str, quick: bool, rel: str,
          study_lines: list[str], verdict_kw: dict | None) -> list[str]:
    """The run table, run times, claims, studies and setting of a part, from the runs' numbers
    (:func:`_metrics`); figure paths are given relative to the report, under ``rel``."""
    lines: list[str] = []
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

    lines += _claim_lines(results, ce, part, quick, rel, verdict_kw)
    lines += study_lines
    lines += ["", "Setting (the paper gives the sizes, robot, noise levels, 40 m range and laps); our deviations: "
              + "; ".join(DEVIATIONS) + " (see docs and `slamcli solvers hybrid`).", ""]
    return lines
