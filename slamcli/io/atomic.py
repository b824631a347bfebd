"""Atomic file creation: write under a temporary name in the destination directory, then ``os.replace``.

A reader (or a sweep coordinator) therefore sees either no file or a complete one, never a half-written
HDF5 file; if writing fails, the temporary file is removed and nothing is left behind.
"""

from __future__ import annotations

import contextlib
import os
import uuid
from collections.abc import Iterator
from pathlib import Path


@contextlib.contextmanager
def atomic_path(path: str | os.PathLike) -> Iterator[Path]:
    """Yield a temporary path next to ``path``; on clean exit rename it onto ``path`` atomically.

    The temporary file lives in the same directory (``os.replace`` is only atomic within one file system).
    The parent directory is created when missing. On any exception the temporary file is deleted and the
    exception propagates; an existing file at ``path`` is left untouched.
    """
    final = Path(path)
    final.parent.mkdir(parents=True, exist_ok=True)
    tmp = final.with_name(f".{final.name}.tmp-{os.getpid()}-{uuid.uuid4().hex[:8]}")
    try:
        yield tmp
        os.replace(tmp, final)
    except BaseException:
        with contextlib.suppress(FileNotFoundError):
            tmp.unlink()
        raise
