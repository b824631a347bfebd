"""``slamcli info``: a rich summary of a dataset or result file (the file is fully validated first)."""

from __future__ import annotations

from pathlib import Path

import typer

from slamcli.cli.app import app, handle_errors, iteration_count, printable, stdout_console


def _flatten(d, prefix: str = "") -> list[tuple[str, str]]:
    out: list[tuple[str, str]] = []
    if isinstance(d, dict):
        for k, v in d.items():
            out += _flatten(v, f"{prefix}{k}.") if isinstance(v, dict) else [(f"{prefix}{k}", _short(v))]
    return out


def _short(v) -> str:
    s = str(v)
    return s if len(s) <= 70 else s[:67] + "..."


def _fmt(x: float, unit: str = "") -> str:
    return f"{x:.4g}{(' ' + unit) if unit else ''}"


def dataset_rows(path: Path) -> tuple[list[tuple[str, str]], list[tuple[str, str]]]:
    """(summary rows, parameter rows) of a dataset file."""
    import numpy as np

    from slamcli.io import dataset_hash, read_dataset, read_header

    hdr = read_header(path)
    ds = read_dataset(path)
    inp, obs, tr = ds.inputs, ds.inputs.observations, ds.truth
    ref = tr if tr is not None and tr.position_reference_only else None
    tr = None if ref is not None else tr
    T = inp.n_poses - 1
    poses = tr.poses_xyt if tr is not None else inp.odometry_xyt
    path_len = float(np.linalg.norm(np.diff(poses[:, :2], axis=0), axis=1).sum()) if T else 0.0
    n_obs = len(obs)
    rows = [
        ("file", f"{path}  ({path.stat().st_size / 1e6:.2f} MB)"),
        ("schema", (f"{hdr.get('schema')} v{hdr.get('schema_version')}  (slamcli {hdr.get('slamcli_version', '?')}, "
                   f"created {hdr.get('created_utc', '?')})")),
        ("scenario", f"{hdr.get('scenario', '—')}   seed {hdr.get('seed', '—')}"),
        ("steps", f"{T}  ({inp.n_poses} poses)"),
        ("dt / duration", f"{_fmt(inp.dt, 's')} / {_fmt(float(inp.timestamps[-1] - inp.timestamps[0]), 's')}"),
        ("path length", f"{_fmt(path_len, 'm')}" + ("  (true)" if tr is not None else "  (odometry)")),
    ]
    if tr is not None:
        n_clutter = int((tr.obs_landmark < 0).sum())
        seen = int(np.unique(tr.obs_landmark[tr.obs_landmark >= 0]).size)
        rows.append(("landmarks", f"{len(tr.landmarks_xy)} true, {seen} observed"))
        rows.append(("observations", f"{n_obs}  ({n_clutter} clutter, {n_obs / max(inp.n_poses, 1):.2f} per pose)"))
    else:
        rows.append(("landmarks", "— (no ground truth in file)"))
        rows.append(("observations", f"{n_obs}  ({n_obs / max(inp.n_poses, 1):.2f} per pose)"))
    n_ids = int((obs.reported_id >= 0).sum())
    rows.append(("reported ids", f"{n_ids} of {n_obs} rows" if n_ids else "none"))
    sensor_cfg = hdr.get("sensor_json") if isinstance(hdr.get("sensor_json"), dict) else {}
    kind = ds.metadata.get("sensor_kind") or sensor_cfg.get("kind")
    rows.append(("sensors", (f"{kind}; " if kind else "")
                 + (", ".join(f"#{s}: {c} rows" for s, c in zip(*np.unique(obs.sensor, return_counts=True)))
                    or "no rows")))
    if n_obs:
        rows.append(("range min / max", f"{_fmt(float(obs.range_m.min()))} / {_fmt(float(obs.range_m.max()), 'm')}"))
    rows.append(("max range", _fmt(inp.max_range, "m")))
    n = inp.noise
    rows.append(("noise σ", (f"motion {np.round(n.motion_std, 6).tolist()}, odometry {np.round(n.odometry_std, 6).tolist()}, "
                            f"range {n.range_std:g} m, bearing {n.bearing_std:g} rad")))
    rows.append(("GPS", f"{len(inp.gps_step)} fixes, σ {inp.gps_std:g} m" if len(inp.gps_step) else "none"))
    if ref is not None:
        rows.append(("reference", f"GPS positions only: {len(ref.ref_time_s)} fixes (evaluate: ATE vs GPS)"))
    if inp.motion_model != "ddmr":
        v = inp.vehicle
        rows.append(("motion model", f"{inp.motion_model} (L {v.wheelbase_m:g} m, H {v.encoder_offset_m:g} m); "
                                     f"sensor at {np.round(inp.sensor_offset_xy, 3).tolist()} m"))
    c = inp.constraints
    if c is not None:
        per_edge = [n for n, a in (("odometry", c.odometry_info), (f"observations ({c.observation_model})",
                                                                   c.observation_info)) if a is not None]
        rows.append(("constraints", f"{c.n_between} loop closures (pose-pose between-factors); per-edge "
                                    f"information: {', '.join(per_edge) or 'none'}"))
    if tr is not None and tr.occupancy is not None:
        rows.append(("true grid", _grid_text(tr.occupancy)))
    rows.append(("content hash", dataset_hash(ds)[:23] + "…"))
    params = hdr.get("scenario_params_json")
    if not isinstance(params, dict):
        params = {k: v for k, v in ds.metadata.items() if k not in ("scenario", "seed")}
    return rows, _flatten(params)


def result_rows(path: Path) -> tuple[list[tuple[str, str]], list[tuple[str, str]]]:
    """(summary rows, parameter rows) of a result file."""
    from slamcli.io import read_header, read_result

    hdr = read_header(path)
    res = read_result(path)
    n_assoc = int((res.assoc >= 0).sum())
    rows = [
        ("file", f"{path}  ({path.stat().st_size / 1e6:.2f} MB)"),
        ("schema", (f"{hdr.get('schema')} v{hdr.get('schema_version')}  (slamcli {hdr.get('slamcli_version', '?')}, "
                   f"created {hdr.get('created_utc', '?')})")),
        ("solver", f"{res.solver} {res.solver_version}"),
        ("status", res.status.value + (f" — {res.message}" if res.message else "")),
        ("wall time", _fmt(res.wall_time_s, "s")),
        ("iterations", str(iteration_count(res)) if iteration_count(res) is not None else "— (no trace)"),
        ("poses", str(len(res.poses_xyt))),
        ("landmarks", str(len(res.landmarks_xy))),
        ("associated obs.", f"{n_assoc} of {len(res.assoc)}"),
        ("covariances", ", ".join(n for n, c in (("pose", res.pose_cov), ("landmark", res.landmark_cov))
                                  if c is not None) or "none"),
        ("dataset", f"{res.extra.get('dataset_path', '—')}  ({res.dataset_hash[:23]}…)"),
    ]
    if res.trace is not None and len(res.trace):
        obj = res.trace.objective
        rows.append(("objective first → last", f"{obj[0]:.6g} → {obj[-1]:.6g}"))
    for name, g in res.grids.items():
        rows.append((f"grid {name}", _grid_text(g)))
    if res.extra.get("used_truth_association"):
        rows.append(("association", "ORACLE (true association given to the solver)"))
    outliers = res.extra.get("chi2_outliers")
    if isinstance(outliers, dict) and outliers:
        rows.append(("χ² outliers 95/99 %", "; ".join(
            f"{name} {d.get('over_95')}/{d.get('over_99')} of {d.get('factors')}" for name, d in outliers.items()
            if isinstance(d, dict))))
    cert = res.extra.get("certificate")
    if isinstance(cert, dict) and "certified" in cert:
        verdict = "certified global optimum" if cert["certified"] else "NOT certified"
        rows.append(("optimality certificate", f"{verdict} (SE-Sync dual: λ_min(S) = {cert.get('lambda_min', float('nan')):.3g},"
                     f" η = {cert.get('eta', float('nan')):.3g}, suboptimality bound "
                     f"{cert.get('suboptimality_bound', float('nan')):.3g})"))
    extra = {k: v for k, v in res.extra.items() if k not in ("dataset_path", "chi2_outliers")}
    params = _flatten({"params": res.params, "extra": extra})
    return rows, params


def _grid_text(g) -> str:
    """One line about an occupancy grid: shape, resolution, origin, observed cells, snapshots."""
    H, W = g.shape
    txt = f"{H}x{W} cells at {g.resolution:g} m, origin ({g.origin_xy[0]:g}, {g.origin_xy[1]:g}) m"
    if g.observed is not None:
        txt += f", {int((g.observed > 0).sum())} observed"
    else:
        txt += f", {int((g.prob > 0.5).sum())} occupied"
    if g.snapshots is not None:
        txt += f", {len(g.snapshots)} snapshots"
    return txt


@app.command("info")
def info_command(
    file: Path = typer.Argument(..., help="A dataset or result file (HDF5)."),
) -> None:
    """Summarise a dataset (steps, duration, landmarks, observations, path length, parameters) or a result
    (solver, status, iterations, landmarks, wall time)."""
    with handle_errors():
        from rich.table import Table
        from rich.text import Text

        from slamcli.errors import SchemaError
        from slamcli.io import DATASET_SCHEMA, RESULT_SCHEMA, read_header

        schema = read_header(file).get("schema")
        if schema == DATASET_SCHEMA:
            rows, params = dataset_rows(file)
            title, ptitle = "dataset", "scenario parameters"
        elif schema == RESULT_SCHEMA:
            rows, params = result_rows(file)
            title, ptitle = "result", "solver parameters"
        else:
            raise SchemaError(f"{file}: @schema: expected {DATASET_SCHEMA!r} or {RESULT_SCHEMA!r}, got {schema!r}")
        console = stdout_console()
        table = Table(title=f"slamcli {title}", show_header=False, title_justify="left")
        table.add_column(style="bold")
        table.add_column()
        for k, v in rows:
            table.add_row(k, Text(printable(v)))
        console.print(table)
        if params:
            pt = Table(title=ptitle, show_header=False, title_justify="left")
            pt.add_column(style="bold")
            pt.add_column()
            for k, v in params:
                pt.add_row(k, Text(printable(v)))
            console.print(pt)
