"""``make reproduce`` section "real-multi": MRCLAM Dataset 7, five robots solved jointly vs each robot alone.

One multi-robot dataset (``slamcli import mrclam DIR --all-robots``: one time base, shared landmarks, inter-robot
range-bearing readings) is solved jointly with ``graph`` (robust=auto → Cauchy on the sensor-reported barcodes)
and ``icm`` (``preset=real``: on data with ids, reported correspondences, information weights, joint Gauss-Newton
steps in every sweep); every robot is also solved alone on the same time
grid (:func:`slamcli.datasets.team.solo_dataset`). The table gives each robot's unaligned ATE against the motion
capture: dead reckoning, solo and joint for both solvers. Every outcome sentence is computed from those numbers.

Full mode: the whole common window of the five robots (891 s at dt = 0.1 s). Quick mode: the first
:data:`QUICK_DURATION_S` seconds and :data:`QUICK_ICM_SWEEPS` ICM sweeps (< 30 s). The dataset folder is
the registered recording ``mrclam7`` (``slamcli datasets add mrclam7 DIR`` or ``slamcli datasets fetch mrclam7``).
"""

from __future__ import annotations

import csv
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np

QUICK_DURATION_S = 30.0
QUICK_ICM_SWEEPS = 10
FULL_ICM_SWEEPS = 50
#: a change of the ATE smaller than this fraction counts as "no change" in the outcome sentences
SAME_FRACTION = 0.02
#: issue 22's goal for team ICM: converged before its sweep cap, mean joint ATE within this fraction of graph's
GOAL_TEAM_MARGIN = 0.10


def dataset_dir() -> Path:
    """The folder of the registered recording ``mrclam7``; :class:`~slamcli.datasets.registry.DatasetMissingError`
    (one line naming the fetch command) when it is not on this machine."""
    from slamcli.datasets.registry import locate

    return locate("mrclam7")


def _ate(est: np.ndarray, true: np.ndarray) -> float:
    from slamcli.metrics.trajectory import ate

    return float(ate(est, true)["ate_rmse_m"])


def measure(directory: Path, *, duration: float | None, icm_sweeps: int,
            progress: Callable[[str], None] | None = None) -> dict:
    """Import the five robots, solve jointly and solo with graph and icm.

    Returns
    -------
    dict with ``rows`` (one dict per robot: robot, odometry, graph_solo, graph_joint, icm_solo, icm_joint — ATE
    in m), ``readings`` (kept inter-robot readings), ``robot_rows`` (the import's accounting), ``duration_s``,
    ``status`` (solver → statuses), ``seconds`` (wall time per solver and mode).
    """
    from slamcli.api.solve import solve_dataset
    from slamcli.datasets.mrclam import import_mrclam_team
    from slamcli.datasets.team import solo_dataset

    log = progress or (lambda s: None)
    ds = import_mrclam_team(directory, [1, 2, 3, 4, 5], duration=duration)
    team = ds.inputs.robots
    fp = team.first_pose
    log(f"real-multi: imported {ds.inputs.n_poses} poses, {len(team.range_m)} inter-robot readings")
    params = {
        "graph": {"covariance": False},
        "icm": {"preset": "real", "max_sweeps": icm_sweeps, "trace_poses_every": 0},
    }
    rows = [{"robot": int(n), "odometry": _ate(ds.inputs.odometry_xyt[fp[r]:fp[r + 1]],
                                               ds.truth.poses_xyt[fp[r]:fp[r + 1]])}
            for r, n in enumerate(team.robot_number)]
    status: dict[str, list[str]] = {}
    seconds: dict[str, float] = {}
    for method, p in params.items():
        t0 = time.perf_counter()
        joint = solve_dataset(ds.inputs, method, p)
        seconds[f"{method}_joint"] = time.perf_counter() - t0
        status.setdefault(method, []).append(joint.status.value)
        status[f"{method}_joint"] = [joint.status.value]
        log(f"real-multi: {method} joint done ({joint.status.value})")
        t0 = time.perf_counter()
        for r in range(team.n_robots):
            solo = solo_dataset(ds, r)
            res = solve_dataset(solo.inputs, method, p)
            status[method].append(res.status.value)
            true = ds.truth.poses_xyt[fp[r]:fp[r + 1]]
            rows[r][f"{method}_solo"] = _ate(res.poses_xyt, true)
            rows[r][f"{method}_joint"] = _ate(joint.poses_xyt[fp[r]:fp[r + 1]], true)
        seconds[f"{method}_solo"] = time.perf_counter() - t0
        log(f"real-multi: {method} solo done")
    return {"rows": rows, "readings": int(len(team.range_m)), "robot_rows": ds.metadata["robot_rows"],
            "duration_s": float(ds.metadata["scenario_params"]["duration_s"]), "status": status,
            "seconds": seconds}


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
    """Issue 22's team-ICM criterion, computed: the joint ICM run stopped on its energy test (``converged``, not
    its sweep cap) and its mean ATE over the robots is within ``margin`` of graph joint's."""
    ic = float(np.mean([r["icm_joint"] for r in rows]))
    gr = float(np.mean([r["graph_joint"] for r in rows]))
    conv, close = icm_joint_status == "converged", ic <= (1 + margin) * gr
    return (f"Team ICM (`preset=real`): status {icm_joint_status}, mean ATE {ic:.3f} m against graph joint's "
            f"{gr:.3f} m (goal: converged and within {100 * margin:.0f} %): "
            f"**{'met' if conv and close else 'not met'}**"
            + ("" if conv else " (it stopped at its sweep cap)") + ("" if close else " (ATE too high)") + ".")


def run_section(out_dir: Path, quick: bool, progress: Callable[[str], None] | None = None) -> tuple[str, bool]:
    """The section's markdown and whether it ran; writes ``real_multi_ate.csv`` under ``out_dir``."""
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    md = ["## Real data: MRCLAM Dataset 7, five robots jointly vs each alone (`graph`, `icm`)", ""]
    from slamcli.datasets.registry import DatasetMissingError

    excerpt = Path(__file__).resolve().parents[2] / "tests" / "data" / "mrclam_team_excerpt"
    try:  # quick mode in a checkout: the 30 s team excerpt shipped with the tests (as the real section does)
        d = excerpt if quick and excerpt.is_dir() else dataset_dir()
    except DatasetMissingError as exc:
        md.append(f"> **Section failed**: {exc}.")
        return "\n".join(md), False
    t0 = time.perf_counter()
    try:
        m = measure(d, duration=QUICK_DURATION_S if quick and d != excerpt else None,
                    icm_sweeps=QUICK_ICM_SWEEPS if quick else FULL_ICM_SWEEPS, progress=progress)
    except Exception as exc:  # noqa: BLE001 - a failed section is reported, never a traceback
        md.append(f"> **Section failed**: {type(exc).__name__}: {str(exc).splitlines()[0] if str(exc) else ''}")
        return "\n".join(md), False
    rows = m["rows"]
    with open(out_dir / "real_multi_ate.csv", "w", newline="") as fh:
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
        "Gauss-Newton steps), "
        f"{QUICK_ICM_SWEEPS if quick else FULL_ICM_SWEEPS} sweeps at most. Solo = the same robot's data alone on the "
        "same time grid. Data: "
        + ("`tests/data/mrclam_team_excerpt` (the first 29.8 s of Dataset 7, all five robots)." if d == excerpt
           else "the registered recording `mrclam7` (`slamcli datasets`)."),
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
    md.append(f"Solver statuses: {statuses}; wall time "
              + ", ".join(f"{k} {v:.1f} s" for k, v in m["seconds"].items())
              + f"; section {time.perf_counter() - t0:.1f} s. Table: `real_multi_ate.csv`.")
    ok = all(s != "failed" for v in m["status"].values() for s in v)
    return "\n".join(md) + "\n", ok
