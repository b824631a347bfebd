"""Expand an :class:`~slamcli.sweep.config.ExperimentConfig` into resolved runs with content-hash ids.

Order (deterministic, independent of execution order)::

    for point in [data entries, unless data is swept] × grid (cartesian, first key slowest) × zip groups:
        for replicate in replicates (a recording, graph or dataset file: the first replicate id only):
            for solver in [[solver]] tables (file order; one with ``init_from`` after the solver it names):
                RunSpec

A point's ``solver.<label>.*`` axes apply only to that solver, its ``scenario.*`` axes only to simulated
entries; runs that resolve to the same configuration are de-duplicated by run id (first kept), and each run
records only the axis values that apply to it (``RunSpec.point``).

Seeds (NumPy's list form, varying id first, never ``root + i``)::

    dataset seed = default_rng([STREAM_SIMULATION, replicate, root_seed]).integers(2**63 - 1)
    solver seed  = default_rng([STREAM_SOLVER + solver.seed, replicate, root_seed]).integers(2**63 - 1)

so every solver of a replicate sees the *same* dataset (common random numbers). An imported dataset's id is
a content hash of importer, version, options and the source's sha256 (:meth:`DatasetSpec.config`). Run id =
the first 12 hex digits of SHA-256 over the canonical JSON of the fully resolved run configuration (slamcli
and schema versions included, output paths not).

A run with ``init_from`` starts from the result of that solver's run on the same dataset and point: its
``init_run`` is that run's id, part of its own configuration (so its id changes with the run it starts from).
"""

from __future__ import annotations

import dataclasses
import hashlib
import itertools
import json
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Protocol

from slamcli.errors import ConfigError, SlamcliError
from slamcli.sweep.config import DataSpec, ExperimentConfig, init_order, route_overrides

STREAM_SIMULATION = 0
STREAM_SOLVER = 1
ID_LENGTH = 12


# -- canonical hashing --------------------------------------------------------------------------------------


def _canonical(obj: Any) -> Any:
    """JSON-ready copy: tuples → lists, numpy scalars/arrays → Python, enums → values; NaN/inf rejected."""
    if isinstance(obj, dict):
        return {str(k): _canonical(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_canonical(v) for v in obj]
    if isinstance(obj, bool) or obj is None or isinstance(obj, (int, str)):
        return obj
    if isinstance(obj, float):
        if not math.isfinite(obj):
            return repr(obj)  # JSON has no inf/NaN; keep them distinguishable
        return obj
    if hasattr(obj, "tolist"):  # numpy arrays and scalars
        return _canonical(obj.tolist())
    if hasattr(obj, "value") and not isinstance(obj, type):  # enum
        return _canonical(obj.value)
    if dataclasses.is_dataclass(obj) and not isinstance(obj, type):
        return _canonical(dataclasses.asdict(obj))
    return str(obj)


def canonical_json(obj: Any) -> str:
    """Sorted keys, no whitespace, floats written by ``repr`` (Python's json does that)."""
    return json.dumps(_canonical(obj), sort_keys=True, separators=(",", ":"), allow_nan=False)


def content_hash(obj: Any, length: int = ID_LENGTH) -> str:
    return hashlib.sha256(canonical_json(obj).encode()).hexdigest()[:length]


def versions() -> dict[str, Any]:
    """The package and file-schema versions that enter every run id."""
    import slamcli
    from slamcli.io.schema import SCHEMA_VERSION

    return {"slamcli": slamcli.__version__, "schema": SCHEMA_VERSION}


# -- seeds --------------------------------------------------------------------------------------------------


def derive_seed(stream: int, replicate: int, root_seed: int) -> int:
    """``default_rng([stream, replicate, root_seed])`` → one 63-bit integer seed for a component."""
    import numpy as np

    return int(np.random.default_rng([stream, replicate, root_seed]).integers(0, 2**63 - 1))


def dataset_seed(replicate: int, root_seed: int) -> int:
    return derive_seed(STREAM_SIMULATION, replicate, root_seed)


def solver_seed(replicate: int, root_seed: int, solver_stream: int = 0) -> int:
    return derive_seed(STREAM_SOLVER + solver_stream, replicate, root_seed)


# -- resolution of scenario / solver parameters ---------------------------------------------------------------


class Resolver(Protocol):
    def scenario(self, name: str, overrides: dict[str, Any], where: str) -> dict[str, Any]: ...

    def data(self, entry: DataSpec, where: str) -> dict[str, Any]: ...

    def solver(self, method: str, params: dict[str, Any], where: str) -> dict[str, Any]: ...

    def evaluate(self, options: dict[str, Any], where: str) -> dict[str, Any]: ...


class RegistryResolver:
    """Resolve against the real simulator scenarios and the registered solvers' ``Params`` dataclasses."""

    def known_keys(self, kind: str, name: str) -> dict[str, Any] | list[str] | None:
        """Known keys for :func:`slamcli.sweep.config.check_keys`: ``{key: type}`` for a scenario or a solver,
        the option names for ``evaluate``; None = unknown solver plugin (reported on resolution)."""
        import typing

        if kind == "scenario":
            from slamcli.sim import resolve_scenario
            from slamcli.sim.config import known_keys

            cfg = resolve_scenario(name)
            top = typing.get_type_hints(type(cfg))
            out = {}
            for key in known_keys(cfg):
                sec, _, leaf = key.rpartition(".")
                out[key] = typing.get_type_hints(type(getattr(cfg, sec)))[leaf] if sec else top[leaf]
            return out
        if kind == "solver":
            from slamcli.solvers import registry

            try:
                return typing.get_type_hints(registry.load(name).Params)
            except SlamcliError:
                return None
        from slamcli.api.evaluate import EvaluateOptions

        return EvaluateOptions.names()

    def data(self, entry: DataSpec, where: str) -> dict[str, Any]:
        """A recording, graph or dataset file: where it is and what identifies its content (the importer, its
        version and options, the source's sha256; a file's sha256). A recording that is not on this machine is
        one line naming the command that gets it."""
        from slamcli.api.recordings import cache_dir, source_sha256
        from slamcli.datasets.options import IMPORTER_VERSION, check_options

        if entry.kind == "file":
            if not Path(entry.path).is_file():
                raise ConfigError(f"{where}.file: {entry.path}: no such file")
            importer, path = "", Path(entry.path)
        else:
            importer, path = _locate(entry, where)
        try:
            digest = source_sha256(path)
        except OSError as exc:
            raise ConfigError(f"{where}.{entry.kind}: cannot read {exc.filename or path} ({exc.strerror})") from None
        if entry.kind == "file":
            return {"path": entry.path, "file_sha256": digest}
        options = check_options(importer, entry.options, where)
        return _canonical({"importer": importer, "importer_version": IMPORTER_VERSION, "options": options,
                           "path": str(path), "source_sha256": digest, "cache": str(cache_dir())})

    def scenario(self, name: str, overrides: dict[str, Any], where: str) -> dict[str, Any]:
        from slamcli.sim import resolve_scenario

        try:
            cfg = resolve_scenario(name, dict(overrides))
        except SlamcliError as exc:
            raise ConfigError(f"{where}: {str(exc).splitlines()[0]}") from None
        return _canonical(dataclasses.asdict(cfg) if dataclasses.is_dataclass(cfg) else cfg)

    def solver(self, method: str, params: dict[str, Any], where: str) -> dict[str, Any]:
        from slamcli.params import build_params
        from slamcli.solvers import registry
        from slamcli.solvers.base import params_to_dict

        try:
            from slamcli.api.solve import _check_finite_params

            cls = registry.load(method)
            p = build_params(cls.Params, dict(params), where=where)
            _check_finite_params(p, method)
        except SlamcliError as exc:
            raise ConfigError(f"{where}: {str(exc).splitlines()[0]}") from None
        return _canonical(params_to_dict(p))

    def evaluate(self, options: dict[str, Any], where: str) -> dict[str, Any]:
        """``[evaluate]`` checked through its schema (:class:`slamcli.api.evaluate.EvaluateOptions`), defaults
        filled."""
        from slamcli.api.evaluate import EvaluateOptions

        return _canonical(EvaluateOptions.keywords(options, where))


def _locate(entry: DataSpec, where: str) -> tuple[str, Path]:
    """``(importer, import path)`` of a recording or graph entry; one-line ConfigError when the name is not
    registered, is read by another importer, or is not on this machine."""
    from slamcli.datasets import DatasetImportError, registry
    from slamcli.params import did_you_mean

    key = f"{where}.{entry.kind}"
    if entry.path:
        if not Path(entry.path).is_file():
            raise ConfigError(f"{key}: {entry.path}: no such file")
        return "g2o", Path(entry.path)
    reg = registry.registry()
    if entry.name not in reg:
        raise ConfigError(f"{key}: {entry.name!r} is not a registered dataset{did_you_mean(entry.name, reg)} "
                          "(`slamcli datasets list` shows them)")
    importer = reg[entry.name].importer
    if entry.kind == "graph" and importer != "g2o":
        raise ConfigError(f"{key}: {entry.name!r} is a recording read by `slamcli import {importer}`: write "
                          f"recording = {entry.name!r}")
    try:
        return importer, registry.locate(entry.name)
    except registry.DatasetMissingError as exc:
        raise AbsentDataError(f"{key}: {exc}", str(exc)) from None
    except DatasetImportError as exc:
        raise ConfigError(f"{key}: {exc}") from None


class AbsentDataError(ConfigError):
    """A registered recording or graph that is not on this machine; ``reason`` is the registry's one line
    (naming the fetch / add command) without the TOML key."""

    def __init__(self, message: str, reason: str) -> None:
        super().__init__(message)
        self.reason = reason


class LiteralResolver:
    """No resolution: the overrides as written (tests, or dry runs before the simulator exists)."""

    def data(self, entry: DataSpec, where: str) -> dict[str, Any]:
        return _canonical({"name": entry.name, "path": entry.path, "options": entry.options})

    def scenario(self, name: str, overrides: dict[str, Any], where: str) -> dict[str, Any]:
        return _canonical(dict(overrides))

    def solver(self, method: str, params: dict[str, Any], where: str) -> dict[str, Any]:
        return _canonical(dict(params))

    def evaluate(self, options: dict[str, Any], where: str) -> dict[str, Any]:
        return _canonical(dict(options))


# -- run specifications -------------------------------------------------------------------------------------


@dataclass(frozen=True)
class DatasetSpec:
    """One dataset, shared by every run on it: a simulated one per (scenario configuration, replicate), or an
    imported recording / graph / dataset file (one replicate).

    Attributes
    ----------
    dataset_id : str            content hash of ``config()``.
    scenario : str              scenario name ("" for a dataset that is not simulated).
    overrides : dict            flat dotted overrides as given (what ``simulate_to_file`` receives).
    resolved : dict             the fully resolved scenario configuration.
    replicate : int
    seed : int                  simulator seed (stream ``STREAM_SIMULATION``; 0 when not simulated).
    label : str                 the ``[[data]]`` entry's label (results.csv column ``data``).
    kind : str                  ``scenario``, ``recording``, ``graph`` or ``file``.
    source : dict               not simulated: what the resolver found (path, importer, options, sha256, and
                                the import cache folder of the machine that expanded the sweep).
    """

    dataset_id: str
    scenario: str
    overrides: dict[str, Any]
    resolved: dict[str, Any]
    replicate: int
    seed: int
    label: str = ""
    kind: str = "scenario"
    source: dict[str, Any] = field(default_factory=dict)

    @property
    def simulated(self) -> bool:
        return self.kind == "scenario"

    def config(self) -> dict[str, Any]:
        """What defines the dataset's content: the scenario, its resolved configuration, replicate and seed; or
        for an import the importer, its version, options and the source's sha256 (not where it lies)."""
        if self.simulated:
            return {"scenario": self.scenario, "resolved": self.resolved, "replicate": self.replicate,
                    "seed": self.seed}
        return {"kind": self.kind, **{k: v for k, v in self.source.items() if k not in ("path", "cache")}}


@dataclass(frozen=True)
class RunSpec:
    """One (dataset, solver configuration) run of an experiment.

    Attributes
    ----------
    run_id : str                content hash of ``config()`` (without the id itself).
    experiment : str
    label, method : str         the ``[[solver]]`` label and registered method.
    params : dict               fully resolved solver parameters.
    param_overrides : dict      the parameters as written / swept (what the solver receives).
    seed : int                  solver seed (stream ``STREAM_SOLVER + solver_stream``).
    solver_stream : int         the ``[[solver]] seed`` value.
    oracle_association : bool
    evaluate : dict             options for ``evaluate_files``.
    dataset : DatasetSpec
    point : dict                the sweep-axis values that apply to this run (key → value).
    versions : dict             slamcli / schema versions (part of the hash).
    init_run : str              id of the run (same dataset) whose result is the initial estimate ("" = none).
    """

    run_id: str
    experiment: str
    label: str
    method: str
    params: dict[str, Any]
    param_overrides: dict[str, Any]
    seed: int
    solver_stream: int
    oracle_association: bool
    evaluate: dict[str, Any]
    dataset: DatasetSpec
    point: dict[str, Any] = field(default_factory=dict)
    versions: dict[str, Any] = field(default_factory=dict)
    init_run: str = ""

    @property
    def replicate(self) -> int:
        return self.dataset.replicate

    def config(self) -> dict[str, Any]:
        """The resolved configuration that defines the run (what is hashed; ``config.json`` adds the id)."""
        init = {"init_run": self.init_run} if self.init_run else {}  # (absent: the ids of other runs unchanged)
        return {**init,
            "dataset": {"id": self.dataset.dataset_id, **self.dataset.config()},
            "solver": {
                "label": self.label,
                "method": self.method,
                "params": self.params,
                "seed": self.seed,
                "stream": self.solver_stream,
                "oracle_association": self.oracle_association,
            },
            "evaluate": self.evaluate,
            "versions": self.versions,
        }


@dataclass(frozen=True)
class RunGroup:
    """The runs that share one dataset (executed together by one worker: simulate once, solve many)."""

    dataset: DatasetSpec
    runs: tuple[RunSpec, ...]


@dataclass(frozen=True)
class Expansion:
    experiment: ExperimentConfig
    runs: tuple[RunSpec, ...]
    axes: tuple[str, ...]  # swept keys, grid then zip order
    skipped: tuple[str, ...] = ()  # one line per absent recording left out ([sweep] absent = "skip")

    @property
    def datasets(self) -> tuple[DatasetSpec, ...]:
        seen: dict[str, DatasetSpec] = {}
        for r in self.runs:
            seen.setdefault(r.dataset.dataset_id, r.dataset)
        return tuple(seen.values())

    def groups(self, runs: tuple[RunSpec, ...] | list[RunSpec] | None = None) -> list[RunGroup]:
        """``runs`` (default all) grouped by dataset, in first-appearance order."""
        by_ds: dict[str, list[RunSpec]] = {}
        ds: dict[str, DatasetSpec] = {}
        for r in self.runs if runs is None else runs:
            by_ds.setdefault(r.dataset.dataset_id, []).append(r)
            ds[r.dataset.dataset_id] = r.dataset
        return [RunGroup(ds[k], tuple(v)) for k, v in by_ds.items()]


#: most runs one experiment may expand to (checked on the grid sizes before anything is expanded)
MAX_RUNS = 100_000


def check_size(cfg: ExperimentConfig) -> int:
    """Most runs ``cfg`` can expand to, from its axis lengths alone; ConfigError above :data:`MAX_RUNS`."""
    sizes = [len(v) for _, v in cfg.sweep.grid] + [len(g[0][1]) for g in cfg.sweep.zips]
    if "data" not in _swept(cfg):
        sizes.insert(0, len(cfg.data))
    n = math.prod(sizes) * len(cfg.sweep.replicates) * max(len(cfg.solvers), 1)
    if n > MAX_RUNS:
        shape = "×".join(str(s) for s in sizes) or "1"
        raise ConfigError(f"{cfg.source}: [sweep]: {n} runs (points {shape} × {len(cfg.sweep.replicates)} "
                          f"replicates × {len(cfg.solvers)} solvers), above the limit of {MAX_RUNS} runs")
    return n


def _swept(cfg: ExperimentConfig) -> tuple[str, ...]:
    return tuple(k for k, _ in cfg.sweep.grid) + tuple(k for g in cfg.sweep.zips for k, _ in g)


def sweep_points(cfg: ExperimentConfig) -> list[dict[str, Any]]:
    """The sweep points (key → value dicts): grid product × each zip group, in deterministic order. Every
    point names its ``data`` entry: without a ``data`` axis, every entry in file order is the slowest axis."""
    factors: list[list[dict[str, Any]]] = []
    if "data" not in _swept(cfg):
        factors.append([{"data": d.label} for d in cfg.data])
    for key, values in cfg.sweep.grid:
        factors.append([{key: v} for v in values])
    for group in cfg.sweep.zips:
        n = len(group[0][1])
        factors.append([{k: vals[i] for k, vals in group} for i in range(n)])
    points = []
    for combo in itertools.product(*factors):
        p: dict[str, Any] = {}
        for part in combo:
            p.update(part)
        points.append(p)
    return points


def _resolve_data(cfg: ExperimentConfig, resolver: Resolver,
                  used: set[str]) -> tuple[dict[str, dict[str, Any]], tuple[str, ...]]:
    """``({label: resolver.data(...)}, skip lines)`` for every entry of ``used`` that is not simulated, before
    anything else is resolved. A recording that is not on this machine fails the sweep before any run starts,
    or with ``[sweep] absent = "skip"`` leaves its entries out: one line per recording naming its entries and
    the command that gets it."""
    out: dict[str, dict[str, Any]] = {}
    absent: dict[str, tuple[str, list[str]]] = {}  # recording name -> (reason, labels of its entries)
    for d in cfg.data:
        if not d.simulated and d.label in used:
            try:
                out[d.label] = resolver.data(d, f"{cfg.source}: {d.where}")
            except AbsentDataError as exc:
                if cfg.sweep.absent != "skip":
                    raise
                absent.setdefault(d.name, (exc.reason, []))[1].append(d.label)
    lines = tuple(f"skipped {', '.join(labels)}: {reason}" for reason, labels in absent.values())
    return out, lines


def _datasets(cfg: ExperimentConfig, entry: DataSpec, scen_over: dict[str, Any], resolved: dict[str, Any],
              vers: dict[str, Any]) -> list[DatasetSpec]:
    """The datasets of one sweep point: one per replicate for a scenario, one (the first replicate id) for a
    recording, graph or file, whose ``resolved`` is the resolver's ``data`` record."""
    if not entry.simulated:
        ds = DatasetSpec(dataset_id="", scenario="", overrides={}, resolved={}, replicate=cfg.sweep.replicates[0],
                         seed=0, label=entry.label, kind=entry.kind, source=resolved)
        return [dataclasses.replace(ds, dataset_id=content_hash({"dataset": ds.config(), "versions": vers}))]
    out = []
    for rep in cfg.sweep.replicates:
        seed = rep if cfg.sweep.dataset_seeds == "replicate" else dataset_seed(rep, cfg.root_seed)
        ds = DatasetSpec(dataset_id="", scenario=entry.name, overrides=_canonical(scen_over), resolved=resolved,
                         replicate=rep, seed=seed, label=entry.label)
        out.append(dataclasses.replace(ds, dataset_id=content_hash({"dataset": ds.config(), "versions": vers})))
    return out


def expand(
    cfg: ExperimentConfig,
    *,
    resolver: Resolver | None = None,
    run_versions: dict[str, Any] | None = None,
) -> Expansion:
    """Every run of the experiment, resolved and hashed (see the module docstring for order and seeds)."""
    check_size(cfg)
    resolver = resolver if resolver is not None else RegistryResolver()
    if hasattr(resolver, "known_keys"):  # name unknown keys by their TOML key, with a "did you mean"
        from slamcli.sweep.config import check_keys

        check_keys(cfg, resolver.known_keys)
    vers = run_versions if run_versions is not None else versions()
    points = sweep_points(cfg)
    imported, skipped = _resolve_data(cfg, resolver, {p["data"] for p in points})
    if skipped:
        points = [p for p in points if cfg.entry(p["data"]).simulated or p["data"] in imported]
        if not points:
            raise ConfigError(f"{cfg.source}: [[data]]: none of the experiment's datasets is on this machine ("
                              + "; ".join(skipped) + ")")
    axes = _swept(cfg)
    solvers = init_order(cfg.solvers, cfg.source)
    scen_cache: dict[str, dict[str, Any]] = {}
    solver_cache: dict[str, dict[str, Any]] = {}
    runs: dict[str, RunSpec] = {}
    for point in points:
        entry = cfg.entry(point["data"])
        scen_over, evaluate, solver_over = route_overrides(cfg, point)
        scen_over = {**entry.parameters, **scen_over}
        if entry.simulated:
            skey = canonical_json([entry.name, scen_over])
            if skey not in scen_cache:
                scen_cache[skey] = resolver.scenario(entry.name, scen_over, f"{cfg.source}: [{entry.where}]")
        resolved = scen_cache[skey] if entry.simulated else imported[entry.label]
        resolved_eval = resolver.evaluate(evaluate, f"{cfg.source}: [evaluate]")
        for ds in _datasets(cfg, entry, scen_over, resolved, vers):
            ids: dict[str, str] = {}  # label -> run id on this dataset and point
            for s in solvers:
                pkey = canonical_json([s.method, solver_over[s.label]])
                if pkey not in solver_cache:
                    solver_cache[pkey] = resolver.solver(
                        s.method, solver_over[s.label], f"{cfg.source}: solver {s.label!r} params"
                    )
                relevant = {k: v for k, v in point.items() if _applies(k, s.label, entry, axes)}
                spec = RunSpec(
                    run_id="",
                    experiment=cfg.name,
                    label=s.label,
                    method=s.method,
                    params=solver_cache[pkey],
                    param_overrides=_canonical(solver_over[s.label]),
                    seed=solver_seed(ds.replicate, cfg.root_seed, s.seed),
                    solver_stream=s.seed,
                    oracle_association=s.oracle_association,
                    evaluate=resolved_eval,
                    dataset=ds,
                    point=_canonical(relevant),
                    versions=vers,
                    init_run=ids[s.init_from] if s.init_from else "",
                )
                rid = ids[s.label] = content_hash(spec.config())
                if rid not in runs:
                    runs[rid] = dataclasses.replace(spec, run_id=rid)
    return Expansion(experiment=cfg, runs=tuple(runs.values()), axes=axes, skipped=skipped)


def _applies(key: str, label: str, entry: DataSpec, axes: tuple[str, ...]) -> bool:
    """Whether point key ``key`` is recorded for the run of solver ``label`` on ``entry``: a ``solver.<label>.*``
    key only for that solver's runs, a ``scenario.*`` key only for simulated entries, ``data`` when swept."""
    if key == "data":
        return key in axes
    if key.startswith("solver."):
        return key.startswith(f"solver.{label}.")
    return entry.simulated or not key.startswith("scenario.")
