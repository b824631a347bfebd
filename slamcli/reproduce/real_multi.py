"""``make reproduce`` section "real-multi": MRCLAM Dataset 7, five robots solved jointly vs each robot alone.

The runs are the shipped experiment ``real-multi`` (``experiments/real-multi.toml``, runnable alone with
``slamcli sweep real-multi``): one multi-robot dataset (``all-robots = true``: one time base, shared landmarks,
inter-robot range-bearing readings) solved jointly with ``graph`` (robust=auto → Cauchy on the sensor-reported
barcodes) and ``icm`` (``preset=real``: on data with ids, reported correspondences, information weights, joint
Gauss-Newton steps in every sweep), and every robot alone on the same time grid (``solo = N``). This module runs it
through :meth:`slamcli.reproduce.report.Reproduction.run` and renders the section from the sweep's files only
(:func:`measure`): each robot's unaligned ATE against the motion capture for dead reckoning, solo and joint. Every
outcome sentence is computed from those numbers.

Full mode: the whole common window of the five robots (891 s at dt = 0.1 s), 50 ICM sweeps at most. Quick mode:
10 ICM sweeps, and in a checkout the 30 s five-robot excerpt of ``tests/data`` in place of the recording. The
dataset folder is the registered recording ``mrclam7`` (``slamcli datasets add mrclam7 DIR`` or ``slamcli
datasets fetch mrclam7``).
"""

from __future__ import annotations

import csv
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np

from slamcli.reproduce.real import import_options, quick_data, refusal, sweep_records

EXPERIMENT = "real-multi.toml"
#: the label of the joint (all-robots) entry of the experiment; the others are the solo entries
TEAM_LABEL = "mrclam7-team"
#: quick mode in a checkout: the registry's mrclam7 is the 30 s five-robot excerpt of tests/data
EXCERPTS = {"mrclam_dataset7": "mrclam_team_excerpt"}
#: a change of the ATE smaller than this fraction counts as "no change" in the outcome sentences
SAME_FRACTION = 0.02
#: the goal for team ICM: converged before its sweep cap, mean joint ATE within this fraction of graph's
GOAL_TEAM_MARGIN = 0.10


def _ate(est: np.ndarray, true: np.ndarray) -> float:
    from slamcli.metrics.trajectory import ate

    return float(ate(est, true)["ate_rmse_m"])


def measure(exp_dir: Path) -> dict:
    """The section's numbers from the finished sweep in ``exp_dir``: ``results.csv`` (the solo runs' ATE, the
    statuses and solve times), the joint runs' ``result.h5`` (each robot's slice of the stacked poses) and the
    team's ``dataset.h5`` (dead reckoning, truth, the import's accounting).

    Returns
    -------
    dict with ``rows`` (one dict per robot: robot, odometry, graph_solo, graph_joint, icm_solo, icm_joint — ATE
    in m), ``readings`` (kept inter-robot readings), ``robot_rows`` (the import's accounting), ``duration_s``,
    ``status`` (solver → statuses; ``<solver>_joint`` → the joint run's), ``seconds`` (solve time per solver and
    mode, s), ``failed`` (one line per failed run).
    """
    from slamcli.io import read_dataset, read_result

    records = sweep_records(exp_dir)
    team_runs = [r for r in records if r["data"] == TEAM_LABEL]
    ds = read_dataset(Path(team_runs[0]["path"]) / "dataset.h5")
    team, truth = ds.inputs.robots, ds.truth.poses_xyt
    fp = team.first_pose
    numbers = [int(n) for n in team.robot_number]
    rows = [{"robot": n, "odometry": _ate(ds.inputs.odometry_xyt[fp[r]:fp[r + 1]], truth[fp[r]:fp[r + 1]])}
            for r, n in enumerate(numbers)]
    status: dict[str, list[str]] = {}
    seconds: dict[str, float] = {}
    failed = []
    for rec in team_runs + [r for r in records if r["data"] != TEAM_LABEL]:
        method, joint = str(rec["label"]), rec["data"] == TEAM_LABEL
        mode = "joint" if joint else "solo"
        if rec["status"] != "completed":
            failed.append(f"{method} {rec['data']}: {refusal(rec.get('error') or 'failed')}")
            continue
        status.setdefault(method, []).append(str(rec["solver_status"]))
        if joint:
            status[f"{method}_joint"] = [str(rec["solver_status"])]
        seconds[f"{method}_{mode}"] = seconds.get(f"{method}_{mode}", 0.0) + float(rec["solve_time_s"])
        if joint:
            poses = read_result(Path(rec["path"]) / "result.h5").poses_xyt
            for r in range(team.n_robots):
                rows[r][f"{method}_joint"] = _ate(poses[fp[r]:fp[r + 1]], truth[fp[r]:fp[r + 1]])
        else:
            rows[numbers.index(int(import_options(rec["path"])["solo"]))][f"{method}_solo"] = float(rec["ate_rmse_m"])
    return {"rows": rows, "readings": int(len(team.range_m)), "robot_rows": ds.metadata["robot_rows"],
            "duration_s": float(ds.metadata["scenario_params"]["duration_s"]), "status": status,
            "seconds": dict(sorted(seconds.items())), "failed": failed}


def outcome_sentences(rows: list[dict], same: float = SAME_FRACTION) -> list[str]:
    """One sentence per solver, computed from the per-robot ATE: how many robots the joint solve helped (ATE lower
    by more than ``same`` of the solo ATE), hurt, or left unchanged, and the mean relative change."""
    out = []
    for method in ("graph", "icm"):
        ch = np.array([(r[f"{method}_joint"] - r[f"{method}_solo"]) / r[f"{method}_solo"] for r in rows])
        better, worse = int(np.sum(ch < -same)), int(np.sum(ch > same))
        unchanged = len(rows) - better - worse
        mean_j = float(np.mean([r[f"{method}_joint"] for r in rows]))
        mean_s = float(np.mean([r[f"{method}_solo"] for r in rows]))
        verdict = ("the joint solve is better for every robot" if better == len(rows) else
                   "the joint solve is better for no robot" if better == 0 else
                   f"the joint solve is better for {better} of {len(rows)} robots")
        out.append(f"**{method}**: {verdict} (ATE lower by more than {100 * same:.0f} %: {better}, higher: {worse}, "
                   f"within ±{100 * same:.0f} %: {unchanged}); mean ATE {mean_s:.3f} m solo → {mean_j:.3f} m joint "
                   f"({100 * (mean_j - mean_s) / mean_s:+.1f} %).")
        odo = float(np.mean([r["odometry"] for r in rows]))
        d = (mean_j - odo) / odo
        rel = (f"within ±{100 * same:.0f} % of" if abs(d) <= same else
               f"{100 * abs(d):.0f} % below" if d < 0 else f"{100 * d:.0f} % above")
        out.append(f"{method} joint mean ATE is {rel} the dead-reckoning mean ({odo:.3f} m).")
    return out


def team_icm_verdict(rows: list[dict], icm_joint_status: str, margin: float = GOAL_TEAM_MARGIN) -> str:
    """The team-ICM goal, computed: the joint ICM run stopped on its energy test (``converged``, not
    its sweep cap) and its mean ATE over the robots is within ``margin`` of graph joint's."""
    ic = float(np.mean([r["icm_joint"] for r in rows]))
    gr = float(np.mean([r["graph_joint"] for r in rows]))
    conv, close = icm_joint_status == "converged", ic <= (1 + margin) * gr
    return (f"Team ICM (`preset=real`): status {icm_joint_status}, mean ATE {ic:.3f} m against graph joint's "
            f"{gr:.3f} m (goal: converged and within {100 * margin:.0f} %): "
            f"**{'met' if conv and close else 'not met'}**"
            + ("" if conv else " (it stopped at its sweep cap)") + ("" if close else " (ATE too high)") + ".")


def run_section(out_dir: Path, quick: bool, progress: Callable[[str], None] | None = None, *,
                run: Callable) -> tuple[str, bool]:
    """Run the experiment (``run(file)`` → :class:`~slamcli.reproduce.report.SweepOutcome`:
    :meth:`~slamcli.reproduce.report.Reproduction.run`) and render the section; writes ``real_multi_ate.csv``
    under ``out_dir``. Returns the markdown and whether every run completed."""
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    md = ["## Real data: MRCLAM Dataset 7, five robots jointly vs each alone (`graph`, `icm`)", ""]
    t0 = time.perf_counter()
    try:
        with quick_data(out_dir, quick, EXCERPTS) as source:
            outcome = run(EXPERIMENT)
        if outcome.missing:
            raise RuntimeError("not run: " + "; ".join(f"{k} ({v})" for k, v in outcome.missing.items()))
        m = measure(outcome.exp_dir)
        md += render(m, quick, source, outcome.cfg.solver("icm").params.get("max_sweeps"), out_dir)
    except Exception as exc:  # noqa: BLE001 - a failed section is reported, never a traceback
        md.append(f"> **Section failed**: {type(exc).__name__}: {(str(exc).splitlines() or [''])[0]}")
        return "\n".join(md), False
    md.append(f"Section {time.perf_counter() - t0:.1f} s. Table: `real_multi_ate.csv`. Experiment: "
              "`experiments/real-multi.toml` (`slamcli sweep real-multi`).")
    ok = not m["failed"] and all(s != "failed" for v in m["status"].values() for s in v)
    return "\n".join(md) + "\n", ok


def render(m: dict, quick: bool, source: str, icm_sweeps, out_dir: Path) -> list[str]:
    """The section's markdown from :func:`measure`'s numbers (without the closing timing); writes
    ``real_multi_ate.csv`` into ``out_dir``."""
    rows = m["rows"]
    md = [f"> **Run failed**: {line}" for line in m["failed"]]
    if m["failed"]:
        return md
    with open(Path(out_dir) / "real_multi_ate.csv", "w", newline="") as fh:
        w = csv.DictWriter(fh, fieldnames=list(rows[0]))
        w.writeheader()
        w.writerows(rows)
    rr = m["robot_rows"]
    md += [
        f"{'Quick mode: the first' if quick else 'The whole common window,'} {m['duration_s']:.1f} s of all five "
        f"robots at dt = 0.1 s; {m['readings']} inter-robot readings kept of {rr['n_rows_with_robot_barcode']} rows "
        f"whose barcode is a robot's ({rr['dropped_outside_time_base']} outside the common time base). Start poses "
        "from the motion capture (one world frame); ATE unaligned, against the motion capture. graph: robust=auto "
        "(Cauchy on the barcodes); icm: preset=real (reported correspondences, information weights, joint "
        f"Gauss-Newton steps), {icm_sweeps} sweeps at most. Solo = the same robot's data alone on the same time "
        f"grid. Data: {source}.",
        "",
        "| robot | dead reckoning [m] | graph solo [m] | graph joint [m] | icm solo [m] | icm joint [m] |",
        "|---:|---:|---:|---:|---:|---:|",
    ]
    for r in rows:
        md.append(f"| {r['robot']} | {r['odometry']:.3f} | {r['graph_solo']:.3f} | {r['graph_joint']:.3f} | "
                  f"{r['icm_solo']:.3f} | {r['icm_joint']:.3f} |")
    icm_joint = m["status"].get("icm_joint", ["—"])[0]
    md += ["", *[f"- {s}" for s in outcome_sentences(rows)], f"- {team_icm_verdict(rows, icm_joint)}", ""]
    st = {k: sorted(set(v)) for k, v in m["status"].items() if not k.endswith("_joint")}
    statuses = ", ".join(f"{k}: {'/'.join(v)}" for k, v in st.items())
    md.append(f"Solver statuses: {statuses}; solve time "
              + ", ".join(f"{k} {v:.1f} s" for k, v in m["seconds"].items()) + ".")
    return md
