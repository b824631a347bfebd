"""The notebook API: ``import slamcli as sc`` (attributes load lazily, so ``import slamcli`` stays cheap).

::

    import slamcli as sc
    ds = sc.simulate("loop", seed=1)                 # Dataset in memory (out="loop.h5" also writes it)
    r = sc.solve(ds, "icm", R=(1,))                   # SolverResult; solver parameters as keywords
    m = sc.evaluate(r, ds)                            # dict of scalar metrics (ate_rmse_m, lm_ospa_m, ...)
    sc.plot.map(r, ds, ax=ax)                         # draw into a matplotlib axis

Every function takes objects or file paths: ``sc.solve("loop.h5", "ekf", out="ekf.h5")`` reads and writes
files exactly as ``slamcli solve`` does (content hash and dataset path recorded); ``sc.evaluate("ekf.h5")``
finds the dataset the result records. Errors are :class:`~slamcli.errors.SlamcliError` with one line.
"""

from __future__ import annotations

import dataclasses
import os
from pathlib import Path
from typing import Any

from slamcli.errors import ConfigError, SchemaError
from slamcli.types import Dataset, SolverResult

PathLike = str | os.PathLike


def _is_path(x: Any) -> bool:
    return isinstance(x, (str, os.PathLike))


def load(path: PathLike) -> Dataset | SolverResult:
    """Read a dataset or a result file (whichever the file's schema says)."""
    from slamcli.io import DATASET_SCHEMA, RESULT_SCHEMA, read_dataset, read_header, read_result

    schema = read_header(path).get("schema")
    if schema == DATASET_SCHEMA:
        return read_dataset(path)
    if schema == RESULT_SCHEMA:
        return read_result(path)
    raise SchemaError(f"{path}: not a slamcli dataset or result (schema {schema!r})")


def save(obj: Dataset | SolverResult, path: PathLike) -> Path:
    """Write a dataset or a result (atomically)."""
    from slamcli.io import write_dataset, write_result

    if isinstance(obj, Dataset):
        return write_dataset(path, obj)
    if isinstance(obj, SolverResult):
        return write_result(path, obj)
    raise TypeError(f"save expects a Dataset or a SolverResult, got {type(obj).__name__}")


def _dataset(ds: Dataset | PathLike) -> Dataset:
    if isinstance(ds, Dataset):
        return ds
    if _is_path(ds):
        from slamcli.io import read_dataset

        return read_dataset(ds)
    raise TypeError(f"expected a Dataset or a dataset path, got {type(ds).__name__}")


def _result(r: SolverResult | PathLike) -> SolverResult:
    if isinstance(r, SolverResult):
        return r
    if _is_path(r):
        from slamcli.io import read_result

        return read_result(r)
    raise TypeError(f"expected a SolverResult or a result path, got {type(r).__name__}")


def _overrides(overrides: dict[str, Any] | None, kwargs: dict[str, Any]) -> dict[str, Any]:
    out = dict(overrides or {})
    out.update({k.replace("__", "."): v for k, v in kwargs.items()})  # sensor__max_range → sensor.max_range
    return out


def simulate(scenario: str = "loop", seed: int = 0, *, out: PathLike | None = None,
             overrides: dict[str, Any] | None = None, progress=None, **kwargs) -> Dataset:
    """Simulate a named scenario (``slamcli simulate --list`` names them).

    Scenario keys go in ``overrides={"sensor.max_range": 5.0}`` or as keywords with ``__`` for the dots
    (``n_steps=200, sensor__max_range=5.0``). ``out`` also writes the dataset file.
    """
    over = _overrides(overrides, kwargs)
    if out is not None:
        from slamcli.api.simulate import simulate_to_file

        return simulate_to_file(scenario, seed, over, out, progress=progress)
    from slamcli.sim import resolve_scenario
    from slamcli.sim import simulate as run

    if int(seed) < 0:
        raise ConfigError(f"seed: must be >= 0, got {seed}")
    return run(resolve_scenario(scenario, over), int(seed), progress=progress)


def solve(ds: Dataset | PathLike, method: str, *, seed: int = 0, init: SolverResult | PathLike | None = None,
          out: PathLike | None = None, oracle_association: bool = False, params: dict[str, Any] | None = None,
          progress=None, **kwargs) -> SolverResult:
    """Run solver ``method`` on a dataset (object or file); solver parameters as keywords (``R=(1,)``) or
    ``params={...}``, validated against the solver's Params dataclass (``slamcli solvers NAME``).

    With a dataset *file* and ``out``, this is exactly ``slamcli solve`` (result written atomically, dataset
    hash/path recorded). Otherwise the result stays in memory, stamped with the dataset's content hash.
    """
    p = {**(params or {}), **kwargs}
    if _is_path(ds) and out is not None:
        from slamcli.api.solve import solve_file

        if init is not None and not _is_path(init):
            raise TypeError("with a dataset file, give init as a result file path")
        return solve_file(ds, method, p, out, init_path=init, seed=seed, oracle_association=oracle_association,
                          progress=progress)
    from slamcli.api.solve import solve_dataset
    from slamcli.io import dataset_hash

    dataset = _dataset(ds)
    inputs = dataset.inputs
    if oracle_association:
        if dataset.truth is None or dataset.truth.position_reference_only:
            raise ConfigError("oracle_association: the dataset has no ground truth (no true association)")
        obs = dataclasses.replace(inputs.observations, reported_id=dataset.truth.obs_landmark.copy())
        inputs = dataclasses.replace(inputs, observations=obs)
    result = solve_dataset(inputs, method, p, seed=seed, init=None if init is None else _result(init),
                           progress=progress)
    extra = {**result.extra, "seed": int(seed), "used_truth_association": bool(oracle_association)}
    if _is_path(ds):
        extra["dataset_path"] = str(Path(ds).resolve())
    result = dataclasses.replace(result, dataset_hash=dataset_hash(dataset), extra=extra)
    if out is not None:
        from slamcli.io import write_result

        write_result(out, result)
    return result


def evaluate(r: SolverResult | PathLike, ds: Dataset | PathLike | None = None, *, out_dir: PathLike | None = None,
             tables: bool = False, check_hash: bool = True, cutoff: float = 1.0, ospa_order: float = 2.0,
             near_path_m: float | None = None, rpe_delta: float = 1.0, rpe_unit: str = "steps"):
    """Metrics of a result against its dataset's ground truth: a dict of scalars (``ate_rmse_m``,
    ``aligned_ate_rmse_m``, ``lm_ospa_m``, ``pose_nees_mean``, ...; NaN → None), or ``(dict, Evaluation)``
    with ``tables=True`` (per-iteration / per-step / per-landmark DataFrames). ``out_dir`` also writes
    ``metrics.json`` and the CSVs. A result file without ``ds`` uses the dataset it records."""
    opts = {"cutoff": cutoff, "ospa_order": ospa_order, "near_path_m": near_path_m, "rpe_delta": rpe_delta,
            "rpe_unit": rpe_unit}
    if _is_path(r) and (ds is None or _is_path(ds)):
        from slamcli.api.evaluate import evaluate_files

        return evaluate_files(r, ds, out_dir, check_hash=check_hash, return_tables=tables, **opts)
    from slamcli.api.evaluate import _json_clean, write_evaluation
    from slamcli.errors import SlamcliError
    from slamcli.io import dataset_hash
    from slamcli.metrics.summary import EvaluationParams, evaluate_result

    result = _result(r)
    if ds is None:
        raise ConfigError("evaluate: give the dataset of an in-memory result")
    dataset = _dataset(ds)
    if check_hash and result.dataset_hash and result.dataset_hash != dataset_hash(dataset):
        raise SlamcliError("evaluate: the result was computed on another dataset (content hash differs)")
    if not cutoff > 0:
        raise ConfigError(f"cutoff must be > 0, got {cutoff}")
    if rpe_unit not in ("steps", "m"):
        raise ConfigError(f"rpe_unit must be 'steps' or 'm', got {rpe_unit!r}")
    params = EvaluationParams(cutoff_m=cutoff, ospa_order=ospa_order, near_path_m=near_path_m,
                              rpe_delta=rpe_delta, rpe_unit=rpe_unit)
    try:
        if dataset.truth is None or dataset.truth.position_reference_only:
            from slamcli.api.evaluate import evaluate_without_truth

            ev = evaluate_without_truth(result, dataset)  # own-model metrics, GPS ATE when there is GPS
        else:
            ev = evaluate_result(result, dataset.truth, dataset.inputs.odometry_xyt, params)
    except ValueError as exc:
        raise SlamcliError(f"evaluate: {exc}") from None
    if out_dir is not None:
        write_evaluation(ev, out_dir)
    scalars = _json_clean(dict(ev.scalars))
    return (scalars, ev) if tables else scalars


def export(obj: SolverResult | Dataset | PathLike, fmt: str, out: PathLike, *,
           data: Dataset | PathLike | None = None) -> dict:
    """Write a result's estimate (needs its dataset: ``data`` or the one it records) or a dataset's ground
    truth as TUM / KITTI / g2o / CSV (see :mod:`slamcli.io.export`)."""
    from slamcli.api.interop import export_file, export_objects

    if _is_path(obj) and (data is None or _is_path(data)):
        return export_file(obj, fmt, out, data=data)
    if isinstance(obj, Dataset) or (_is_path(obj) and data is None):
        return export_objects(fmt, out, _dataset(obj))
    if data is None:
        raise ConfigError("export: give the dataset of an in-memory result (data=...)")
    return export_objects(fmt, out, _dataset(data), _result(obj))


def import_trajectory(path: PathLike, data: PathLike, out: PathLike, **kwargs) -> SolverResult:
    """A foreign TUM/KITTI trajectory → result file (see :func:`slamcli.api.interop.import_trajectory_file`)."""
    from slamcli.api.interop import import_trajectory_file

    return import_trajectory_file(path, data, out, **kwargs)


def aggregate(exp_dir: PathLike, by=None, metrics=None, confidence: float = 0.95):
    """Per-configuration mean / std / t-CI / n of a finished sweep (completed runs only) as a DataFrame."""
    from slamcli.metrics.aggregate import aggregate as agg
    from slamcli.metrics.aggregate import completed, read_table

    ok, _ = completed(read_table(exp_dir))
    return agg(ok, by, metrics, confidence)[0]


def solver_names() -> list[str]:
    """Names of the registered solver plugins."""
    from slamcli.solvers import registry

    return [i.name for i in registry.available()]
