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
from pathlib import Path

from slamcli.errors import SlamcliError

OUTPUT_FILES = ("metrics.json", "per_iteration.csv", "per_step.csv", "per_landmark.csv")


def check_evaluation_options(*, cutoff: float = 1.0, ospa_order: float = 2.0, near_path_m: float | None = None,
                             rpe_delta: float = 1.0, rpe_unit: str = "steps", where: str = "") -> None:
    """Value checks of the evaluation options (CLI flags and experiment ``[evaluate]`` tables alike).

    Raises a one-line :class:`SlamcliError` naming the option: cut-off, RPE separation and near-path distance
    must be finite and > 0, the OSPA order finite and >= 1, the RPE unit ``steps`` or ``m``.
    """
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


def write_evaluation(evaluation, out_dir, extra_scalars: dict | None = None) -> Path:
    """Write ``metrics.json`` and the three CSVs into ``out_dir`` without ever mixing two evaluations.

    * ``out_dir`` missing, or holding only the files of an earlier evaluation: the four files are written
      into a temporary sibling folder that then replaces ``out_dir`` (:func:`slamcli.io.atomic.atomic_folder`);
      a ``kill -9`` leaves the previous folder intact.
    * ``out_dir`` holding other files too (a sweep's run folder, a user's folder): the four files are written
      under temporary names first and renamed into place together at the end.

    OS failures (read-only folder, a file in the way) become one-line SlamcliErrors.
    """
    from slamcli.io.atomic import atomic_folder, clean_stale_temporaries, temporary_sibling

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
        own = not out.exists() or all(e.name in OUTPUT_FILES for e in out.iterdir())
        if own:
            with atomic_folder(out) as tmp:
                for name, write in files.items():
                    write(tmp / name)
            return out
        clean_stale_temporaries(out)
        staged = {}
        try:
            for name, write in files.items():
                staged[name] = temporary_sibling(out / name)
                write(staged[name])
            for name, tmp in staged.items():
                os.replace(tmp, out / name)
        finally:
            for tmp in staged.values():
                tmp.unlink(missing_ok=True)
    except OSError as exc:
        where = exc.filename if exc.filename is not None else out
        raise SlamcliError(f"{where}: cannot write the evaluation ({exc.strerror or exc})") from None
    return out


def evaluate_files(result_path: str | os.PathLike, data_path: str | os.PathLike | None = None,
                   out_dir: str | os.PathLike | None = None, *, cutoff: float = 1.0, ospa_order: float = 2.0,
                   near_path_m: float | None = None, rpe_delta: float = 1.0, rpe_unit: str = "steps",
                   check_hash: bool = True, return_tables: bool = False):
    """Evaluate one result file.

    Parameters
    ----------
    result_path : result HDF5 file.
    data_path : dataset HDF5 file; None = the path recorded in the result (hash-checked).
    out_dir : where to write ``metrics.json`` + CSVs; None = write nothing.
    cutoff, ospa_order, near_path_m, rpe_delta, rpe_unit : see :class:`slamcli.metrics.summary.EvaluationParams`.
    return_tables : also return the :class:`~slamcli.metrics.summary.Evaluation` (tables included).

    Returns
    -------
    dict of scalar metrics (JSON-clean: NaN → None), or ``(dict, Evaluation)`` with ``return_tables``.
    """
    from slamcli.metrics.summary import EvaluationParams, evaluate_result

    check_evaluation_options(cutoff=cutoff, ospa_order=ospa_order, near_path_m=near_path_m, rpe_delta=rpe_delta,
                             rpe_unit=rpe_unit)
    result, dataset, data_path = load_result_and_dataset(result_path, data_path, check_hash=check_hash)
    params = EvaluationParams(cutoff_m=cutoff, ospa_order=ospa_order, near_path_m=near_path_m,
                              rpe_delta=rpe_delta, rpe_unit=rpe_unit)
    try:
        ev = evaluate_result(result, dataset.truth, dataset.inputs.odometry_xyt, params)
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
