"""Export to / import from the formats other SLAM tools use (TUM, KITTI, g2o, CSV; see :mod:`slamcli.io.export`).

* :func:`export_file`: a result (its estimate) or a dataset (its ground truth) → one TUM/KITTI/g2o/CSV file.
* :func:`import_trajectory_file`: another estimator's TUM/KITTI trajectory → a slamcli result file on a given
  dataset, so ``evaluate``, ``plot`` and sweeps score estimators that are not slamcli plugins.

Time matching of an imported trajectory (:func:`trajectory_at`): each dataset time stamp ``τ`` inside
the file's time span takes the file's pose at ``τ``: an exact stamp (``|Δt| ≤ tol``) is copied, otherwise
the neighbours ``a`` (before) and ``b`` (after) are interpolated with ``s = (τ − t_a)/(t_b − t_a)``:
positions linearly, the heading along the shorter arc ``θ = wrap(θ_a + s·angle_diff(θ_b, θ_a))``
(:func:`slamcli.models.se2.interpolate_poses`).
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from slamcli.errors import ConfigError, SchemaError, SlamcliError
from slamcli.numerics import STAMP_MATCH_TOL_S


def _schema_of(path: Path) -> str:
    from slamcli.io import read_header

    return str(read_header(path).get("schema", ""))


def export_file(src: str | os.PathLike, fmt: str, out: str | os.PathLike, *, data: str | os.PathLike | None = None,
                check_hash: bool = True) -> dict:
    """Export a result's estimate or a dataset's ground truth to ``out`` (written atomically).

    Parameters
    ----------
    src : result file (estimate; its dataset supplies time stamps, odometry and noise) or dataset file
          (ground truth poses and landmarks, observations attached by the true association).
    fmt : "tum" | "kitti" | "g2o" | "gtsam" | "csv".
    data : dataset of a result; default the one recorded in it (hash-checked).

    Returns
    -------
    dict ``{"kind": "result"|"dataset", "format", "n_poses", "n_landmarks", "n_edges", "n_loop_closures",
    "n_sightings", "n_unassociated"}`` (the last four: g2o/gtsam only; ``n_edges`` counts odometry,
    loop-closure and landmark edges; every sighting is written, the ``n_unassociated`` ones as landmarks of
    their own), plus ``"warning"`` (one line) when the file cannot carry the whole graph for GTSAM.
    :func:`describe_export` words it as one line.
    """
    from slamcli.io import DATASET_SCHEMA, RESULT_SCHEMA, read_dataset
    from slamcli.io import export as ex

    if fmt.lower() not in ex.FORMATS:
        raise ConfigError(f"--format: {fmt!r} is not one of {', '.join(ex.FORMATS)}")
    src, out = Path(src), Path(out)
    if out.exists() and src.exists() and out.resolve() == src.resolve():
        raise ConfigError(f"-o {out}: refusing to overwrite the input file")
    schema = _schema_of(src)
    if schema == RESULT_SCHEMA:
        from slamcli.api.evaluate import load_result_and_dataset

        res, ds, _ = load_result_and_dataset(src, data, check_hash=check_hash, require_truth=False)
        return export_objects(fmt, out, ds, res)
    if schema == DATASET_SCHEMA:
        ds = read_dataset(src)
        if ds.truth is None or ds.truth.position_reference_only:
            raise SlamcliError(f"{src}: dataset has no ground truth to export (export a result instead)")
        return export_objects(fmt, out, ds)
    raise SchemaError(f"{src}: not a slamcli result or dataset (schema {schema!r})")


def export_objects(fmt: str, out: str | os.PathLike, dataset, result=None) -> dict:
    """Export ``result``'s estimate (on ``dataset``), or with ``result=None`` the dataset's ground truth.

    Time stamps, odometry, observations and noise come from ``dataset.inputs``; the g2o landmark edges
    follow the result's association (or the true association for ground truth). Returns the summary dict
    of :func:`export_file`.
    """
    from slamcli.io import export as ex

    fmt = fmt.lower()
    if fmt not in ex.FORMATS:
        raise ConfigError(f"--format: {fmt!r} is not one of {', '.join(ex.FORMATS)}")
    if result is not None:
        kind, poses, lms, assoc = "result", result.poses_xyt, result.landmarks_xy, result.assoc
        pose_cov, lm_cov = result.pose_cov, result.landmark_cov
    else:
        if dataset.truth is None or dataset.truth.position_reference_only:
            raise SlamcliError("the dataset has no ground truth to export")
        t = dataset.truth
        kind, poses, lms, assoc = "dataset", t.poses_xyt, t.landmarks_xy, t.obs_landmark
        pose_cov = lm_cov = None
    inp = dataset.inputs
    if len(poses) != inp.n_poses:
        raise SlamcliError(f"{len(poses)} poses but the dataset has {inp.n_poses} (wrong dataset)")
    summary = {"kind": kind, "format": fmt, "n_poses": int(len(poses)), "n_landmarks": int(len(lms))}
    if fmt == "tum":
        ex.write_tum(out, inp.timestamps, poses)
    elif fmt == "kitti":
        ex.write_kitti(out, poses)
    elif fmt == "csv":
        ex.write_csv(out, inp.timestamps, poses, lms, pose_cov, lm_cov)
    else:
        obs = inp.observations
        # the factor graph the graph solver builds: per-edge information unless the result was solved
        # with edge_info=false; loop closures always (they carry nothing but their own information)
        use_edge_info = bool(result.params.get("edge_info", True)) if result is not None else True
        cons = inp.constraints
        writer = ex.write_g2o if fmt == "g2o" else ex.write_gtsam
        written = writer(out, poses, lms, inp.odometry_xyt, inp.noise.odometry_std, obs.step, obs.range_m,
                         obs.bearing_rad, assoc, inp.noise.range_std, inp.noise.bearing_std,
                         constraints=cons, use_edge_info=use_edge_info)
        n_between = cons.n_between if cons is not None else 0
        n_sightings = len(obs)
        summary["n_edges"] = int(len(poses) - 1 + n_between + n_sightings)
        summary["n_loop_closures"] = int(n_between)
        summary["n_sightings"] = int(n_sightings)
        summary["n_unassociated"] = int(np.count_nonzero(np.asarray(assoc) < 0))
        if fmt == "g2o" and n_sightings:
            summary["warning"] = f"GTSAM's readG2o skips the {n_sightings} EDGE_SE2_XY lines: use --format gtsam"
        elif fmt == "gtsam" and written[1]:
            summary["warning"] = f"{written[1]} BR lines drop a bearing-range correlation (BR has two σ)"
        if np.any(np.asarray(inp.sensor_offset_xy) != 0) and n_sightings:
            summary["warning"] = "; ".join(x for x in (summary.get("warning"),
                                                       "sensor offset not in the file (edges from the body pose)") if x)
    return summary


def describe_export(summary: dict) -> str:
    """What an export wrote, in the terms of its format (TUM and KITTI hold poses only; CSV poses and
    landmarks; g2o/GTSAM the whole graph), e.g. ``gtsam: estimate, 151 poses, 12 landmarks, 180 sightings
    (3 unassociated, written as landmarks of their own), 330 edges``."""
    s = summary
    what = "estimate" if s["kind"] == "result" else "ground truth"
    head = f"{s['format']}: {what}, {s['n_poses']} poses"
    if s["format"] in ("tum", "kitti"):
        return f"{head}; {s['format'].upper()} holds poses only"
    if s["format"] == "csv":
        return f"{head}, {s['n_landmarks']} landmarks"
    alone = (f" ({s['n_unassociated']} unassociated, written as landmarks of their own)"
             if s["n_unassociated"] else "")
    return (f"{head}, {s['n_landmarks']} landmarks, {s['n_sightings']} sightings{alone}, {s['n_loop_closures']} "
            f"loop closures, {s['n_edges']} edges")


def trajectory_at(t_src, poses_src, t_query, *, tol: float = STAMP_MATCH_TOL_S) -> tuple[np.ndarray, np.ndarray]:
    """Poses of a time-stamped trajectory at ``t_query`` (module docstring).

    Parameters
    ----------
    t_src : (n,) strictly increasing; poses_src : (n, 3); t_query : (m,).

    Returns
    -------
    poses_xyt (m, 3)   NaN rows where ``t_query`` is outside ``[t_src[0] − tol, t_src[-1] + tol]``.
    exact (m,) bool    the query matched a source stamp within ``tol`` (no interpolation).
    """
    from slamcli.models.se2 import interpolate_poses

    t = np.asarray(t_src, float)
    P = np.asarray(poses_src, float).reshape(-1, 3)
    q = np.asarray(t_query, float).reshape(-1)
    out = np.full((len(q), 3), np.nan)
    j = np.clip(np.searchsorted(t, q), 0, len(t) - 1)  # first source stamp ≥ q
    near = np.where(np.abs(t[j] - q) <= np.abs(t[np.maximum(j - 1, 0)] - q), j, np.maximum(j - 1, 0))
    exact = np.abs(t[near] - q) <= tol
    out[exact] = P[near[exact]]
    inside = (~exact) & (q > t[0]) & (q < t[-1])
    out[inside] = interpolate_poses(t, P, q[inside])
    return out, exact


def import_trajectory_file(path: str | os.PathLike, data_path: str | os.PathLike, out_path: str | os.PathLike, *,
                           fmt: str = "auto", times: str | os.PathLike | None = None, time_offset: float = 0.0,
                           extrapolate: str = "error", tol: float = STAMP_MATCH_TOL_S, name: str | None = None):
    """Turn a foreign TUM/KITTI trajectory into a result file on ``data_path`` (written atomically).

    Parameters
    ----------
    fmt : "tum" | "kitti" | "auto" (by extension: ``.tum``/``.txt`` with 8 columns → TUM, ``.kitti`` → KITTI).
    times : KITTI only: a ``times.txt`` with one stamp per pose; without it the file must hold exactly one
            pose per dataset pose (matched by index).
    time_offset : seconds added to the file's stamps (another clock).
    extrapolate : dataset stamps outside the file's span: "error" (default; one line naming how many) or
                  "hold" (take the nearest end pose; recorded as ``extra["n_held"]``).
    name : solver name recorded in the result (default ``"imported:<format>"``).

    Returns
    -------
    SolverResult  (status ``completed``, no landmarks, every observation unassociated).
    """
    from slamcli.api.solve import dataset_relpath
    from slamcli.io import dataset_hash, read_dataset, write_result
    from slamcli.io import export as ex
    from slamcli.types import SolverResult, Status

    path, data_path, out_path = Path(path), Path(data_path), Path(out_path)
    if extrapolate not in ("error", "hold"):
        raise ConfigError(f"--extrapolate: must be error or hold, got {extrapolate!r}")
    if fmt == "auto":
        suffix = path.suffix.lower()
        if suffix == ".kitti":
            fmt = "kitti"
        elif suffix in (".tum", ".txt", ".csv"):
            first = next((ln for ln in path.read_text(errors="replace").splitlines()
                          if ln.strip() and not ln.lstrip().startswith("#")), "") if path.is_file() else ""
            fmt = "kitti" if len(first.replace(",", " ").split()) == 12 else "tum"
        else:
            raise ConfigError(f"{path}: cannot tell the format from {suffix or 'no extension'!r}; pass --format")
    if fmt not in ("tum", "kitti"):
        raise ConfigError(f"--format: {fmt!r} is not one of tum, kitti")
    for p in (data_path,):
        if out_path.exists() and p.exists() and out_path.resolve() == p.resolve():
            raise ConfigError(f"-o {out_path}: refusing to overwrite the input dataset")
    ds = read_dataset(data_path)
    ts = np.asarray(ds.inputs.timestamps, float)
    n = len(ts)
    n_held = 0
    if fmt == "tum" or times is not None:
        if fmt == "tum":
            t_src, P = ex.read_tum(path)
        else:
            P = ex.read_kitti(path)
            t_src = ex.read_times(times)
            if len(t_src) != len(P):
                raise SchemaError(f"{times}: {len(t_src)} stamps for {len(P)} poses in {path}")
            if np.any(np.diff(t_src) <= 0):
                raise SchemaError(f"{times}: stamps must increase strictly")
        t_src = t_src + float(time_offset)
        if t_src[-1] < ts[0] - tol or t_src[0] > ts[-1] + tol:
            raise SlamcliError(f"{path}: no time overlap: the file covers [{t_src[0]:.6g}, {t_src[-1]:.6g}] s, "
                               f"dataset {data_path} covers [{ts[0]:.6g}, {ts[-1]:.6g}] s (try --time-offset)")
        poses, exact = trajectory_at(t_src, P, ts, tol=tol)
        missing = np.flatnonzero(np.isnan(poses[:, 0]))
        if missing.size:
            if extrapolate == "error":
                raise SlamcliError(
                    f"{path}: covers [{t_src[0]:.6g}, {t_src[-1]:.6g}] s, so {missing.size} of {n} dataset poses "
                    f"(from {ts[missing[0]]:.6g} s) lie outside it; pass --extrapolate hold to keep the end poses")
            poses[missing] = np.where((ts[missing] < t_src[0])[:, None], P[0], P[-1])
            n_held = int(missing.size)
        n_exact = int(exact.sum())
    else:
        poses = ex.read_kitti(path)
        if len(poses) != n:
            raise SchemaError(f"{path}: {len(poses)} KITTI poses but dataset {data_path} has {n} poses; give the "
                              f"stamps with --times")
        n_exact = n
    result = SolverResult(
        solver=name or f"imported:{fmt}",
        solver_version="",
        params={"source": str(path), "format": fmt, "time_offset": float(time_offset), "extrapolate": extrapolate},
        status=Status.COMPLETED,
        message=f"{n_exact} poses matched, {n - n_exact - n_held} interpolated, {n_held} held",
        poses_xyt=poses,
        landmarks_xy=np.zeros((0, 2)),
        assoc=np.full(len(ds.inputs.observations), -1, np.int64),
        dataset_hash=dataset_hash(ds),
        extra={"dataset_path": str(data_path.resolve()), "dataset_relpath": dataset_relpath(data_path, out_path),
               "source_path": str(path.resolve()), "n_matched": n_exact, "n_interpolated": n - n_exact - n_held,
               "n_held": n_held},
    )
    write_result(out_path, result)
    return result
