"""Solve workflow: dataset file → solver plugin → result file.

* :func:`solve_dataset` runs a registered solver on :class:`~slamcli.types.SlamInputs` (in memory).
* :func:`solve_file` reads a dataset file, hands ONLY ``dataset.inputs`` to the solver, stamps the result with
  the dataset's content hash, path and seed, and writes the result file atomically.

Randomness: the solver's generator is ``np.random.default_rng([SOLVER_STREAM, seed])`` (NumPy's list form,
varying id first). :data:`SOLVER_STREAM` is a stream id of its own, so the solver's draws (particles, ICM
visiting orders, ...) never coincide with the simulator's world/motion/sensor streams for the same seed.
"""

from __future__ import annotations

import dataclasses
import os
from pathlib import Path
from typing import Any

import numpy as np

from slamcli.errors import ConfigError, SlamcliError, SolverError
from slamcli.types import ProgressFn, SlamInputs, SolverResult, Status

#: stream id of the solver's random generator: ``default_rng([SOLVER_STREAM, seed])``.
SOLVER_STREAM = 0x50_17E5  # "SOLVEs"; distinct from every simulator stream id



def solver_rng(seed: int) -> np.random.Generator:
    """The only source of randomness a solver gets: ``default_rng([SOLVER_STREAM, seed])``."""
    if int(seed) < 0:
        raise ConfigError(f"--seed: must be >= 0, got {seed}")
    return np.random.default_rng([SOLVER_STREAM, int(seed)])


def dataset_relpath(data_path: str | os.PathLike, result_path: str | os.PathLike) -> str:
    """Path of the dataset relative to the result file's directory (POSIX separators; "" when the two live
    on different drives)."""
    try:
        rel = os.path.relpath(Path(data_path).resolve(), Path(result_path).resolve().parent)
    except ValueError:  # different drives on Windows
        return ""
    return Path(rel).as_posix()


def make_solver(method: str, params: Any = None, inputs: SlamInputs | None = None):
    """Instantiate the solver registered as ``method``.

    ``params`` is a Params instance, a dict ``{"key": value}`` or a list of ``"key=value"`` strings; keys and
    types are validated against the solver's frozen Params dataclass (one-line ConfigError listing the
    known keys). A Params class with presets (``resolve``) is resolved once here, with ``inputs`` when given
    (the preset's rule for the dataset). Unknown/broken plugins raise PluginError listing the available names.
    """
    from slamcli.params import build_params, given_values
    from slamcli.solvers import registry

    cls = registry.load(method)
    where = f"--param ({method})"
    if params is None:
        params = {}
    resolve = getattr(cls.Params, "resolve", None)
    if isinstance(params, cls.Params):
        given = params.given() if resolve is not None and inputs is not None else None
        if given is not None:
            params = resolve(given, inputs)
    else:
        given = given_values(cls.Params, params, where=where)
        params = build_params(cls.Params, given, where=where, inputs=inputs)
    _check_finite_params(params, method)
    solver = cls(params)
    note = getattr(cls.Params, "resolve_note", None)
    if given is not None and note is not None and inputs is not None:
        solver.config_note = note(given, inputs)
    return solver


def _check_finite_params(params: Any, method: str) -> None:
    """``inf`` is refused like ``nan`` for every float parameter whose default is finite (a default of ``inf``
    means "unlimited", so ``inf`` stays allowed there)."""
    import math

    for f in dataclasses.fields(params):
        v = getattr(params, f.name)
        default = f.default if f.default is not dataclasses.MISSING else None
        for x in (v if isinstance(v, tuple) else (v,)):
            if isinstance(x, float) and math.isinf(x) and not (isinstance(default, float) and math.isinf(default)):
                raise ConfigError(f"--param ({method}) {f.name}: must be finite, got {x}")


def _one_line(exc: BaseException) -> str:
    lines = str(exc).strip().splitlines()
    return f"{type(exc).__name__}: {lines[0]}" if lines else type(exc).__name__


def _check_result(result: Any, method: str, inputs: SlamInputs) -> SolverResult:
    if not isinstance(result, SolverResult):
        raise SolverError(f"solver {method!r} returned {type(result).__name__}, expected SolverResult")
    n_poses, n_obs = inputs.n_poses, len(inputs.observations)
    if np.shape(result.poses_xyt) != (n_poses, 3):
        raise SolverError(f"solver {method!r} returned poses_xyt of shape {np.shape(result.poses_xyt)}, "
                          f"expected ({n_poses}, 3)")
    if np.shape(result.assoc) != (n_obs,):
        raise SolverError(f"solver {method!r} returned assoc of shape {np.shape(result.assoc)}, expected ({n_obs},)")
    if not isinstance(result.status, Status):
        raise SolverError(f"solver {method!r} returned status {result.status!r}, expected a Status")
    return result


def solve_dataset(
    inputs: SlamInputs,
    method: str,
    params: Any = None,
    *,
    seed: int = 0,
    init: SolverResult | None = None,
    progress: ProgressFn | None = None,
) -> SolverResult:
    """Run solver ``method`` on ``inputs`` (never ground truth) with ``rng = solver_rng(seed)``.

    Raises
    ------
    PluginError   unknown or broken solver plugin (lists the available names).
    ConfigError   bad parameter key/value (lists the known keys).
    SolverError   the solver raised, or returned something that breaks the result contract.
    """
    if not isinstance(inputs, SlamInputs):
        raise TypeError(f"solve_dataset expects SlamInputs (no ground truth), got {type(inputs).__name__}")
    from slamcli.solvers.sensor_frame import (
        check_motion_model,
        check_multi_robot,
        result_to_body,
        to_sensor_frame,
    )

    solver = make_solver(method, params, inputs)
    check_motion_model(solver, method, inputs)  # one line instead of running the wrong kinematics
    check_multi_robot(solver, method, inputs)  # multi-robot data: graph / icm only
    if getattr(solver, "needs_noise_bounds", False) and inputs.noise_bounds is None:
        hint = getattr(solver, "noise_bounds_hint", "simulate with bounded.enabled=true")
        raise SolverError(f"solver {method!r} needs guaranteed error bounds (inputs/noise_bounds), which this "
                          f"dataset does not declare; {hint}")
    offset = np.asarray(inputs.sensor_offset_xy, float).reshape(2).copy()
    solver_inputs = to_sensor_frame(inputs)  # the sensor mounting offset, for every solver
    if init is not None and offset.any():
        from slamcli.models.observation import sensor_pose

        init = dataclasses.replace(init, poses_xyt=sensor_pose(init.poses_xyt, offset))
    rng = solver_rng(seed)
    try:
        result = solver.solve(solver_inputs, init=init, rng=rng, progress=progress)
    except SlamcliError:
        raise
    except Exception as exc:
        raise SolverError(f"solver {method!r} failed: {_one_line(exc)}") from exc
    result = _check_result(result, method, inputs)
    return result_to_body(result, offset)


def solve_file(
    data_path: str | os.PathLike,
    method: str,
    params: Any,
    out_path: str | os.PathLike,
    *,
    init_path: str | os.PathLike | None = None,
    seed: int = 0,
    oracle_association: bool = False,
    progress: ProgressFn | None = None,
) -> SolverResult:
    """Read ``data_path``, solve with ``method``, write the result to ``out_path`` (atomically).

    The result records ``dataset_hash`` and, in ``extra``: ``dataset_path`` (absolute), ``dataset_relpath``
    (relative to the result's directory, so a result moved together with its dataset still finds it), ``seed``,
    ``used_truth_association`` and, with ``init_path``, ``init_path``.

    ``oracle_association=True`` copies the TRUE association (``truth.obs_landmark``) into
    ``observations.reported_id`` before solving. That is ground truth leaking into the inputs on purpose (an
    upper-bound experiment), so it is explicit and recorded as ``extra["used_truth_association"] = True``.

    A solver exception becomes a one-line :class:`SolverError` and no result file is written; a result with
    ``status == FAILED`` is still written (it documents the failure).
    """
    from slamcli.io import dataset_hash, read_dataset, read_result, write_result

    data_path, out_path = Path(data_path), Path(out_path)
    if out_path.exists() and data_path.exists() and out_path.resolve() == data_path.resolve():
        raise ConfigError(f"-o {out_path}: refusing to overwrite the input dataset")
    dataset = read_dataset(data_path)
    inputs = dataset.inputs
    if oracle_association:
        if dataset.truth is None or dataset.truth.position_reference_only:
            raise ConfigError(f"--oracle-association: {data_path} has no /truth group (no true association)")
        obs = dataclasses.replace(inputs.observations, reported_id=dataset.truth.obs_landmark.copy())
        inputs = dataclasses.replace(inputs, observations=obs)
    init = None
    if init_path is not None:
        init = read_result(init_path)
        if init.poses_xyt.shape[0] != inputs.n_poses or init.assoc.shape[0] != len(inputs.observations):
            raise ConfigError(
                f"--init {init_path}: result has {init.poses_xyt.shape[0]} poses / {init.assoc.shape[0]} "
                f"observations, dataset {data_path} has {inputs.n_poses} / {len(inputs.observations)}"
            )
    try:
        result = solve_dataset(inputs, method, params, seed=seed, init=init, progress=progress)
    except SolverError as exc:
        raise SolverError(f"{data_path}: {exc}") from None
    extra = dict(result.extra)
    extra.update(dataset_path=str(data_path.resolve()), seed=int(seed), used_truth_association=bool(oracle_association))
    extra["dataset_relpath"] = dataset_relpath(data_path, out_path)
    if init_path is not None:
        extra["init_path"] = str(Path(init_path).resolve())
    result = dataclasses.replace(result, dataset_hash=dataset_hash(dataset), extra=extra)
    write_result(out_path, result)
    return result
