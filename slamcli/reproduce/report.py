"""``slamcli reproduce``: run the paper experiments and write figures + ``REPORT.md``.

Sections (paper 000 = "Iterated Conditional Modes to Solve SLAM in Markov Random Fields Context", 2018), in the
order of :data:`SECTIONS`:

* Fig. 5 (``fig5-sim1.toml``): ICM on ``paper-sim1``; maps at the initialisation and iterations 10/20/30;
  min/mean/max landmark error per iteration with S = 0 and S = I; the post-radius study (``fig5-radius.toml``).
* Initialisation study (``fig5-mobilesim.toml``): the same on ``paper-sim1-mobilesim``, MobileSim's documented
  Pioneer/SICK properties (``benchmarks/bench_icm_init.py`` varies them one at a time).
* Fig. 6 (``fig6-kinematic.toml``): ICM from the kinematic-only initialisation, 100 iterations.
* Fig. 7 (``fig7-sim2.toml``): ``paper-sim2`` (10 m laser), S = 0 and S = I.
* Fig. 9 (``fig9-octagon.toml``): the octagon world; map change per iteration, on-line init time per sample.
* ICM as a post-processor (paper abstract and §4, ``postprocess.toml``): ICM started from odometry, EKF,
  FastSLAM and graph results (``init_from``) on several scenarios and seeds.
* Solver comparison (``compare.toml`` + every other registered solver with default parameters), including ICM
  with information weights.
* Monte-Carlo NEES (``nees.toml``): average pose NEES with the 95 % χ² band.

Experiment files ship in :mod:`slamcli.experiments` (another folder only with ``--experiments``). Outcome
sentences come from :mod:`slamcli.reproduce.outcomes`, verdicts from the one rule of
:mod:`slamcli.reproduce.verdicts`; ``REPORT.md`` opens with the verdict count, and a section whose runs fail
is marked FAILED (non-zero exit). Other papers' sections hook in through :data:`SECTIONS` (see
:func:`_external_section`).
"""

from __future__ import annotations

import contextlib
import dataclasses
import math
import os
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from slamcli.errors import ConfigError, SlamcliError
from slamcli.io.schema import utc_now
from slamcli.sweep.config import (
    ExperimentConfig,
    SolverSpec,
    apply_overrides,
    init_order,
    load_experiment,
    quick_variant,
)
from slamcli.types import LogFn

# The paper's numbers (paper 000 §5-§6), quoted where the report puts ours beside them.
PAPER = {
    "sim1_final_mean_err_m": 0.148,  # §5: "The final mean error is 0.148 m"
    "sim1_near_path_mean_err_m": 0.112,  # §5: landmarks of the three rows adjacent to the trajectory
    "sim1_convergence_iteration": 27,  # §5: "in the iteration 27, the algorithm already reached the convergence"
    "sim1_total_time_s": 432.24,  # §5: Matlab (fminunc), Intel i7-4790 3.6 GHz
    "octagon_max_map_change_mm": 35.0,  # §6: "the maximum change from the initial estimation is less than 35 mm"
    "octagon_init_ms_per_sample": 6.0,  # §6: 10.8 s for 183 s of data at 0.1 s, "approximately 6 ms"
    "octagon_s_per_iteration": 10.8,  # §6: "each ICM iteration also required approximately 10.8 s"
}

APPROXIMATION = """\
**Our scenarios approximate the paper's setting; they do not replay it.** The paper's simulations ran
MobileSim (a Pioneer P3-DX with its SICK laser) driven from Matlab, and its experiment a Pioneer 3-AT in an
open field; neither the MobileSim world nor the logs are available, so they cannot be replayed. Our simulator
(`slamcli.sim`) rebuilds them from the text and figures:

* `paper-sim1`: ≈ 50 m × 40 m, 7 rows of 9 landmarks 5 m apart (slightly jittered) as in Fig. 4, an
  irregular lawn-mower path along three lanes between the rows, Δt = 0.1 s, a differential-drive robot
  following waypoints with a tracking controller, a 181-beam / 180° laser at full range hitting 0.25 m-radius posts
  (several returns per landmark per scan), max-range and isolated returns dropped as in §5, small odometry
  noise ("almost negligible over short distances") and a little clutter for sensing errors.
* `paper-sim2`: the same world with a 10 m laser (Fig. 7).
* `octagon`: 8 cones on a 7.12 m-radius octagon + centre cone + two static people (positions assumed, the
  paper gives none), a ≈ 10.5 m-radius circuit for 183 s at 0.1 s, outdoor laser, noisier skid-steer odometry.

Consequences: trajectories, noise levels and landmark positions differ from the paper's, so our numbers are
comparable in kind and order of magnitude, not digit for digit. The paper reports one run per figure; we list
the seeds we used. Times are not comparable across hardware and implementations (Matlab `fminunc` there,
numpy Gauss-Newton here). The paper's landmark error is the distance of each estimate to its *nearest* true
landmark, which hides collapsed or missing landmarks; we report it for comparability and add the honest
assignment-based numbers (OSPA with cut-off c, matched RMSE, missed/spurious counts; formulas in the docstrings
of `slamcli/metrics/landmarks.py`)."""


# -- small helpers ---------------------------------------------------------------------------------------------


def _fmt(v: Any, digits: int = 3) -> str:
    if v is None:
        return "n/a"
    if isinstance(v, bool):
        return str(v)
    if isinstance(v, (int,)):
        return str(v)
    try:
        f = float(v)
    except (TypeError, ValueError):
        return str(v)
    if math.isnan(f):
        return "n/a"
    return f"{f:.{digits}f}" if abs(f) < 1e4 else f"{f:.3g}"


def _md_table(header: list[str], rows: list[list[Any]]) -> str:
    out = ["| " + " | ".join(header) + " |", "|" + "|".join("---" for _ in header) + "|"]
    out += ["| " + " | ".join(str(c) for c in r) + " |" for r in rows]
    return "\n".join(out)


def available_solvers() -> tuple[list[str], dict[str, str]]:
    """(loadable solver names, {name: why not} for registered solvers that fail to load)."""
    from slamcli.solvers import registry

    ok, bad = [], {}
    for name in registry.names():
        try:
            registry.load(name)
            ok.append(name)
        except SlamcliError as exc:
            bad[name] = str(exc).splitlines()[0]
    return ok, bad


def default_experiments_dir() -> Path:
    """The experiment files shipped inside the package (``./experiments`` only when passed explicitly)."""
    from slamcli import experiments

    return experiments.path()


@dataclass
class Section:
    key: str
    title: str
    markdown: list[str] = field(default_factory=list)
    figures: list[Path] = field(default_factory=list)
    ok: bool = True
    problems: list[str] = field(default_factory=list)
    claims: list = field(default_factory=list)  # verdicts.Judgement of every claim judged here, in order

    def add(self, text: str) -> None:
        self.markdown.append(text)

    def add_claim(self, judgement, prefix: str = "") -> None:
        """A judged claim (:class:`slamcli.reproduce.verdicts.Judgement`): kept for the report's verdict table
        and written as its line, after ``prefix``."""
        self.claims.append(judgement)
        self.add(prefix + judgement.line())

    def status_line(self) -> str:
        """The closing line: the claim verdicts when the section checks paper claims, else the run status."""
        from slamcli.reproduce import outcomes as oc

        if self.claims:
            return oc.claims_status(self.claims, self.ok, self.problems)
        return oc.section_status(self.ok, self.problems)

    def fail(self, why: str) -> None:
        """Mark the section failed (reported in REPORT.md and in the exit status of ``slamcli reproduce``)."""
        self.ok = False
        self.problems.append(why)


@dataclass
class SweepOutcome:
    cfg: ExperimentConfig
    expansion: Any
    summary: Any
    table: Any  # pandas DataFrame (results.csv)
    exp_dir: Path
    missing: dict[str, str]  # label -> why the solver is not run


def snapshot_path_xy(result, k: int):
    """Estimated path ``(T+1, 2)`` after iteration ``k`` of ``result.trace``: the trace's poses of that
    iteration when recorded, the final poses for the last iteration, else None (nothing honest to draw)."""
    poses = result.trace.poses_at(k) if result.trace is not None else None
    if poses is None and result.trace is not None and k == len(result.trace) - 1:
        poses = result.poses_xyt
    return None if poses is None else poses[:, :2]


class Reproduction:
    """Runs the sections and assembles the report."""

    def __init__(self, out_dir: Path, *, quick: bool, workers: int, experiments_dir: Path,
                 log: LogFn, executor: str = "local", scheduler: str | None = None) -> None:
        self.executor, self.scheduler = executor, scheduler  # run_sweep's: local pool or Dask (scheduler address)
        self.pool = None  # the executor every section's sweep shares, opened by :func:`reproduce`
        self.turn: threading.Lock | None = None  # overlapped sections: held by a section unless its sweep runs
        self._local = threading.local()  # overlapped sections: the running section's start signal
        self._ended: dict[str, threading.Event] = {}  # overlapped sections: set when section ``key`` has ended
        self.out = Path(out_dir)
        self.runs_dir = self.out / "runs"
        self.fig_dir = self.out / "figures"
        self.quick = quick
        self.workers = workers
        self.experiments_dir = Path(experiments_dir)
        self.log = log
        self.solvers, self.broken = available_solvers()

    # -- running ---------------------------------------------------------------------------------------------

    def prepare(self, file: str, *, add_all_solvers: bool = False,
                quick_overrides: tuple[str, ...] = ()) -> tuple[ExperimentConfig, dict[str, str]]:
        """The experiment ``file`` as this reproduction runs it (with ``--quick``: its ``[quick]`` table, then
        ``quick_overrides`` as on ``slamcli sweep``'s command line) without the solvers that are not available
        or start from one that is not (``init_from``), and ``{label: why not run}`` of those."""
        cfg = load_experiment(self.experiments_dir / file)
        if self.quick:
            cfg = quick_variant(cfg)
            if quick_overrides:
                from slamcli.sweep.expand import RegistryResolver

                cfg = apply_overrides(cfg, list(quick_overrides), RegistryResolver().known_keys)
        missing: dict[str, str] = {}
        for s in init_order(cfg.solvers, cfg.source):  # a solver before those that start from its result
            if s.method not in self.solvers:
                missing[s.label] = self.broken.get(s.method, f"solver {s.method!r} is not registered")
            elif s.init_from in missing:
                missing[s.label] = f"it starts from the result of `{s.init_from}`, which is not run"
        keep = [s for s in cfg.solvers if s.label not in missing]
        if add_all_solvers:
            present = {s.method for s in keep} | {s.method for s in cfg.solvers}
            labels = {s.label for s in cfg.solvers}
            from slamcli.solvers import registry

            for name in self.solvers:
                # set-membership solvers (cuik) need bounded-noise data and have their own section
                if name not in present and name not in labels and not getattr(
                        registry.load(name), "needs_noise_bounds", False):
                    keep.append(SolverSpec(label=name, method=name))
        dropped = set(missing)

        def relevant(key: str) -> bool:
            parts = key.split(".")
            return not (parts[0] == "solver" and parts[1] in dropped)

        sweep = dataclasses.replace(
            cfg.sweep,
            grid=tuple((k, v) for k, v in cfg.sweep.grid if relevant(k)),
            zips=tuple(g for g in (tuple((k, v) for k, v in z if relevant(k)) for z in cfg.sweep.zips) if g),
        )
        return dataclasses.replace(cfg, solvers=tuple(keep), sweep=sweep), missing

    def run(self, file: str, *, add_all_solvers: bool = False,
            quick_overrides: tuple[str, ...] = ()) -> SweepOutcome | None:
        import pandas as pd

        from slamcli.sweep.expand import expand
        from slamcli.sweep.runner import load_results, progress_lines, run_sweep

        cfg, missing = self.prepare(file, add_all_solvers=add_all_solvers, quick_overrides=quick_overrides)
        if not cfg.solvers:
            return SweepOutcome(cfg, None, None, pd.DataFrame(), self.runs_dir / cfg.name, missing)
        expansion = expand(cfg)
        self.log(f"{cfg.name}: {len(expansion.runs)} runs")
        with self._turn_given_up():
            summary = run_sweep(expansion, self.runs_dir, workers=self.workers, executor=self.executor,
                                scheduler=self.scheduler, progress=progress_lines(cfg.name, self.log), pool=self.pool)
        table = load_results(summary.exp_dir)  # path columns joined onto the sweep folder
        return SweepOutcome(cfg, expansion, summary, table, summary.exp_dir, missing)

    @contextlib.contextmanager
    def _turn_given_up(self):
        """With overlapped sections (:func:`_run_sections_overlapped`): another section may take the turn while
        this one's sweep is in the shared pool; the first time, the next section is signalled to start."""
        if self.turn is None:
            yield
            return
        self.turn.release()
        started = getattr(self._local, "started", None)
        if started is not None:
            started.set()
        try:
            yield
        finally:
            self.turn.acquire()

    def wait_for(self, key: str) -> None:
        """Return once section ``key`` (one before the caller in :data:`SECTIONS`) has ended, when it runs beside
        the caller (overlapped sections; the turn is given up meanwhile); at once when it ended or is not run.
        :meth:`found_by` reads what another section found through it."""
        ended = self._ended.get(key)
        if ended is not None and not ended.is_set():
            with self._turn_given_up():
                ended.wait()

    def found_by(self, key: str, name: str, default: Any = None) -> Any:
        """The attribute ``name`` that section ``key`` (one before the caller in :data:`SECTIONS`) sets on this
        reproduction, read once that section has ended (:meth:`wait_for`); ``default`` when it did not set it."""
        self.wait_for(key)
        return getattr(self, name, default)

    # -- report pieces ---------------------------------------------------------------------------------------------

    @staticmethod
    def _missing_note(sec: Section, outcome: SweepOutcome) -> None:
        for label, why in outcome.missing.items():
            sec.add(f"> **Not run: `{label}`** — {why}.")
            sec.fail(f"`{label}` not run ({why})")

    @staticmethod
    def _failures_note(sec: Section, outcome: SweepOutcome) -> None:
        if outcome.summary is None or not outcome.summary.failures:
            return
        rows = [[f["run_id"], f["label"], f["replicate"], str(f.get("error") or "").replace("|", "/")[:160]]
                for f in outcome.summary.failures[:10]]
        sec.add(f"> **{len(outcome.summary.failures)} run(s) failed** (traceback in `<run_id>/status.json`):\n\n"
                + _md_table(["run", "solver", "replicate", "error"], rows))
        sec.fail(f"{len(outcome.summary.failures)} run(s) failed")

    def _completed(self, outcome: SweepOutcome, label: str):
        t = outcome.table
        if t.empty:
            return t
        return t[(t["label"] == label) & (t["status"] == "completed")].sort_values("replicate")

    def _save(self, sec: Section, fig, name: str) -> Path:
        from slamcli.plots import save_figure

        path = save_figure(fig, self.fig_dir / f"{name}.png", dpi=110)
        fig.set_layout_engine("none")  # keep the layout the PNG computed: the PDF re-uses it (half the cost)
        pdf = save_figure(fig, self.fig_dir / f"{name}.pdf")
        sec.figures += [path, pdf]
        sec.add(f"![{name}](figures/{path.name}) ([PDF](figures/{pdf.name}))")
        return path

    @staticmethod
    def _figure(n: int, width: float = 5.0, height: float = 4.2):
        import matplotlib

        matplotlib.use("Agg", force=True)
        from matplotlib.figure import Figure

        fig = Figure(figsize=(width * n, height), layout="constrained")
        return fig, [fig.add_subplot(1, n, i + 1) for i in range(n)]

    @staticmethod
    def _s_name(outcome: SweepOutcome, label: str) -> str:
        params = outcome.cfg.solver(label).params
        s = params.get("S")
        if s is None:
            return label
        vals = s if isinstance(s, list) else [s]
        if all(float(v) == 0 for v in vals):
            name = "S = 0"
        elif all(float(v) == 1 for v in vals):
            name = "S = I"
        else:
            name = f"S = diag{tuple(vals)}"
        off = float(params.get("range_offset", 0.0) or 0.0)
        name += f", range offset {off:.3g} m (beyond the paper)" if off else ""
        if params.get("filtered", "drop") == "drop":
            name += ", ς-filtered observations dropped (default, beyond the paper)"
        else:
            name += ", ς-filtered observations re-matched (paper eq. 13)"
        if params.get("surface"):
            name += ", surface-aware model (beyond the paper)"
        return name

    @staticmethod
    def _is_paper_config(outcome: SweepOutcome, label: str) -> bool:
        """Whether configuration ``label`` is the paper's ICM: eq. 13's re-matching of ς-filtered observations, no
        range offset, no surface-aware model (claims judged on it are paper claims; on others, findings)."""
        params = outcome.cfg.solver(label).params
        return (params.get("filtered", "drop") == "rematch" and not params.get("surface")
                and not float(params.get("range_offset", 0.0) or 0.0))

    def _per_iteration(self, row) -> Any:
        import pandas as pd

        p = Path(row["path"]) / "per_iteration.csv"
        return pd.read_csv(p) if p.exists() else pd.DataFrame()

    # -- sections ---------------------------------------------------------------------------------------------

    def icm_section(self, key: str, title: str, file: str, snapshots: tuple[int, ...], intro: str,
                    letters: str = "abcdefghij", paper_ref: float | None = None,
                    checks: Callable[[Section, dict, list[str], set[str]], None] | None = None) -> Section:
        """One ICM figure over several seeds: error curves (every seed), map snapshots of the first seed of the
        first configuration, a table of seed means ± standard deviations, and the figure's outcome sentences
        (``checks(sec, per_label_seed_stats, labels, paper_labels)``, ``paper_labels`` the configurations that
        are the paper's own, :meth:`_is_paper_config`)."""

        sec = Section(key, title)
        sec.add(intro)
        outcome = self.run(file)
        self._missing_note(sec, outcome)
        if outcome.expansion is None:
            sec.add("_Section not produced: none of its solvers is available._")
            sec.fail("no solver available")
            return sec
        labels = [s.label for s in outcome.cfg.solvers]
        rows_by_label = {lb: self._completed(outcome, lb) for lb in labels}
        done = [lb for lb in labels if len(rows_by_label[lb])]
        self._failures_note(sec, outcome)
        if not done:
            sec.add("_No completed run; nothing to show._")
            sec.fail("no completed run")
            return sec
        reps = sorted({int(r) for lb in done for r in rows_by_label[lb]["replicate"]})
        seeds = sorted({int(r) for lb in done for r in rows_by_label[lb]["dataset_seed"]})
        sec.add(f"Scenario `{outcome.cfg.scenario}`, {len(reps)} replicate(s) {reps} (dataset seeds {seeds}); "
                f"numbers are mean ± standard deviation over the replicates; runs in `runs/{outcome.cfg.name}/`.")
        stats = {lb: [self._seed_stats(row) for _, row in rows_by_label[lb].iterrows()] for lb in done}
        # map snapshots of the first configuration's first replicate: panels (a), (b), ...
        n_snap = len(set(snapshots))  # curve panels keep the paper's letters (Fig. 5e, 5f) even if runs stop early
        self._snapshots(sec, key, rows_by_label[done[0]].iloc[0], snapshots, f"{self._s_name(outcome, done[0])}",
                        letters=letters)
        # error curves, one panel per configuration, every seed: the panels after the snapshots
        from slamcli.plots.curves import plot_error_curves

        fig, axes = self._figure(len(done))
        for i, (ax, lb) in enumerate(zip(axes, done)):
            its = [st["per_it"] for st in stats[lb]]
            letter = letters[min(n_snap + i, len(letters) - 1)]
            if len(its[0]):
                plot_error_curves(ax, its[0]["iteration"], its[0]["err_min_m"], its[0]["err_mean_m"],
                                  its[0]["err_max_m"],
                                  title=f"({letter}) {title.split(':')[0]}: {self._s_name(outcome, lb)}")
            for it in its[1:]:
                if len(it):
                    ax.plot(it["iteration"], it["err_mean_m"], "-", color="0.55", lw=0.8)
            if len(its) > 1:
                ax.plot([], [], "-", color="0.55", lw=0.8, label=f"Mean error, other {len(its) - 1} seed(s)")
            if paper_ref is not None:
                ax.axhline(paper_ref, color="tab:purple", ls=":", lw=1.2,
                           label=f"paper final mean error ({paper_ref:g} m)")
            from slamcli.plots.curves import legend_below

            legend_below(ax, ncol=2)
        self._save(sec, fig, f"{key}_errors")
        sec.add(_md_table(["quantity"] + (["paper"] if key == "fig5" else []) +
                          [self._s_name(outcome, lb) for lb in done], self._icm_rows(key, done, stats)))
        if checks is not None:
            checks(sec, stats, done, {lb for lb in done if self._is_paper_config(outcome, lb)})
        sec.add(sec.status_line())
        return sec

    def _seed_stats(self, row) -> dict:
        """Per-replicate numbers of one ICM run (from its tidy row and per-iteration table)."""
        it = self._per_iteration(row)

        def get(name):
            v = row.get(name)
            try:
                return float(v)
            except (TypeError, ValueError):
                return math.nan

        first_below = None
        if len(it) and "map_change_m" in it:
            hit = it[(it["iteration"] > 0) & (it["map_change_m"] < 1e-3)]
            first_below = int(hit["iteration"].iloc[0]) if len(hit) else None
        return {
            "per_it": it,
            "init_err": float(it["err_mean_m"].iloc[0]) if len(it) else math.nan,
            "final_err": get("paper_err_mean_m"),
            "near_err": get("paper_err_mean_near_path_m"),
            "min_err": get("paper_err_min_m"), "max_err": get("paper_err_max_m"),
            "first_below_1mm": first_below,
            "iterations": max(int(get("n_iterations")) - 1, 0) if math.isfinite(get("n_iterations")) else 0,
            "status": str(row.get("metric.status", row.get("status"))),
            "wall_s": get("metric.wall_time_s") if math.isfinite(get("metric.wall_time_s")) else get("solve_time_s"),
            "n_est": get("n_landmarks_est"), "n_true": get("n_landmarks_true"),
            "ospa": get("lm_ospa_m"), "rmse": get("lm_rmse_matched_m"), "missed": get("lm_n_missed"),
            "spurious": get("lm_n_spurious"), "ate": get("ate_rmse_m"),
        }

    def _icm_rows(self, key, done, stats) -> list[list[str]]:
        from slamcli.reproduce.outcomes import pm

        paper = key == "fig5"

        def col(name, digits=3):
            return [pm([st[name] for st in stats[lb]], digits) for lb in done]

        def r(name, paper_value, values):
            return [name] + ([paper_value] if paper else []) + values

        def below(lb):
            v = [st["first_below_1mm"] for st in stats[lb]]
            return ", ".join("not reached" if x is None else str(x) for x in v)

        return [
            r("mean landmark error at the initialisation (m, nearest true)", "—", col("init_err")),
            r("final mean landmark error (m, nearest true)", _fmt(PAPER["sim1_final_mean_err_m"]) + " (S = 0)",
              col("final_err")),
            r("final mean error, landmarks near the path (m)", _fmt(PAPER["sim1_near_path_mean_err_m"]),
              col("near_err")),
            r("final min / max error (m)", "—",
              [f"{pm([st['min_err'] for st in stats[lb]])} / {pm([st['max_err'] for st in stats[lb]])}"
               for lb in done]),
            r("ICM iterations run (stop reason), per seed", "—",
              [", ".join(f"{st['iterations']} ({st['status']})" for st in stats[lb]) for lb in done]),
            r("first iteration with mean map change < 1 mm, per seed",
              str(PAPER["sim1_convergence_iteration"]) + " (convergence)", [below(lb) for lb in done]),
            r("solver wall time (s)", _fmt(PAPER["sim1_total_time_s"], 2) + " (Matlab, i7-4790)", col("wall_s", 1)),
            r("landmarks estimated / true", "—",
              [f"{pm([st['n_est'] for st in stats[lb]], 1)} / {pm([st['n_true'] for st in stats[lb]], 0)}"
               for lb in done]),
            r("OSPA, c = 1 m (m)", "—", col("ospa")),
            r("matched RMSE (m)", "—", col("rmse")),
            r("missed / spurious landmarks", "—",
              [f"{pm([st['missed'] for st in stats[lb]], 1)} / {pm([st['spurious'] for st in stats[lb]], 1)}"
               for lb in done]),
            r("ATE RMSE, unaligned (m)", "—", col("ate")),
        ]

    def _snapshots(self, sec: Section, key: str, row, snapshots: tuple[int, ...], what: str,
                   letters: str = "abcdefghij") -> dict:
        """Map panels after the requested iterations; returns ``{iteration: axes}`` of the saved figure."""
        from slamcli.io import read_dataset, read_result
        from slamcli.plots.maps import plot_map

        run_dir = Path(row["path"])
        result = read_result(run_dir / "result.h5")
        dataset = read_dataset(run_dir / "dataset.h5")
        truth = dataset.truth
        n_trace = len(result.trace) if result.trace is not None else 0
        if n_trace == 0:
            sec.add("_The result has no iteration trace; map snapshots are not available._")
            return {}
        ks = sorted({min(k, n_trace - 1) for k in snapshots})
        fig, axes = self._figure(len(ks), width=4.6, height=4.4)
        paths = {k: snapshot_path_xy(result, k) for k in ks}
        for i, (ax, k) in enumerate(zip(axes, ks)):
            plot_map(ax, true_landmarks_xy=truth.landmarks_xy, est_landmarks_xy=result.trace.landmarks_at(k),
                     true_path_xy=truth.poses_xyt[:, :2], odometry_path_xy=dataset.inputs.odometry_xyt[:, :2],
                     est_path_xy=paths[k],
                     title=f"({letters[min(i, len(letters) - 1)]}) "
                           f"{'initialisation' if k == 0 else f'iteration {k}'} ({what})")
        self._save(sec, fig, f"{key}_maps")
        clipped = [k for k in snapshots if k > n_trace - 1]
        note = (f" Requested iterations {clipped} do not exist (the run stopped after {n_trace - 1}); the last "
                "iteration is shown instead." if clipped else "")
        no_path = [k for k in ks if paths[k] is None]
        if no_path:
            how = ("the trace stores no poses per iteration" if result.trace.poses_xyt is None
                   else "the trace holds no poses for these iterations (the solver recorded only some)")
            sec.add(f"Landmark estimates per iteration come from the result's trace; {how}, so panels {no_path} "
                    "show no estimated trajectory." + note)
        else:
            sec.add("Landmark estimates and the estimated trajectory of each panel come from the result's "
                    "per-iteration trace." + note)
        return dict(zip(ks, axes))

    # -- the paper's ICM figures ---------------------------------------------------------------------------------

    @staticmethod
    def _icm_checks(sec: Section, stats: dict, done: list[str], *, paper_final: float | None,
                    s0: str = "icm-S0", si: str = "icm-SI", close_rel: float | None = None,
                    names: dict | None = None, figure: str = "", paper_labels: set[str] = frozenset()) -> None:
        """Outcome sentences shared by Figs. 5, 6, 7 and the initialisation study: does ICM lower the error of
        its initialisation (with ``close_rel``: does it stay close to it), how does the result compare with the
        paper, does S = I converge faster than S = 0. With ``figure`` (e.g. "Fig. 5") these are the paper's
        claims of that figure, judged (:mod:`slamcli.reproduce.verdicts`) on the ``paper_labels``; the other
        configurations get the sentences only."""
        from slamcli.reproduce import outcomes as oc

        names = names or {}
        for lb in done:
            st = stats[lb]
            init, final = [x["init_err"] for x in st], [x["final_err"] for x in st]
            if figure and lb in paper_labels:
                sec.add_claim(oc.lowers_claim(init, final, f"ICM corrects the initial map ({figure}, `{lb}`)")
                              if close_rel is None else
                              oc.stays_close_claim(init, final, close_rel,
                                                   f"ICM converges close to its initialisation ({figure}, `{lb}`)"))
                continue
            sec.add(oc.lowers(init, final, "mean landmark error of its initialisation", who=f"ICM ({names.get(lb, lb)})"))
            if close_rel is not None:
                sec.add(oc.stays_close(init, final, close_rel, "mean landmark error") + f" [{names.get(lb, lb)}]")
        if paper_final is not None and s0 in stats:
            sec.add(oc.versus_paper([x["final_err"] for x in stats[s0]], paper_final,
                                    f"final mean landmark error with {names.get(s0, s0)}"))
        if s0 in stats and si in stats:
            n_max = max([x["iterations"] for x in stats[s0] + stats[si]] + [0])
            fast, slow = [x["first_below_1mm"] for x in stats[si]], [x["first_below_1mm"] for x in stats[s0]]
            crit = "a mean map change below 1 mm"
            if figure and {s0, si} <= paper_labels:
                sec.add_claim(oc.faster_claim(fast, slow, names.get(si, si), names.get(s0, s0), n_max,
                                              f"S = I (odometry used) converges faster than S = 0 ({figure})", crit))
            else:
                sec.add("Paper: S = I (odometry used) converges faster than S = 0. Ours: "
                        + oc.faster(fast, slow, names.get(si, si), names.get(s0, s0), crit, n_max))

    def fig5_section(self) -> Section:
        intro = ("Paper §5: R = Q = I, ϑ = 1 m, ς = 500; initialisation (Algorithm 2 step 1) then 30 ICM "
                 "iterations; maps after the initialisation and iterations 10, 20, 30 (Fig. 5a-d); min/mean/max "
                 "error per iteration with S = 0 (Fig. 5e) and S = I (Fig. 5f). Paper's outcome: ICM corrects a "
                 "visibly wrong initial map and path, down to a final mean error of 0.148 m. Three columns go "
                 "beyond the paper: `range_offset` re-centres the laser's returns from the SURFACE of the 0.25 m-radius "
                 "posts (on average π/4 · 0.25 m short of the centre; `benchmarks/bench_icm_study.py`), "
                 "`surface = true` is the surface-aware observation model with the radius the dataset declares "
                 "(per-return offsets √(ρ² − s²) from the current estimate, `slamcli/solvers/icm/surface.py`), and "
                 "`filtered = drop` takes the observations of map points removed by the ς filter out of the model "
                 "instead of re-matching them to the nearest remaining point (eq. 13, the paper's rule and our "
                 "default) — the clutter and rarely-seen returns then no longer pull on the map.")
        return self.icm_section(
            "fig5", "Fig. 5: Simulation 1 (paper-sim1), ICM with S = 0 and S = I", "fig5-sim1.toml",
            (0, 10, 20, 30), intro, letters="abcdefgh", paper_ref=PAPER["sim1_final_mean_err_m"],
            checks=self._fig5_checks)

    def _fig5_checks(self, sec: Section, stats: dict, done: list[str], paper_labels: set[str]) -> None:
        """Fig. 5's claims (ICM corrects the initial map, S = I converges faster, final mean error 0.148 m with
        S = 0), the surface-aware model against 0.148 m (a finding) and the post-radius sensitivity study; keeps
        the initial errors for Fig. 7 and the initialisation study."""
        from slamcli.reproduce import outcomes as oc
        from slamcli.reproduce import verdicts as vd

        self._icm_checks(sec, stats, done, paper_final=None, figure="Fig. 5", paper_labels=paper_labels)
        self.fig5_init_errs = [x["init_err"] for x in stats.get("icm-S0", [])]
        paper = PAPER["sim1_final_mean_err_m"]
        if "icm-S0" in paper_labels:
            sec.add_claim(oc.value_claim([x["final_err"] for x in stats["icm-S0"]], paper,
                                         f"final mean landmark error {paper:g} m (Fig. 5e, S = 0)"))
        for lb in sorted(paper_labels & set(done)):
            series = [list(x["per_it"]["err_mean_m"]) for x in stats[lb] if "err_mean_m" in x["per_it"]]
            sec.add_claim(oc.earlier_iterate_claim(
                series, f"the optimum of ICM's energy is further from the truth than an earlier iterate (Fig. 5, "
                        f"`{lb}`): a finding about the energy, not a reason to stop early"))
        if "icm-S0-surface" in stats:
            sec.add_claim(oc.value_claim([x["final_err"] for x in stats["icm-S0-surface"]], paper,
                                         f"the surface-aware model (beyond the paper) reaches the paper's {paper:g} m",
                                         kind=vd.FINDING))
        self._surface_sensitivity(sec)

    #: ``reproduce --quick`` runs two post radii of ``fig5-radius.toml`` (``slamcli sweep`` override syntax)
    RADIUS_QUICK_AXES = ("scenario.world.landmark_radius=0.10,0.25",)
    RADIUS_AXIS = "scenario.world.landmark_radius"

    def _surface_sensitivity(self, sec: Section) -> None:
        """paper-sim1's paper metric against the post radius, paper-exact and surface-aware ICM (S = 0): the
        sweep ``fig5-radius.toml`` rendered from its ``results.csv``."""
        from slamcli.reproduce import outcomes as oc
        from slamcli.reproduce import verdicts as vd

        if "icm" not in self.solvers:
            return
        outcome = self.run("fig5-radius.toml", quick_overrides=self.RADIUS_QUICK_AXES)
        self._failures_note(sec, outcome)
        table = self._radius_table(outcome)
        if table.empty:
            sec.add("_Post-radius study: no completed run; nothing to show._")
            sec.fail("post-radius study: no completed run")
            return
        exact = outcome.cfg.solver("exact").params
        md = [[f"{rho:.2f}"] + [oc.pm_range(g[g.model == m]["paper_err_mean_m"]) for m in ("exact", "surface")]
              + [oc.pm(g[g.model == "exact"]["n_landmarks_est"], 1)] for rho, g in table.groupby("rho_m")]
        sec.add(f"**Surface bias: sensitivity to the post radius** (beyond the paper, which gives no radius). The "
                f"laser returns come from the posts' surfaces, π/4 · ρ short of the centres on average. "
                f"`paper-sim1` re-simulated with post radius ρ, seeds {sorted(set(table['seed']))}, ICM with S = 0, "
                f"ς = {exact['min_observations']}, {exact['max_sweeps']} sweeps, eq. 13 re-matching; final mean "
                "landmark error (m, nearest true), mean ± standard deviation (smallest-largest over the seeds; "
                "sweep `fig5-radius.toml`, table: `runs/fig5-radius/results.csv`):")
        sec.add(_md_table(["post radius ρ (m)", "paper-exact ICM", "surface-aware ICM (`surface = true`)",
                           "landmarks kept by ς (paper-exact, of 63)"], md))
        sec.add("Thinner posts give fewer returns per post, so fewer posts reach ς returns and are kept: the error "
                "of the posts that remain is shown; the number kept is in the last column.")
        sec.add(oc.sensitivity_sentence([{"rho": r.rho_m, "model": r.model, "err": r.paper_err_mean_m}
                                         for r in table.itertuples()], PAPER["sim1_final_mean_err_m"]))
        paper = PAPER["sim1_final_mean_err_m"]
        for rho, g in table.groupby("rho_m"):
            sec.add_claim(oc.value_claim(g[g.model == "surface"]["paper_err_mean_m"].tolist(), paper,
                                         f"the surface bias explains the gap at ρ = {rho:.2f} m: surface-aware ICM "
                                         f"reaches the paper's {paper:g} m", kind=vd.FINDING))

    def _radius_table(self, outcome: SweepOutcome):
        """The completed runs of ``fig5-radius``: one row per (post radius ``rho_m``, ``seed``, ``model``
        exact/surface) with the final mean landmark error and the number of landmarks estimated."""
        import pandas as pd

        t = outcome.table
        cols = ["rho_m", "seed", "model", "paper_err_mean_m", "n_landmarks_est"]
        if t.empty:
            return pd.DataFrame(columns=cols)
        t = t[(t["status"] == "completed") & t["label"].isin(["exact", "surface"])]
        out = pd.DataFrame({"rho_m": t[self.RADIUS_AXIS].astype(float), "seed": t["dataset_seed"].astype(int),
                            "model": t["label"], "paper_err_mean_m": t["paper_err_mean_m"],
                            "n_landmarks_est": t["n_landmarks_est"]})
        return out.sort_values(["rho_m", "seed", "model"], kind="stable").reset_index(drop=True)

    def init_study_section(self) -> Section:
        intro = ("Why does our on-line initialisation already sit near ICM's fixed point while the paper's Fig. 5(a) "
                 "is visibly off? The scenario `paper-sim1-mobilesim` adds MobileSim's documented Pioneer P3-DX "
                 "and SICK LMS-200 properties to `paper-sim1` (sources in the scenario's docstring, "
                 "`slamcli/sim/scenarios.py`): velocity ramps of 0.3 m/s² (0.6 m/s² braking) and 1.74 rad/s², so "
                 "the executed motion lags the commanded u that the motion potential sees; the constant 0.75 % "
                 "odometry error of MobileSim's `random_init` mode; the LMS-200's range/angle noise. It was fixed "
                 "before ICM was run on it; `benchmarks/bench_icm_init.py` switches each property on alone. Same "
                 "ICM settings as Fig. 5.")
        return self.icm_section(
            "init", "Initialisation study: MobileSim's Pioneer/SICK model (paper-sim1-mobilesim)",
            "fig5-mobilesim.toml", (0, 30), intro, letters="abcdefgh", paper_ref=PAPER["sim1_final_mean_err_m"],
            checks=self._init_checks)

    def _init_checks(self, sec: Section, stats: dict, done: list[str], paper_labels: set[str]) -> None:
        """The study's question answered (our hypothesis, a finding): do MobileSim's properties make the initial
        map visibly worse (as the paper's Fig. 5a) than `paper-sim1`'s, and does ICM then move away from it?"""
        from slamcli.reproduce import outcomes as oc
        from slamcli.reproduce import verdicts as vd

        self._icm_checks(sec, stats, done, paper_final=PAPER["sim1_final_mean_err_m"], close_rel=0.1)
        s0 = stats.get("icm-S0", [])
        # paired by replicate: paper-sim1's initial map (Fig. 5's runs) should be the better one
        sec.add_claim(oc.better_initial_claim(self.found_by("fig5", "fig5_init_errs", []), [x["init_err"] for x in s0],
                                              "the paper's visibly wrong initial map (Fig. 5a) comes from MobileSim's "
                                              "robot and laser properties",
                                              names=("paper-sim1", "paper-sim1-mobilesim"), kind=vd.FINDING),
                      prefix="Answer to the question above: ")

    def fig6_section(self) -> Section:
        intro = ("Paper Fig. 6: poses initialised from the kinematic model only (a very bad initialisation, errors "
                 "of several metres); ICM still corrects the map and the path over 100 iterations.")
        return self.icm_section(
            "fig6", "Fig. 6: very bad (kinematic-only) initialisation, 100 iterations", "fig6-kinematic.toml",
            (0, 100), intro, letters="abcdefgh", checks=self._fig6_checks)

    def _fig6_checks(self, sec: Section, stats: dict, done: list[str], paper_labels: set[str]) -> None:
        """Fig. 6's claim: ICM recovers from the kinematic-only initialisation (error falls, landmarks found)."""
        from slamcli.reproduce import outcomes as oc
        from slamcli.reproduce import verdicts as vd

        self._icm_checks(sec, stats, done, paper_final=None)
        for lb in done:
            st = stats[lb]
            n_true = max([x["n_true"] for x in st if math.isfinite(x["n_true"])] + [0.0])
            sec.add_claim(oc.recovery_claim([x["init_err"] for x in st], [x["final_err"] for x in st],
                                            [x["missed"] for x in st], n_true,
                                            f"ICM recovers from a very bad initialisation (Fig. 6, `{lb}`)",
                                            kind=vd.PAPER if lb in paper_labels else vd.FINDING))

    def fig7_section(self) -> Section:
        intro = ("Paper Fig. 7: a 10 m laser gives a better initial map, so ICM converges close to its "
                 "initialisation with little change; S = I again speeds convergence.")
        return self.icm_section(
            "fig7", "Fig. 7: Simulation 2 (paper-sim2, 10 m laser), S = 0 and S = I", "fig7-sim2.toml", (0, 10),
            intro, letters="abcdefgh", checks=self._fig7_checks)

    def _fig7_checks(self, sec: Section, stats: dict, done: list[str], paper_labels: set[str]) -> None:
        """Fig. 7's claims: ICM converges close to its initialisation, S = I converges faster, and the 10 m laser
        gives a better initial map than Fig. 5's full-range laser."""
        from slamcli.reproduce import outcomes as oc

        self._icm_checks(sec, stats, done, paper_final=None, close_rel=0.1, figure="Fig. 7",
                         paper_labels=paper_labels)
        st = stats.get("icm-S0", [])
        reason = ""
        if st:
            reason = (f"with the 10 m laser ICM ends with {oc.pm([x['n_est'] for x in st], 1)} landmarks estimated "
                      f"of {oc.pm([x['n_true'] for x in st], 0)}, {oc.pm([x['missed'] for x in st], 1)} missed")
        sec.add_claim(oc.better_initial_claim([x["init_err"] for x in st], self.found_by("fig5", "fig5_init_errs", []),
                                              "the 10 m laser gives a better initial map (Fig. 7 vs Fig. 5)",
                                              reason=reason))

    def octagon_section(self) -> Section:
        from slamcli.reproduce import outcomes as oc

        sec = Section("fig9", "Fig. 9: octagon world, map change per iteration")
        sec.add("Paper §6: R = Q = S = I, ϑ = 1 m, ς = 500; the map changes by less than 35 mm from the initial "
                "estimate; the on-line initialisation costs ≈ 6 ms per sample and an ICM iteration ≈ 10.8 s.")
        outcome = self.run("fig9-octagon.toml")
        self._missing_note(sec, outcome)
        if outcome.expansion is None:
            sec.add("_Section not produced: none of its solvers is available._")
            sec.fail("no solver available")
            return sec
        self._failures_note(sec, outcome)
        labels = [s.label for s in outcome.cfg.solvers if len(self._completed(outcome, s.label))]
        if not labels:
            sec.add("_No completed run; nothing to show._")
            sec.fail("no completed run")
            return sec
        import numpy as np

        from slamcli.io import read_result
        from slamcli.plots.curves import legend_below, plot_map_change

        per_label: dict[str, list[dict]] = {}
        fig, axes = self._figure(1, width=6.0)
        for lb in labels:
            per = per_label.setdefault(lb, [])
            for _, row in self._completed(outcome, lb).iterrows():
                it = self._per_iteration(row)
                result = read_result(Path(row["path"]) / "result.h5")
                if len(it):
                    plot_map_change(axes[0], it["iteration"], it["map_change_m"],
                                    title="(d) Octagon: map change per iteration",
                                    label=f"{lb}, replicate {int(row['replicate'])}", log=True)
                mc = it[it["iteration"] > 0]["map_change_m"] if len(it) else []
                drift = math.nan
                tr = result.trace
                if tr is not None and len(tr) > 1 and len(tr.landmarks_at(0)) and len(tr.landmarks_at(len(tr) - 1)):
                    first, last = tr.landmarks_at(0), tr.landmarks_at(len(tr) - 1)
                    # each final landmark against its nearest initial estimate (labels may fuse, so no identity)
                    drift = float(np.linalg.norm(last[:, None, :] - first[None, :, :], axis=-1).min(axis=1).max()) * 1e3
                times = tr.time_s[1:] if tr is not None and len(tr) > 1 else []
                per.append({
                    "max_mc_mm": float(mc.max()) * 1e3 if len(mc) else math.nan,
                    "drift_mm": drift,
                    "init_ms": float(result.timings.get("init_ms_per_step",
                                                        result.extra.get("init_ms_per_step", math.nan))),
                    "s_per_it": float(sum(times) / len(times)) if len(times) else math.nan,
                    "steps": int(row.get("n_poses", 0) or 0) - 1,
                    "iters": f"{max(int(row.get('n_iterations', 0) or 0) - 1, 0)} ({row.get('metric.status', '')})",
                    "err": float(row.get("paper_err_mean_m", math.nan)),
                    "init_err": float(it["err_mean_m"].iloc[0]) if len(it) and "err_mean_m" in it else math.nan,
                    "mc_series": [float(x) for x in mc],
                    "ospa": float(row.get("lm_ospa_m", math.nan)),
                })
        axes[0].axhline(PAPER["octagon_max_map_change_mm"], color="tab:purple", ls=":", lw=1.2,
                        label=f"paper bound ({PAPER['octagon_max_map_change_mm']:g} mm)")
        legend_below(axes[0], ncol=2)
        self._save(sec, fig, "fig9_map_change")
        self._snapshots(sec, "fig9", self._completed(outcome, labels[0]).iloc[0], (0, 10, 100), labels[0],
                        letters="bcd")

        def col(k, d=2):
            return [oc.pm([p[k] for p in per_label[lb]], d) for lb in labels]

        mx = PAPER["octagon_max_map_change_mm"]
        table = [
            ["max per-iteration map change (mm, Fig. 9d quantity)", f"< {mx:.0f}"] + col("max_mc_mm"),
            ["max distance final → nearest initial landmark estimate (mm)", f"< {mx:.0f}"] + col("drift_mm", 1),
            ["on-line initialisation time per sample (ms)", f"≈ {PAPER['octagon_init_ms_per_sample']:.0f}"]
            + col("init_ms"),
            ["time per ICM iteration (s)", f"≈ {PAPER['octagon_s_per_iteration']}"] + col("s_per_it", 3),
            ["samples (steps)", "1830"] + [", ".join(str(p["steps"]) for p in per_label[lb]) for lb in labels],
            ["ICM iterations run (stop reason), per seed", "100"]
            + [", ".join(p["iters"] for p in per_label[lb]) for lb in labels],
            ["mean landmark error at the initialisation (m, nearest true)", "— (no ground truth)"]
            + col("init_err", 3),
            ["final mean landmark error (m, nearest true)", "— (no ground truth)"] + col("err", 3),
            ["OSPA, c = 1 m (m)", "—"] + col("ospa", 3),
        ]
        sec.add(f"{len(per_label[labels[0]])} replicate(s), mean ± standard deviation. "
                + " ".join(f"`{lb}`: {self._s_name(outcome, lb)}." for lb in labels))
        sec.add(_md_table(["quantity", "paper"] + [f"`{lb}`" for lb in labels], table))
        for lb in labels:
            self._octagon_claims(sec, lb, per_label[lb], self._is_paper_config(outcome, lb))
        sec.add(sec.status_line())
        return sec

    @staticmethod
    def _octagon_claims(sec: Section, lb: str, per: list[dict], paper_config: bool) -> None:
        """§6's claims on configuration ``lb`` (paper claims on the paper's configuration, else findings): the
        map changes by less than 35 mm from the initial estimate, the estimates practically converge in the first
        iterations (Fig. 9d), initial errors are quickly corrected."""
        from slamcli.reproduce import outcomes as oc
        from slamcli.reproduce import verdicts as vd

        kind = vd.PAPER if paper_config else vd.FINDING
        mx = PAPER["octagon_max_map_change_mm"]
        sec.add(f"`{lb}`: " + oc.within_bound([p["max_mc_mm"] for p in per], mx,
                                             "largest per-iteration map change (Fig. 9d)", "mm"))
        sec.add_claim(oc.bound_claim([p["drift_mm"] for p in per], mx,
                                     f"the map changes by less than {mx:g} mm from the initial estimate (§6, `{lb}`)",
                                     quantity="distance of a final landmark from its nearest initial estimate",
                                     unit="mm", kind=kind))
        sec.add_claim(oc.falls_claim([[1e3 * x for x in p["mc_series"]] for p in per],
                                     f"the estimates practically converge in the first iterations (Fig. 9d, `{lb}`)",
                                     quantity="map change per iteration", unit="mm", kind=kind))
        sec.add_claim(oc.lowers_claim([p["init_err"] for p in per], [p["err"] for p in per],
                                      f"initial errors are quickly corrected by the ICM iterations (§6, `{lb}`)",
                                      kind=kind))

    def compare_section(self) -> Section:
        sec = Section("compare", "Solver comparison on the same datasets")
        outcome = self.run("compare.toml", add_all_solvers=True)
        self._missing_note(sec, outcome)
        if outcome.expansion is None:
            sec.add("_Section not produced: no solver is available._")
            return sec
        reps = outcome.cfg.sweep.replicates
        sec.add(f"Scenario `{outcome.cfg.scenario}`, replicates {list(reps)} (root seed {outcome.cfg.root_seed}): "
                "every solver solves the identical dataset of each replicate, with its own data association. "
                "Mean ± standard deviation over replicates; wall time is the solver's own.")
        self._failures_note(sec, outcome)
        t = outcome.table
        rows = []
        metrics = [("paper_err_mean_m", 3), ("lm_ospa_m", 3), ("lm_rmse_matched_m", 3), ("lm_n_missed", 1),
                   ("lm_n_spurious", 1), ("ate_rmse_m", 3), ("metric.wall_time_s", 2)]
        for s in outcome.cfg.solvers:
            sub = t[(t["label"] == s.label)]
            ok = sub[sub["status"] == "completed"]
            cells = [f"`{s.label}`", f"{len(ok)}/{len(sub)}"]
            for m, d in metrics:
                col = m if m in ok else ("solve_time_s" if m == "metric.wall_time_s" else None)
                if col is None or not len(ok):
                    cells.append("n/a")
                    continue
                v = ok[col].astype(float)
                cells.append(f"{_fmt(v.mean(), d)} ± {_fmt(v.std(ddof=0), d)}")
            rows.append(cells)
        sec.add(_md_table(["solver", "completed", "paper error mean (m)", "OSPA c=1 m (m)", "matched RMSE (m)",
                           "missed", "spurious", "ATE RMSE (m)", "wall time (s)"], rows))
        done = t[t["status"] == "completed"] if len(t) else t
        labels = [s.label for s in outcome.cfg.solvers if len(done) and (done["label"] == s.label).any()]
        if labels:  # the figure of `slamcli plot compare` (one implementation), one panel per metric
            from slamcli.metrics.aggregate import groups_of
            from slamcli.plots import new_figure
            from slamcli.plots.figures import draw_compare
            from slamcli.plots.style import PAGE_IN

            fig, axes = new_figure(PAGE_IN, 3.2, ncols=2)
            for ax, col in zip(axes, ("ate_rmse_m", "lm_ospa_m")):
                draw_compare(ax, groups_of(done, col, "solver", order=labels),
                             title=f"{len(reps)} replicates, same datasets for every solver")
            self._save(sec, fig, "compare")
        from slamcli.reproduce import outcomes as oc

        def vals(label, col):
            sub = done[done["label"] == label] if len(done) else done
            if not len(sub) or col not in sub:
                return []
            return sub.sort_values("replicate")[col].astype(float).tolist()  # paired by replicate

        have = set(labels)
        if {"icm-info", "icm-info-gs", "icm-joint"} & have:
            sec.add("One change at a time: `icm` = the paper's identity weights and Gauss-Seidel sweeps; "
                    "`icm-info-gs` changes only the weights (R, S, Q from the dataset's noise model); `icm-joint` "
                    "changes only the optimiser (joint Gauss-Newton steps every sweep); `icm-info` changes both. "
                    "Each difference is paired over the replicates (same datasets) and tested against its spread.")
        pairs = (("icm", "graph", "ICM against graph"), ("icm", "ekf", "ICM against EKF"),
                 ("icm-info-gs", "icm", "the weights alone"), ("icm-joint", "icm", "the optimiser alone"),
                 ("icm-info", "icm-info-gs", "the optimiser, with information weights"),
                 ("icm-info", "icm", "weights and optimiser together"))
        for a, b, why in pairs:
            if a in have and b in have:
                for col, what in (("lm_ospa_m", "landmark OSPA (c = 1 m, m)"), ("ate_rmse_m", "ATE RMSE (m)")):
                    sec.add(f"{why[0].upper() + why[1:]}: " + oc.ratio(vals(a, col), vals(b, col), f"`{a}`", f"`{b}`",
                                                                         what + ", mean over replicates")
                            + " " + oc.spread(vals(a, col), vals(b, col), f"`{a}`", f"`{b}`", what))
        sec.add(sec.status_line())
        return sec

    def postprocess_section(self) -> Section:
        """ICM started from each base solver's result (``postprocess.toml``, ``init_from``): base → after-ICM
        numbers per dataset and base, paired by replicate, and the paper's post-processing claim."""
        from slamcli.reproduce import outcomes as oc

        sec = Section("postprocess", "ICM as a post-processor of other solvers' results")
        outcome = self.run("postprocess.toml")
        cfg = outcome.cfg
        posts = [s for s in cfg.solvers if s.init_from]
        sweeps = posts[0].params.get("max_sweeps") if posts else "?"
        sec.add("Paper abstract and §4: ICM \"can be used as a post-processing\" step of other SLAM methods. ICM "
                f"(R = Q = S = I, ϑ = 1 m, ς = 1, ≤ {sweeps} sweeps, nearest-point matchings) starts from the "
                "poses, map and associations of each base solver's result on the same dataset (`init_from` in "
                "`postprocess.toml`). Scenarios "
                + ", ".join(f"`{d.name}`" + (f" ({o})" if (o := {**d.parameters, **cfg.scenario_params}) else "")
                            for d in cfg.data)
                + f"; seeds {list(cfg.sweep.replicates)}.")
        self._missing_note(sec, outcome)
        self._failures_note(sec, outcome)
        pairs = self._postprocess_pairs(outcome)
        if not pairs:
            sec.add("_No completed run; nothing to show._")
            sec.fail("no completed run")
            sec.add(sec.status_line())
            return sec
        md_rows = [[f"`{data}`", f"`{base}`", str(len(b))]
                   + [f"{oc.pm(b[c])} → {oc.pm(i[c])}" for c in ("paper_err_mean_m", "lm_ospa_m", "ate_rmse_m")]
                   for data, base, b, i in pairs]
        sec.add("Base result → after ICM, mean ± standard deviation over seeds (table: "
                "`runs/postprocess/results.csv`):")
        sec.add(_md_table(["scenario", "base", "seeds", "mean landmark error (m)", "OSPA c = 1 m (m)",
                           "ATE RMSE (m)"], md_rows))
        per_base: dict[str, tuple[list, list]] = {}
        for s in posts:
            runs = [(b, i) for _, base, b, i in sorted(pairs, key=lambda p: p[0]) if base == s.init_from]
            if not runs:
                continue
            b = [x for r, _ in runs for x in r["paper_err_mean_m"]], [x for r, _ in runs for x in r["ate_rmse_m"]]
            i = [x for _, r in runs for x in r["paper_err_mean_m"]], [x for _, r in runs for x in r["ate_rmse_m"]]
            who = f"ICM started from `{s.init_from}`"
            sec.add(oc.lowers(b[0], i[0], "mean landmark error", who=who, item="run") + " "
                    + oc.lowers(b[1], i[1], "ATE RMSE", who=who, item="run"))
            if cfg.solver(s.init_from).method != "odometry":
                per_base[s.init_from] = (b[1], i[1])
        sec.add_claim(oc.postprocess_claim(per_base,
                                           "ICM as a post-processor of EKF / FastSLAM / graph improves their result"))
        sec.add(sec.status_line())
        return sec

    def _postprocess_pairs(self, outcome: SweepOutcome) -> list[tuple[str, str, Any, Any]]:
        """``(data label, base label, base rows, after-ICM rows)`` per dataset (file order) and ``init_from``
        solver (file order): the completed runs of both, on the replicates where both completed, by replicate."""
        t = outcome.table
        if t.empty:
            return []
        t = t[t["status"] == "completed"]
        out = []
        for d in outcome.cfg.data:
            on = t[t["data"] == d.label]
            for s in (s for s in outcome.cfg.solvers if s.init_from):
                b = on[on["label"] == s.init_from].set_index("replicate")
                i = on[on["label"] == s.label].set_index("replicate")
                reps = sorted(set(b.index) & set(i.index))
                if reps:
                    out.append((d.label, s.init_from, b.loc[reps], i.loc[reps]))
        return out

    def nees_section(self) -> Section:
        sec = Section("nees", "Monte-Carlo pose NEES")
        outcome = self.run("nees.toml")
        self._missing_note(sec, outcome)
        if outcome.expansion is None:
            sec.add("_Section not produced: no solver is available._")
            return sec
        n_rep = len(outcome.cfg.sweep.replicates)
        sec.add(f"Scenario `{outcome.cfg.scenario}`, {n_rep} independent replicates (root seed "
                f"{outcome.cfg.root_seed}), true correspondences given to every solver (recorded in the results). "
                "Average pose NEES ε̄_k (un-normalised, E = 3) against the two-sided 95 % band "
                "chi2.ppf([0.025, 0.975], 3N)/N (`slamcli/metrics/consistency.py`), on a log axis so the band "
                "stays visible next to an overconfident filter.")
        if self.quick:
            sec.add("_Quick mode: far fewer than 50 replicates; the band is wide and the test weak._")
        self._failures_note(sec, outcome)
        from slamcli.api.evaluate import monte_carlo_nees_files
        from slamcli.plots.curves import plot_nees
        from slamcli.reproduce import outcomes as oc

        rows, curves = [], []
        for s in outcome.cfg.solvers:
            ok = self._completed(outcome, s.label)
            if not len(ok):
                rows.append([f"`{s.label}`", "0", "n/a", "n/a", "n/a", "no completed run"])
                continue
            paths = [Path(p) / "result.h5" for p in ok["path"]]
            data = [Path(p) / "dataset.h5" for p in ok["path"]]
            avg, why = monte_carlo_nees_files(paths, data)
            if avg is None:
                rows.append([f"`{s.label}`", str(len(paths)), "n/a", "n/a", "n/a", why])
                continue
            curves.append((s.label, avg))
            rows.append([f"`{s.label}`", str(avg.n_runs), f"[{avg.lower:.2f}, {avg.upper:.2f}]",
                         _fmt(100 * avg.fraction_inside, 0) + " %", _fmt(avg.mean, 2),
                         oc.nees_note(avg.fraction_inside, avg.mean, avg.lower, avg.upper)])
        if curves:
            import numpy as np

            fig, axes = self._figure(len(curves))
            for i, (ax, (label, avg)) in enumerate(zip(axes, curves)):
                plot_nees(ax, np.arange(len(avg.anees)), avg.anees, avg.lower, avg.upper, avg.dof, avg.n_runs,
                          avg.fraction_inside, title=f"({'abcdefgh'[i]}) {label}: average pose NEES")
                ax.set_yscale("log")
            self._save(sec, fig, "nees")
        sec.add(_md_table(["solver", "runs", "95 % band", "steps inside band", "time-average ε̄",
                           "consistency (≥ 90 % of steps inside the band)"], rows))
        for label, avg in curves:
            sec.add(oc.nees_verdict(avg.fraction_inside, avg.mean, avg.lower, avg.upper, label))
        sec.add(sec.status_line())
        return sec


# The report's sections, in order. An entry is (key, builder): a method name of Reproduction (paper 000), or
# "module:function" with run_section(out_dir: Path, quick: bool, progress) -> (markdown: str, ok: bool).
# Other papers hook in with one line each, e.g. ("paper001", "slamcli.reproduce.paper001:section").
#: what each paper or data source is, for the report's title (a section's source: :func:`section_source`)
SOURCES = {
    "000": "paper 000 (ICM-SLAM, Int. J. Automation and Computing 15(3), 2018)",
    "001": "paper 001 (hybrid Bayesian/frequentist occupancy-grid SLAM)",
    "004": "paper 004 (CuikSLAM, set-membership SLAM)",
    "real": "public real recordings",
}


def section_source(key: str) -> str:
    """The :data:`SOURCES` key of a section: paper001*/paper004 by name, real* the recordings, else paper 000."""
    if key.startswith("paper001"):
        return "001"
    if key == "paper004":
        return "004"
    return "real" if key.startswith("real") else "000"


def report_title(keys: list[str]) -> str:
    """``# slamcli reproduction of …`` naming only the papers/sources whose sections ran, in report order."""
    order = list(dict.fromkeys(section_source(k) for k in keys)) or ["000"]
    return "# slamcli reproduction of " + "; ".join(SOURCES[o] for o in order)


SECTIONS: list[tuple[str, str]] = [
    ("fig5", "fig5_section"),
    ("init", "init_study_section"),
    ("fig6", "fig6_section"),
    ("fig7", "fig7_section"),
    ("fig9", "octagon_section"),
    ("postprocess", "postprocess_section"),
    ("compare", "compare_section"),
    ("nees", "nees_section"),
    ("paper001", "slamcli.reproduce.paper001:section"),
    ("paper004", "slamcli.reproduce.paper004:section"),
    ("real", "slamcli.reproduce.real:run_section"),
    ("real-multi", "slamcli.reproduce.real_multi:run_section"),
    ("paper001-map4", "slamcli.reproduce.paper001:section_map4"),
]


@dataclass
class ReproduceOutcome:
    """What ``reproduce`` wrote, which sections failed (``[(key, reason)]``; empty = all ok) and the judged
    claims (:class:`slamcli.reproduce.verdicts.Judgement`) of every section."""

    report: Path
    failed: list[tuple[str, str]]
    claims: list = field(default_factory=list)

    @property
    def ok(self) -> bool:
        return not self.failed

    def summary(self) -> str:
        """Two lines: the run status with the report's path, then the verdict count."""
        from slamcli.reproduce.verdicts import count_line

        if self.ok:
            status = f"all sections' runs completed; report: {self.report}"
        else:
            status = (f"{len(self.failed)} section(s) failed — " + "; ".join(f"{k}: {why}" for k, why in self.failed)
                      + f"; report: {self.report}")
        return status + "\n" + count_line(self.claims)


def verdict_summary(sections: list[Section]) -> list[str]:
    """The report's opening lines: the verdict count and a table of every judged claim (section, kind,
    verdict, the numbers it rests on)."""
    from slamcli.reproduce import verdicts as vd

    claims = [(s, j) for s in sections for j in s.claims]
    lines = [f"**{vd.count_line(j for _, j in claims)}** Rule (`slamcli/reproduce/verdicts.py`): reproduced = the "
             f"paper's stated effect holds in ≥ {100 * vd.HOLDS_FRACTION:.0f} % of the seeds and its mean exceeds "
             f"the replicate spread ({vd.SPREAD_Z:g} × standard error); partly = holds in a majority, or holds "
             "with a smaller effect; not = otherwise, or a stated condition fails. Claims judged on configurations "
             "beyond the paper, and our own hypotheses, are findings (supported / partly / not supported).", ""]
    if claims:
        rows = [[s.title.split(":")[0], j.what.replace("|", "/"), "paper" if j.kind == vd.PAPER else "finding",
                 f"**{j.label}**", j.numbers.replace("|", "/")] for s, j in claims]
        lines += [_md_table(["section", "claim", "kind", "verdict", "numbers"], rows), ""]
    external = [s.key for s in sections if ":" in dict(SECTIONS).get(s.key, "")]
    if external:
        lines += ["Sections " + ", ".join(f"`{k}`" for k in external) + " (other papers and real recordings) "
                  "state their claims' outcomes in their own lists, by their own criteria; they are not counted "
                  "here.", ""]
    return lines


def _external_section(key: str, target: str, rep: Reproduction) -> Section:
    """Another paper's or the real data's section, ``module:function``, sweep-driven: a function whose first
    parameter is ``rep`` returns its :class:`Section` (``function(rep)``); otherwise
    ``function(out_dir, quick, progress, *, run) -> (markdown, ok)`` with ``out_dir = <report dir>/<key>`` and
    ``run`` = :meth:`Reproduction.run`, the markdown opening with its own ``## `` heading (the title). Either way
    the experiments run through the sweep engine and the section renders from the sweep folders."""
    import importlib
    import inspect

    mod_name, _, fn_name = target.partition(":")
    fn = getattr(importlib.import_module(mod_name), fn_name)
    if next(iter(inspect.signature(fn).parameters), "") == "rep":
        return fn(rep)
    markdown, ok = fn(rep.out / key, rep.quick, rep.log, run=rep.run)
    head, _, body = str(markdown).partition("\n")
    sec = Section(key, head.removeprefix("## ").strip() + ("" if ok else " — FAILED"))
    sec.add(body.strip())
    if not ok:
        sec.fail(f"{target} reported failure")
    return sec


def _run_section(key: str, target: str, rep: Reproduction, t0: float) -> Section:
    """Section ``key`` (``target``: a method of :class:`Reproduction` or ``module:function``); a crashing section
    is returned as a failed one, so that the others still run."""
    try:
        if ":" in target:
            sec = _external_section(key, target, rep)
        else:
            sec = getattr(rep, target)()
    except Exception as exc:  # noqa: BLE001 - a crashing section is reported, the others still run
        sec = Section(key, key)
        msg = f"{type(exc).__name__}: {(str(exc).splitlines() or [''])[0]}"
        sec.add(f"> **Section failed**: {msg}")
        sec.fail(msg)
    if ":" not in target and not any(b.startswith("Section status") for b in sec.markdown):
        from slamcli.reproduce.outcomes import section_status

        sec.add(section_status(sec.ok, sec.problems))
    rep.log(f"section {key} {'ok' if sec.ok else 'FAILED'} ({time.perf_counter() - t0:.0f} s)")
    return sec


def _run_sections_overlapped(todo: list[tuple[str, str]], rep: Reproduction, t0: float, *,
                             in_flight: int) -> list[Section]:
    """The sections of ``todo`` (``[(key, target)]``), up to ``in_flight`` at once, one thread each, so that the
    shared pool's workers run the next section's runs while a section waits for its last long runs or draws
    its figures; returns them in the order of ``todo``.

    A section holds ``rep.turn`` except while its sweep is in the pool, so the coordinator's own work (planning
    a sweep, reading its tables, matplotlib) is done by one section at a time. Sections start in order, each once
    the one before has handed its first sweep to the pool or ended; one that reads what an earlier one found waits
    for it (:meth:`Reproduction.wait_for`). Numbers do not depend on the overlap: every run's result is a
    function of its configuration alone.
    """
    rep.turn = threading.Lock()
    rep._ended = {key: threading.Event() for key, _ in todo}
    slots = threading.Semaphore(in_flight)
    sections: list[Section | None] = [None] * len(todo)
    escaped: list[BaseException] = []  # what a section let through (Ctrl-C reaching it from a worker)

    def section(i: int, key: str, target: str, started: threading.Event) -> None:
        rep._local.started = started
        try:
            with rep.turn:
                sections[i] = _run_section(key, target, rep, t0)
        except BaseException as exc:  # noqa: BLE001 - handed to the coordinating thread, raised there
            escaped.append(exc)
        finally:
            rep._ended[key].set()
            started.set()
            slots.release()

    threads = []
    for i, (key, target) in enumerate(todo):
        slots.acquire()
        if escaped:
            break
        started = threading.Event()
        th = threading.Thread(target=section, args=(i, key, target, started), name=f"slamcli-section-{key}",
                              daemon=True)  # a Ctrl-C in this thread ends the command without waiting for them
        th.start()
        threads.append(th)
        started.wait()
    for th in threads:
        th.join()
    if escaped:
        raise escaped[0]
    return [s for s in sections if s is not None]


def reproduce(
    out_dir: str | Path,
    *,
    quick: bool = False,
    workers: int | None = None,
    experiments_dir: str | Path | None = None,
    log: LogFn = lambda s: None,
    only: list[str] | None = None,
    executor: str = "local",
    scheduler: str | None = None,
) -> ReproduceOutcome:
    """Run the sections of :data:`SECTIONS` (or the keys in ``only``), write figures and ``REPORT.md`` into
    ``out_dir``; returns the report path and the failed sections. ``executor``/``scheduler``: where the sweeps
    of the sections run (:func:`slamcli.sweep.runner.make_executor`). On a local pool of ``workers`` processes,
    up to ``workers + 1`` sections overlap (:func:`_run_sections_overlapped`); on one worker or Dask they run one
    after the other."""
    from slamcli.io import atomic_path
    from slamcli.sweep.runner import git_revision

    t0 = time.perf_counter()
    keys = [k for k, _ in SECTIONS]
    if only:  # before anything is created: bad input leaves no output folder
        unknown = [k for k in only if k not in keys]
        if unknown:
            raise ConfigError(f"--section: unknown section(s) {', '.join(unknown)}; known: {', '.join(keys)}")
    if workers is None:
        workers = 1 if quick else max(1, min(2, os.cpu_count() or 1))
    rep = Reproduction(Path(out_dir), quick=quick, workers=workers,
                       experiments_dir=Path(experiments_dir) if experiments_dir else default_experiments_dir(),
                       log=log, executor=executor, scheduler=scheduler)
    rep.out.mkdir(parents=True, exist_ok=True)
    from slamcli.sweep.runner import LocalPool, make_executor

    todo = [(key, target) for key, target in SECTIONS if not only or key in only]
    with make_executor(executor, workers, scheduler) as rep.pool:  # one pool for every section's sweeps
        if isinstance(rep.pool, LocalPool) and len(todo) > 1:
            sections = _run_sections_overlapped(todo, rep, t0, in_flight=workers + 1)
        else:
            sections = [_run_section(key, target, rep, t0) for key, target in todo]
    elapsed = time.perf_counter() - t0

    import slamcli

    lines = [
        report_title([sec.key for sec in sections]),
        "",
        *verdict_summary(sections),
        (
            f"Generated {utc_now()} by "
            f"`slamcli reproduce{' --quick' if quick else ''}` (slamcli {slamcli.__version__}, git {git_revision()}), "
            f"{workers} worker(s), {elapsed:.0f} s. Runs: `runs/<experiment>/<run_id>/` (config, dataset, "
            "result, metrics, status, log); tables: `runs/<experiment>/results.csv`."
        ),
        "",
    ]
    if quick:
        lines += [
            (
                "> **QUICK MODE** — few seeds, short trajectories, few iterations: a smoke check of the whole "
                "pipeline. These numbers are not a reproduction of the paper; run `make reproduce`."
            ),
            "",
        ]
    if rep.broken:
        lines += ["Registered solvers that failed to load: "
                  + "; ".join(f"`{k}`: {v}" for k, v in rep.broken.items()), ""]
    lines += ["Solvers available: " + ", ".join(f"`{s}`" for s in rep.solvers), "", "## Setting", "",
              APPROXIMATION, ""]
    failed = [(s.key, "; ".join(s.problems)) for s in sections if not s.ok]
    from slamcli.reproduce.verdicts import count_line

    claims = [j for s in sections for j in s.claims]
    lines += ["## Summary", "",
              ("The runs of every section completed. " if not failed else
               f"**{len(failed)} section(s) FAILED**: " + "; ".join(f"`{k}` ({why})" for k, why in failed) + ". ")
              + count_line(claims) + " The table of claims is at the top of this report.", ""]
    for s in sections:
        if s.title:
            lines += [f"## {s.title}", ""]
        for block in s.markdown:
            lines += [block, ""]
    report = rep.out / "REPORT.md"
    with atomic_path(report) as tmp:
        tmp.write_text("\n".join(lines))
    return ReproduceOutcome(report, failed, claims)
