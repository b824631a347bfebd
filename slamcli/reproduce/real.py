"""Real-data section of ``make reproduce``: every solver on recordings nobody here made, run by the sweep engine.

The runs are the shipped experiments ``real-victoria-park``, ``real-mrclam`` and ``real-carpark``
(``experiments/*.toml``, each runnable alone with ``slamcli sweep NAME``); this module runs them through
:meth:`slamcli.reproduce.report.Reproduction.run` (resumable, ``-j N``) and renders the section from what the
sweeps wrote — ``results.csv``, each run's ``config.json``, ``result.h5`` and ``dataset.h5`` — never solving.

* **Victoria Park** (car, laser at (3.78, 0.50) m, tree trunks, unknown association): GPS ATE after SE(2)
  alignment (the run's start frame is not the GPS frame), map size, wall time; a map figure per solver. The
  full section uses the first 300 s of the run (the EKF's update cost grows with the square of the map).
* **MRCLAM Dataset 7**: each of the five robots solo with its barcode ids (ATE against the motion-capture
  truth — the start pose is known, so unaligned — and the landmark error against the surveyed landmarks:
  matched RMSE after optimal assignment within 1 m). The joint multi-robot run is another section.
* **ACFR car park**: GPS ATE (aligned), beacons found of the 15 surveyed ones (matched within 2 m after the
  trajectory's alignment) and their RMSE.

ICM runs three ways on every recording — its paper defaults, the information weights and ``preset=real`` — and
the section ends with one computed verdict per ``preset=real`` goal (:func:`icm_verdicts`). Solvers that do not
support a recording refuse in one line (``cuik`` needs error bounds, ``hybrid`` walls and DDMR controls); the
table shows that line. Quick mode reads the excerpts of ``tests/data`` when present (:func:`excerpt_registry`).
Data: the registered recordings ``victoria-park``, ``mrclam7`` and ``acfr-carpark``; a missing one is one line
naming its ``slamcli datasets fetch``/``add`` command.
"""

from __future__ import annotations

import contextlib
import json
import math
import os
import time
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import numpy as np

from slamcli.types import LogFn

#: the section's experiments (shipped experiment files), in report order
EXPERIMENTS = {"vp": "real-victoria-park.toml", "mr": "real-mrclam.toml", "cp": "real-carpark.toml"}
#: table row names of the experiments' solver labels that are not a solver's own name
ROW_NAMES = {"graph-incremental": "graph (incremental)", "graph-defaults": "graph (defaults)", "icm-info": "icm (information weights)",
             "icm-real": "icm (preset=real)"}
ICM_PRESET_ROW = ROW_NAMES["icm-real"]
#: the row ``preset=real``'s MRCLAM goal compares with: ``graph`` with every parameter at its default
GRAPH_BASELINE_ROW = ROW_NAMES["graph-defaults"]
#: the ``preset=real`` goals: Victoria Park first 300 s and car park GPS ATE (m), beacons, and the MRCLAM solo
#: margin over graph (fraction)
GOAL_VP300_M, GOAL_CP_M, GOAL_MRCLAM_MARGIN = 1.4, 0.45, 0.10
#: registry folder (``$SLAMCLI_DATASETS`` layout) → excerpt in ``tests/data`` read in quick mode
EXCERPTS = {"victoria_park": "victoria_park_excerpt", "acfr_carpark": "carpark_excerpt",
            "mrclam_dataset7": "mrclam_excerpt"}


def repo_root() -> Path:
    return Path(__file__).resolve().parents[2]


@contextlib.contextmanager
def excerpt_registry(folder: Path, links: dict[str, str]) -> Iterator[str]:
    """While inside: the dataset registry finds its recordings only in ``folder``, which holds a link per
    registry folder to the excerpt of ``tests/data`` named in ``links``, and keeps its import cache there
    (``$SLAMCLI_DATASETS`` and ``$SLAMCLI_DATA_DIR`` set, ``$SLAMCLI_DATASET_REGISTRY`` unset, restored on exit).
    Yields the sentence naming the data for the report."""
    from slamcli.datasets import registry

    shared = Path(folder) / "shared"
    shared.mkdir(parents=True, exist_ok=True)
    for name, excerpt in links.items():
        link = shared / name
        if link.is_symlink():
            link.unlink()
        link.symlink_to(repo_root() / "tests" / "data" / excerpt, target_is_directory=True)
    from unittest import mock  # patch.dict: the environment as it was on exit, whatever happened inside

    with mock.patch.dict(os.environ, {registry.ENV_SHARED: str(shared),
                                      registry.ENV_DATA_DIR: str(Path(folder) / "cache")}):
        os.environ.pop(registry.ENV_REGISTRY, None)
        yield ("the excerpts shipped in `tests/data` ("
               + ", ".join(f"`tests/data/{e}`" for e in links.values()) + ")")


def quick_data(out: Path, quick: bool, links: dict[str, str]):
    """The context the section's sweeps run in: :func:`excerpt_registry` in quick mode in a checkout, else the
    registry as it is (yielding the sentence that names the data)."""
    if quick and all((repo_root() / "tests" / "data" / e).is_dir() for e in links.values()):
        return excerpt_registry(out / "quick-recordings", links)
    return contextlib.nullcontext("the registered recordings of `slamcli datasets`")


def _fmt(v, nd=2) -> str:
    return "—" if v is None or (isinstance(v, float) and not math.isfinite(v)) else f"{v:.{nd}f}"


def param_text(params: dict) -> str:
    """``k=v, ...`` of a configuration's parameters as the experiment file gives them, or ``defaults``."""
    return ", ".join(f"{k}={v}" for k, v in params.items()) or "defaults"


def refusal(error: str) -> str:
    """The first line of a failed run's error without the exception's class and the dataset path that the sweep
    puts in front (``SolverError: <run>/dataset.h5: solver 'x' ...`` → ``solver 'x' ...``)."""
    line = (str(error).splitlines() or [""])[0]
    head, sep, rest = line.partition(": ")
    if sep and head.isidentifier():
        line = rest
    head, sep, rest = line.partition(": ")
    return rest if sep and head.endswith(".h5") else line


# ----------------------------------------------------------------------------------------------------------
# rows from a finished sweep (results.csv and the run folders)
# ----------------------------------------------------------------------------------------------------------
def _num(v) -> float | None:
    try:
        f = float(v)
    except (TypeError, ValueError):
        return None
    return f if math.isfinite(f) else None


def _int(v) -> int | None:
    f = _num(v)
    return None if f is None else int(round(f))


def _wall(rec: dict) -> float | None:
    """The solver's own wall time (the result's), else the sweep's solve time, s."""
    return _num(rec.get("metric.wall_time_s", rec.get("solve_time_s")))


def sweep_records(exp_dir: Path) -> list[dict]:
    """The rows of ``exp_dir/results.csv`` (path columns joined onto ``exp_dir``), in the sweep's order."""
    from slamcli.sweep.runner import load_results

    return load_results(exp_dir).to_dict("records")


def _base_row(rec: dict, params: dict[str, str]) -> dict[str, Any]:
    label = str(rec["label"])
    failed = rec["status"] != "completed"
    return {"solver": ROW_NAMES.get(label, label), "label": label, "params": params.get(label, "defaults"),
            "refused": refusal(rec.get("error") or "failed") if failed else None, "run_dir": Path(rec["path"])}


def gps_rows(records: list[dict], params: dict[str, str]) -> list[dict]:
    """One row per run on a GPS-referenced recording: status, aligned GPS ATE, map size, wall time, surveyed
    landmarks found and their RMSE (``None`` where the recording has no survey); ``refused`` = the one line of
    a failed run."""
    rows = []
    for rec in records:
        row = _base_row(rec, params)
        if not row["refused"]:
            row.update(status=rec["solver_status"], gps_ate=_num(rec.get("gps_ate_aligned_rmse_m")),
                       odo_gps_ate=_num(rec.get("odometry_gps_ate_aligned_rmse_m")),
                       n_lm=_int(rec.get("n_landmarks_est")), wall_s=_wall(rec), n_gps=_int(rec.get("gps_n_matched")),
                       survey_matched=_int(rec.get("survey_lm_matched")), survey_rmse=_num(rec.get("survey_lm_rmse_m")))
        rows.append(row)
    return rows


def mrclam_rows(records: list[dict], params: dict[str, str] | None = None) -> list[dict]:
    """One row per solo MRCLAM run: the robot (its ``config.json``'s import options), the solver's parameters
    as written (``params``: label → text), status, ATE and dead reckoning's, landmarks matched / true, matched
    landmark RMSE, wall time."""
    rows = []
    for rec in records:
        row = _base_row(rec, params or {})
        row["robot"] = int(import_options(row["run_dir"]).get("robot", 1))
        if not row["refused"]:
            row.update(status=rec["solver_status"], ate=_num(rec.get("ate_rmse_m")),
                       odo_ate=_num(rec.get("odometry_ate_rmse_m")), lm_rmse=_num(rec.get("lm_rmse_matched_m")),
                       lm_matched=_int(rec.get("lm_n_matched")), n_true=_int(rec.get("lm_n_true")),
                       n_lm=_int(rec.get("lm_n_est")), wall_s=_wall(rec))
        rows.append(row)
    return rows


def _alignment(result, dataset):
    """SE(2) alignment (R, t) of the estimate's reference point onto the GPS (as the metric computes it)."""
    from slamcli.metrics.reference import ate_vs_position_reference
    from slamcli.models.observation import sensor_pose

    tr = dataset.truth
    off = np.zeros(2) if tr.ref_offset_xy is None else np.asarray(tr.ref_offset_xy, float)
    g = ate_vs_position_reference(dataset.inputs.timestamps, sensor_pose(result.poses_xyt, off), tr.ref_time_s,
                                  tr.ref_xy)
    return g["gps_alignment"]


# ----------------------------------------------------------------------------------------------------------
# figures
# ----------------------------------------------------------------------------------------------------------
def _map_figure(rows, dataset, path: Path, title: str) -> Path | None:
    """One panel per solver that ran: its path and landmarks (read from the run's ``result.h5``) moved into the
    GPS frame by its own alignment, the GPS fixes (grey) and, for the car park, the surveyed beacons (squares)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from slamcli.io import read_result
    from slamcli.models.observation import sensor_pose
    from slamcli.plots import save_figure

    ran = [(r, read_result(r["run_dir"] / "result.h5")) for r in rows if not r["refused"]]
    if not ran:
        return None
    n = len(ran)
    cols = min(3, n)
    rws = math.ceil(n / cols)
    fig, axes = plt.subplots(rws, cols, figsize=(4.2 * cols, 3.8 * rws), squeeze=False)
    tr = dataset.truth
    off = np.zeros(2) if tr.ref_offset_xy is None else np.asarray(tr.ref_offset_xy, float)
    for ax, (r, res) in zip(axes.ravel(), ran):
        R, t = _alignment(res, dataset)
        p = sensor_pose(res.poses_xyt, off)[:, :2] @ R.T + t
        lm = np.asarray(res.landmarks_xy, float).reshape(-1, 2) @ R.T + t
        ax.plot(tr.ref_xy[:, 0], tr.ref_xy[:, 1], ".", color="0.6", ms=2, label="GPS")
        ax.plot(p[:, 0], p[:, 1], "-", color="tab:blue", lw=0.8, label="estimate")
        ax.plot(lm[:, 0], lm[:, 1], "*", color="tab:red", ms=3, label=f"landmarks ({len(lm)})")
        if tr.landmarks_xy is not None:
            ax.plot(tr.landmarks_xy[:, 0], tr.landmarks_xy[:, 1], "s", mfc="none", color="black", ms=5,
                    label="surveyed")
        ax.set_title(f"{r['solver']}: GPS ATE {_fmt(r['gps_ate'])} m", fontsize=9)
        ax.set_aspect("equal", adjustable="datalim")
        ax.tick_params(labelsize=7)
    for ax in axes.ravel()[n:]:
        ax.axis("off")
    axes.ravel()[0].legend(fontsize=6, loc="best")
    fig.suptitle(title, fontsize=10)
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    for suffix in (".png", ".pdf"):
        save_figure(fig, path.with_suffix(suffix), dpi=130)
    plt.close(fig)
    return path.with_suffix(".png")


# ----------------------------------------------------------------------------------------------------------
# markdown
# ----------------------------------------------------------------------------------------------------------
def _gps_table(rows, with_survey: bool, n_survey: int = 0) -> list[str]:
    head = "| solver | parameters | status | GPS ATE aligned (m) | map size | wall time (s) |"
    sep = "|---|---|---|---|---|---|"
    if with_survey:
        head += f" beacons found of {n_survey} | beacon RMSE (m) |"
        sep += "---|---|"
    out = [head, sep]
    for r in rows:
        if r["refused"]:
            cells = [f"`{r['solver']}`", r["params"], f"refused: {r['refused']}", "—", "—", "—"]
            if with_survey:
                cells += ["—", "—"]
        else:
            cells = [f"`{r['solver']}`", r["params"], str(r["status"]), _fmt(r["gps_ate"]), str(r["n_lm"]),
                     _fmt(r["wall_s"], 1)]
            if with_survey:
                cells += [str(r["survey_matched"]), _fmt(r["survey_rmse"])]
        out.append("| " + " | ".join(cells) + " |")
    return out


def _gps_sentences(rows, label: str) -> list[str]:
    ran = [r for r in rows if not r["refused"] and r["gps_ate"] is not None and math.isfinite(r["gps_ate"])]
    refused = [r["solver"] for r in rows if r["refused"]]
    out = []
    if ran:
        best = min(ran, key=lambda r: r["gps_ate"])
        odo = ran[0]["odo_gps_ate"]
        ran = [r for r in ran if r["solver"] != "odometry"] or ran  # dead reckoning is the reference
        better = [r["solver"] for r in ran if odo is not None and r["gps_ate"] < odo]
        out.append(f"On {label}, `{best['solver']}` has the lowest aligned GPS ATE ({best['gps_ate']:.3f} m over "
                   f"{best['n_gps']} fixes); dead reckoning of the car model has {_fmt(odo, 3)} m. "
                   + (f"{len(better)} of {len(ran)} solvers beat dead reckoning ({', '.join(better)})."
                      if better else f"None of the {len(ran)} solvers beats dead reckoning."))
        big = [r for r in ran if odo is not None and r["gps_ate"] > 2 * odo]
        if big:
            out.append("Worse than twice dead reckoning (diverged or mis-associated): "
                       + ", ".join(f"`{r['solver']}` ({r['gps_ate']:.2f} m)" for r in big) + ".")
    if refused:
        out.append(f"Refused in one line: {', '.join(refused)}.")
    return out


def _mrclam_table(rows) -> list[str]:
    out = ["| robot | solver | parameters | status | ATE (m) | dead reckoning ATE (m) | landmarks matched / true | "
           "landmark RMSE (m) | wall time (s) |", "|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        head = f"| {r['robot']} | `{r['solver']}` | {r['params']} |"
        if r["refused"]:
            out.append(f"{head} refused: {r['refused']} | — | — | — | — | — |")
        else:
            out.append(f"{head} {r['status']} | {_fmt(r['ate'])} | {_fmt(r['odo_ate'])} | "
                       f"{r['lm_matched']} / {r['n_true']} | {_fmt(r['lm_rmse'])} | {_fmt(r['wall_s'], 1)} |")
    return out


def _mrclam_sentences(rows) -> list[str]:
    ran = [r for r in rows if not r["refused"]]
    if not ran:
        return []
    out = []
    by_solver: dict[str, list[dict]] = {}
    for r in ran:
        by_solver.setdefault(r["solver"], []).append(r)
    means = {s: float(np.mean([r["ate"] for r in rs])) for s, rs in by_solver.items()}
    best = min(means, key=means.get)
    robots = sorted({r["robot"] for r in ran})
    out.append(f"Over robot(s) {', '.join(map(str, robots))}, `{best}` has the lowest mean ATE "
               f"({means[best]:.3f} m); " + ", ".join(f"`{s}` {v:.3f} m" for s, v in sorted(means.items())) + ".")
    # the odometry solver is dead reckoning (plus a map): it is the reference, not a contender
    worse = [f"`{r['solver']}` robot {r['robot']}" for r in ran
             if r["solver"] != "odometry" and r["odo_ate"] is not None and r["ate"] > r["odo_ate"]]
    out.append(("Runs worse than dead reckoning: " + ", ".join(worse) + ".") if worse
               else "Every SLAM run is better than dead reckoning.")
    return out


def _find(rows, label, **where):
    return next((r for r in rows if r["solver"] == label and not r["refused"]
                 and all(r.get(k) == v for k, v in where.items())), None)


def icm_verdicts(vp_rows, cp_rows, mr_rows, vp_label: str) -> list[str]:
    """One computed verdict per "Done when" criterion of ``preset=real`` from the rows of this run:
    Victoria Park (the prefix run) ≤ :data:`GOAL_VP300_M`, car park ≤ :data:`GOAL_CP_M` with every surveyed
    beacon found, each MRCLAM robot's ATE within :data:`GOAL_MRCLAM_MARGIN` of :data:`GRAPH_BASELINE_ROW`'s (and
    the ratio of their solve times). A criterion whose rows are missing says so."""
    out = []
    vp = _find(vp_rows or [], ICM_PRESET_ROW)
    if vp is not None and vp["gps_ate"] is not None:
        ok = vp["gps_ate"] <= GOAL_VP300_M
        out.append(f"`preset=real` on {vp_label}: GPS ATE {vp['gps_ate']:.3f} m, goal ≤ {GOAL_VP300_M} m: "
                   f"**{'met' if ok else 'not met'}**.")
    else:
        out.append(f"`preset=real` on {vp_label}: no result, criterion not checked.")
    cp = _find(cp_rows or [], ICM_PRESET_ROW)
    if cp is not None and cp["gps_ate"] is not None:
        ok = cp["gps_ate"] <= GOAL_CP_M and cp.get("n_survey") is not None and cp["survey_matched"] == cp["n_survey"]
        out.append(f"`preset=real` on the car park: GPS ATE {cp['gps_ate']:.3f} m with {cp['survey_matched']} of "
                   f"{cp.get('n_survey')} beacons, goal ≤ {GOAL_CP_M} m with all: **{'met' if ok else 'not met'}**.")
    else:
        out.append("`preset=real` on the car park: no result, criterion not checked.")
    robots = sorted({r["robot"] for r in mr_rows or []})
    per = []
    for rb in robots:
        ic, gr = _find(mr_rows, ICM_PRESET_ROW, robot=rb), _find(mr_rows, GRAPH_BASELINE_ROW, robot=rb)
        if ic is not None and gr is not None:
            per.append((rb, ic, gr, ic["ate"] <= (1 + GOAL_MRCLAM_MARGIN) * gr["ate"]))
    if per:
        n_ok = sum(p[3] for p in per)
        out.append(f"`preset=real` on MRCLAM solo: {n_ok} of {len(per)} robots within "
                   f"{100 * GOAL_MRCLAM_MARGIN:.0f} % of the ATE of `{GRAPH_BASELINE_ROW}` (graph with every "
                   "parameter at its default) ("
                   + ", ".join(f"robot {rb} {ic['ate']:.4f} vs {gr['ate']:.4f} m, ratio {ic['ate'] / gr['ate']:.3f}"
                               + _time_ratio(ic, gr) for rb, ic, gr, _ in per) + "): "
                   f"**{'met' if n_ok == len(per) else 'not met'}**.")
    else:
        out.append(f"`preset=real` on MRCLAM solo: no paired icm / `{GRAPH_BASELINE_ROW}` rows, criterion not "
                   "checked.")
    return out


def _time_ratio(icm_row: dict, graph_row: dict) -> str:
    """``", solve time 1.9×"``: the ratio of the two rows' solve wall times, or ``""`` when one is missing."""
    a, b = icm_row.get("wall_s"), graph_row.get("wall_s")
    return f", solve time {a / b:.2f}×" if a is not None and b else ""


def _preset_text() -> str:
    from slamcli.solvers.icm.presets import expansion_text  # the preset's documented expansion (text only)

    return expansion_text("real")


def experiment_params(cfg) -> dict[str, str]:
    """``{solver label: parameter text}`` of an experiment (its ``[[solver]]`` parameters as written, after
    ``[quick]``), the table's "parameters" column."""
    return {s.label: param_text(s.params) for s in cfg.solvers}


def _dataset_of(records: list[dict]):
    """The dataset the runs of one recording solved (the sweep's ``dataset.h5`` of its first run)."""
    from slamcli.io import read_dataset

    return read_dataset(Path(records[0]["path"]) / "dataset.h5")


def import_options(run_dir: Path) -> dict:
    """The import options of the recording a run solved (its ``config.json``), e.g. ``{"duration": 300.0}``."""
    cfg = json.loads((Path(run_dir) / "config.json").read_text(encoding="utf-8"))
    return dict(cfg["dataset"].get("options", {}))


def _duration_text(run_dir: Path) -> str:
    """``"first 300 s"`` style length of a recording imported with ``duration``, else ``"whole run"``."""
    dur = import_options(run_dir).get("duration")
    return f"first {float(dur):g} s" if dur is not None else "whole run"


def render_vp(records: list[dict], params: dict[str, str], out: Path) -> tuple[list[str], list[dict]]:
    """Victoria Park's subsection from its sweep's rows (markdown lines, table rows)."""
    vp = _dataset_of(records)
    dur_txt = _duration_text(Path(records[0]["path"]))
    rows = gps_rows(records, params)
    lines = ["", "### Victoria Park", "",
             f"{dur_txt.capitalize()} of the run ({vp.inputs.n_poses - 1} steps of {vp.inputs.dt:g} s, "
             f"{len(vp.inputs.observations)} tree detections without ids, {len(vp.truth.ref_xy)} GPS fixes). GPS ATE: "
             "positions of the laser point against GPS after an SE(2) alignment (the run's own frame is not the GPS "
             "frame); map size: landmarks in the estimate (no true map exists).", ""]
    lines += _gps_table(rows, False)
    lines += [""] + _gps_sentences(rows, f"the {dur_txt} of Victoria Park")
    fig = _map_figure(rows, vp, out / "victoria_park_maps", f"Victoria Park, {dur_txt}")
    if fig is not None:
        lines += ["", f"![Victoria Park maps]({out.name}/{fig.name})"]
    return lines, rows


def render_mrclam(records: list[dict], params: dict[str, str]) -> tuple[list[str], list[dict]]:
    """MRCLAM's solo subsection from its sweep's rows (``params``: solver label → its parameters as written)."""
    rows = mrclam_rows(records, params)
    robots = sorted({r["robot"] for r in rows})
    lines = ["", "### MRCLAM Dataset 7, each robot solo", "",
             f"Robot(s) {', '.join(map(str, robots))}, each solved alone. Barcode ids as reported ids; ATE against "
             "the motion-capture truth (unaligned: the start pose is known); landmark RMSE of the estimates matched "
             "to the surveyed landmarks within 1 m.", ""]
    return lines + _mrclam_table(rows) + [""] + _mrclam_sentences(rows), rows


def render_cp(records: list[dict], params: dict[str, str], out: Path) -> tuple[list[str], list[dict]]:
    """The car park's subsection from its sweep's rows."""
    cp = _dataset_of(records)
    rows = gps_rows(records, params)
    n_s = len(cp.truth.landmarks_xy)
    for r in rows:
        r["n_survey"] = n_s
    lines = ["", "### ACFR car park", "",
             f"{cp.inputs.n_poses - 1} steps, {len(cp.inputs.observations)} beacon detections, "
             f"{n_s} surveyed beacons. Beacons found: estimated landmarks moved into the GPS frame by the "
             "trajectory's alignment and matched to the surveyed beacons within 2 m (optimal assignment).", ""]
    lines += _gps_table(rows, True, n_s)
    lines += [""] + _gps_sentences(rows, "the car park")
    found = [r for r in rows if not r["refused"] and r["survey_matched"] is not None]
    if found:
        b = max(found, key=lambda r: (r["survey_matched"], -(r["survey_rmse"] or 1e9)))
        lines.append(f"Most beacons found: `{b['solver']}`, {b['survey_matched']} of {n_s} "
                     f"(RMSE {_fmt(b['survey_rmse'])} m).")
    fig = _map_figure(rows, cp, out / "carpark_maps", "ACFR car park")
    if fig is not None:
        lines += ["", f"![Car park maps]({out.name}/{fig.name})"]
    return lines, rows


TITLES = {"vp": "Victoria Park", "mr": "MRCLAM", "cp": "Car park"}


def run_section(out_dir: Path, quick: bool, progress: LogFn | None = None, *,
                run: Callable) -> tuple[str, bool]:
    """Run the three experiments (``run(file)`` → :class:`~slamcli.reproduce.report.SweepOutcome`:
    :meth:`~slamcli.reproduce.report.Reproduction.run`) and render the section into ``out_dir``; return the
    markdown (figure paths relative to the report's folder, ``out_dir``'s parent) and whether every recording
    ran."""
    t0 = time.perf_counter()
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    outcomes, ok, failed = {}, True, []
    with quick_data(out, quick, EXCERPTS) as source:
        for key, file in EXPERIMENTS.items():
            try:
                outcomes[key] = run(file)
            except Exception as exc:  # noqa: BLE001 - one recording's failure is reported, the others still run
                ok = False
                failed.append(f"> **{TITLES[key]} not run**: {(str(exc).splitlines() or [''])[0]}")
    md, rows, ok2 = render(outcomes, out, quick, source)
    lines = ["## Real recordings (Victoria Park, MRCLAM Dataset 7, ACFR car park)", "",
             f"Data: {source}. Every built-in solver runs with the parameters listed; a solver that cannot "
             "run a recording refuses in one line, shown in the table. Experiments: "
             + ", ".join(f"`experiments/{f}`" for f in EXPERIMENTS.values())
             + " (`slamcli sweep NAME`); renderer: `slamcli/reproduce/real.py`."]
    lines += ["", *failed] if failed else []
    lines += md + ["", f"Section time: {time.perf_counter() - t0:.0f} s."]
    return "\n".join(lines), ok and ok2


def render(outcomes: dict, out: Path, quick: bool, source: str = "") -> tuple[list[str], dict, bool]:
    """The section's subsections and verdicts from finished sweeps (``{"vp"|"mr"|"cp": SweepOutcome}``;
    reads ``outcome.exp_dir`` and the parameters of ``outcome.cfg`` only); ``(lines, rows per key, ok)``."""
    lines: list[str] = []
    rows: dict[str, list[dict] | None] = {"vp": None, "mr": None, "cp": None}
    ok = True
    for key, o in outcomes.items():
        for label, why in o.missing.items():
            ok = False
            lines += ["", f"> **Not run on {TITLES[key]}: `{label}`** — {why}."]
        try:
            records = sweep_records(o.exp_dir)
            params = experiment_params(o.cfg)
            part, rows[key] = (render_vp(records, params, out) if key == "vp" else render_mrclam(records, params)
                               if key == "mr" else render_cp(records, params, out))
            lines += part
        except Exception as exc:  # noqa: BLE001 - the recording's failure is reported, the others still render
            ok = False
            lines += ["", f"> **{TITLES[key]} failed**: {type(exc).__name__}: {(str(exc).splitlines() or [''])[0]}"]
    vp_label = "Victoria Park"
    if rows["vp"]:
        vp_label = f"the {_duration_text(rows['vp'][0]['run_dir'])} of Victoria Park"
    lines += ["", "### ICM on real recordings: `preset=real` against its goals", "",
              "ICM runs three ways on every recording: the paper's defaults (row `icm`), the information weights "
              "and `preset=real` (" + _preset_text() + "). Each verdict is computed from the rows above."
              + (" Quick mode: the rows are the excerpts, the goals are the full recordings' (indicative only)."
                 if quick else ""), ""]
    lines += ["- " + v for v in icm_verdicts(rows["vp"], rows["cp"], rows["mr"], vp_label)]
    return lines, rows, ok
