"""One configuration schema: frozen dataclasses converted from mappings by :func:`from_mapping`.

Solver parameters, scenario overrides, importer options and experiment files all convert their values here:
``msgspec.convert(value, type=T, strict=False)`` does the typing (int, float, bool, str, ``Literal``, enums,
tuples, nested tuples, ``X | None``); :func:`convert` first reads the command-line notations (``1,2,3`` or
``[1, 2, 3]`` for a tuple, ``none``, ``yes``/``no``/``on``/``off``, an enum member's name) and refuses NaN.
Every error is one :class:`ConfigError` line naming where the value came from and the key, with "did you
mean" for an unknown key. A field's documentation is its ``metadata["doc"]`` (:func:`param_docs`).
"""

from __future__ import annotations

import dataclasses
import enum
import json
import math
import re
import types
import typing
from typing import Any, Literal

from slamcli.errors import ConfigError

_BOOL_WORDS = {"1": True, "true": True, "yes": True, "on": True, "0": False, "false": False, "no": False,
               "off": False}
#: how an error line names the type msgspec expected
_TYPE_WORDS = {"int": "an integer", "float": "a number", "bool": "a boolean (true/false)", "str": "a string",
               "array": "a list", "object": "a table", "null": "none"}


def split_override(text: str, where: str = "--param") -> tuple[str, str]:
    if "=" not in text:
        raise ConfigError(f"{where}: expected key=value, got {text!r}")
    key, value = text.split("=", 1)
    key = key.strip()
    if not key:
        raise ConfigError(f"{where}: empty key in {text!r}")
    return key, value.strip()


def did_you_mean(key: str, known, prefix: str = "") -> str:
    """``"; did you mean 'x'?"`` for the closest known names (:func:`difflib.get_close_matches`), else ``""``."""
    import difflib

    close = difflib.get_close_matches(key, list(known), n=2, cutoff=0.6)
    return f"; did you mean {' or '.join(repr(prefix + c) for c in close)}?" if close else ""


def known_text(key: str, known) -> str:
    """What follows "unknown key 'k'" in an error line: a "did you mean" when a known name is close, then
    the known names (``"; did you mean 'x'? (known: a, b)"`` or ``"; known: a, b"``)."""
    listing = ", ".join(known) or "none"
    hint = did_you_mean(key, known)
    return f"{hint} (known: {listing})" if hint else f"; known: {listing}"


def _notation(value: Any, tp: Any, where: str) -> Any:
    """``value`` with the command-line notations of type ``tp`` read (see the module docstring)."""
    if not isinstance(value, str):
        return value
    s, origin, args = value.strip(), typing.get_origin(tp), typing.get_args(tp)
    if origin in (typing.Union, types.UnionType):
        if type(None) in args and s.lower() in ("none", "null"):
            return None
        for a in args:
            out = _notation(value, a, where)
            if out is not value:
                return out
        return value
    if tp is bool and s.lower() in _BOOL_WORDS:
        return _BOOL_WORDS[s.lower()]
    if origin is tuple:
        if not s.startswith("["):
            return [v for v in s.split(",") if v.strip()]
        try:
            return json.loads(s)
        except json.JSONDecodeError:
            raise ConfigError(f"{where}: cannot parse {value!r} as a list") from None
    if isinstance(tp, type) and issubclass(tp, enum.Enum):
        return next((m.value for m in tp if m.name == s), value)
    return value


def _has_nan(value: Any) -> bool:
    if isinstance(value, float):
        return math.isnan(value)
    return isinstance(value, tuple) and any(_has_nan(v) for v in value)


def _error_text(exc: Exception, value: Any, tp: Any) -> str:
    """msgspec's error as one line of our wording: ``expected an integer, got '1.5'``."""
    allowed = allowed_values(tp)
    if allowed and "true" not in allowed and not isinstance(value, (list, tuple)):  # a Literal or an enum
        return f"{value!r} is not one of {', '.join(allowed)}{did_you_mean(str(value), allowed)}"
    text = str(exc).split(" - at `", 1)[0]
    m = re.fullmatch(r"Expected `array` of length (\d+), got (\d+)", text)
    if m:
        return f"expected {m[1]} values, got {m[2]}"
    m = re.fullmatch(r"Expected `([^`]+)`, got `[^`]+`", text)
    if m:
        words = " or ".join(_TYPE_WORDS.get(t.strip(), t.strip()) for t in m[1].split("|"))
        return f"expected {words}, got {value!r}"
    return text


def convert(value: Any, tp: Any, where: str, *, strict: bool = False) -> Any:
    """``value`` (a string from the command line, or a TOML/JSON/Python value) as type ``tp``; one-line
    :class:`ConfigError` ``"<where>: expected …, got …"`` otherwise. ``strict``: a typed value (a TOML
    table's own keys) must already have the type — no string is read as a number."""
    import msgspec

    raw = value if strict else _notation(value, tp, where)
    try:
        out = msgspec.convert(raw, type=tp, strict=strict)
    except msgspec.ValidationError as exc:
        raise ConfigError(f"{where}: {_error_text(exc, value, tp)}") from None
    if _has_nan(out):
        raise ConfigError(f"{where}: NaN is not allowed")
    return out


def from_mapping(cls: type, mapping: dict[str, Any], *, where: str, what: str = "parameter") -> dict[str, Any]:
    """The typed keyword arguments of dataclass ``cls`` for ``mapping`` (keys checked, with "did you mean")."""
    fields = {f.name for f in dataclasses.fields(cls) if f.init}
    unknown = next((k for k in mapping if k not in fields), None)
    if unknown is not None:
        raise ConfigError(f"{where}: unknown {what} {unknown!r} for {cls.__name__}{known_text(unknown, sorted(fields))}")
    # the annotations are evaluated only when there is something to convert: for a class with string
    # annotations (``from __future__ import annotations``) that costs about a millisecond per call
    hints = typing.get_type_hints(cls) if mapping else {}
    return {k: convert(v, hints[k], f"{where} {k}") for k, v in mapping.items()}


def given_values(params_cls: type, overrides: dict[str, Any] | list[str], *, where: str = "--param") -> dict[str, Any]:
    """The typed values of the keys given (``{"k": v}`` or ``["k=v", ...]``), validated against ``params_cls``."""
    if isinstance(overrides, list):
        pairs: dict[str, Any] = {}
        for text in overrides:
            k, v = split_override(text, where)
            pairs[k] = v
        overrides = pairs
    return from_mapping(params_cls, overrides, where=where)


def build_params(params_cls: type, overrides: dict[str, Any] | list[str], *, where: str = "--param",
                 inputs: Any = None) -> Any:
    """Instantiate ``params_cls`` with overrides (``{"k": v}`` or ``["k=v", ...]``), validating keys and types.

    A class with a ``resolve(given, inputs)`` classmethod (a preset) is built by it from the keys given, so a
    preset fills only what was left unset. Raises :class:`ConfigError` naming the key and the known keys.
    """
    given = given_values(params_cls, overrides, where=where)
    resolve = getattr(params_cls, "resolve", None)
    try:
        return resolve(given, inputs) if resolve is not None else params_cls(**given)
    except (TypeError, ValueError) as exc:
        raise ConfigError(f"{where}: {exc}") from None


def describe_params(params_cls: type) -> list[tuple[str, str, str]]:
    """``[(name, type, default)]`` for help output."""
    hints = typing.get_type_hints(params_cls)
    out = []
    for f in dataclasses.fields(params_cls):
        if f.default is not dataclasses.MISSING:
            default = f.default
        elif f.default_factory is not dataclasses.MISSING:  # type: ignore[misc]
            default = f.default_factory()  # type: ignore[misc]
        else:
            default = "required"
        tp = hints[f.name]
        generic = typing.get_origin(tp) is not None
        tname = (None if generic else getattr(tp, "__name__", None)) or str(tp).replace("typing.", "")
        out.append((f.name, tname, str(default.value if isinstance(default, enum.Enum) else default)))
    return out


def param(default: Any, doc: str) -> Any:
    """A dataclass field with default ``default`` and its documentation (``metadata["doc"]``, what
    ``slamcli solvers NAME`` shows)."""
    return dataclasses.field(default=default, metadata={"doc": doc})


def param_docs(params_cls: type) -> dict[str, tuple[str, str]]:
    """``{field: (type, documentation)}`` of ``params_cls``, from each field's ``metadata["doc"]``; fields
    without one are absent."""
    types_ = {n: t for n, t, _d in describe_params(params_cls)}
    return {f.name: (types_[f.name], f.metadata["doc"]) for f in dataclasses.fields(params_cls) if "doc" in f.metadata}


def allowed_values(tp: Any) -> list[str]:
    """Allowed values of a field type: Literal members, enum values, ``true``/``false``; [] = any of the type
    (``X | None`` adds ``none``)."""
    origin = typing.get_origin(tp)
    args = typing.get_args(tp)
    if origin in (typing.Union, types.UnionType):
        vals = [v for a in args if a is not type(None) for v in allowed_values(a)]
        return [*vals, "none"] if vals and type(None) in args else vals
    if origin is Literal:
        return [str(a) for a in args]
    if isinstance(tp, type) and issubclass(tp, enum.Enum):
        return [str(m.value) for m in tp]
    if tp is bool:
        return ["true", "false"]
    return []


#: ceiling of the memory a parameter may ask for, whatever the machine has, bytes (SLAMCLI_MEMORY_LIMIT_MB
#: overrides it); below it the limit is half of the memory available now (``MemAvailable``)
MEMORY_CEILING_BYTES = 8 << 30


def memory_limit_bytes() -> int:
    """The allocation a parameter may imply: ``min(MEMORY_CEILING_BYTES, MemAvailable / 2)``, or the
    ``SLAMCLI_MEMORY_LIMIT_MB`` environment variable when set."""
    import os

    env = os.environ.get("SLAMCLI_MEMORY_LIMIT_MB")
    if env:
        try:
            return int(float(env) * 2**20)
        except ValueError:
            raise ConfigError(f"SLAMCLI_MEMORY_LIMIT_MB: expected a number of MiB, got {env!r}") from None
    limit = MEMORY_CEILING_BYTES
    try:
        with open("/proc/meminfo") as fh:
            for line in fh:
                if line.startswith("MemAvailable:"):
                    limit = min(limit, int(line.split()[1]) * 1024 // 2)
                    break
    except OSError:
        pass
    return limit


def check_allocation(name: str, value: Any, n_bytes: float, what: str, hint: str = "use a smaller value") -> None:
    """Refuse a parameter value whose estimated allocation ``n_bytes`` exceeds :func:`memory_limit_bytes`.

    One line naming the parameter, its value, the estimate and what it is for, e.g. ``n_particles=1e+08:
    needs about 18.6 GB for the particle maps (limit 4.0 GB)``; raised before anything is allocated.
    """
    limit = memory_limit_bytes()
    if not n_bytes <= limit:  # also nan
        raise ConfigError(f"{name}={value}: needs about {n_bytes / 1e9:.3g} GB for {what} (limit "
                          f"{limit / 1e9:.3g} GB); {hint}")
