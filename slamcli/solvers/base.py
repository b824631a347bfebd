"""The solver contract.

A solver is a class registered under the entry-point group ``slamcli.solvers``::

    class MySolver(BaseSolver):
        name = "mine"
        Params = MyParams            # a frozen dataclass with documented defaults

        def solve(self, inputs, *, init=None, rng, progress=None) -> SolverResult: ...

* ``__init__(params=None)`` only stores the (validated, frozen) parameters — no work, no I/O.
* ``solve`` receives :class:`~slamcli.types.SlamInputs` (never ground truth), an optional previous
  :class:`~slamcli.types.SolverResult` to start from, a ``numpy.random.Generator`` that is the only source of
  randomness, and an optional ``progress(done, total)`` callback (the CLI renders it; solvers print nothing).
* It returns a :class:`~slamcli.types.SolverResult` whose ``status`` says how it ended.
"""

from __future__ import annotations

import dataclasses
import functools
import time
from typing import Any, ClassVar

import numpy as np

from slamcli.types import IterationTrace, ProgressFn, SlamInputs, SolverResult, Status


@dataclasses.dataclass(frozen=True)
class NoParams:
    """A solver without parameters."""


class BaseSolver:
    """Convenience base class: stores params and fills the bookkeeping fields of the result."""

    name: ClassVar[str] = "base"
    Params: ClassVar[type] = NoParams
    #: motion models (``SlamInputs.motion_model``) this solver implements; others are refused in one line
    motion_models: ClassVar[tuple[str, ...]] = ("ddmr",)

    def __init__(self, params: Any | None = None) -> None:
        if params is None:
            params = self.Params()
        if not isinstance(params, self.Params):
            raise TypeError(f"{type(self).__name__} expects {self.Params.__name__}, got {type(params).__name__}")
        self.params = params

    def solve(
        self,
        inputs: SlamInputs,
        *,
        init: SolverResult | None = None,
        rng: np.random.Generator,
        progress: ProgressFn | None = None,
    ) -> SolverResult:  # pragma: no cover - interface
        raise NotImplementedError

    # -- helpers for subclasses -------------------------------------------------------------------------
    @classmethod
    def version(cls) -> str:
        """Version of the distribution that ships this solver (falls back to slamcli's)."""
        return _distribution_version(cls.__module__.split(".")[0])

    def make_result(
        self,
        *,
        status: Status,
        poses_xyt: np.ndarray,
        landmarks_xy: np.ndarray,
        assoc: np.ndarray,
        t_start: float,
        message: str = "",
        pose_cov: np.ndarray | None = None,
        landmark_cov: np.ndarray | None = None,
        trace: IterationTrace | None = None,
        extra: dict[str, Any] | None = None,
        timings: dict[str, float] | None = None,
    ) -> SolverResult:
        """Assemble a :class:`SolverResult`; ``t_start`` is a ``time.perf_counter()`` reading.

        ``extra`` must be deterministic; wall-clock measurements go to ``timings`` (never to ``extra``).
        """
        return SolverResult(
            solver=self.name,
            solver_version=self.version(),
            params=params_to_dict(self.params),
            status=status,
            message=message,
            poses_xyt=np.asarray(poses_xyt, float),
            landmarks_xy=np.asarray(landmarks_xy, float).reshape(-1, 2),
            assoc=np.asarray(assoc, np.int64),
            pose_cov=None if pose_cov is None else np.asarray(pose_cov, float),
            landmark_cov=None if landmark_cov is None else np.asarray(landmark_cov, float),
            trace=trace,
            wall_time_s=time.perf_counter() - t_start,
            extra=dict(extra or {}),
            timings={str(k): float(v) for k, v in (timings or {}).items()},
        )


@functools.cache
def _distribution_version(module_root: str) -> str:
    """Version of the installed distribution providing ``module_root``, falling back to slamcli's.

    Cached: ``packages_distributions()`` scans every installed package, so the usual case (the distribution is
    named like its top-level module) is looked up by name first. slamcli's own solvers read
    ``slamcli.__version__``, which is the distribution's version (pyproject.toml takes it from there), and no
    metadata at all (cost: benchmarks/results/design_notes.md).
    """
    import slamcli

    if module_root == "slamcli":
        return slamcli.__version__
    from importlib import metadata

    try:
        return metadata.version(module_root)
    except metadata.PackageNotFoundError:
        pass
    try:
        dists = metadata.packages_distributions().get(module_root, [])
        if dists:
            return metadata.version(dists[0])
    except Exception:  # noqa: BLE001,S110 - metadata lookup is best effort
        pass
    return slamcli.__version__


def params_to_dict(params: Any) -> dict[str, Any]:
    """JSON-friendly dict of a params dataclass (tuples become lists, enums their values)."""
    out: dict[str, Any] = {}
    for f in dataclasses.fields(params):
        v = getattr(params, f.name)
        if isinstance(v, tuple):
            v = [list(x) if isinstance(x, tuple) else x for x in v]
        elif hasattr(v, "value") and not isinstance(v, (int, float, str, bool)):
            v = v.value
        out[f.name] = v
    return out
