"""Shared pieces of the slamcli HDF5 schemas: names, versions, JSON attributes and a validating reader.

Every schema violation becomes a :class:`~slamcli.errors.SchemaError` with ONE line of the form
``<file>: <group/field>: <what is wrong>``. See ``docs/schema.md`` for the full layout.
"""

from __future__ import annotations

import contextlib
import datetime as _dt
import itertools
import json
import math
import os
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import h5py
import numpy as np

from slamcli.errors import SchemaError, SlamcliError
from slamcli.io.atomic import write_bytes_atomic

DATASET_SCHEMA = "slamcli.dataset"
RESULT_SCHEMA = "slamcli.result"
SCHEMA_VERSION = 1

#: compression for every non-scalar, non-empty dataset: portable gzip + byte shuffle. Level 1, chosen by
#: measurement (docs/schema.md "Compression"; benchmarks/results/design_notes.md); lzf is faster but only
#: h5py reads it.
#: Files written with any level (v1 used 4) read the same: HDF5 records the filter per dataset.
GZIP_LEVEL = 1
#: chunk length along the first (time / row) axis (chosen by measurement: benchmarks/results/design_notes.md)
CHUNK_ROWS = 16384
#: the h5py filter arguments of every compressed dataset (the one place they are set)
COMPRESSION: dict[str, Any] = {"compression": "gzip", "compression_opts": GZIP_LEVEL, "shuffle": True,
                               "fletcher32": True}
#: The only fields of a dataset/result file that differ between two runs with the same inputs and seed:
#: the creation time and the wall-clock timings (docs/schema.md, "Timings"). ``slamcli diff`` ignores exactly
#: these; every other attribute and array must be bit-identical for the same seed.
NONDETERMINISTIC_FIELDS = ("@created_utc", "@wall_time_s", "@timings_json", "trace/time_s")
#: sane bound on the element count of one stored array, checked on the *declared* shape before anything is
#: read (5·10⁷ float64 = 400 MB; a 10 Hz run of 10⁷ steps stays far below it with its (T+1,3) poses).
MAX_ELEMENTS = 50_000_000
#: sane bound on the number of poses (T+1) of a dataset/result (10⁷ steps = 11.6 days at 10 Hz).
MAX_POSES = 10_000_001


def json_default(obj: Any) -> Any:
    """``json.dumps`` fallback for numpy scalars/arrays, enums, paths and tuples-in-dataclasses."""
    if isinstance(obj, np.ndarray):
        return obj.tolist()
    if isinstance(obj, np.generic):
        return obj.item()
    if hasattr(obj, "value") and not isinstance(obj, (int, float, str, bool)):  # enum.Enum
        return obj.value
    if isinstance(obj, os.PathLike):
        return os.fspath(obj)
    raise TypeError(f"{type(obj).__name__} is not JSON serialisable")


def to_json(obj: Any) -> str:
    """Canonical JSON (sorted keys); ``inf``/``nan`` floats are kept (Python's json extension)."""
    return json.dumps(obj, sort_keys=True, default=json_default)


def utc_now() -> str:
    """The current UTC time to the second, ``YYYY-MM-DDTHH:MM:SSZ`` (the one time format of files and runs)."""
    return _dt.datetime.now(_dt.UTC).strftime("%Y-%m-%dT%H:%M:%SZ")


def write_json(path: str | os.PathLike, obj: Any) -> None:
    """Write ``obj`` as a JSON text file (indent 2, sorted keys, :func:`json_default` — unknown types raise
    ``TypeError`` — ``inf``/``nan`` kept, final newline) under a temporary name, renamed onto ``path``
    atomically (:func:`~slamcli.io.atomic.write_bytes_atomic`: a full disk is one line naming ``path``, the
    temporary removed; on any error ``path`` is left as it was)."""
    text = json.dumps(obj, indent=2, sort_keys=True, default=json_default, allow_nan=True) + "\n"
    write_bytes_atomic(path, text.encode())


def attr_text(value: Any) -> str:
    """``str(value)`` as a valid UTF-8 attribute string: a file name's undecodable bytes (``\\udcNN``
    surrogates, which HDF5 cannot store) kept as the visible escape ``\\udcNN``."""
    return str(value).encode("utf-8", "backslashreplace").decode("utf-8")


def write_array(group: h5py.Group, name: str, data: np.ndarray, *, units: str, frame: str, doc: str) -> None:
    """Write one dataset with ``units``/``frame``/``doc`` attributes; gzip+shuffle, chunked along axis 0."""
    data = np.asarray(data)
    if data.ndim:
        data = np.ascontiguousarray(data)  # (ascontiguousarray would turn a scalar into shape (1,))
    kwargs: dict[str, Any] = {}
    if data.ndim >= 1 and data.size > 0:
        chunks = (min(data.shape[0], CHUNK_ROWS),) + data.shape[1:]
        kwargs = {"chunks": chunks, **COMPRESSION}
    ds = group.create_dataset(name, data=data, **kwargs)
    ds.attrs["units"] = units
    ds.attrs["frame"] = frame
    ds.attrs["doc"] = doc


@contextlib.contextmanager
def create_h5(path: str | os.PathLike, check: Callable[[h5py.File], None] | None = None) -> Iterator[h5py.File]:
    """Open a new HDF5 file for writing at ``path`` atomically (see :func:`~slamcli.io.atomic.atomic_path`).

    The file is built in memory (HDF5's ``core`` driver, no backing store) and its image written in one
    piece by :func:`~slamcli.io.atomic.write_bytes_atomic`: a full disk or an I/O error then fails in plain
    Python (one line naming the file, the temporary removed) instead of inside HDF5's close, where h5py
    raised and then crashed the interpreter at exit (exit 139) when it closed the file a second time.
    ``check(f)``, when given, reads the finished in-memory file first; whatever it raises leaves ``path`` as
    it was.
    """
    if Path(path).is_dir():
        raise SlamcliError(f"{path}: is a directory, expected a file name")
    name = f"slamcli-{os.getpid()}-{id(path):x}-{next(_CORE_IDS)}.h5"  # unique per open in-memory file
    try:
        f = h5py.File(name, "w", driver="core", backing_store=False)
        try:
            yield f
            f.flush()
            if check is not None:
                check(f)
            image = f.id.get_file_image()
        finally:
            f.close()
    except OSError as exc:  # raised by HDF5 while building the image (nothing is on disk yet)
        raise SlamcliError(f"{path}: cannot write file ({_one_line(exc)})") from None
    write_bytes_atomic(path, image)


_CORE_IDS = itertools.count()


def check_path(path: str | os.PathLike) -> Path:
    """Raise a one-line SchemaError for a missing path, a directory, or a non-HDF5 file."""
    p = Path(path)
    if not p.exists():
        raise SchemaError(f"{p}: no such file")
    if p.is_dir():
        raise SchemaError(f"{p}: is a directory, expected an HDF5 file")
    if not p.is_file():  # a FIFO or a device: opening it could block forever
        raise SchemaError(f"{p}: not a regular file (a FIFO, socket or device), expected an HDF5 file")
    try:
        ok = h5py.is_hdf5(str(p))
    except OSError as exc:
        raise SchemaError(f"{p}: cannot read file ({_one_line(exc)})") from None
    if not ok:
        raise SchemaError(f"{p}: not an HDF5 file")
    return p


def _one_line(exc: BaseException) -> str:
    s = str(exc).strip().splitlines()
    return (s[0] if s else type(exc).__name__)[:200]


class Reader:
    """Validating accessor over an open HDF5 file; every failure names the file and the field."""

    def __init__(self, f: h5py.File, path: Path) -> None:
        self.f = f
        self.path = path

    def fail(self, where: str, what: str) -> SchemaError:
        return SchemaError(f"{self.path}: {where}: {what}")

    # -- attributes ---------------------------------------------------------------------------------
    def attr(self, obj_path: str, key: str, kind: type | tuple[type, ...], *, default: Any = ...) -> Any:
        obj = self.group(obj_path) if obj_path != "/" else self.f
        where = f"{obj_path.rstrip('/')}@{key}" if obj_path != "/" else f"@{key}"
        if key not in obj.attrs:
            if default is not ...:
                return default
            raise self.fail(where, "missing attribute")
        try:
            v = obj.attrs[key]
        except Exception as exc:  # noqa: BLE001 - corrupt attribute storage
            raise self.fail(where, f"unreadable attribute ({_one_line(exc)})") from None
        if isinstance(v, bytes):
            v = v.decode("utf-8", "replace")
        if isinstance(v, np.generic):
            v = v.item()
        if kind is float and isinstance(v, int) and not isinstance(v, bool):
            v = float(v)
        if not isinstance(v, kind) or (isinstance(v, bool) and kind in (int, float)):
            want = kind.__name__ if isinstance(kind, type) else "/".join(k.__name__ for k in kind)
            raise self.fail(where, f"expected {want}, got {type(v).__name__} {v!r}"[:200])
        return v

    def json_attr(self, obj_path: str, key: str, *, default: Any = ...) -> Any:
        if default is ...:
            text = self.attr(obj_path, key, str)
        else:
            text = self.attr(obj_path, key, str, default=None)
            if text is None:
                return default
        where = f"@{key}" if obj_path == "/" else f"{obj_path}@{key}"
        try:
            return json.loads(text)
        except json.JSONDecodeError as exc:
            raise self.fail(where, f"invalid JSON ({exc.msg} at char {exc.pos})") from None

    def finite_attr(self, obj_path: str, key: str, *, positive: bool = False, allow_inf: bool = False) -> float:
        v = self.attr(obj_path, key, float)
        where = f"@{key}" if obj_path == "/" else f"{obj_path}@{key}"
        if math.isnan(v) or (math.isinf(v) and not allow_inf):
            raise self.fail(where, f"must be finite, got {v}")
        if positive and not v > 0:
            raise self.fail(where, f"must be > 0, got {v}")
        return v

    def check_schema(self, expected: str) -> None:
        schema = self.attr("/", "schema", str)
        if schema != expected:
            raise self.fail("@schema", f"expected {expected!r}, got {schema!r}")
        version = self.attr("/", "schema_version", int)
        if version != SCHEMA_VERSION:
            raise self.fail(
                "@schema_version", f"unsupported version {version} (this slamcli reads version {SCHEMA_VERSION})"
            )

    # -- groups / datasets --------------------------------------------------------------------------
    def has(self, name: str) -> bool:
        try:
            return name in self.f
        except Exception:  # noqa: BLE001
            return False

    def group(self, name: str) -> h5py.Group:
        try:
            g = self.f[name]
        except KeyError:
            raise self.fail(name, "missing group") from None
        except Exception as exc:  # noqa: BLE001
            raise self.fail(name, f"unreadable ({_one_line(exc)})") from None
        if not isinstance(g, h5py.Group):
            raise self.fail(name, "expected a group, found a dataset")
        return g

    def array(
        self,
        name: str,
        *,
        dtype: str,
        shape: tuple[int | None, ...],
        finite: bool = True,
    ) -> np.ndarray:
        """Read ``name`` fully; check kind (``"f"`` float / ``"i"`` integer), rank/shape and finiteness.

        ``shape`` entries of None are free; integers must match.
        """
        try:
            obj = self.f[name]
        except KeyError:
            raise self.fail(name, "missing dataset") from None
        except Exception as exc:  # noqa: BLE001
            raise self.fail(name, f"unreadable ({_one_line(exc)})") from None
        if not isinstance(obj, h5py.Dataset):
            raise self.fail(name, "expected a dataset, found a group")
        self._check_declared(name, obj, shape)
        try:
            data = obj[()]
        except Exception as exc:  # noqa: BLE001 - truncated/corrupt chunks surface here
            raise self.fail(name, f"unreadable data, file truncated or corrupt ({_one_line(exc)})") from None
        data = np.asarray(data)
        kind = data.dtype.kind
        if dtype == "f" and kind != "f":
            raise self.fail(name, f"expected floating-point data, got dtype {data.dtype}")
        if dtype == "i" and kind not in "iu":
            raise self.fail(name, f"expected integer data, got dtype {data.dtype}")
        if finite and kind == "f" and data.size and not np.isfinite(data).all():
            bad = np.argwhere(~np.isfinite(np.atleast_1d(data)))[0]
            idx = tuple(int(i) for i in bad)
            value = data[idx] if data.ndim else data[()]
            where = "" if not data.ndim else f" at index {idx if len(idx) > 1 else idx[0]}"
            raise self.fail(name, f"non-finite value {value}{where}")
        if kind == "u" and data.size and data.dtype.itemsize >= 8 and int(data.max()) > np.iinfo(np.int64).max:
            k = int(np.argmax(data.reshape(-1) > np.iinfo(np.int64).max))
            raise self.fail(name, f"value {int(data.reshape(-1)[k])} at index {k} does not fit in int64")
        return data

    def declared_shape(self, name: str) -> tuple[int, ...] | None:
        """Shape of dataset ``name`` as declared in the file (nothing is read); None when absent/not a dataset."""
        try:
            obj = self.f[name]
        except Exception:  # noqa: BLE001
            return None
        return tuple(int(d) for d in obj.shape) if isinstance(obj, h5py.Dataset) and obj.shape is not None else None

    def _check_declared(self, name: str, obj: h5py.Dataset, shape: tuple[int | None, ...]) -> None:
        """Rank/shape, the :data:`MAX_ELEMENTS` bound and allocated storage, all from the header (no data read).

        A forged header can declare 10⁹ rows in a 100 kB file (unwritten chunks read back as fill values); such
        a dataset is refused here instead of being materialised in memory.
        """
        dshape = obj.shape
        if dshape is None:
            raise self.fail(name, "dataset has no shape (empty dataspace)")
        if len(shape) != len(dshape) or any(s is not None and s != d for s, d in zip(shape, dshape)):
            want = "(" + ", ".join("*" if s is None else str(s) for s in shape) + ("," if len(shape) == 1 else "") + ")"
            raise self.fail(name, f"expected shape {want}, got {tuple(dshape)}")
        n = math.prod(int(d) for d in dshape)
        if n > MAX_ELEMENTS:
            raise self.fail(name, f"declares {n} elements {tuple(dshape)}, above the limit of {MAX_ELEMENTS}")
        if n == 0:
            return
        try:
            if obj.is_virtual or obj.external:
                raise self.fail(name, "external or virtual storage is not supported")
            if obj.chunks is not None:
                expected = math.prod(-(-int(d) // int(c)) for d, c in zip(dshape, obj.chunks))
                stored = obj.id.get_num_chunks()
                if stored < expected:
                    raise self.fail(name, f"declares shape {tuple(dshape)} but only {stored} of {expected} "
                                          "chunks are stored (truncated or forged header)")
            elif obj.id.get_storage_size() < n * obj.dtype.itemsize:
                raise self.fail(name, f"declares shape {tuple(dshape)} ({n * obj.dtype.itemsize} bytes) but stores "
                                      f"only {obj.id.get_storage_size()} bytes (truncated or forged header)")
        except SchemaError:
            raise
        except Exception as exc:  # noqa: BLE001 - corrupt layout messages surface here
            raise self.fail(name, f"unreadable layout ({_one_line(exc)})") from None

    def expect_len(self, name: str, data: np.ndarray, n: int, what: str) -> None:
        if data.shape[0] != n:
            raise self.fail(name, f"length {data.shape[0]} does not match {what} ({n})")


def _refuse_escapes(f: h5py.File, p: Path) -> None:
    """Raise a one-line SchemaError when ``f`` could make a read leave the file ``p``: an external link (or a
    user-defined link) anywhere in it, or a dataset with external storage or a virtual layout. Nothing is
    followed: links are listed (``H5Lvisit``, hard links only), then each dataset's creation properties read."""
    from h5py import h5l

    escapes: list[str] = []

    def check_link(name: bytes, info) -> None:
        if info.type not in (h5l.TYPE_HARD, h5l.TYPE_SOFT) and not escapes:
            escapes.append(name.decode("utf-8", "backslashreplace"))

    f.id.links.visit(check_link, info=True)
    if escapes:
        link = f.get(escapes[0], getlink=True)
        target = f" to {link.path!r} in {link.filename!r}" if isinstance(link, h5py.ExternalLink) else ""
        raise SchemaError(f"{p}: {escapes[0]}: external link{target} refused (slamcli reads only the file named)")

    def check_object(name: str, obj: Any) -> None:
        if isinstance(obj, h5py.Dataset) and not escapes and (obj.is_virtual or obj.external):
            escapes.append(name)

    f.visititems(check_object)
    if escapes:
        raise SchemaError(f"{p}: {escapes[0]}: external or virtual storage refused "
                          "(slamcli reads only the file named)")


def open_h5(path: str | os.PathLike) -> h5py.File:
    """Open the HDF5 file ``path`` read-only, refusing anything that would read another file (external links,
    external storage, virtual datasets: :func:`_refuse_escapes`); the one place slamcli opens a file it reads.
    Failures are one-line SchemaErrors naming the file."""
    p = check_path(path)
    try:
        f = h5py.File(p, "r")
    except Exception as exc:  # noqa: BLE001 - h5py raises OSError for truncated/corrupt files
        raise SchemaError(f"{p}: cannot open HDF5 file, truncated or corrupt ({_one_line(exc)})") from None
    try:
        _refuse_escapes(f, p)
    except SchemaError:
        f.close()
        raise
    except Exception as exc:  # noqa: BLE001 - corrupt link or object headers surface here
        f.close()
        raise SchemaError(f"{p}: corrupt HDF5 file ({_one_line(exc)})") from None
    return f


@contextlib.contextmanager
def open_for_read(path: str | os.PathLike) -> Iterator[Reader]:
    """Open ``path`` read-only (:func:`open_h5`) as a :class:`Reader`; low-level HDF5 failures become one-line
    SchemaErrors."""
    f = open_h5(path)
    p = Path(path)
    try:
        with f:
            yield Reader(f, p)
    except SchemaError:
        raise
    except (OSError, RuntimeError, KeyError, ValueError) as exc:
        raise SchemaError(f"{p}: corrupt HDF5 file ({_one_line(exc)})") from None
