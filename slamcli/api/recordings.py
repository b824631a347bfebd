"""Datasets that are not simulated: recordings and graphs imported once into a content-addressed cache, and
existing dataset files.

The cache is ``<data folder>/imported/<key>.h5`` (the data folder of
:func:`slamcli.datasets.registry.data_dir`: ``$SLAMCLI_DATA_DIR`` or the per-user cache), shared by every
sweep on the machine. ``<key>`` is the caller's content hash of the importer version, the options and the
source's sha256 (:func:`source_sha256`), so a changed recording, option or importer gives a new file;
``<key>.json`` records what went in, the file's sha256 (a file that no longer matches is imported again) and
the dataset's reference kind (:func:`reference_kind`).
"""

from __future__ import annotations

import os
import shutil
from pathlib import Path
from typing import Any

#: what a dataset can be evaluated against: full ground truth, a position-only reference, or nothing
REFERENCE_KINDS = ("truth", "gps", "none")


def source_sha256(path: str | os.PathLike) -> str:
    """sha256 of an importer's input: the file itself, or for a folder the sha256 of the sorted lines
    ``<name> <sha256>`` of its regular files (not recursive; hidden files skipped)."""
    import hashlib

    from slamcli.datasets.registry import sha256_of

    p = Path(path)
    if p.is_file():
        return sha256_of(p)
    lines = "".join(f"{f.name} {sha256_of(f)}\n" for f in sorted(p.iterdir())
                    if f.is_file() and not f.name.startswith("."))
    return hashlib.sha256(lines.encode()).hexdigest()


def reference_kind(dataset) -> str:
    """``truth`` (true poses), ``gps`` (a time-stamped position reference only) or ``none``."""
    t = dataset.truth
    if t is None:
        return "none"
    if t.poses_xyt is not None:
        return "truth"
    return "gps" if t.ref_xy is not None else "none"


def cache_dir() -> Path:
    from slamcli.datasets.registry import data_dir

    return data_dir() / "imported"


def _link_or_copy(src: Path, dst: Path) -> None:
    try:
        os.link(src, dst)
    except OSError:
        shutil.copyfile(src, dst)


def cached_import(key: str, source: dict[str, Any], out_path: str | os.PathLike) -> dict[str, Any]:
    """Put the import of ``source`` (``importer``, ``path``, ``options``; ``cache``: the cache folder, default
    :func:`cache_dir`) at ``out_path`` (a hard link to the cache file, or a copy), importing it only when the
    cache has no valid ``<key>.h5``. Returns the cache record (``reference``, ``file_sha256``,
    ``imported_utc``, what went in)."""
    import json

    from slamcli.datasets.options import import_recording
    from slamcli.datasets.registry import sha256_of
    from slamcli.io import write_dataset
    from slamcli.io.schema import utc_now, write_json

    cache = Path(source["cache"]) if source.get("cache") else cache_dir()
    cache.mkdir(parents=True, exist_ok=True)
    target, sidecar = cache / f"{key}.h5", cache / f"{key}.json"
    try:
        rec = json.loads(sidecar.read_text(encoding="utf-8"))
    except (OSError, ValueError):
        rec = None
    if not (isinstance(rec, dict) and target.is_file() and rec.get("file_sha256") == sha256_of(target)):
        ds = import_recording(source["importer"], source["path"], source["options"])
        write_dataset(target, ds)
        rec = {"key": key, **{k: v for k, v in source.items() if k not in ("path", "cache")},
               "file_sha256": sha256_of(target),
               "reference": reference_kind(ds), "imported_utc": utc_now()}
        write_json(sidecar, rec)
    _link_or_copy(target, Path(out_path))
    return rec


def prepare_dataset(kind: str, key: str, source: dict[str, Any], out_path: str | os.PathLike) -> dict[str, Any]:
    """Write the dataset of a non-simulated experiment entry to ``out_path``: an imported recording or graph
    (:func:`cached_import`), or a copy of an existing dataset file (``kind == "file"``). Returns at least
    ``{"reference": kind of reference}``."""
    if kind != "file":
        return cached_import(key, source, out_path)
    from slamcli.io import read_dataset

    shutil.copyfile(source["path"], out_path)  # a copy: the user's file may change after the sweep
    return {"reference": reference_kind(read_dataset(out_path))}
