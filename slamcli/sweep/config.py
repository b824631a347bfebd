"""Experiment files: TOML (stdlib :mod:`tomllib`) → validated, frozen :class:`ExperimentConfig`.

An experiment file::

    [experiment]                      # ExperimentTable: name, description, root_seed
    name = "ekf-vs-odometry"
    [[data]]                          # scenario = "loop" (+ [data.parameters]), recording = "mrclam7" (+ its
    scenario = "loop"                 # importer's options), graph = "dlr" or a path, file = "runs/day1.h5"
    [[solver]]                        # SolverTable: method, label, seed, oracle_association,
    method = "ekf"                    # init_from (a solver label: start from its result), [solver.params]
    [evaluate]                        # slamcli.api.evaluate.EvaluateOptions
    cutoff_m = 1.0
    [sweep]                           # SweepTable: replicates, grid, zip, absent, dataset_seeds
    replicates = 50
    grid = { "scenario.sensor.max_range" = [5.0, 10.0], "solver.ekf.gate_prob" = [0.95, 0.99] }
    zip = { "scenario.sensor.range_std" = [0.01, 0.05], "scenario.sensor.bearing_std" = [0.01, 0.05] }
    absent = "skip"                   # optional: skip a recording not on this machine (default "fail")
    dataset_seeds = "replicate"       # optional: simulator seed = replicate id (default "derived")
    [quick]                           # fixed overrides for `reproduce --quick` / `sweep --quick`
    replicates = 2

Sweep keys: ``scenario.<dotted key>``, ``solver.<label>.<param>``, ``evaluate.<option>`` and ``data`` (entry
labels); reference ``docs/experiments.md``. Tables are typed dataclasses converted by the schema
(:func:`typed_table`); every error is one line naming file and key, unknown keys with "did you mean".
"""

from __future__ import annotations

import re
import tomllib
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Literal

from slamcli.errors import ConfigError
from slamcli.params import did_you_mean

_NAME_RE = re.compile(r"^[A-Za-z0-9][A-Za-z0-9._-]*$")
_RANGE_RE = re.compile(r"^\s*range\(\s*(-?\d+)\s*(?:,\s*(-?\d+)\s*)?(?:,\s*(-?\d+)\s*)?\)\s*$")

TOP_KEYS = ("experiment", "scenario", "data", "solver", "evaluate", "sweep", "quick")
#: the keys that say what a [[data]] entry is (exactly one per entry)
DATA_KINDS = ("scenario", "recording", "graph", "file")
NAMESPACES = ("scenario", "solver", "evaluate")


@dataclass(frozen=True)
class SolverSpec:
    """One ``[[solver]]`` table.

    Attributes
    ----------
    label : str                 unique name inside the experiment (used in sweep keys and tables).
    method : str                registered solver name.
    params : dict               parameter overrides as written (resolved against ``Params`` at expansion).
    seed : int                  extra solver stream id (see :func:`slamcli.sweep.expand.solver_seed`).
    oracle_association : bool   give the solver the true data association (ground truth; recorded).
    init_from : str             label of the ``[[solver]]`` whose result on the same dataset is this one's
                                initial estimate ("" = none).
    """

    label: str
    method: str
    params: dict[str, Any] = field(default_factory=dict)
    seed: int = 0
    oracle_association: bool = False
    init_from: str = ""


@dataclass(frozen=True)
class DataSpec:
    """One ``[[data]]`` entry, or the ``[scenario]`` shorthand.

    Attributes
    ----------
    label : str         its name in ``results.csv`` (column ``data``) and in the ``data`` sweep axis.
    kind : str          ``scenario``, ``recording``, ``graph`` or ``file`` (:data:`DATA_KINDS`).
    name : str          the scenario, the registered recording/graph name, or the path as written.
    where : str         TOML key of the entry, for messages (``data[2]`` or ``scenario``).
    path : str          a graph or file given by path: the absolute path ("" for a registered name).
    parameters : dict   scenario: flat dotted simulator keys.
    options : dict      recording / graph: importer options by CLI flag without dashes.
    """

    label: str
    kind: str
    name: str
    where: str
    path: str = ""
    parameters: dict[str, Any] = field(default_factory=dict)
    options: dict[str, Any] = field(default_factory=dict)

    @property
    def simulated(self) -> bool:
        return self.kind == "scenario"


@dataclass(frozen=True)
class ExperimentTable:
    """The ``[experiment]`` table."""

    name: str
    description: str = ""
    root_seed: int = 0

    def __post_init__(self) -> None:
        if not _NAME_RE.match(self.name):
            raise ValueError(f"name: {self.name!r} must start with a letter/digit and use only letters, digits, "
                             "'.', '_', '-'")
        if self.root_seed < 0:
            raise ValueError(f"root_seed: must be >= 0, got {self.root_seed}")


@dataclass(frozen=True)
class ScenarioTable:
    """The ``[scenario]`` shorthand of one simulated ``[[data]]`` entry."""

    name: str
    parameters: dict[str, Any] = field(default_factory=dict)


@dataclass(frozen=True)
class SolverTable:
    """One ``[[solver]]`` table as written (``label`` "" = the method)."""

    method: str
    label: str = ""
    params: dict[str, Any] = field(default_factory=dict)
    seed: int = 0
    oracle_association: bool = False
    init_from: str = ""

    def __post_init__(self) -> None:
        label = self.label or self.method
        if not _NAME_RE.match(label) or "." in label:
            raise ValueError(f"label: {label!r} must use only letters, digits, '_', '-' (no dots)")
        if self.seed < 0:
            raise ValueError(f"seed: must be >= 0, got {self.seed}")


@dataclass(frozen=True)
class SweepTable:
    """The ``[sweep]`` table as written (the axes are checked by :func:`parse_experiment`)."""

    grid: dict[str, Any] = field(default_factory=dict)
    zip: dict[str, Any] | list[dict[str, Any]] = field(default_factory=dict)
    replicates: Any = None
    seed: Any = None
    absent: Literal["fail", "skip"] = "fail"
    dataset_seeds: Literal["derived", "replicate"] = "derived"


def typed_table(cls: type, raw: Any, where: str, source: str) -> Any:
    """The TOML table ``raw`` at ``where`` as dataclass ``cls`` through the schema (:func:`slamcli.params.convert`,
    strict: TOML values are typed); one line ``"<source>: <where>.<key>: ..."`` for an unknown key (with "did
    you mean"), a missing one, a value of the wrong type or one ``cls`` refuses."""
    import dataclasses
    import typing

    from slamcli.params import convert

    if not isinstance(raw, dict):
        raise ConfigError(f"{source}: {where}: expected a table, got {_type_name(raw)}")
    fields = dataclasses.fields(cls)
    allowed = tuple(f.name for f in fields)
    for k in raw:
        if k not in allowed:
            raise ConfigError(f"{source}: {where}.{k}: unknown key{did_you_mean(k, allowed)} "
                              f"(allowed: {', '.join(allowed)})")
    for f in fields:
        if f.name not in raw and f.default is dataclasses.MISSING and f.default_factory is dataclasses.MISSING:
            raise ConfigError(f"{source}: {where}.{f.name}: missing")
    hints = typing.get_type_hints(cls)
    kwargs = {k: convert(v, hints[k], f"{source}: {where}.{k}", strict=True) for k, v in raw.items()}
    try:
        return cls(**kwargs)
    except ValueError as exc:
        raise ConfigError(f"{source}: {where}.{exc}") from None


@dataclass(frozen=True)
class SweepSpec:
    """The ``[sweep]`` table.

    Attributes
    ----------
    grid : tuple of (key, values)          cartesian axes in file order.
    zips : tuple of tuple of (key, values) zipped groups; each group's lists have one common length.
    replicates : tuple of int              replicate ids.
    absent : str                           a registered recording or graph that is not on this machine:
                                           ``fail`` (before any run) or ``skip`` (one line per recording).
    dataset_seeds : str                    ``derived`` (:func:`slamcli.sweep.expand.dataset_seed`) or
                                           ``replicate`` (the simulator seed is the replicate id).
    """

    grid: tuple[tuple[str, tuple[Any, ...]], ...] = ()
    zips: tuple[tuple[tuple[str, tuple[Any, ...]], ...], ...] = ()
    replicates: tuple[int, ...] = (0,)
    absent: str = "fail"
    dataset_seeds: str = "derived"


@dataclass(frozen=True)
class ExperimentConfig:
    """A validated experiment file."""

    name: str
    source: str  # file the config came from (for error messages)
    scenario_params: dict[str, Any]  # flat dotted keys applied to every simulated entry
    solvers: tuple[SolverSpec, ...]
    evaluate: dict[str, Any] = field(default_factory=dict)
    sweep: SweepSpec = field(default_factory=SweepSpec)
    root_seed: int = 0
    description: str = ""
    quick: dict[str, Any] = field(default_factory=dict)
    data: tuple[DataSpec, ...] = ()

    @property
    def scenario(self) -> str:
        """The first simulated entry's scenario ("" when every entry is a recording or a file)."""
        return next((d.name for d in self.data if d.simulated), "")

    def entry(self, label: str) -> DataSpec:
        for d in self.data:
            if d.label == label:
                return d
        raise KeyError(label)

    def solver(self, label: str) -> SolverSpec:
        for s in self.solvers:
            if s.label == label:
                return s
        raise KeyError(label)

    def err(self, key: str, message: str) -> ConfigError:
        return ConfigError(f"{self.source}: {key}: {message}")


# -- helpers ------------------------------------------------------------------------------------------------


def flatten(table: dict[str, Any], prefix: str = "") -> dict[str, Any]:
    """``{"sensor": {"max_range": 10}}`` → ``{"sensor.max_range": 10}`` (TOML dotted keys are nested tables)."""
    out: dict[str, Any] = {}
    for k, v in table.items():
        key = f"{prefix}{k}"
        if isinstance(v, dict):
            out.update(flatten(v, key + "."))
        else:
            out[key] = v
    return out


def _type_name(v: Any) -> str:
    return {bool: "boolean", int: "integer", float: "float", str: "string", list: "array", dict: "table"}.get(
        type(v), type(v).__name__
    )


def check_keys(cfg: ExperimentConfig, known: Callable[[str, str], Any]) -> None:
    """Check every key of ``cfg`` against the real scenario / solver / evaluate key sets, naming the TOML key.

    ``known(kind, name)`` returns the known keys: ``("scenario", scenario name)`` → ``{dotted simulator key:
    type}``, ``("solver", method)`` → ``{Params field: type}``, ``("evaluate", "")`` → option names; None =
    cannot tell (unknown plugin: the resolver reports that). Unknown scenario names and keys raise a one-line
    :class:`ConfigError` ``"<file>: <TOML key>: unknown ...; did you mean '...'?"``; a value (every value of a
    sweep axis) whose type does not fit its key raises ``"<file>: <TOML key>: expected ..."``. Checks that
    involve several keys together stay with the resolution.
    """
    from slamcli.params import convert
    from slamcli.sim.scenarios import SCENARIOS

    c = _Rules(cfg.source)
    scenarios: dict[str, Any] = {}  # scenario name -> its known keys, for every simulated entry
    for d in cfg.data:
        if d.simulated and d.name not in SCENARIOS:
            raise c.fail(f"{d.where}.name" if d.where == "scenario" else f"{d.where}.scenario",
                         f"unknown scenario {d.name!r}{did_you_mean(d.name, SCENARIOS)} (known: {', '.join(SCENARIOS)})")
        if d.simulated:
            scenarios[d.name] = known("scenario", d.name) or []
    methods = {s.label: s.method for s in cfg.solvers}

    def typed(values: tuple, tp: Any, toml_key: str) -> None:
        for v in values:
            try:
                convert(v, tp, "\0")
            except ConfigError as exc:
                raise c.fail(toml_key, str(exc).split("\0", 1)[-1].lstrip(": ")) from None

    def scenario_key(scen: Any, rest: str, toml_key: str, values: tuple) -> None:
        if scen and rest not in scen:
            raise c.fail(toml_key, f"unknown scenario key {rest!r}{did_you_mean(rest, scen)} "
                                   f"(`slamcli simulate --keys` lists them)")
        if isinstance(scen, dict):
            typed(values, scen[rest], toml_key)

    def check(ns_key: str, toml_key: str, values: tuple) -> None:
        ns, _, rest = ns_key.partition(".")
        if ns == "scenario":
            if not scenarios:
                raise c.fail(toml_key, "no simulated [[data]] entry (scenario = ...) for a scenario key")
            for scen in scenarios.values():
                scenario_key(scen, rest, toml_key, values)
        elif ns == "solver":
            label, _, param = rest.partition(".")
            fields = known("solver", methods[label]) if label in methods else None
            if fields is not None and param not in fields:
                raise c.fail(toml_key, f"unknown parameter {param!r} of {methods[label]}"
                                       f"{did_you_mean(param, fields)} (`slamcli solvers {methods[label]}` lists them)")
            if isinstance(fields, dict):
                typed(values, fields[param], toml_key)
        elif ns == "evaluate":
            opts = known("evaluate", "") or []
            if opts and rest not in opts:
                raise c.fail(toml_key, f"unknown option {rest!r}{did_you_mean(rest, opts)} (known: {', '.join(opts)})")

    for k, v in cfg.scenario_params.items():
        check(f"scenario.{k}", f"scenario.parameters.{k}", (v,))
    for d in cfg.data:
        for k, v in d.parameters.items():
            scenario_key(scenarios[d.name], k, f"{d.where}.parameters.{k}", (v,))
    for i, s in enumerate(cfg.solvers):
        for k, v in s.params.items():
            check(f"solver.{s.label}.{k}", f"solver[{i}].params.{k}", (v,))
    for k, v in cfg.evaluate.items():
        check(f"evaluate.{k}", f"evaluate.{k}", (v,))
    for k, vals in cfg.sweep.grid:
        check(k, f"sweep.grid {k!r}", vals)
    for g in cfg.sweep.zips:
        for k, vals in g:
            check(k, f"sweep.zip {k!r}", vals)
    for k, v in cfg.quick.items():
        if k != "replicates":
            check(k, f"quick {k!r}", (v,))


#: most values one sweep axis or replicate list may hold (the whole expansion is bounded in sweep.expand)
MAX_AXIS_VALUES = 100_000


def parse_range(text: str) -> list[int] | None:
    """``"range(0, 50)"`` → ``[0, ..., 49]`` (Python semantics); None when ``text`` is not a range().

    Raises ValueError for a zero step or more than :data:`MAX_AXIS_VALUES` values (checked before listing).
    """
    m = _RANGE_RE.match(text)
    if not m:
        return None
    a, b, c = m.groups()
    if c is not None and int(c) == 0:
        raise ValueError(f"{text}: step must not be 0")
    r = range(int(a)) if b is None else range(int(a), int(b), int(c) if c is not None else 1)
    if len(r) > MAX_AXIS_VALUES:
        raise ValueError(f"{text} has {len(r)} values, above the limit of {MAX_AXIS_VALUES}")
    return list(r)


class _Rules:
    """The experiment-file rules no type expresses (sweep axes, replicate lists, data labels, paths inside the
    experiment's folder), each failing with one line ``"<source>: <key>: ..."``; the types themselves go
    through the schema (:meth:`typed`)."""

    def __init__(self, source: str, data_labels: tuple[str, ...] = ()) -> None:
        self.source = source
        self.data_labels = data_labels  # labels of the [[data]] entries (for the data axis)

    def fail(self, key: str, message: str) -> ConfigError:
        return ConfigError(f"{self.source}: {key}: {message}")

    def typed(self, value: Any, tp: Any, key: str) -> Any:
        """``value`` at TOML key ``key`` as type ``tp`` (:func:`slamcli.params.convert`, strict)."""
        from slamcli.params import convert

        return convert(value, tp, f"{self.source}: {key}", strict=True)

    def tables(self, raw: dict[str, Any], key: str, alternative: str = "") -> list[dict[str, Any]]:
        """The ``[[key]]`` tables of ``raw``: present, an array of tables, at least one."""
        if key not in raw:
            raise self.fail(f"[[{key}]]", f"missing: give at least one [[{key}]] table{alternative}")
        value = raw[key]
        if not isinstance(value, list) or not all(isinstance(t, dict) for t in value):
            raise self.fail(key, f"expected [[{key}]] tables (an array of tables)")
        if not value:
            raise self.fail(f"[[{key}]]", f"empty: give at least one [[{key}]] table")
        return value

    def known(self, table: dict[str, Any], allowed: tuple[str, ...], where: str) -> None:
        for k in table:
            if k not in allowed:
                raise self.fail(f"{where}.{k}" if where else k,
                                f"unknown key{did_you_mean(k, allowed)} (allowed: {', '.join(allowed)})")

    def inside(self, name: str, key: str) -> str:
        """``name`` resolved against the experiment file's folder; refused when it leaves that folder."""
        base = Path(self.source).resolve().parent
        p = (base / name).resolve()
        if not p.is_relative_to(base):
            raise self.fail(key, f"{name!r} leaves the experiment file's folder {base} (put the file beside the "
                                 "experiment, or register it: `slamcli datasets add`)")
        return str(p)

    def name(self, value: Any, key: str) -> str:
        s = self.typed(value, str, key)
        if not _NAME_RE.match(s):
            raise self.fail(key, f"{s!r} must start with a letter/digit and use only letters, digits, '.', '_', '-'")
        return s

    def values(self, value: Any, key: str) -> tuple[Any, ...]:
        """A sweep axis: a non-empty array, or a ``"range(...)"`` string."""
        if isinstance(value, str):
            try:
                r = parse_range(value)
            except ValueError as exc:
                raise self.fail(key, str(exc)) from None
            if r is None:
                raise self.fail(key, f"expected an array of values or 'range(a, b[, step])', got {value!r}")
            value = r
        if not isinstance(value, list):
            raise self.fail(key, f"expected an array of values, got {_type_name(value)}")
        if not value:
            raise self.fail(key, "empty list: a sweep axis needs at least one value")
        return tuple(value)

    def replicates(self, value: Any, key: str) -> tuple[int, ...]:
        if isinstance(value, bool):
            raise self.fail(key, "expected an integer count, an array of integers or 'range(a, b)'")
        if isinstance(value, int):
            if value < 1:
                raise self.fail(key, f"must be >= 1, got {value}")
            if value > MAX_AXIS_VALUES:
                raise self.fail(key, f"{value} replicates, above the limit of {MAX_AXIS_VALUES}")
            return tuple(range(value))
        vals = self.values(value, key)
        if min(self.typed(list(vals), list[int], key)) < 0:
            raise self.fail(key, f"must be >= 0, got {min(vals)}")
        if len(set(vals)) != len(vals):
            raise self.fail(key, "replicate ids must be unique")
        return tuple(vals)

    def axis(self, key: str, value: Any, where: str, labels: set[str]) -> tuple[Any, ...]:
        """A checked sweep axis ``key = value`` (see :meth:`sweep_key`, :meth:`values`)."""
        self.sweep_key(key, where, labels)
        vals = self.values(value, f"{where} {key!r}")
        if key == "data":
            self.data_values(vals, f"{where} {key!r}")
        return vals

    def data_values(self, values: tuple[Any, ...], key: str) -> None:
        """Every value of a ``data`` axis names a ``[[data]]`` entry (its label)."""
        for v in values:
            if v not in self.data_labels:
                raise self.fail(key, f"no [[data]] entry labelled {v!r}{did_you_mean(str(v), self.data_labels)} "
                                     f"(labels: {', '.join(self.data_labels)})")
        if len(set(values)) != len(values):
            raise self.fail(key, "a data label is given twice")

    def sweep_key(self, key: str, where: str, labels: set[str]) -> None:
        if key == "data":
            return
        parts = key.split(".")
        ns = parts[0]
        if ns not in NAMESPACES or len(parts) < 2 or not all(parts):
            raise self.fail(
                f"{where} {key!r}",
                "keys must be scenario.<dotted key>, solver.<label>.<param>, evaluate.<option> or data",
            )
        if ns == "solver":
            if len(parts) != 3:
                raise self.fail(f"{where} {key!r}", "solver keys are solver.<label>.<param>")
            if parts[1] not in labels:
                raise self.fail(
                    f"{where} {key!r}", f"no [[solver]] labelled {parts[1]!r}; labels: {', '.join(sorted(labels))}"
                )


# -- loading ------------------------------------------------------------------------------------------------


def load_experiment(path: str | Path) -> ExperimentConfig:
    """Read and validate an experiment file; :class:`ConfigError` (one line, file + key) on any problem."""
    p = Path(path)
    if not p.is_file():
        raise ConfigError(f"{p}: experiment file not found")
    try:
        with p.open("rb") as fh:
            raw = tomllib.load(fh)
    except tomllib.TOMLDecodeError as exc:
        raise ConfigError(f"{p}: not valid TOML: {exc}") from None
    except UnicodeDecodeError as exc:
        raise ConfigError(f"{p}: not valid TOML: not UTF-8 text (byte 0x{exc.object[exc.start]:02x} at "
                          f"offset {exc.start})") from None
    except OSError as exc:
        raise ConfigError(f"{p}: cannot read: {exc.strerror}") from None
    except RecursionError:  # tomllib parses nested arrays/tables recursively
        raise ConfigError(f"{p}: not valid TOML for an experiment: nested deeper than {MAX_TOML_DEPTH} "
                          "levels (the parser's recursion limit was reached)") from None
    depth = _depth(raw)
    if depth > MAX_TOML_DEPTH:
        raise ConfigError(f"{p}: arrays/tables nested more than {MAX_TOML_DEPTH} levels deep (the limit of "
                          "an experiment file)")
    return parse_experiment(raw, source=str(p))


#: deepest nesting of tables/arrays an experiment file may have (far above what the schema needs)
MAX_TOML_DEPTH = 32


def _depth(v: Any) -> int:
    """Nesting depth of a parsed TOML value (a scalar 0), capped at MAX_TOML_DEPTH + 1; iterative."""
    best, stack = 0, [(v, 0)]
    while stack:
        x, d = stack.pop()
        best = max(best, d)
        if d <= MAX_TOML_DEPTH and isinstance(x, (dict, list)):
            stack.extend((y, d + 1) for y in (x.values() if isinstance(x, dict) else x))
    return best


def _parse_data(c: _Rules, raw: dict[str, Any]) -> tuple[tuple[DataSpec, ...], dict[str, Any]]:
    """The dataset entries and the experiment-wide scenario parameters: ``[scenario]`` is one simulated entry
    whose parameters apply as ``scenario.*`` keys; ``[[data]]`` entries carry their own."""
    if "scenario" in raw and "data" in raw:
        raise c.fail("[scenario]", "give either one [scenario] table or [[data]] entries, not both")
    if "scenario" in raw:
        scen = typed_table(ScenarioTable, raw["scenario"], "scenario", c.source)
        name, params = scen.name, flatten(scen.parameters)
        return (DataSpec(label=name, kind="scenario", name=name, where="scenario"),), params
    out: list[DataSpec] = []
    for i, d in enumerate(c.tables(raw, "data", " (or one [scenario] table)")):
        spec = _data_entry(c, d, f"data[{i}]")
        if any(o.label == spec.label for o in out):
            raise c.fail(f"data[{i}].label", f"duplicate label {spec.label!r}; give each [[data]] entry a "
                                             "unique label")
        out.append(spec)
    return tuple(out), {}


def _data_entry(c: _Rules, d: dict[str, Any], where: str) -> DataSpec:
    """One ``[[data]]`` table (see the module docstring)."""
    kinds = [k for k in DATA_KINDS if k in d]
    if len(kinds) != 1:
        raise c.fail(where, f"give exactly one of {', '.join(DATA_KINDS)}"
                            + (f" (got {', '.join(kinds)})" if kinds else ""))
    kind = kinds[0]
    name = c.typed(d[kind], str, f"{where}.{kind}")
    if not name:
        raise c.fail(f"{where}.{kind}", "empty")
    rest = {k: v for k, v in d.items() if k not in (kind, "label")}
    path = ""
    if kind == "scenario":
        c.known(rest, ("parameters",), where)
    elif kind == "file" or (kind == "graph" and looks_like_path(name)):
        if kind == "file":
            c.known(rest, (), where)
        path = c.inside(name, f"{where}.{kind}")
    default = Path(name).stem if path else name
    label = c.name(d.get("label", default), f"{where}.label")
    params = flatten(c.typed(rest.pop("parameters", {}), dict, f"{where}.parameters")) if kind == "scenario" else {}
    return DataSpec(label=label, kind=kind, name=name, where=where, path=path, parameters=params,
                    options=rest if kind in ("recording", "graph") else {})


def init_order(solvers, source: str) -> list[SolverSpec]:
    """``solvers`` ordered so that each comes after the one its ``init_from`` names (file order otherwise);
    one-line ConfigError for a label that names no ``[[solver]]`` or a cycle."""
    by_label = {s.label: s for s in solvers}
    order: list[SolverSpec] = []
    for s in solvers:
        chain: list[SolverSpec] = []
        while s not in order and s not in chain:
            chain.append(s)
            if not s.init_from:
                break
            if s.init_from not in by_label:
                raise ConfigError(f"{source}: solver {s.label!r} init_from: {s.init_from!r} is not the label of a "
                                  f"[[solver]]{did_you_mean(s.init_from, by_label)}")
            s = by_label[s.init_from]
        else:
            if s in chain:
                raise ConfigError(f"{source}: solver {chain[0].label!r} init_from: cycle "
                                  + " -> ".join(x.label for x in chain + [s]))
        order += [x for x in reversed(chain) if x not in order]
    return order


def looks_like_path(name: str) -> bool:
    """Whether a graph entry names a file (a folder separator or a suffix) rather than a registered name."""
    return "/" in name or "\\" in name or bool(Path(name).suffix)


def parse_experiment(raw: dict[str, Any], *, source: str = "<experiment>") -> ExperimentConfig:
    """Validate the parsed TOML document ``raw`` (see the module docstring for the schema)."""
    c = _Rules(source)
    c.known(raw, TOP_KEYS, "")

    if "experiment" not in raw:
        raise c.fail("[experiment]", "missing table")
    exp = typed_table(ExperimentTable, raw["experiment"], "experiment", source)

    data, scenario_params = _parse_data(c, raw)
    c.data_labels = tuple(d.label for d in data)

    solvers: list[SolverSpec] = []
    labels: set[str] = set()
    for i, s in enumerate(c.tables(raw, "solver")):
        where = f"solver[{i}]"
        t = typed_table(SolverTable, s, where, source)
        label = t.label or t.method
        if label in labels:
            raise c.fail(f"{where}.label", f"duplicate label {label!r}; give each [[solver]] a unique label")
        labels.add(label)
        solvers.append(SolverSpec(label=label, method=t.method, params=dict(t.params), seed=t.seed,
                                  oracle_association=t.oracle_association, init_from=t.init_from))
    init_order(solvers, source)

    evaluate = dict(c.typed(raw.get("evaluate", {}), dict, "[evaluate]"))
    if "against" in evaluate:  # a result file: resolved here, and it must stay beside the experiment
        evaluate["against"] = c.inside(c.typed(evaluate["against"], str, "evaluate.against"), "evaluate.against")

    sweep = SweepSpec()
    if "sweep" in raw:
        sw = raw["sweep"]
        typed_table(SweepTable, sw, "sweep", source)
        if "replicates" in sw and "seed" in sw:
            raise c.fail("sweep.seed", "give either sweep.replicates or sweep.seed, not both")
        rep_key = "replicates" if "replicates" in sw else "seed"
        replicates = c.replicates(sw[rep_key], f"sweep.{rep_key}") if rep_key in sw else (0,)
        grid_raw = c.typed(sw.get("grid", {}), dict, "sweep.grid")
        if "grid" in sw and not grid_raw:
            raise c.fail("sweep.grid", "empty grid: give at least one key = [values]")
        grid_raw = flatten(grid_raw)
        grid = []
        for k, v in grid_raw.items():
            grid.append((k, c.axis(k, v, "sweep.grid", labels)))
        zips = []
        if "zip" in sw:
            groups = sw["zip"] if isinstance(sw["zip"], list) else [sw["zip"]]
            for gi, g in enumerate(groups):
                where = "sweep.zip" if not isinstance(sw["zip"], list) else f"sweep.zip[{gi}]"
                g = flatten(c.typed(g, dict, where))
                if not g:
                    raise c.fail(where, "empty zip group: give at least one key = [values]")
                group = []
                for k, v in g.items():
                    group.append((k, c.axis(k, v, where, labels)))
                lengths = {k: len(v) for k, v in group}
                if len(set(lengths.values())) != 1:
                    listing = ", ".join(f"{k}={n}" for k, n in lengths.items())
                    raise c.fail(where, f"zipped lists must have equal lengths, got {listing}")
                zips.append(tuple(group))
        all_keys = [k for k, _ in grid] + [k for g in zips for k, _ in g]
        dup = sorted({k for k in all_keys if all_keys.count(k) > 1})
        if dup:
            raise c.fail("[sweep]", f"key {dup[0]!r} is swept more than once")
        absent = sw.get("absent", "fail")
        sweep = SweepSpec(grid=tuple(grid), zips=tuple(zips), replicates=replicates, absent=absent,
                          dataset_seeds=sw.get("dataset_seeds", "derived"))

    quick: dict[str, Any] = {}
    if "quick" in raw:
        q = flatten(c.typed(raw["quick"], dict, "[quick]"))
        for k, v in q.items():
            if k in ("replicates", "seed"):
                quick["replicates"] = c.replicates(v, f"quick.{k}")
            else:
                c.sweep_key(k, "quick", labels)
                if k == "data":
                    c.data_values((v,), f"quick {k!r}")
                quick[k] = v

    return ExperimentConfig(
        name=exp.name,
        source=source,
        data=data,
        scenario_params=scenario_params,
        solvers=tuple(solvers),
        evaluate=evaluate,
        sweep=sweep,
        root_seed=exp.root_seed,
        description=exp.description,
        quick=quick,
    )


def route_overrides(
    cfg: ExperimentConfig, overrides: dict[str, Any]
) -> tuple[dict[str, Any], dict[str, Any], dict[str, dict[str, Any]]]:
    """Apply sweep-key overrides (``scenario.x``, ``solver.<label>.p``, ``evaluate.k``) on copies of the
    experiment's scenario parameters, evaluate options and per-solver parameters.

    Returns ``(scenario_params, evaluate, {label: params})``; an unknown namespace or solver label raises a
    one-line :class:`ConfigError` naming the file and key.
    """
    scenario_params = dict(cfg.scenario_params)
    evaluate = dict(cfg.evaluate)
    solvers = {s.label: dict(s.params) for s in cfg.solvers}
    for key, value in overrides.items():
        ns, _, rest = key.partition(".")
        if key == "data":  # selects an entry (sweep.expand); no parameter to route
            continue
        if ns == "scenario":
            scenario_params[rest] = value
        elif ns == "evaluate":
            evaluate[rest] = value
        elif ns == "solver":
            label, _, param = rest.partition(".")
            if label not in solvers:
                raise cfg.err(key, f"no [[solver]] labelled {label!r}")
            solvers[label][param] = value
        else:
            raise cfg.err(key, "override keys must be scenario.*, solver.<label>.*, evaluate.* or data")
    return scenario_params, evaluate, solvers


def apply_fixed(cfg: ExperimentConfig, overrides: dict[str, Any], *, replicates: tuple[int, ...] | None = None):
    """A copy of ``cfg`` with fixed overrides in sweep-key form (``scenario.x``, ``solver.<label>.p``, ...).

    A fixed override of a key that is also swept replaces that axis (the axis is dropped); a fixed ``data``
    keeps only that entry, and when it is not simulated, the ``scenario.*`` keys (which then apply to nothing)
    are dropped too.
    """
    import dataclasses

    data = tuple(d for d in cfg.data if "data" not in overrides or d.label == overrides["data"])
    scenario_params, evaluate, solvers = route_overrides(cfg, overrides)
    simulated = any(d.simulated for d in data)
    if not simulated:
        scenario_params = {}

    def dropped(k: str) -> bool:
        return k in overrides or (not simulated and k.startswith("scenario."))

    grid = tuple((k, v) for k, v in cfg.sweep.grid if not dropped(k))
    zips = tuple(g2 for g2 in (tuple((k, v) for k, v in g if not dropped(k)) for g in cfg.sweep.zips) if g2)
    sweep = dataclasses.replace(
        cfg.sweep, grid=grid, zips=zips, replicates=replicates if replicates is not None else cfg.sweep.replicates
    )
    return dataclasses.replace(
        cfg,
        scenario_params=scenario_params,
        evaluate=evaluate,
        solvers=tuple(dataclasses.replace(s, params=solvers[s.label]) for s in cfg.solvers),
        sweep=sweep,
        data=data,
        quick={k: v for k, v in cfg.quick.items() if simulated or not k.startswith("scenario.")},
    )


def quick_variant(cfg: ExperimentConfig) -> ExperimentConfig:
    """Apply the file's ``[quick]`` table (few replicates, short runs) for smoke checks."""
    q = dict(cfg.quick)
    reps = q.pop("replicates", None)
    return apply_fixed(cfg, q, replicates=reps)


def _override_values(text: str) -> tuple[Any, ...]:
    """``0.9,0.99`` → ``(0.9, 0.99)``; each piece a TOML literal (``true``, ``"a,b"``, ``[1.0, 2.0]``), else the
    bare text as a string. A value starting with ``[`` is one array, not a list of values."""
    def literal(piece: str) -> Any:
        try:
            return tomllib.loads(f"v = {piece}")["v"]
        except tomllib.TOMLDecodeError:
            return piece

    text = text.strip()
    if text.startswith("[") or text.startswith('"'):
        return (literal(text),)
    return tuple(literal(p.strip()) for p in text.split(","))


def apply_overrides(cfg: ExperimentConfig, items: list[str], known: Callable[[str, str], Any]) -> ExperimentConfig:
    """Hydra-style command-line overrides on ``cfg``, validated like the TOML (:func:`check_keys`).

    ``key=value`` fixes a sweep key (``scenario.<dotted key>``, ``solver.<label>.<param>``, ``evaluate.<opt>``;
    an axis of that key is dropped); ``key=v1,v2,...`` makes it a grid axis (replacing the file's values of that
    axis; a new axis varies fastest, except ``data``, which stays the slowest as when it is not swept);
    ``data=label`` keeps one ``[[data]]`` entry; ``solver=a,b`` keeps those ``[[solver]]`` labels and
    ``+solver=m`` adds registered solver ``m`` with its defaults (label ``m``; its parameters then take
    ``solver.m.<param>`` overrides); ``replicates=N`` (or a list / ``range(a, b)``) sets the replicates. Errors are one line
    ``"<file> (command line): <key>: ..."`` with the TOML checks' "did you mean".
    """
    import dataclasses

    c = _Rules(f"{cfg.source} (command line)", tuple(d.label for d in cfg.data))
    cfg, items = _select_solvers(cfg, c, items)
    labels = {s.label for s in cfg.solvers}
    fixed: dict[str, Any] = {}
    axes: dict[str, tuple[Any, ...]] = {}
    replicates = None
    for item in items:
        key, sep, text = item.partition("=")
        key = key.strip()
        if not sep or not key or not text.strip():
            raise c.fail(repr(item), "expected key=value or key=v1,v2 (e.g. solver.ekf.gate_prob=0.9,0.99)")
        if key in ("replicates", "seed"):
            raw = text.strip()
            vals = _override_values(raw)
            replicates = c.replicates(raw if raw.startswith("range(") else list(vals) if len(vals) > 1 else vals[0],
                                      key)
            continue
        c.sweep_key(key, "override", labels)
        if key in fixed or key in axes:
            raise c.fail(key, "given twice on the command line")
        values = _override_values(text)
        if key == "data":
            c.data_values(values, key)
        if len(values) == 1:
            fixed[key] = values[0]
        elif any(key == k for g in cfg.sweep.zips for k, _ in g):
            raise c.fail(key, "is a zipped axis of the file: give one value, or edit the file's [sweep.zip]")
        else:
            axes[key] = values
    probe = dataclasses.replace(cfg, source=c.source, scenario_params={}, evaluate={}, quick={},
                                solvers=tuple(dataclasses.replace(s, params={}) for s in cfg.solvers),
                                sweep=SweepSpec(grid=tuple({**{k: (v,) for k, v in fixed.items()}, **axes}.items())))
    try:
        check_keys(probe, known)
    except ConfigError as exc:  # name the override as typed, not the probe's sweep.grid table
        raise ConfigError(re.sub(r"sweep\.grid '([^']+)'", r"\1", str(exc))) from None
    out = apply_fixed(cfg, fixed, replicates=replicates)
    first = [("data", axes.pop("data"))] if "data" in axes and "data" not in [k for k, _ in out.sweep.grid] else []
    grid = first + [(k, axes.pop(k) if k in axes else v) for k, v in out.sweep.grid] + list(axes.items())
    return dataclasses.replace(out, sweep=dataclasses.replace(out.sweep, grid=tuple(grid)))


def _select_solvers(cfg: ExperimentConfig, c: _Rules, items: list[str]) -> tuple[ExperimentConfig, list[str]]:
    """Apply ``solver=LABELS`` (keep those ``[[solver]]`` labels, in file order) and ``+solver=METHODS`` (add
    each registered method with its default parameters, labelled by its name; the method is checked when the
    sweep is resolved); the other items are returned untouched."""
    import dataclasses

    solvers, rest = list(cfg.solvers), []
    for item in items:
        key, _, text = item.partition("=")
        key, names = key.strip(), [n.strip() for n in text.split(",") if n.strip()]
        if key not in ("solver", "+solver"):
            rest.append(item)
            continue
        if not names:
            raise c.fail(key, "give one or more names, e.g. solver=ekf,graph or +solver=mine")
        labels = [s.label for s in solvers]
        for n in names:
            if key == "solver" and n not in labels:
                raise c.fail(key, f"no [[solver]] labelled {n!r}{did_you_mean(n, labels)} (labels: "
                                  f"{', '.join(labels)}; +solver={n} adds a registered solver)")
            if key == "+solver" and (n in labels or not _NAME_RE.match(n) or "." in n):
                raise c.fail(key, f"{n!r} is already a [[solver]] label" if n in labels else
                             f"{n!r} is not a solver name (letters, digits, '_', '-')")
        if key == "solver":
            solvers = [s for s in solvers if s.label in names]
        else:
            solvers += [SolverSpec(label=n, method=n) for n in names]
    kept = {f"solver.{s.label}." for s in solvers}

    def live(k: str) -> bool:  # a solver.<label>.* key of a configuration left out applies to nothing
        return not k.startswith("solver.") or any(k.startswith(p) for p in kept)

    sweep = dataclasses.replace(cfg.sweep, grid=tuple((k, v) for k, v in cfg.sweep.grid if live(k)),
                                zips=tuple(g2 for g in cfg.sweep.zips if (g2 := tuple(kv for kv in g if live(kv[0])))))
    return dataclasses.replace(cfg, solvers=tuple(solvers), sweep=sweep,
                               quick={k: v for k, v in cfg.quick.items() if live(k)}), rest
