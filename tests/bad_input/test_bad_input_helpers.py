"""Helpers of the bad-input tests (no tests here): a fork server that runs CLI invocations and measures them,
and functions that damage a valid ``slamcli simulate`` / ``solve`` output with h5py.

``CliServer`` starts ONE fresh Python process that imports slamcli's CLI and its heavy dependencies once;
each invocation is a ``fork()`` of it, so a case costs milliseconds instead of a full interpreter start, and
``os.wait4`` returns the child's own ``resource.struct_rusage`` (peak RSS ``ru_maxrss``, KiB on Linux).
Every child also gets an address-space limit (its inherited size + 1.5 GiB): a memory-bomb regression fails
its case with a MemoryError traceback instead of taking the CI machine down.
"""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

import h5py
import numpy as np

SERVER = r'''
import io, json, os, resource, sys, traceback
import numpy, h5py, pandas, scipy.sparse, matplotlib
matplotlib.use("Agg")
import matplotlib.pyplot
import rich.console, rich.table, rich.progress
from slamcli.cli import app
import slamcli.api.evaluate, slamcli.api.simulate, slamcli.api.solve, slamcli.metrics.summary, slamcli.plots.maps
import slamcli.plots.curves, slamcli.sim, slamcli.sweep.runner, slamcli.sweep.expand, slamcli.datasets.mrclam
import slamcli.datasets.g2o, slamcli.io.diff
from slamcli.solvers import registry
for _info in registry.available():
    registry.load(_info.name)

def vm_bytes():
    for line in open("/proc/self/status"):
        if line.startswith("VmSize:"):
            return int(line.split()[1]) * 1024
    return 0

for line in sys.stdin:
    req = json.loads(line)
    out_path, err_path = req["stdout"], req["stderr"]
    pid = os.fork()
    if pid == 0:
        code = 99
        try:
            os.chdir(req["cwd"])
            fo = os.open(out_path, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o644)
            fe = os.open(err_path, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o644)
            os.dup2(fo, 1); os.dup2(fe, 2)
            sys.stdout = io.TextIOWrapper(os.fdopen(1, "wb", closefd=False), encoding="utf-8", line_buffering=True)
            sys.stderr = io.TextIOWrapper(os.fdopen(2, "wb", closefd=False), encoding="utf-8", line_buffering=True)
            limit = vm_bytes() + 1536 * 2**20
            resource.setrlimit(resource.RLIMIT_AS, (limit, limit))
            if req.get("fsize"):  # a size-limited file: writes beyond it fail with EFBIG (SIGXFSZ is ignored)
                resource.setrlimit(resource.RLIMIT_FSIZE, (req["fsize"], req["fsize"]))
            os.environ.update(req.get("env") or {})
            args = [os.fsdecode(os.fsencode(a)) if isinstance(a, str) else a for a in req["args"]]
            try:
                app(args=args, prog_name="slamcli", standalone_mode=True)
                code = 0
            except SystemExit as exc:
                code = exc.code if isinstance(exc.code, int) else (0 if exc.code is None else 1)
            except BaseException:
                traceback.print_exc()
                code = 1
            sys.stdout.flush(); sys.stderr.flush()
        finally:
            os._exit(code)
    _, status, ru = os.wait4(pid, 0)
    code = os.waitstatus_to_exitcode(status)
    print(json.dumps({"code": code, "maxrss_kb": ru.ru_maxrss}), flush=True)
'''


class CliServer:
    """``run(args, cwd)`` → dict(code, stdout, stderr, maxrss_mb); see the module docstring."""

    def __init__(self, workdir: Path) -> None:
        self.workdir = Path(workdir)
        env = dict(os.environ, MPLBACKEND="Agg", COLUMNS="200", OMP_NUM_THREADS="1", OPENBLAS_NUM_THREADS="1")
        self.proc = subprocess.Popen([sys.executable, "-c", SERVER], stdin=subprocess.PIPE, stdout=subprocess.PIPE,
                                     text=True, env=env)
        self.n = 0

    def run(self, args: list[str], cwd: Path, fsize: int | None = None, env: dict | None = None) -> dict:
        """``fsize``: RLIMIT_FSIZE of the child, bytes (None = unlimited); ``env``: variables set in the child."""
        self.n += 1
        out, err = self.workdir / f"case{self.n}.out", self.workdir / f"case{self.n}.err"
        # non-UTF-8 file names travel as surrogate escapes: JSON keeps the lone surrogates as \udcxx
        req = {"args": list(map(str, args)), "cwd": str(cwd), "stdout": str(out), "stderr": str(err),
               "fsize": fsize, "env": env}
        self.proc.stdin.write(json.dumps(req) + "\n")
        self.proc.stdin.flush()
        line = self.proc.stdout.readline()
        if not line:
            raise RuntimeError("CLI fork server died")
        rep = json.loads(line)
        return {"code": rep["code"], "maxrss_mb": rep["maxrss_kb"] / 1024.0,
                "stdout": out.read_bytes().decode("utf-8", "replace"),
                "stderr": err.read_bytes().decode("utf-8", "replace")}

    def close(self) -> None:
        if self.proc.poll() is None:
            self.proc.stdin.close()
            self.proc.wait(timeout=30)


# -- damaging valid files --------------------------------------------------------------------------------------


def damaged(src: Path, dst: Path, edit) -> Path:
    """Copy ``src`` to ``dst`` and apply ``edit(h5py.File)`` to the copy."""
    shutil.copyfile(src, dst)
    with h5py.File(dst, "r+") as f:
        edit(f)
    return dst


def replace(f: h5py.File, name: str, data, **kw) -> None:
    """Replace dataset ``name`` by ``data`` (any dtype/shape), keeping nothing of the old one."""
    del f[name]
    f.create_dataset(name, data=data, **kw)


def forge_rows(f: h5py.File, name: str, rows: int, dtype="f8", cols: tuple[int, ...] = ()) -> None:
    """Replace ``name`` by a chunked, compressed dataset that *declares* ``rows`` rows but stores no chunk:
    a 100 kB file claiming gigabytes (unwritten chunks read back as fill values)."""
    del f[name]
    f.create_dataset(name, shape=(rows, *cols), dtype=dtype, chunks=(min(rows, 16384), *cols), compression="gzip")


def set_attr(f: h5py.File, key: str, value, obj: str = "/") -> None:
    f[obj].attrs[key] = value


def flip_chunk_bytes(path: Path, name: str) -> None:
    """Corrupt the first stored chunk of dataset ``name`` on disk (Fletcher-32 must catch it)."""
    with h5py.File(path, "r") as f:
        info = f[name].id.get_chunk_info(0)
        offset, size = info.byte_offset, info.size
    with open(path, "r+b") as fh:
        fh.seek(offset + size // 2)
        b = fh.read(8)
        fh.seek(offset + size // 2)
        fh.write(bytes(x ^ 0xFF for x in b))


def dead_pid() -> int:
    """The pid of a process that has exited (and been reaped)."""
    p = subprocess.Popen([sys.executable, "-c", "pass"])
    p.wait()
    return p.pid


def mrclam_copy(src: Path, dst: Path, edit_measurement=None) -> Path:
    """Copy the MRCLAM excerpt; ``edit_measurement(lines) -> lines`` edits Robot1_Measurement.dat."""
    shutil.copytree(src, dst)
    if edit_measurement is not None:
        p = dst / "Robot1_Measurement.dat"
        lines = p.read_text().splitlines()
        p.write_text("\n".join(edit_measurement(lines)) + "\n")
    return dst


def first_data_line(lines: list[str]) -> int:
    return next(i for i, s in enumerate(lines) if s.strip() and not s.lstrip().startswith("#"))


def np_uint64_max() -> np.ndarray:
    return np.array([np.iinfo(np.uint64).max], dtype=np.uint64)
