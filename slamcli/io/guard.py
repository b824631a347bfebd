"""The output guard: one check, run by every command that writes, before any work is done.

An atomic write (temporary sibling + ``os.replace``) replaces whatever is at the output path, so a wrong
``-o`` loses data without a trace. :func:`guard_output` refuses, with one line naming the option and the
path (:class:`OutputRefused`, exit status 2):

* an output that resolves (after symlinks, ``os.path.samefile``) to one of the command's inputs, or to an
  existing file inside an input folder (``import mrclam DIR -o DIR/Robot1_Odometry.dat``) unless it is a
  previous output of the same ``kind``;
* a folder output that *is* an input folder, or that holds an input when the command replaces the folder
  as a whole (``evaluate R.h5 -o .`` would move the folder with ``R.h5`` in it aside and delete it);
* an output that exists and is not a regular file (a character device such as ``/dev/null``, a FIFO, a
  socket): the rename would replace the device node by a regular file;
* an output inside the results folder of a running sweep (its ``.sweep.lock`` is held);
* with ``kind`` set, an existing file that is not a slamcli file of that kind (a result written over a
  dataset, a dataset over a text file); ``force=True`` replaces it anyway. Overwriting a previous output of
  the same kind is allowed: re-running a command is the point.
"""

from __future__ import annotations

import os
import stat
from collections.abc import Iterable
from pathlib import Path

from slamcli.errors import SlamcliError

#: name of the lock file a running sweep holds in its results folder (slamcli.sweep.runner.LOCK_NAME)
SWEEP_LOCK_NAME = ".sweep.lock"


class OutputRefused(SlamcliError):
    """An output path the guard refuses; the CLI exits with status 2 (a usage error, nothing was done)."""

    exit_code = 2


def _real(path: Path) -> Path:
    return Path(os.path.realpath(path))


def _inside(child: Path, folder: Path) -> bool:
    return child == folder or folder in child.parents


def _same(a: Path, b: Path) -> bool:
    try:
        return os.path.samefile(a, b)
    except OSError:
        return False


def _sweep_lock_holder(path: Path) -> Path | None:
    """The results folder of a running sweep that contains ``path`` (its lock is held), else None."""
    for folder in (path, *path.parents):
        lock = folder / SWEEP_LOCK_NAME
        if lock.is_file() and _is_held(lock):
            return folder
    return None


def _is_held(lock: Path) -> bool:
    """Whether another process holds the sweep lock file ``lock`` (a probe: taken and given back at once)."""
    from filelock import FileLock, Timeout

    probe = FileLock(lock, timeout=0)
    try:
        probe.acquire()
    except Timeout:
        return True
    except OSError:  # cannot even open it (permissions): not a lock this user's sweep holds
        return False
    probe.release()
    return False


def file_kind(path: Path) -> str | None:
    """``"dataset"`` / ``"result"`` for a slamcli HDF5 file (its ``schema`` attribute), else None."""
    from slamcli.io.schema import open_h5

    try:
        with open_h5(path) as f:
            schema = f.attrs.get("schema")
    except (SlamcliError, OSError, RuntimeError):
        return None
    schema = schema.decode() if isinstance(schema, bytes) else str(schema)
    return {"slamcli.dataset": "dataset", "slamcli.result": "result"}.get(schema)


def guard_output(out: str | os.PathLike, inputs: Iterable[str | os.PathLike | None] = (), *,
                 folder: bool = False, replaces_folder: bool = False, option: str = "-o",
                 kind: str | None = None, force: bool = False) -> None:
    """Refuse ``out`` (raise :class:`OutputRefused`) when writing it could destroy data; see the module doc.

    Parameters
    ----------
    out : the file (or, with ``folder``, the folder) the command will write.
    inputs : every file and folder the command reads (None entries are skipped).
    folder : ``out`` is a folder the command writes into.
    replaces_folder : the command replaces ``out`` as a whole (an input anywhere inside it is refused).
    option : the option's name for the message (``-o``, ``--out``, ``--solo-dir``).
    kind : ``"dataset"`` or ``"result"``: an existing ``out`` must be a slamcli file of this kind.
    force : allow replacing an existing file of another kind (``kind`` check only).
    """
    p = Path(out)
    real = _real(p)
    where = f"{option} {p}"
    if os.path.lexists(p) and p.exists():
        mode = os.stat(p).st_mode
        if not folder and not stat.S_ISREG(mode) and not stat.S_ISDIR(mode):
            raise OutputRefused(f"{where}: exists and is not a regular file (a device, FIFO or socket); "
                                "refusing to replace it")
    for q in (Path(i) for i in inputs if i is not None):
        if not q.exists():
            continue
        rq = _real(q)
        if _same(p, q) or real == rq:
            raise OutputRefused(f"{where}: is the input {q}; refusing to overwrite an input")
        if q.is_dir() and not folder and _inside(real, rq) and p.exists() and not (kind and file_kind(p) == kind):
            # (a previous output of the same kind inside the folder, e.g. DIR/robot1.h5, may be replaced)
            raise OutputRefused(f"{where}: is a file inside the input folder {q}; refusing to overwrite it")
        if folder and replaces_folder and _inside(rq, real):
            raise OutputRefused(f"{where}: contains the input {q}, and the folder is replaced as a whole")
    holder = _sweep_lock_holder(real if folder else real.parent)
    if holder is not None:
        raise OutputRefused(f"{where}: is inside {holder}, the results folder of a running sweep; "
                            "wait for it to finish or write elsewhere")
    if kind is not None and not force and p.is_file() and p.stat().st_size > 0:
        found = file_kind(p)
        if found != kind:
            what = f"a slamcli {found}" if found else "not a slamcli file"
            raise OutputRefused(f"{where}: exists and is {what}, not a {kind}; --force replaces it")
