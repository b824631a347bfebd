"""Compare two slamcli files (datasets or results) field by field, ignoring exactly the timing fields.

"Same seed, same numbers" is checkable with ``slamcli diff A.h5 B.h5``: every group, dataset and attribute
of the two files must be equal (arrays bit for bit, NaN equal to NaN; JSON attributes as parsed JSON),
except the fields listed in :data:`~slamcli.io.schema.NONDETERMINISTIC_FIELDS` — the creation time and
the wall-clock timings, documented in ``docs/schema.md`` ("Timings: the only non-deterministic fields").

Recorded file-system paths (``@dataset_path``, and inside JSON attributes keys such as ``dataset_relpath``,
``init_path``, ``source_dir``, ``source_file``: every name ending in one of :data:`PATH_KEY_SUFFIXES`) say where
a file was, not what it holds, so they are skipped unless ``paths=True`` (``slamcli diff --paths``): two results of
identical datasets stored in different folders are "same".

Every array is checked against its declared shape and allocated storage before it is read
(:meth:`Reader._check_declared`), so a forged header cannot make a diff allocate gigabytes.
"""

from __future__ import annotations

import json
import os
from dataclasses import dataclass, field
from typing import Any

import h5py
import numpy as np

from slamcli.io.schema import NONDETERMINISTIC_FIELDS, Reader, open_for_read

#: a key (attribute name or JSON key) whose name ends so records a file-system location, not content
PATH_KEY_SUFFIXES = ("_path", "_relpath", "_dir", "_file")


def is_path_key(key: str) -> bool:
    """Whether ``key`` names a recorded file-system path (see :data:`PATH_KEY_SUFFIXES`)."""
    return key.endswith(PATH_KEY_SUFFIXES)


def _without_paths(v: Any) -> tuple[Any, int]:
    """``v`` with every path key of its nested JSON objects removed, and how many were removed."""
    if isinstance(v, dict):
        out, n = {}, 0
        for k, x in v.items():
            if is_path_key(str(k)):
                n += 1
                continue
            out[k], m = _without_paths(x)
            n += m
        return out, n
    if isinstance(v, list):
        parts = [_without_paths(x) for x in v]
        return [x for x, _ in parts], sum(m for _, m in parts)
    return v, 0


@dataclass
class FileDiff:
    """Outcome of :func:`diff_files`: how many fields were compared and which differ (with a short why)."""

    n_compared: int = 0
    differences: list[tuple[str, str]] = field(default_factory=list)  # (field, what differs)
    n_paths_ignored: int = 0  # recorded paths skipped (attributes and JSON keys); 0 with paths=True

    @property
    def same(self) -> bool:
        return not self.differences

    def summary(self, a: str, b: str) -> str:
        ignored = ", ".join(NONDETERMINISTIC_FIELDS)
        if self.n_paths_ignored:
            ignored += f" and {self.n_paths_ignored} recorded paths; --paths compares them"
        if self.same:
            return f"same: {a} and {b} agree on all {self.n_compared} fields (ignoring {ignored})"
        shown = "; ".join(f"{k}: {why}" for k, why in self.differences[:3])
        more = f"; and {len(self.differences) - 3} more" if len(self.differences) > 3 else ""
        return f"different: {len(self.differences)} of {self.n_compared} fields differ: {shown}{more}"


def _objects(f: h5py.File) -> dict[str, h5py.HLObject]:
    out: dict[str, h5py.HLObject] = {"/": f}
    f.visititems(lambda name, obj: out.__setitem__(name, obj))
    return out


def _attr_value(obj: h5py.HLObject, key: str) -> Any:
    v = obj.attrs[key]
    if isinstance(v, bytes):
        v = v.decode("utf-8", "replace")
    if isinstance(v, np.generic):
        v = v.item()
    if key.endswith("_json") and isinstance(v, str):
        try:
            return json.loads(v)
        except json.JSONDecodeError:
            return v
    return v


def _equal(a: Any, b: Any) -> bool:
    if isinstance(a, np.ndarray) or isinstance(b, np.ndarray):
        a, b = np.asarray(a), np.asarray(b)
        if a.shape != b.shape or a.dtype != b.dtype:
            return False
        return bool(np.array_equal(a, b, equal_nan=a.dtype.kind in "fc"))
    if isinstance(a, float) and isinstance(b, float) and a != a and b != b:
        return True
    if isinstance(a, dict) and isinstance(b, dict):
        return a.keys() == b.keys() and all(_equal(a[k], b[k]) for k in a)
    if isinstance(a, list) and isinstance(b, list):
        return len(a) == len(b) and all(_equal(x, y) for x, y in zip(a, b))
    return type(a) is type(b) and a == b


def _short(v: Any) -> str:
    s = repr(v)
    return s if len(s) <= 40 else s[:37] + "..."


def _describe(a: Any, b: Any) -> str:
    """``a vs b``; for two JSON objects only the keys that differ."""
    if isinstance(a, dict) and isinstance(b, dict):
        keys = [k for k in sorted(set(a) | set(b)) if k not in a or k not in b or not _equal(a[k], b[k])]
        parts = [f"{k} {_short(a.get(k, '<absent>'))} vs {_short(b.get(k, '<absent>'))}" for k in keys[:2]]
        return "keys " + ", ".join(parts) + (f" (+{len(keys) - 2} more)" if len(keys) > 2 else "")
    return f"{_short(a)} vs {_short(b)}"


def _field_name(path: str, key: str | None = None) -> str:
    base = "" if path == "/" else path
    return f"{base}@{key}" if key is not None else base


def diff_files(path_a: str | os.PathLike, path_b: str | os.PathLike, *, paths: bool = False) -> FileDiff:
    """Compare two HDF5 files written by slamcli; see the module docstring for what "equal" means.

    ``paths=False`` skips recorded file-system paths (:func:`is_path_key`); ``True`` compares them too.

    Raises :class:`~slamcli.errors.SchemaError` (one line) for a missing/non-HDF5/corrupt file.
    """
    out = FileDiff()
    ignored = set(NONDETERMINISTIC_FIELDS)
    with open_for_read(path_a) as ra, open_for_read(path_b) as rb:
        objs_a, objs_b = _objects(ra.f), _objects(rb.f)
        for name in sorted(set(objs_a) | set(objs_b)):
            label = _field_name(name) or "/"
            if name not in objs_a or name not in objs_b:
                out.n_compared += 1
                if label not in ignored:
                    out.differences.append((label, f"only in {'A' if name in objs_a else 'B'}"))
                continue
            oa, ob = objs_a[name], objs_b[name]
            if isinstance(oa, h5py.Dataset) != isinstance(ob, h5py.Dataset):
                out.n_compared += 1
                out.differences.append((label, "group in one file, dataset in the other"))
                continue
            for key in sorted(set(oa.attrs) | set(ob.attrs)):
                fname = _field_name(name, key)
                if fname in ignored:
                    continue
                if not paths and is_path_key(key):
                    out.n_paths_ignored += 1
                    continue
                out.n_compared += 1
                if key not in oa.attrs or key not in ob.attrs:
                    out.differences.append((fname, f"only in {'A' if key in oa.attrs else 'B'}"))
                    continue
                va, vb = _attr_value(oa, key), _attr_value(ob, key)
                if not paths:
                    (va, na), (vb, nb) = _without_paths(va), _without_paths(vb)
                    out.n_paths_ignored += max(na, nb)
                if not _equal(va, vb):
                    out.differences.append((fname, _describe(va, vb)))
            if isinstance(oa, h5py.Dataset) and label not in ignored:
                out.n_compared += 1
                why = _dataset_difference(ra, rb, name, oa, ob)
                if why:
                    out.differences.append((label, why))
    return out


def _dataset_difference(ra: Reader, rb: Reader, name: str, oa: h5py.Dataset, ob: h5py.Dataset) -> str | None:
    if oa.shape != ob.shape:
        return f"shape {oa.shape} vs {ob.shape}"
    if oa.dtype != ob.dtype:
        return f"dtype {oa.dtype} vs {ob.dtype}"
    rank = (None,) * len(oa.shape) if oa.shape is not None else ()
    ra._check_declared(name, oa, rank)
    rb._check_declared(name, ob, rank)
    a, b = np.asarray(oa[()]), np.asarray(ob[()])
    if _equal(a, b):
        return None
    if a.dtype.kind in "fiu" and a.size:
        d = np.abs(a.astype(np.float64) - b.astype(np.float64))
        d = np.where(np.isnan(d), np.inf, d)
        k = np.unravel_index(int(np.argmax(d)), a.shape) if a.ndim else ()
        n = int(np.count_nonzero(d))
        return f"{n} of {a.size} values differ, max |Δ| {float(d[k]):.3g} at {tuple(int(i) for i in k)}"
    return "values differ"
