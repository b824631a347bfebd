"""Parse ``key=value`` overrides into frozen parameter dataclasses, with one-line errors.

Supported field types: ``bool``, ``int``, ``float``, ``str``, ``Literal[...]``, ``enum.Enum`` subclasses,
``tuple[float, ...]`` / ``tuple[int, ...]`` (written ``1,2,3`` or ``[1, 2, 3]``), nested tuples
(JSON ``[[1,0],[0,1]]``) and ``X | None`` of those (``none`` gives None).
"""

from __future__ import annotations

import dataclasses
import enum
import json
import math
import types
import typing
from typing import Any, Literal

from slamcli.errors import ConfigError


def split_override(text: str, where: str = "--param") -> tuple[str, str]:
    if "=" not in text:
        raise ConfigError(f"{where}: expected key=value, got {text!r}")
    key, value = text.split("=", 1)
    key = key.strip()
    if not key:
        raise ConfigError(f"{where}: empty key in {text!r}")
    return key, value.strip()


def _coerce(value: Any, tp: Any, where: str) -> Any:
    origin = typing.get_origin(tp)
    args = typing.get_args(tp)
    if origin in (typing.Union, types.UnionType):
        non_none = [a for a in args if a is not type(None)]
        if isinstance(value, str) and value.lower() in ("none", "null") and len(non_none) < len(args):
            return None
        if value is None and len(non_none) < len(args):
            return None
        errors = []
        for a in non_none:
            try:
                return _coerce(value, a, where)
            except ConfigError as exc:
                errors.append(str(exc))
        raise ConfigError(errors[0] if errors else f"{where}: cannot parse {value!r}")
    if origin is Literal:
        for a in args:
            if str(a) == str(value):
                return a
        raise ConfigError(f"{where}: {value!r} is not one of {', '.join(map(str, args))}")
    if isinstance(tp, type) and issubclass(tp, enum.Enum):
        for member in tp:
            if str(member.value) == str(value) or member.name == str(value):
                return member
        raise ConfigError(f"{where}: {value!r} is not one of {', '.join(str(m.value) for m in tp)}")
    if tp is bool:
        if isinstance(value, bool):
            return value
        s = str(value).lower()
        if s in ("1", "true", "yes", "on"):
            return True
        if s in ("0", "false", "no", "off"):
            return False
        raise ConfigError(f"{where}: expected a boolean (true/false), got {value!r}")
    if tp is int:
        if isinstance(value, bool):
            raise ConfigError(f"{where}: expected an integer, got {value!r}")
        if isinstance(value, int):
            return value
        if isinstance(value, float) and value.is_integer():
            return int(value)
        try:
            return int(str(value))
        except ValueError:
            pass
        try:  # 1e8: an integer written in exponent notation (exact up to 2^53)
            f = float(str(value))
        except ValueError:
            f = math.nan
        if math.isfinite(f) and f.is_integer() and abs(f) <= 2**53:
            return int(f)
        raise ConfigError(f"{where}: expected an integer, got {value!r}")
    if tp is float:
        if isinstance(value, bool):
            raise ConfigError(f"{where}: expected a number, got {value!r}")
        try:
            out = float(value)
        except (TypeError, ValueError):
            raise ConfigError(f"{where}: expected a number, got {value!r}") from None
        if math.isnan(out):
            raise ConfigError(f"{where}: NaN is not allowed")
        return out
    if tp is str:
        return str(value)
    if origin is tuple:
        if isinstance(value, str):
            s = value.strip()
            if s.startswith("["):
                try:
                    value = json.loads(s)
                except json.JSONDecodeError:
                    raise ConfigError(f"{where}: cannot parse {value!r} as a list") from None
            else:
                value = [v for v in s.split(",") if v.strip()]
        if not isinstance(value, (list, tuple)):
            raise ConfigError(f"{where}: expected a list, got {value!r}")
        if len(args) == 2 and args[1] is Ellipsis:
            return tuple(_coerce(v, args[0], where) for v in value)
        if len(args) != len(value):
            raise ConfigError(f"{where}: expected {len(args)} values, got {len(value)}")
        return tuple(_coerce(v, a, where) for v, a in zip(value, args))
    raise ConfigError(f"{where}: unsupported parameter type {tp!r}")


def given_values(params_cls: type, overrides: dict[str, Any] | list[str], *, where: str = "--param") -> dict[str, Any]:
    """The typed values of the keys given (``{"k": v}`` or ``["k=v", ...]``), validated against ``params_cls``."""
    if isinstance(overrides, list):
        pairs: dict[str, Any] = {}
        for text in overrides:
            k, v = split_override(text, where)
            pairs[k] = v
        overrides = pairs
    # the annotations are evaluated only to coerce overrides: for a Params class with string annotations
    # (``from __future__ import annotations``) that is ≈ 1-2 ms per call, paid twice by every default solve
    hints = typing.get_type_hints(params_cls) if overrides else {}
    fields = {f.name: f for f in dataclasses.fields(params_cls)}
    kwargs = {}
    for key, value in overrides.items():
        if key not in fields:
            known = ", ".join(sorted(fields)) or "none"
            raise ConfigError(f"{where}: unknown parameter {key!r} for {params_cls.__name__}; known: {known}")
        kwargs[key] = _coerce(value, hints[key], f"{where} {key}")
    return kwargs


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
        tname = getattr(tp, "__name__", None) or str(tp).replace("typing.", "")
        out.append((f.name, tname, str(default.value if isinstance(default, enum.Enum) else default)))
    return out


def param_docs(params_cls: type) -> dict[str, tuple[str, str]]:
    """Per-field descriptions parsed from the ``Attributes`` section of a Params class docstring (the one
    source of parameter documentation). Two layouts are understood (numpydoc)::

        name : type                      name : type     description on the same line
            description ...                              continued, indented deeper

    Several names may share one entry (``R, S, Q : tuple of float``). Returns ``{name: (type as written,
    description)}`` with whitespace collapsed; fields without an entry are absent.
    """
    import inspect
    import re

    doc = inspect.cleandoc(params_cls.__doc__ or "")
    lines = doc.splitlines()
    try:
        start = next(i for i, ln in enumerate(lines[:-1])
                     if ln.strip() == "Attributes" and set(lines[i + 1].strip()) == {"-"}) + 2
    except StopIteration:
        return {}
    head = re.compile(r"^(?P<names>[A-Za-z_][\w]*(?:\s*,\s*[A-Za-z_][\w]*)*)\s+:\s+(?P<rest>.*)$")
    entries: list[tuple[list[str], str, list[str]]] = []
    base = None
    for ln in lines[start:]:
        if not ln.strip():
            continue
        indent = len(ln) - len(ln.lstrip())
        if base is None:
            base = indent
        if indent < base:
            break
        m = head.match(ln.strip()) if indent == base else None
        if m:
            rest = m.group("rest").strip()
            tp, _, text = (p.strip() for p in re.split(r"(\s{2,})", rest, maxsplit=1)) if re.search(
                r"\s{2,}", rest) else (rest, "", "")
            entries.append(([n.strip() for n in m.group("names").split(",")], tp, [text] if text else []))
        elif entries:
            if indent == base and set(ln.strip()) == {"-"}:
                break  # next numpydoc section
            entries[-1][2].append(ln.strip())
    out: dict[str, tuple[str, str]] = {}
    for names, tp, text in entries:
        desc = " ".join(" ".join(text).split())
        for n in names:
            out[n] = (tp, desc)
    return out


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
