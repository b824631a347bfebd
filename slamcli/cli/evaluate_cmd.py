"""``slamcli evaluate``: metrics of one result file against its dataset's ground truth."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

from slamcli.cli.app import app, check_output, choice, handle_errors, stdout_console

# (row name, key(s) in metrics.json) in display order; a row of one key is named by the metric registry
# (None), a row of several keys gets a group name. Units always come from the registry
# (slamcli.metrics.registry; angles in radians). Missing keys are skipped.
_ROWS = [
    ("ATE RMSE (unaligned)", "ate_rmse_m"),
    ("ATE RMSE (SE(2)-aligned)", "aligned_ate_rmse_m"),
    ("heading RMSE (unaligned)", "heading_rmse_rad"),
    (None, "odometry_ate_rmse_m"),
    (None, "rpe_trans_rmse_m"),
    (None, "rpe_rot_rmse_rad"),
    ("landmarks true / estimated", ("n_landmarks_true", "n_landmarks_est")),
    ("landmark error min / mean / max", ("paper_err_min_m", "paper_err_mean_m", "paper_err_max_m")),
    (None, "paper_err_mean_near_path_m"),
    ("landmarks matched / missed / spurious", ("lm_n_matched", "lm_n_missed", "lm_n_spurious")),
    (None, "lm_rmse_matched_m"),
    (None, "lm_aligned_rmse_matched_m"),
    (None, "lm_ospa_m"),
    ("landmark GOSPA (α=2)", "lm_gospa_m"),
    ("pose NEES (time mean, E = 3)", "pose_nees_mean"),
    ("landmark NEES (mean, E = 2)", "landmark_nees_mean"),
    ("iterations in trace", "n_iterations"),
    # occupancy grids (paper 001): over the cells the frequentist map observed
    (None, "grid_frequentist_n_observed"),
    ("map error per cell: frequentist / log-odds", ("grid_frequentist_mean_abs_error", "grid_logodds_mean_abs_error")),
    ("total map error: frequentist / log-odds", ("grid_frequentist_total_abs_error", "grid_logodds_total_abs_error")),
    ("cell accuracy at 0.5: frequentist / log-odds", ("grid_frequentist_accuracy", "grid_logodds_accuracy")),
    # no ground truth / GPS reference
    ("GPS ATE RMSE (SE(2)-aligned)", "gps_ate_aligned_rmse_m"),
    ("GPS ATE RMSE (unaligned)", "gps_ate_rmse_m"),
    ("GPS ATE RMSE, glitches kept (al. / unal.)", ("gps_ate_aligned_raw_rmse_m", "gps_ate_raw_rmse_m")),
    (None, "gps_n_rejected"),
    (None, "odometry_gps_ate_aligned_rmse_m"),
    ("GPS fixes matched / gaps / longest gap", ("gps_n_matched", "gps_gap_count", "gps_longest_gap_s")),
    ("surveyed landmarks matched / RMSE", ("survey_lm_matched", "survey_lm_rmse_m")),
    (None, "final_cost"),
    ("mean NIS / 95 % band", ("nis_mean", "nis_band_lo", "nis_band_hi")),
    ("estimated landmarks (map size)", "n_landmarks_est"),
    ("against: ATE (unaligned / aligned)", ("against_ate_rmse_m", "against_ate_aligned_rmse_m")),
    ("against: landmarks matched / RMSE", ("against_lm_matched", "against_lm_rmse_m")),
    ("set: soundness (true hypothesis)", "set_soundness"),
    ("set: hypotheses / distinct", ("set_n_hypotheses", "set_n_hypotheses_distinct")),
    (None, "set_true_correspondence_survived"),
    ("set: mean box width pose x / y / θ", ("set_true_pose_width_x_mean", "set_true_pose_width_y_mean",
                                            "set_true_pose_width_t_mean")),
    ("set: mean landmark box width", "set_true_landmark_width_mean"),
]


def _row_name_unit(name: str | None, keys: tuple[str, ...]) -> tuple[str, str]:
    """A row's name (the registry's for a single metric) and unit: the registry's units of its keys, one unit
    when they agree, else each (``-`` for a count)."""
    from slamcli.metrics.registry import metric_info

    infos = [metric_info(k) for k in keys]
    units = [i.unit for i in infos]
    unit = units[0] if len(set(units)) == 1 else " / ".join(u or "-" for u in units)
    return name or infos[0].name, unit


def _fmt(v) -> str:
    if v is None:
        return "n/a"
    if isinstance(v, float):
        return f"{v:.4g}"
    return str(v)


@app.command("evaluate")
def evaluate_command(
    result: Annotated[Path, typer.Argument(help="Result file (HDF5) written by `slamcli solve`.")],
    data: Annotated[Path | None, typer.Option(
        "--data", "-d", help="Dataset file; default: the path recorded in the result (hash-checked).")] = None,
    out_dir: Annotated[Path | None, typer.Option(
        "-o", "--out-dir", help="Directory for metrics.json and CSVs; default: <result stem>_eval/ beside it.")] = None,
    cutoff: Annotated[float, typer.Option(help="Landmark assignment / OSPA / GOSPA cut-off c, m.")] = 1.0,
    near_path: Annotated[float | None, typer.Option(
        help="Also report the paper's error over landmarks within this distance of the true path, m.")] = None,
    rpe_delta: Annotated[float, typer.Option(help="RPE pair separation (see --rpe-unit).")] = 1.0,
    rpe_unit: Annotated[choice("RpeUnit", ("steps", "m")), typer.Option(
        help="RPE separation unit: pose steps or metres travelled.")] = "steps",
    no_hash_check: Annotated[bool, typer.Option(
        "--no-hash-check", help="Do not require the dataset hash to match the result's record.")] = False,
    quiet: Annotated[bool, typer.Option("--quiet", "-q", help="Print nothing; just write the files.")] = False,
    against: Annotated[Path | None, typer.Option(
        "--against", help="Another result of the same dataset: ATE and landmark distances against it.")] = None,
) -> None:
    """Compute trajectory, map and consistency metrics; write metrics.json + per_{iteration,step,landmark}.csv."""
    with handle_errors():
        from slamcli.api.evaluate import evaluate_files

        out = out_dir if out_dir is not None else result.parent / f"{result.stem}_eval"
        check_output(out, folder=True, option="-o" if out_dir is not None else "output folder",
                     inputs=[result, data, against], replaces_folder=True)
        m = evaluate_files(result, data, out, cutoff=cutoff, near_path_m=near_path, rpe_delta=rpe_delta,
                           rpe_unit=str(rpe_unit), check_hash=not no_hash_check, against=against)
        if quiet:
            return
        from rich.table import Table

        table = Table(title=f"{result.name}: solver {m.get('solver')} ({m.get('status')}), cut-off {cutoff:g} m")
        table.add_column("metric")
        table.add_column("value", justify="right")
        table.add_column("unit")
        for name, key in _ROWS:
            keys = key if isinstance(key, tuple) else (key,)
            if not all(k in m for k in keys):
                continue
            row_name, unit = _row_name_unit(name, keys)
            table.add_row(row_name, " / ".join(_fmt(m[k]) for k in keys), unit)
        con = stdout_console()
        con.print(table)
        if m.get("robots"):  # multi-robot result: one row per robot
            rt = Table(title="per robot (multi-robot dataset)")
            from slamcli.metrics.registry import metric_label

            for col in ("robot", *(metric_label(k) for k in ("ate_rmse_m", "aligned_ate_rmse_m",
                                                              "odometry_ate_rmse_m"))):
                rt.add_column(col, justify="right")
            for n in m["robots"]:
                rt.add_row(str(n), *(_fmt(m.get(f"robot{n}_{k}")) for k in ("ate_rmse_m", "aligned_ate_rmse_m",
                                                                            "odometry_ate_rmse_m")))
            con.print(rt)
        for note in ("pose_nees_note", "landmark_nees_note", "per_iteration_note", "final_cost_note", "nis_note"):
            if str(m.get(note, "")).startswith("not available"):
                con.print(f"{note.removesuffix('_note').replace('_', ' ')}: {m[note]}", markup=False)
        if m.get("gps_note"):
            con.print(f"GPS: {m['gps_note']}", markup=False, soft_wrap=True)
        if m.get("not_available"):
            con.print(f"not available without ground truth: {'; '.join(m['not_available'])}", markup=False,
                      soft_wrap=True)
        con.print(f"wrote {out}/ (metrics.json, per_iteration.csv, per_step.csv, per_landmark.csv)", markup=False, soft_wrap=True)
