"""Evaluate result files against their dataset's ground truth and write the metric files.

``evaluate_files`` is the file-level workflow behind ``slamcli evaluate`` and the sweep runner:

* the dataset is the one given, or the path recorded in the result (``extra["dataset_path"]``, tried as
  given and relative to the result's directory, then ``extra["dataset_relpath"]`` relative to the result's
  directory, so a result and its dataset moved together still evaluate); its content hash must equal the
  hash recorded in the result, otherwise the metrics would describe a different run → one-line :class:`SlamcliError`;
* outputs (each written atomically): ``metrics.json`` (scalars, NaN → null), and tidy CSVs
  ``per_iteration.csv``, ``per_step.csv``, ``per_landmark.csv``.

``monte_carlo_nees_files`` averages the pose NEES of N (result, dataset) pairs for ``plot nees`` and sweeps.
"""

from __future__ import annotations

import json
import math
import os
from dataclasses import dataclass, fields
from pathlib import Path
from typing import Any

from slamcli.errors import SlamcliError

#: bound on |log10(cutoff^ospa_order)|: OSPA/GOSPA sum such powers over landmarks in float64 (max ≈ 1e308)
MAX_POWER_DECADES = 250
OUTPUT_FILES = ("metrics.json", "per_iteration.csv", "per_step.csv", "per_landmark.csv")
#: the empty file evaluate writes into every folder it makes: only a folder holding it (and nothing but the
#: files above) is evaluate's own, to be replaced whole by the next evaluation
EVALUATION_MARKER = ".slamcli-evaluation"


def _own_folder(out: Path) -> bool:
    """``out`` is missing, or a folder evaluate made: its marker and regular files of :data:`OUTPUT_FILES` only."""
    if not out.exists():
        return True
    entries = list(out.iterdir())
    return any(e.name == EVALUATION_MARKER for e in entries) and all(
        e.name in (*OUTPUT_FILES, EVALUATION_MARKER) and e.is_file() and not e.is_symlink() for e in entries)


@dataclass(frozen=True)
class EvaluateOptions:
    """An experiment's ``[evaluate]`` table: the options of :class:`slamcli.metrics.summary.EvaluationParams`
    (``cutoff_m``; ``cutoff``, :func:`evaluate_files`' keyword, is accepted as its old spelling) and ``against``."""

    cutoff_m: float = 1.0
    ospa_order: float = 2.0
    near_path_m: float | None = None
    rpe_delta: float = 1.0
    rpe_unit: str = "steps"
    against: str | None = None

    def __post_init__(self) -> None:
        try:
            check_evaluation_options(cutoff=self.cutoff_m, ospa_order=self.ospa_order, near_path_m=self.near_path_m,
                                     rpe_delta=self.rpe_delta, rpe_unit=self.rpe_unit)
        except SlamcliError as exc:
            raise ValueError(str(exc).replace("cutoff:", "cutoff_m:", 1)) from None

    @staticmethod
    def names() -> list[str]:
        """The keys an ``[evaluate]`` table may hold (both spellings of the cut-off)."""
        return sorted([f.name for f in fields(EvaluateOptions)] + ["cutoff"])

    @classmethod
    def keywords(cls, options: dict[str, Any], where: str) -> dict[str, Any]:
        """``options`` checked through the schema, as :func:`evaluate_files`' keywords with every default
        filled; the values as written are kept (they enter the run ids)."""
        from slamcli.errors import ConfigError
        from slamcli.params import from_mapping

        opts = dict(options)
        if "cutoff" in opts:
            if "cutoff_m" in opts:
                raise ConfigError(f"{where}: cutoff_m and cutoff (its old spelling) both given; keep cutoff_m")
            opts["cutoff_m"] = opts.pop("cutoff")
        try:
            cls(**from_mapping(cls, opts, where=where, what="option"))
        except ValueError as exc:
            raise ConfigError(f"{where}: {exc}") from None
        written = {("cutoff" if k == "cutoff_m" else k): v for k, v in opts.items()}
        defaults = {("cutoff" if f.name == "cutoff_m" else f.name): f.default for f in fields(cls)}
        return defaults | written


def check_evaluation_options(*, cutoff: float = 1.0, ospa_order: float = 2.0, near_path_m: float | None = None,
                             rpe_delta: float = 1.0, rpe_unit: str = "steps", where: str = "") -> None:
    """Value checks of the evaluation options (CLI flags and experiment ``[evaluate]`` tables alike).

    Raises a one-line :class:`SlamcliError` naming the option: cut-off, RPE separation and near-path distance
    must be finite and > 0, the OSPA order finite and >= 1, the RPE unit ``steps`` or ``m``; cutoff^order
    within 1e±:data:`MAX_POWER_DECADES`, an RPE separation in steps at most :data:`~slamcli.io.schema.MAX_POSES`.
    """
    from slamcli.io.schema import MAX_POSES

    pre = f"{where}: " if where else ""

    def num(v) -> float | None:
        return float(v) if isinstance(v, (int, float)) and not isinstance(v, bool) else None

    for name, v in (("cutoff", cutoff), ("rpe_delta", rpe_delta), ("near_path_m", near_path_m)):
        if name == "near_path_m" and v is None:
            continue
        x = num(v)
        if x is None or not (math.isfinite(x) and x > 0):
            raise SlamcliError(f"{pre}{name}: must be a finite number > 0, got {v!r}")
    x = num(ospa_order)
    if x is None or not (math.isfinite(x) and x >= 1):
        raise SlamcliError(f"{pre}ospa_order: must be a finite number >= 1, got {ospa_order!r}")
    if rpe_unit not in ("steps", "m"):
        raise SlamcliError(f"{pre}rpe_unit: must be 'steps' or 'm', got {rpe_unit!r}")
    if abs(math.log10(float(cutoff))) * float(ospa_order) > MAX_POWER_DECADES:
        raise SlamcliError(f"{pre}cutoff: cutoff^ospa_order = {float(cutoff):g}^{float(ospa_order):g} is beyond "
                           f"1e±{MAX_POWER_DECADES} (over- or underflows in OSPA/GOSPA)")
    if rpe_unit == "steps" and float(rpe_delta) > MAX_POSES:
        raise SlamcliError(f"{pre}rpe_delta: {float(rpe_delta):g} steps is more than any dataset has ({MAX_POSES})")


def _resolve_dataset_path(result_path: Path, recorded: str, relpath: str = "") -> Path:
    """The recorded dataset: as recorded (absolute, or relative to the cwd / the result's directory), then
    ``relpath`` relative to the result's directory (a result and its dataset moved together)."""
    if not recorded and not relpath:
        raise SlamcliError(f"{result_path}: the result records no dataset path; pass the dataset with --data")
    candidates = []
    if recorded:
        p = Path(recorded)
        candidates += [p] if p.is_absolute() else [p, result_path.parent / p]
    if relpath:
        candidates.append(result_path.parent / relpath)
    for c in candidates:
        if c.is_file():
            return c
    raise SlamcliError(f"{result_path}: recorded dataset {recorded!r} not found; pass the dataset with --data")


def load_result_and_dataset(result_path, data_path=None, *, check_hash: bool = True, require_truth: bool = True):
    """Read a result and the dataset it was computed on.

    Returns
    -------
    (SolverResult, Dataset, Path of the dataset)

    Raises
    ------
    SlamcliError  missing dataset, dataset without ground truth (unless ``require_truth=False``, e.g. for a
                  map of a real recording), or dataset hash ≠ the result's record.
    """
    from slamcli.io import dataset_hash, read_dataset, read_result

    result_path = Path(result_path)
    result = read_result(result_path)
    if data_path is None:
        data_path = _resolve_dataset_path(result_path, str(result.extra.get("dataset_path", "") or ""),
                                          str(result.extra.get("dataset_relpath", "") or ""))
    data_path = Path(data_path)
    dataset = read_dataset(data_path)
    if check_hash and result.dataset_hash:
        h = dataset_hash(dataset)
        if h != result.dataset_hash:
            raise SlamcliError(f"{result_path}: computed on dataset {result.dataset_hash[:19]}…, but {data_path} "
                               f"has hash {h[:19]}… (wrong or modified dataset)")
    if require_truth and dataset.truth is None:
        raise SlamcliError(f"{data_path}: dataset has no ground truth; nothing to evaluate against")
    if require_truth and dataset.truth.position_reference_only:
        raise SlamcliError(f"{data_path}: dataset has no ground truth (a GPS position reference only)")
    n_poses, n_obs = dataset.inputs.n_poses, len(dataset.inputs.observations)
    if result.poses_xyt.shape[0] != n_poses:
        raise SlamcliError(f"{result_path}: poses_xyt: {result.poses_xyt.shape[0]} poses, but dataset {data_path} "
                           f"has {n_poses}")
    if result.assoc.shape[0] != n_obs:
        raise SlamcliError(f"{result_path}: assoc: {result.assoc.shape[0]} rows, but dataset {data_path} has "
                           f"{n_obs} observations")
    return result, dataset, data_path


def _json_clean(obj):
    """NaN/inf → None and numpy scalars → Python, so metrics.json is strict JSON."""
    if isinstance(obj, dict):
        return {str(k): _json_clean(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_json_clean(v) for v in obj]
    if hasattr(obj, "item") and not isinstance(obj, (str, bytes)):
        obj = obj.item()
    if isinstance(obj, float) and not math.isfinite(obj):
        return None
    return obj


def recorded_dataset(result_path: str | os.PathLike) -> Path | None:
    """The dataset file the result ``result_path`` records and :func:`load_result_and_dataset` would read
    without ``--data`` (from the header only); None for a file that is not a readable result, or whose
    recorded dataset is not found."""
    from slamcli.io import RESULT_SCHEMA, read_header

    try:
        hdr = read_header(result_path)
        if hdr.get("schema") != RESULT_SCHEMA:
            return None
        extra = hdr.get("extra_json") if isinstance(hdr.get("extra_json"), dict) else {}
        recorded = str(extra.get("dataset_path") or hdr.get("dataset_path") or "")
        return _resolve_dataset_path(Path(result_path), recorded, str(extra.get("dataset_relpath") or ""))
    except SlamcliError:
        return None


def write_evaluation(evaluation, out_dir, extra_scalars: dict | None = None) -> Path:
    """Write ``metrics.json`` and the three CSVs into ``out_dir`` without ever mixing two evaluations.

    * ``out_dir`` missing, or a folder an earlier evaluation made (:data:`EVALUATION_MARKER` and its files,
      nothing else): the four files and the marker are written into a temporary sibling folder that then
      replaces ``out_dir`` (:func:`slamcli.io.atomic.atomic_folder`); a ``kill -9`` leaves the previous
      folder intact.
    * any other folder (a sweep's run folder, a user's folder, even one holding only files with these names):
      the four files are written under temporary names first and renamed into place together at the end; an
      entry of one of these names that is not a regular file is refused before anything is written.

    OS failures (read-only folder, a file in the way) become one-line SlamcliErrors.
    """
    from slamcli.io.atomic import atomic_files, atomic_folder

    out = Path(out_dir)
    scalars = dict(evaluation.scalars)
    scalars.update(extra_scalars or {})
    files = {"metrics.json": lambda p: p.write_text(json.dumps(_json_clean(scalars), indent=2, allow_nan=False) + "\n"),
             "per_iteration.csv": lambda p: evaluation.per_iteration.to_csv(p, index=False),
             "per_step.csv": lambda p: evaluation.per_step.to_csv(p, index=False),
             "per_landmark.csv": lambda p: evaluation.per_landmark.to_csv(p, index=False)}
    if out.is_symlink() or (out.exists() and not out.is_dir()):
        raise SlamcliError(f"{out}: exists and is not a folder; give -o a folder name")
    try:
        if _own_folder(out):
            with atomic_folder(out) as tmp:
                for name, write in files.items():
                    write(tmp / name)
                (tmp / EVALUATION_MARKER).write_bytes(b"")
            return out
        for name in files:
            if os.path.lexists(out / name) and not (out / name).is_file():
                raise SlamcliError(f"{out / name}: exists and is not a regular file; refusing to replace it "
                                   "(give -o a new folder)")
        with atomic_files([out / name for name in files]) as tmps:
            for write, tmp in zip(files.values(), tmps):
                write(tmp)
    except OSError as exc:
        where = exc.filename if exc.filename is not None else out
        raise SlamcliError(f"{where}: cannot write the evaluation ({exc.strerror or exc})") from None
    return out


def evaluate_files(result_path: str | os.PathLike, data_path: str | os.PathLike | None = None,
                   out_dir: str | os.PathLike | None = None, *, cutoff: float = 1.0, ospa_order: float = 2.0,
                   near_path_m: float | None = None, rpe_delta: float = 1.0, rpe_unit: str = "steps",
                   check_hash: bool = True, return_tables: bool = False,
                   against: str | os.PathLike | None = None):
    """Evaluate one result file.

    Parameters
    ----------
    result_path : result HDF5 file.
    data_path : dataset HDF5 file; None = the path recorded in the result (hash-checked).
    out_dir : where to write ``metrics.json`` + CSVs; None = write nothing.
    cutoff, ospa_order, near_path_m, rpe_delta, rpe_unit : see :class:`slamcli.metrics.summary.EvaluationParams`.
    return_tables : also return the :class:`~slamcli.metrics.summary.Evaluation` (tables included).
    against : another result file of the same dataset; adds ``against_*`` metrics (this result's ATE and
        landmark distances with the other as reference). A dataset without ground truth (or with a GPS-only
        reference) gets :func:`evaluate_without_truth` instead of the truth metrics.

    Returns
    -------
    dict of scalar metrics (JSON-clean: NaN → None), or ``(dict, Evaluation)`` with ``return_tables``.
    """
    from slamcli.metrics.summary import EvaluationParams, evaluate_result

    check_evaluation_options(cutoff=cutoff, ospa_order=ospa_order, near_path_m=near_path_m, rpe_delta=rpe_delta,
                             rpe_unit=rpe_unit)
    result, dataset, data_path = load_result_and_dataset(result_path, data_path, check_hash=check_hash,
                                                         require_truth=False)
    params = EvaluationParams(cutoff_m=cutoff, ospa_order=ospa_order, near_path_m=near_path_m,
                              rpe_delta=rpe_delta, rpe_unit=rpe_unit)
    try:
        if dataset.truth is None or dataset.truth.position_reference_only:
            ev = evaluate_without_truth(result, dataset)
        else:
            ev = evaluate_result(result, dataset.truth, dataset.inputs.odometry_xyt, params)
            if dataset.inputs.robots is not None:  # multi-robot: per-robot ATE, within-robot RPE
                ev = _add_per_robot(ev, result, dataset, params)
        if against is not None:
            ev = _add_against(ev, result, against, cutoff)
    except ValueError as exc:
        raise SlamcliError(f"{result_path} vs {data_path}: {exc}") from None
    files = {"result_path": str(result_path), "dataset_path": str(data_path),
             "dataset_hash": result.dataset_hash, "wall_time_s": float(result.wall_time_s)}
    if result.grids and dataset.truth.occupancy is not None:  # occupancy maps (paper 001)
        from slamcli.metrics.occupancy import occupancy_scalars

        files.update(occupancy_scalars(result.grids, dataset.truth.occupancy, dataset.truth.lap_end_step))
    if out_dir is not None:
        write_evaluation(ev, out_dir, files)
    scalars = _json_clean({**ev.scalars, **files})
    return (scalars, ev) if return_tables else scalars


def monte_carlo_nees_files(result_paths, data_paths=None, *, confidence: float = 0.95, check_hash: bool = True):
    """Average pose NEES over N result files (independent Monte-Carlo runs of the same scenario).

    Parameters
    ----------
    result_paths : sequence of result files.
    data_paths : None (use each result's recorded dataset) or a sequence of the same length.

    Returns
    -------
    (AverageNees, None) or (None, reason)   reason when any run has no pose covariances or lengths differ.
    """
    from slamcli.metrics.summary import monte_carlo_pose_nees

    result_paths = list(result_paths)
    if data_paths is None:
        data_paths = [None] * len(result_paths)
    data_paths = list(data_paths)
    if len(data_paths) != len(result_paths):
        raise SlamcliError(f"got {len(result_paths)} results but {len(data_paths)} datasets; give one per result")
    pairs = []
    for rp, dp in zip(result_paths, data_paths):
        res, ds, _ = load_result_and_dataset(rp, dp, check_hash=check_hash)
        pairs.append((res, ds.truth))
    return monte_carlo_pose_nees(pairs, confidence)


# ------------------------------------------------------------------------------------------------------
# real recordings: no ground truth, or a position-only reference
# ------------------------------------------------------------------------------------------------------
def evaluate_without_truth(result, dataset):
    """Metrics of a result whose dataset has no true poses/landmarks: the solver's own final cost, NIS with
    its χ² band (filters), map size, dead-reckoning distance, and — with a position reference (GPS) — ATE
    against it matched by time with the gaps stated. ``not_available`` lists what needs the truth."""
    import numpy as np
    import pandas as pd

    from slamcli.metrics.reference import TRUTH_ONLY_METRICS, ate_vs_position_reference, own_model_metrics
    from slamcli.metrics.summary import Evaluation

    inp = dataset.inputs
    est = np.asarray(result.poses_xyt, float)
    if est.shape[0] != inp.n_poses:
        raise ValueError(f"result has {est.shape[0]} poses but the dataset has {inp.n_poses}")
    s = {"solver": result.solver, "status": getattr(result.status, "value", str(result.status)),
         "n_poses": int(est.shape[0]), "truth": "none"}
    s.update(own_model_metrics(result))
    s["path_length_m"] = float(np.sum(np.linalg.norm(np.diff(est[:, :2], axis=0), axis=1)))
    per_step = pd.DataFrame({"step": np.arange(len(est)), "time_s": inp.timestamps, "est_x": est[:, 0],
                             "est_y": est[:, 1], "est_theta": est[:, 2]})
    missing = list(TRUTH_ONLY_METRICS)
    truth = dataset.truth
    if truth is not None and truth.ref_time_s is not None:
        s["truth"] = "position reference (GPS) only"
        from slamcli.models.observation import sensor_pose

        off = np.zeros(2) if truth.ref_offset_xy is None else np.asarray(truth.ref_offset_xy, float)
        # the reference positions refer to the body point `off` (e.g. the GPS antenna)
        g = ate_vs_position_reference(inp.timestamps, sensor_pose(est, off), truth.ref_time_s, truth.ref_xy)
        odo = ate_vs_position_reference(inp.timestamps, sensor_pose(inp.odometry_xyt, off), truth.ref_time_s,
                                        truth.ref_xy)
        s["gps_ref_point_xy_m"] = off.tolist()
        errs, t_m, align = g.pop("gps_errors_aligned_m"), g.pop("gps_matched_time_s"), g.pop("gps_alignment")
        odo.pop("gps_alignment")
        s.update(g)
        missing = [m for m in missing if not m.startswith("ate_rmse_m")]
        if truth.landmarks_xy is not None and align is not None:  # surveyed landmarks (car park beacons)
            from slamcli.metrics.reference import landmarks_vs_surveyed

            s.update(landmarks_vs_surveyed(result.landmarks_xy, truth.landmarks_xy, *align))
            missing = [m for m in missing if not m.startswith("landmark errors")]
            s["survey_note"] = ("estimated landmarks moved into the GPS frame by the trajectory's SE(2) alignment, "
                                "then optimally assigned to the surveyed ones within the cut-off")
        s["odometry_gps_ate_aligned_rmse_m"] = odo["gps_ate_aligned_rmse_m"]
        s["gps_note"] = (f"positions vs GPS at {g['gps_n_matched']} fixes (estimate interpolated at the GPS times); "
                         f"{g['gps_gap_count']} gaps > {g['gps_gap_threshold_s']:g} s without GPS, "
                         f"{g['gps_gap_total_s']:.1f} s in all, longest {g['gps_longest_gap_s']:.1f} s; the "
                         "unaligned ATE assumes the run's start frame is the GPS frame (it is not known to be), "
                         f"the aligned one removes that frame; positions of the body point {off.tolist()} m; "
                         f"{g['gps_n_rejected']} fix(es) rejected as glitches (farther than "
                         f"{g['gps_glitch_max_speed_mps']:g} m/s · Δt + {g['gps_glitch_tol_m']:g} m from both "
                         "neighbouring fixes, which agree with each other; reference only)"
                         + (f" at {[round(x, 3) for x in g['gps_rejected_time_s']]} s, kept in gps_ate_*_raw_rmse_m"
                            if g["gps_n_rejected"] else ""))
        per_step["gps_aligned_err_m"] = np.interp(inp.timestamps, t_m, errs) if len(t_m) else np.nan
    s["not_available"] = missing
    n_it = len(result.trace) if result.trace is not None else 0
    per_iteration = pd.DataFrame({"iteration": np.arange(n_it),
                                  "objective": result.trace.objective if n_it else np.zeros(0),
                                  "n_landmarks": [len(result.trace.landmarks_at(k)) for k in range(n_it)]})
    lm = np.asarray(result.landmarks_xy, float).reshape(-1, 2)
    counts = np.bincount(np.asarray(result.assoc)[np.asarray(result.assoc) >= 0], minlength=len(lm))[:len(lm)]
    per_landmark = pd.DataFrame({"landmark": np.arange(len(lm)), "est_x": lm[:, 0], "est_y": lm[:, 1],
                                 "n_obs": counts})
    return Evaluation(scalars=s, per_iteration=per_iteration, per_step=per_step, per_landmark=per_landmark)


def _add_per_robot(ev, result, dataset, params):
    """Per-robot metrics of a multi-robot result (:mod:`slamcli.metrics.team`); the RPE is replaced by the
    one over within-robot pairs, and ``per_step`` gains a ``robot`` column."""
    import dataclasses

    import numpy as np

    from slamcli.metrics.team import per_robot_trajectory_metrics

    team = dataset.inputs.robots
    m = per_robot_trajectory_metrics(result.poses_xyt, dataset.truth.poses_xyt, team.first_pose, team.robot_number,
                                     dataset.inputs.odometry_xyt, params.rpe_delta, params.rpe_unit)
    m["multi_robot_note"] = (f"{team.n_robots} robots: ate_rmse_m is over all stacked poses (the joint overall), "
                             "aligned_ate_rmse_m with one SE(2) alignment for all; robot<N>_* per robot; RPE over "
                             "pairs within one robot")
    per_step = ev.per_step.copy()
    per_step["robot"] = np.asarray(team.robot_number)[np.asarray(team.pose_robot)]
    return dataclasses.replace(ev, scalars={**ev.scalars, **m}, per_step=per_step)


def _add_against(ev, result, against_path, cutoff: float):
    """Add ``against_*`` scalars: this result against another result of the same dataset."""
    import dataclasses

    from slamcli.io import read_result
    from slamcli.metrics.reference import trajectory_against

    other = read_result(against_path)
    if result.dataset_hash and other.dataset_hash and result.dataset_hash != other.dataset_hash:
        raise ValueError(f"--against {against_path}: computed on a different dataset "
                         f"({other.dataset_hash[:19]}… vs {result.dataset_hash[:19]}…)")
    m = trajectory_against(result.poses_xyt, other.poses_xyt, result.landmarks_xy, other.landmarks_xy,
                           cutoff_m=max(cutoff, 1e-9))
    m["against"] = f"{other.solver} ({against_path})"
    return dataclasses.replace(ev, scalars={**ev.scalars, **m})
