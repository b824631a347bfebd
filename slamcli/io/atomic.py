"""Atomic file creation: write under a temporary name in the destination directory, then ``os.replace``.

A reader (or a sweep coordinator) therefore sees either no file or a complete one, never a half-written
HDF5 file; if writing fails, the temporary file is removed and nothing is left behind.

Temporary names are ``.<name>.tmp-<pid>-<8 hex>``. A process killed with ``kill -9`` cannot remove its
temporary file, so every atomic write first removes the temporaries of *dead* processes in its destination
directory (:func:`clean_stale_temporaries`); those of live processes are never touched.
"""

from __future__ import annotations

import contextlib
import errno
import os
import re
import shutil
import uuid
from collections.abc import Iterator
from pathlib import Path

from slamcli.errors import SlamcliError

#: head-room kept free when checking a write of n bytes against the free space (metadata, the directory entry)
FREE_SPACE_MARGIN = 4096

#: errno values of a write that failed because of the medium: a full disk or quota, a file beyond
#: RLIMIT_FSIZE or the file system's size limit, an I/O error, a read-only file system
WRITE_FAULTS = frozenset({errno.ENOSPC, errno.EDQUOT, errno.EFBIG, errno.EIO, errno.EROFS})

_TMP_RE = re.compile(r"^\..*\.tmp-(\d+)-[0-9a-f]{8}$")


def _name_max(directory: Path) -> int:
    try:
        return int(os.pathconf(directory, "PC_NAME_MAX"))
    except (OSError, ValueError):
        return 255


def pid_alive(pid: int) -> bool:
    """Whether a process with this pid exists (on this host)."""
    if pid <= 0:
        return False
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True  # exists, owned by another user
    return True


def clean_stale_temporaries(directory: str | os.PathLike) -> int:
    """Remove ``.<name>.tmp-<pid>-<hex>`` files/folders in ``directory`` whose process no longer exists.

    Returns how many were removed. Errors (a vanished entry, no permission) are ignored: cleaning is best
    effort and must never make a write fail.
    """
    d = Path(directory)
    n = 0
    try:
        entries = list(os.scandir(d))
    except OSError:
        return 0
    for e in entries:
        m = _TMP_RE.match(e.name)
        if not m or int(m.group(1)) == os.getpid() or pid_alive(int(m.group(1))):
            continue
        try:
            if e.is_dir(follow_symlinks=False):
                shutil.rmtree(e.path)
            else:
                os.unlink(e.path)
            n += 1
        except OSError:
            pass
    return n


def temporary_sibling(path: str | os.PathLike) -> Path:
    """``.<name>.tmp-<pid>-<hex>`` beside ``path`` (the name shortened when it would exceed NAME_MAX).

    Raises a one-line :class:`SlamcliError` when the final name itself is too long for the file system.
    """
    final = Path(path)
    limit = _name_max(final.parent if final.parent.is_dir() else Path("."))
    size = len(os.fsencode(final.name))
    if size > limit:
        raise SlamcliError(f"{final}: file name too long ({size} bytes, the file system allows {limit})")
    suffix = f".tmp-{os.getpid()}-{uuid.uuid4().hex[:8]}"
    stem = os.fsencode(final.name)[: max(1, limit - len(suffix) - 1)]
    return final.with_name("." + os.fsdecode(stem) + suffix)


@contextlib.contextmanager
def atomic_path(path: str | os.PathLike) -> Iterator[Path]:
    """Yield a temporary path next to ``path``; on clean exit rename it onto ``path`` atomically.

    The temporary file lives in the same directory (``os.replace`` is only atomic within one file system).
    The parent directory is created when missing; stale temporaries of dead processes there are removed. On
    any exception the temporary file is deleted and the exception propagates; an existing file at ``path``
    is left untouched.
    """
    final = Path(path)
    final.parent.mkdir(parents=True, exist_ok=True)
    clean_stale_temporaries(final.parent)
    tmp = temporary_sibling(final)
    try:
        yield tmp
        os.replace(tmp, final)
    except BaseException as exc:
        with contextlib.suppress(FileNotFoundError, IsADirectoryError, NotADirectoryError):
            tmp.unlink()
        if isinstance(exc, OSError) and exc.errno in WRITE_FAULTS:  # name the file the user asked for
            raise SlamcliError(write_fault_message(final, exc)) from None
        raise


@contextlib.contextmanager
def atomic_files(paths: list[Path]) -> Iterator[list[Path]]:
    """Yield one temporary sibling per path of ``paths``; on clean exit all are renamed into place together.

    Several outputs written as one: a failure while any of them is written (a full disk on the third of four
    tables) removes every temporary and leaves every ``path`` as it was — never some new files beside old
    ones. Write faults become one line naming the file, as in :func:`atomic_path`.
    """
    finals = [Path(p) for p in paths]
    for folder in {f.parent for f in finals}:
        folder.mkdir(parents=True, exist_ok=True)
        clean_stale_temporaries(folder)
    tmps: list[Path] = []
    try:
        tmps.extend(temporary_sibling(f) for f in finals)
        yield tmps
        for tmp, final in zip(tmps, finals):
            os.replace(tmp, final)
    except BaseException as exc:
        for tmp in tmps:
            with contextlib.suppress(FileNotFoundError, IsADirectoryError, NotADirectoryError):
                tmp.unlink()
        if isinstance(exc, OSError) and exc.errno in WRITE_FAULTS:
            where = next((f for t, f in zip(tmps, finals) if exc.filename in (str(t), t)), finals[0])
            raise SlamcliError(write_fault_message(where, exc)) from None
        raise


@contextlib.contextmanager
def atomic_folder(path: str | os.PathLike) -> Iterator[Path]:
    """Yield a temporary folder next to ``path``; on clean exit it *becomes* ``path``.

    An existing folder at ``path`` is moved aside (``.<name>.tmp-<pid>-<hex>``), the new one renamed into
    place and the old one removed, so ``path`` never mixes files of two runs: a crash leaves the previous
    folder, or (between the two renames) none. On an exception the temporary folder is removed.
    """
    final = Path(path)
    if final.is_symlink() or (final.exists() and not final.is_dir()):
        raise SlamcliError(f"{final}: exists and is not a folder")
    final.parent.mkdir(parents=True, exist_ok=True)
    clean_stale_temporaries(final.parent)
    tmp = temporary_sibling(final)
    tmp.mkdir()
    try:
        yield tmp
        old = None
        if final.exists():
            old = temporary_sibling(final)
            os.rename(final, old)
        os.rename(tmp, final)
        if old is not None:
            shutil.rmtree(old, ignore_errors=True)
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise


def check_free_space(path: str | os.PathLike, n_bytes: int) -> None:
    """Refuse (one line naming ``path``) a write of ``n_bytes`` that cannot fit in its folder's free space.

    The check is advisory (another process may fill the disk in between); :func:`write_bytes_atomic` still
    handles ENOSPC. File systems that do not report free space are not checked.
    """
    final = Path(path)
    try:
        free = shutil.disk_usage(final.parent if str(final.parent) else ".").free
    except OSError:
        return
    if n_bytes + FREE_SPACE_MARGIN > free:
        raise SlamcliError(f"{final}: not enough free space ({n_bytes} bytes to write, {free} bytes free on its "
                           "file system); nothing was written")


def write_fault_message(path: str | os.PathLike, exc: OSError) -> str:
    """``<path>: cannot write file (No space left on device)``: one line for a failed write."""
    why = exc.strerror or os.strerror(exc.errno or 0) or type(exc).__name__
    return f"{path}: cannot write file ({why}); nothing was written"


def write_bytes_atomic(path: str | os.PathLike, data: bytes | memoryview) -> Path:
    """Write ``data`` to ``path`` through a temporary sibling (:func:`atomic_path`), after a free-space check.

    A full disk, a file-size limit, an I/O error (or any other operating-system error) become one :class:`SlamcliError` naming ``path``; the
    temporary is removed and an existing file at ``path`` is left as it was.
    """
    final = Path(path)
    view = memoryview(data)
    check_free_space(final, view.nbytes)
    try:
        with atomic_path(final) as tmp:
            fd = os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o644)
            try:
                while view.nbytes:  # os.write may write less than asked (a signal, a pipe)
                    view = view[os.write(fd, view):]
                # no fsync: slow per file (thousands of writes in the tests, benchmarks/results/design_notes.md); ext4
                # reserves blocks at write(), so a full disk fails here, and it flushes a file renamed over
                # another (auto_da_alloc)
            finally:
                os.close(fd)
    except OSError as exc:  # a full disk, EIO, a parent that is a file, no permission: one line
        raise SlamcliError(write_fault_message(final, exc)) from None
    return final
