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
    """Write ``metrics.json`` and the three CSVs into ``out_dir`` (created if missing), each atomically."""
    from slamcli.io import atomic_path

    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    scalars = dict(evaluation.scalars)
    scalars.update(extra_scalars or {})
    with atomic_path(out / "metrics.json") as tmp:
        tmp.write_text(json.dumps(_json_clean(scalars), indent=2, allow_nan=False) + "\n")
    for name, df in (("per_iteration.csv", evaluation.per_iteration), ("per_step.csv", evaluation.per_step),
                     ("per_landmark.csv", evaluation.per_landmark)):
        with atomic_path(out / name) as tmp:
            df.to_csv(tmp, index=False)
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

    if not cutoff > 0:
        raise SlamcliError(f"--cutoff must be > 0, got {cutoff}")
    if rpe_unit not in ("steps", "m"):
        raise SlamcliError(f"rpe unit must be 'steps' or 'm', got {rpe_unit!r}")
    result, dataset, data_path = load_result_and_dataset(result_path, data_path, check_hash=check_hash)
    params = EvaluationParams(cutoff_m=cutoff, ospa_order=ospa_order, near_path_m=near_path_m,
                              rpe_delta=rpe_delta, rpe_unit=rpe_unit)
    try:
        ev = evaluate_result(result, dataset.truth, dataset.inputs.odometry_xyt, params)
    except ValueError as exc:
        raise SlamcliError(f"{result_path} vs {data_path}: {exc}") from None
    files = {"result_path": str(result_path), "dataset_path": str(data_path),
             "dataset_hash": result.dataset_hash, "wall_time_s": float(result.wall_time_s)}
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
