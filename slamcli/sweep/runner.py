"""Execute an :class:`~slamcli.sweep.expand.Expansion`: resumable, fail-soft, local process pool or Dask.

On disk (``results/<experiment>/``)::

    datasets/<dataset_id>.h5 (+ .json)  one dataset per (scenario config, replicate) or imported file, shared
                                        by its runs; the JSON records its sha256 and reference
    <run_id>/config.json, dataset.h5    resolved run configuration; hard link to the shared dataset
    <run_id>/result.h5, metrics.json    solver result; scalar metrics (+ tidy CSVs of the evaluation)
    <run_id>/status.json, run.log       completed | failed, solver status, error, times, host, sha256s
    manifest.csv, results.csv/.parquet  one row per run: ids, labels, dataset, sweep point, status, metrics

* **Atomic**: a run is built in ``.<run_id>.tmp-<pid>-<rand>/`` and renamed once ``status.json`` (written last)
  is in place; datasets are written under a temporary name and ``os.replace``-d; leftovers are removed by the
  next sweep.
* **Fail-soft**: a ``failed``/``diverged`` result fails its run (not evaluated, sweep exits non-zero); other
  solver statuses are recorded as ``solver_status``. A worker that dies fails only its run.
* **Locked**: one sweep per folder (``filelock`` on ``.sweep.lock``); a second one is refused naming the pid.
  Workers exit when the coordinator is gone.
* **Resumable**: a run is skipped when its status says ``completed``, every artefact exists and every sha256
  it records (config, dataset, result, metrics, shared dataset) still matches; otherwise (or without hashes)
  it is redone. A cached dataset whose bytes changed is simulated again.
* **Parallel**: each shared dataset is made once, then its runs are submitted one task each; paths are made
  absolute in the coordinator; workers never share an open HDF5 file (``spawn`` start method); the
  coordinator reads only the JSON files.
"""

from __future__ import annotations

import concurrent.futures as cf
import contextlib
import functools
import hashlib
import json
import logging
import math
import os
import platform
import shutil
import signal
import subprocess
import threading
import time
import traceback
import uuid
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Protocol

from slamcli.errors import ConfigError, SlamcliError
from slamcli.io.atomic import write_bytes_atomic
from slamcli.io.schema import utc_now, write_json
from slamcli.sweep.expand import DatasetSpec, Expansion, RunSpec, canonical_json
from slamcli.sweep.threads import single_threaded_blas

ARTEFACTS = ("config.json", "dataset.h5", "result.h5", "metrics.json", "status.json", "run.log")
COMPLETED = "completed"
FAILED = "failed"
MISSING = "missing"
#: solver statuses (``SolverResult.status`` values) that make a run failed: no usable estimate
FAILING_SOLVER_STATUSES = ("failed", "diverged")
LOCK_NAME = ".sweep.lock"
#: the running sweep's pid, for the message that refuses a second sweep
PID_NAME = ".sweep.pid"

log = logging.getLogger(__name__)


# -- the pipeline a run executes ------------------------------------------------------------------------------


class Pipeline(Protocol):
    """What one run does; injectable so tests can exercise the runner with a trivial picklable pipeline."""

    def simulate(self, dataset: DatasetSpec, out_path: Path) -> dict[str, Any] | None:
        """Write the dataset for ``dataset`` to ``out_path`` (the runner handles atomic renaming); may return
        facts to record beside it (``{"reference": "truth" | "gps" | "none"}``)."""

    def solve(self, run: RunSpec, dataset_path: Path, result_path: Path) -> Any:
        """Solve ``dataset_path`` with the run's solver configuration, writing ``result_path``. A run with
        ``init_run`` is called with the keyword ``init_path`` too: that run's ``result.h5``, the initial estimate.

        May return the result (anything with ``status`` and ``message``) so the runner can fail the run on a
        failed solver status."""

    def evaluate(self, run: RunSpec, dataset_path: Path, result_path: Path, out_dir: Path) -> dict[str, Any]:
        """Evaluate the result; may write tidy files into ``out_dir``; returns the scalar metrics."""


class WorkflowPipeline:
    """The real pipeline: ``slamcli.api.simulate`` → ``slamcli.api.solve`` → ``slamcli.api.evaluate``."""

    def simulate(self, dataset: DatasetSpec, out_path: Path) -> dict[str, Any]:
        """Simulate the dataset, or put an imported recording / graph / dataset file there
        (:func:`slamcli.api.recordings.prepare_dataset`); returns ``{"reference": truth | gps | none, ...}``."""
        if not dataset.simulated:
            from slamcli.api.recordings import prepare_dataset

            rec = prepare_dataset(dataset.kind, dataset.dataset_id, dict(dataset.source), out_path)
            return {"reference": rec["reference"], "imported_utc": rec.get("imported_utc")}
        from slamcli.api.simulate import simulate_to_file

        simulate_to_file(
            scenario=dataset.scenario, seed=dataset.seed, overrides=dict(dataset.overrides), out_path=out_path
        )
        return {"reference": "truth"}

    def solve(self, run: RunSpec, dataset_path: Path, result_path: Path, init_path: Path | None = None) -> Any:
        from slamcli.api.solve import solve_file

        return solve_file(
            dataset_path,
            run.method,
            dict(run.param_overrides),
            result_path,
            seed=run.seed,
            oracle_association=run.oracle_association,
            init_path=init_path,
        )

    def evaluate(self, run: RunSpec, dataset_path: Path, result_path: Path, out_dir: Path) -> dict[str, Any]:
        from slamcli.api.evaluate import evaluate_files

        return dict(evaluate_files(result_path, dataset_path, out_dir, **dict(run.evaluate)))


# -- small file helpers -----------------------------------------------------------------------------------------


@functools.lru_cache(maxsize=1)
def git_revision() -> str:
    """``<short sha>`` of the slamcli checkout, ``+dirty`` when tracked files differ; "unknown" outside git."""
    here = Path(__file__).resolve().parent
    try:
        sha = subprocess.run(["git", "rev-parse", "--short", "HEAD"], cwd=here, capture_output=True, text=True,
                             timeout=5, check=False).stdout.strip()
        dirty = subprocess.run(["git", "status", "--porcelain", "--untracked-files=no"], cwd=here,
                               capture_output=True, text=True, timeout=5, check=False).stdout.strip()
    except (OSError, subprocess.SubprocessError):
        return "unknown"
    return f"{sha}{'+dirty' if dirty else ''}" if sha else "unknown"


def read_json(path: Path) -> dict[str, Any] | None:
    try:
        with path.open() as fh:
            out = json.load(fh)
        return out if isinstance(out, dict) else None
    except (OSError, ValueError):
        return None


def _link_or_copy(src: Path, dst: Path) -> None:
    try:
        os.link(src, dst)
    except OSError:
        shutil.copy2(src, dst)


def run_status(exp_dir: Path, run_id: str) -> str:
    """``completed`` (status says so and every artefact exists), ``failed``, or ``missing``."""
    d = exp_dir / run_id
    if d.is_symlink() or not d.is_dir():  # a link or a plain file in the way is not a run: redo it
        return MISSING
    st = read_json(d / "status.json")
    if st is None or st.get("run_id") != run_id:
        return MISSING
    if (st.get("status") == COMPLETED and all((d / a).exists() for a in ARTEFACTS) and _artefacts_valid(d, st)
            and _shared_dataset_valid(exp_dir, st)):
        return COMPLETED
    return FAILED if st.get("status") == FAILED else MISSING


#: artefacts whose sha256 a completed run records in status.json and a resume checks: every file a later
#: step (aggregate, plot, evaluate, export) reads. ``dataset.h5`` is a hard link to the shared
#: ``datasets/<id>.h5`` (checked by its own sidecar): a corrupted inode is caught through both names.
HASHED = ("config.json", "dataset.h5", "result.h5", "metrics.json")


def _artefacts_valid(d: Path, st: dict[str, Any]) -> bool:
    """Whether the finished run ``d`` still holds what it recorded: a hash in ``status.json`` for every
    :data:`HASHED` file, each matching the file, and ``metrics.json`` a JSON object. A run without a hash
    of one of them (written by an older slamcli) is redone, as is any run that fails here (a corrupted
    ``metrics.json`` value never reaches results.csv)."""
    recorded = st.get("sha256")
    if not isinstance(recorded, dict):
        log.warning("%s: status.json records no sha256 of its files; the run is redone", d)
        return False
    for name in HASHED:
        if recorded.get(name) is None or recorded.get(name) != _cached_sha256(d / name):
            log.warning("%s: %s does not match its recorded hash (or has none); the run is redone", d, name)
            return False
    return isinstance(read_json(d / "metrics.json"), dict)


def _shared_dataset_valid(exp_dir: Path, st: dict[str, Any]) -> bool:
    """Whether ``datasets/<dataset_id>.h5`` — the file the run's result records, which evaluate, plot and
    export read — still holds the bytes of the run's ``dataset.h5`` (as its sidecar says too)."""
    shared = exp_dir / "datasets" / f"{st.get('dataset_id')}.h5"
    rec = read_json(shared.with_suffix(".json")) or {}
    want = (st.get("sha256") or {}).get("dataset.h5")
    ok = shared.is_file() and not shared.is_symlink() and rec.get("file_sha256") == want == _cached_sha256(shared)
    if not ok:
        log.warning("%s: missing or does not match the run's dataset.h5; the run is redone", shared)
    return ok


#: (device, inode, size, mtime) → sha256 of files hashed by this process: the runs of one dataset share
#: one inode (hard links), which a resume then reads once instead of once per run
_SHA_BY_INODE: dict[tuple[int, int, int, int], str] = {}


def _cached_sha256(path: Path) -> str:
    st = os.stat(path)
    key = (st.st_dev, st.st_ino, st.st_size, st.st_mtime_ns)
    if key not in _SHA_BY_INODE:
        _SHA_BY_INODE[key] = file_sha256(path)
    return _SHA_BY_INODE[key]


def clean_temporaries(exp_dir: Path) -> int:
    """Remove leftovers of interrupted runs (hidden ``*.tmp-*`` entries); returns how many were removed."""
    n = 0
    for base in (exp_dir, exp_dir / "datasets"):
        if not base.is_dir():
            continue
        for p in base.iterdir():
            if p.name.startswith(".") and ".tmp-" in p.name:
                _remove(p)
                n += 1
    return n


def _remove(p: Path) -> None:
    """Remove a file, a symlink (never its target) or a directory tree."""
    if p.is_symlink() or not p.is_dir():
        p.unlink(missing_ok=True)
    else:
        shutil.rmtree(p, ignore_errors=True)


@contextlib.contextmanager
def sweep_lock(exp_dir: Path) -> Iterator[None]:
    """Exclusive, non-blocking lock on ``exp_dir/.sweep.lock`` for the duration of a sweep
    (:class:`filelock.FileLock`: ``flock`` on POSIX, ``LockFileEx`` on Windows); the holder's pid is in
    ``exp_dir/.sweep.pid`` while it holds the lock.

    Raises a one-line :class:`ConfigError` when another process holds it. The operating system drops the lock
    when its holder dies (even by ``kill -9``), so a crashed sweep never blocks the next one.
    """
    from filelock import FileLock, Timeout

    path, pid_path = exp_dir / LOCK_NAME, exp_dir / PID_NAME
    lock = FileLock(path, timeout=0)
    try:
        lock.acquire()
    except Timeout:
        try:
            holder = pid_path.read_text().strip() or "unknown"
        except OSError:
            holder = "unknown"
        raise ConfigError(f"{exp_dir}: another sweep (pid {holder}) is running on this results folder; "
                          "wait for it to finish or use another --out") from None
    except OSError as exc:
        raise ConfigError(f"{path}: cannot create the sweep lock ({exc.strerror})") from None
    try:
        pid_path.write_text(f"{os.getpid()}\n")
        yield
    finally:
        pid_path.unlink(missing_ok=True)  # before the release: a next holder's pid is never removed
        lock.release()


def file_sha256(path: Path) -> str:
    h = hashlib.sha256()
    with open(path, "rb") as fh:
        for block in iter(lambda: fh.read(1 << 20), b""):
            h.update(block)
    return "sha256:" + h.hexdigest()


# -- worker side ----------------------------------------------------------------------------------------------------


@contextlib.contextmanager
def _run_log(path: Path) -> Iterator[logging.Logger]:
    """Send every log record of this process to ``path`` while the run lasts."""
    handler = logging.FileHandler(path, mode="a", encoding="utf-8", errors="backslashreplace")  # (file names)
    handler.setFormatter(logging.Formatter("%(asctime)s %(levelname)s %(name)s: %(message)s"))
    root = logging.getLogger()
    old_level = root.level
    root.addHandler(handler)
    root.setLevel(logging.INFO)
    try:
        yield logging.getLogger("slamcli.sweep.run")
    finally:
        root.removeHandler(handler)
        root.setLevel(old_level)
        handler.close()


def dataset_path(exp_dir: Path, dataset: DatasetSpec) -> Path:
    return exp_dir / "datasets" / f"{dataset.dataset_id}.h5"


def _ensure_dataset(dataset: DatasetSpec, exp_dir: Path, pipeline: Pipeline, fresh: bool) -> tuple[Path, str | None]:
    """Simulate ``dataset`` unless its file exists; returns (path, traceback text or None)."""
    ds_dir = exp_dir / "datasets"
    ds_dir.mkdir(parents=True, exist_ok=True)
    path = dataset_path(exp_dir, dataset)
    sidecar = path.with_suffix(".json")
    if path.is_file() and not path.is_symlink() and not fresh:
        rec = read_json(sidecar) or {}
        if rec.get("dataset_id") == dataset.dataset_id and rec.get("file_sha256") == file_sha256(path):
            return path, None
        log.warning("%s: cached dataset does not match its recorded hash; simulating it again", path)
    tmp = ds_dir / f".{path.name}.tmp-{os.getpid()}-{uuid.uuid4().hex[:8]}"
    try:
        facts = pipeline.simulate(dataset, tmp)
        digest = file_sha256(tmp)
        if path.is_symlink() or path.is_dir():
            _remove(path)
        os.replace(tmp, path)
        write_json(sidecar, {**(facts or {}), "dataset_id": dataset.dataset_id, "file_sha256": digest})
        return path, None
    except Exception:  # noqa: BLE001 - fail-soft: every run of the group records this failure
        with contextlib.suppress(FileNotFoundError):
            tmp.unlink()
        return path, traceback.format_exc()


def execute_run(
    run: RunSpec,
    exp_dir: Path,
    dataset_path: Path,
    pipeline: Pipeline,
    dataset_error: str | None = None,
) -> dict[str, Any]:
    """Execute one run into a temporary directory and rename it onto ``<exp_dir>/<run_id>``.

    Never raises for a failing run (``Exception``); the failure is recorded in ``status.json``.
    ``KeyboardInterrupt`` propagates and leaves only a hidden temporary directory behind.
    """
    final = exp_dir / run.run_id
    tmp = exp_dir / f".{run.run_id}.tmp-{os.getpid()}-{uuid.uuid4().hex[:8]}"
    tmp.mkdir(parents=True)
    started = utc_now()
    t0 = time.perf_counter()
    status: dict[str, Any] = {
        "run_id": run.run_id,
        "experiment": run.experiment,
        "label": run.label,
        "method": run.method,
        "replicate": run.replicate,
        "dataset_id": run.dataset.dataset_id,
        "started_utc": started,
        "host": platform.node(),
        "pid": os.getpid(),
        "python": platform.python_version(),
        "git": git_revision(),  # not part of the run id (the slamcli version is); recorded for provenance
    }
    try:
        return _execute_in(tmp, final, run, status, t0, dataset_path, pipeline, dataset_error)
    except OSError as exc:  # a full disk while writing the run's own files: no half run is left behind
        _remove(tmp)
        raise SlamcliError(f"{final}: cannot write the run ({exc.strerror or exc})") from None
    except SlamcliError:
        _remove(tmp)
        raise


def _execute_in(tmp: Path, final: Path, run: RunSpec, status: dict[str, Any], t0: float, dataset_path: Path,
                pipeline: Pipeline, dataset_error: str | None) -> dict[str, Any]:
    """The body of :func:`execute_run` inside its temporary folder ``tmp``."""
    write_json(tmp / "config.json", {"run_id": run.run_id, "point": run.point, **run.config()})
    with _run_log(tmp / "run.log") as rlog:
        rlog.info("run %s (%s, replicate %d) on dataset %s", run.run_id, run.label, run.replicate, dataset_path)
        try:
            if dataset_error is not None:
                raise RuntimeError(
                    f"simulating dataset {run.dataset.dataset_id} failed:\n{dataset_error.rstrip()}"
                )
            _link_or_copy(dataset_path, tmp / "dataset.h5")
            init = {"init_path": _init_result(final.parent, run)} if run.init_run else {}
            t1, c1 = time.perf_counter(), time.process_time()
            solved = pipeline.solve(run, dataset_path, tmp / "result.h5", **init)
            t2, c2 = time.perf_counter(), time.process_time()
            rlog.info("solve (%s) took %.3f s", run.method, t2 - t1)
            _check_solver_status(status, solved, run)
            metrics = pipeline.evaluate(run, dataset_path, tmp / "result.h5", tmp)
            if solved is None:  # a pipeline that returns no result: the metrics carry the solver status
                _check_solver_status(status, metrics, run)
            rlog.info("evaluate took %.3f s", time.perf_counter() - t2)
            # paths that point into the temporary directory must name the final one
            metrics = {
                k: v.replace(str(tmp), str(final)) if isinstance(v, str) else v for k, v in metrics.items()
            }
            write_json(tmp / "metrics.json", metrics)
            status.update(status=COMPLETED, solve_time_s=t2 - t1, solve_cpu_s=c2 - c1)
        except Exception as exc:  # noqa: BLE001 - fail-soft by design
            tb = traceback.format_exc()
            rlog.error("run failed:\n%s", tb)
            last = str(exc).strip().splitlines()
            status.update(status=FAILED, error=f"{type(exc).__name__}: {last[-1] if last else ''}", traceback=tb)
    status.update(finished_utc=utc_now(), wall_time_s=time.perf_counter() - t0)
    if status.get("status") == COMPLETED:
        status["sha256"] = {name: file_sha256(tmp / name) for name in HASHED}
    write_json(tmp / "status.json", status)
    if final.is_symlink() or final.exists():
        _remove(final)
    os.replace(tmp, final)
    return {k: status.get(k) for k in ("run_id", "status", "error", "wall_time_s")}


def _init_result(exp_dir: Path, run: RunSpec) -> Path:
    """``result.h5`` of the run whose result is ``run``'s initial estimate; RuntimeError when it did not complete."""
    state = run_status(exp_dir, run.init_run)
    if state != COMPLETED:
        raise RuntimeError(f"its initial estimate, run {run.init_run}, is {state}: nothing to start from")
    return exp_dir / run.init_run / "result.h5"


class SolverFailed(SlamcliError):
    """The solver returned a result whose status says there is no usable estimate."""


def _check_solver_status(status: dict[str, Any], solved: Any, run: RunSpec) -> None:
    """Record the solver's status; raise :class:`SolverFailed` for a failing one (the run becomes failed)."""
    if solved is None:
        return
    st = solved.get("status") if isinstance(solved, dict) else getattr(solved, "status", None)
    if st is None:
        return
    st = str(getattr(st, "value", st))
    message = solved.get("message", "") if isinstance(solved, dict) else getattr(solved, "message", "")
    status["solver_status"] = st
    if st in FAILING_SOLVER_STATUSES:
        raise SolverFailed(f"solver {run.method!r} returned status {st}: {message or 'no message'}")


def record_dead_run(run: RunSpec, exp_dir: Path, error: str) -> dict[str, Any]:
    """Write ``<run_id>/`` with ``config.json`` + a failed ``status.json`` for a run whose worker died."""
    final = exp_dir / run.run_id
    tmp = exp_dir / f".{run.run_id}.tmp-{os.getpid()}-{uuid.uuid4().hex[:8]}"
    tmp.mkdir(parents=True)
    write_json(tmp / "config.json", {"run_id": run.run_id, "point": run.point, **run.config()})
    now = utc_now()
    status = {"run_id": run.run_id, "experiment": run.experiment, "label": run.label, "method": run.method,
              "replicate": run.replicate, "dataset_id": run.dataset.dataset_id, "status": FAILED, "error": error,
              "started_utc": now, "finished_utc": now, "host": platform.node(), "git": git_revision()}
    write_json(tmp / "status.json", status)
    if final.is_symlink() or final.exists():
        _remove(final)
    os.replace(tmp, final)
    return {"run_id": run.run_id, "status": FAILED, "error": error, "wall_time_s": None}


def simulate_dataset(dataset: DatasetSpec, exp_dir: str, pipeline: Pipeline, fresh: bool = False) -> str | None:
    """Worker entry point (parallel phase 1): make sure the dataset file exists; traceback text on failure."""
    return _ensure_dataset(dataset, Path(exp_dir), pipeline, fresh)[1]


def execute_single(run: RunSpec, exp_dir: str, pipeline: Pipeline, dataset_error: str | None = None) -> dict:
    """Worker entry point (parallel phase 2): one run on its (already simulated) dataset."""
    exp = Path(exp_dir)
    return execute_run(run, exp, dataset_path(exp, run.dataset), pipeline, dataset_error)


# -- coordinator side -------------------------------------------------------------------------------------------------


@dataclass
class Counts:
    total: int = 0
    done: int = 0
    failed: int = 0
    skipped: int = 0

    @property
    def finished(self) -> int:
        return self.done + self.failed + self.skipped


@dataclass
class SweepSummary:
    experiment: str
    exp_dir: Path
    counts: Counts
    failures: list[dict[str, Any]] = field(default_factory=list)  # {run_id, label, replicate, error}
    wall_time_s: float = 0.0
    interrupted: bool = False
    tables: dict[str, Path] = field(default_factory=dict)

    @property
    def ok(self) -> bool:
        return self.counts.failed == 0 and not self.interrupted


def watch_parent(parent_pid: int, interval_s: float = 0.25) -> None:
    """Pool-worker initializer: a daemon thread that ends this process as soon as its parent is gone.

    After a ``kill -9`` of the coordinator the worker is re-parented (``getppid()`` changes); it then exits
    within ``interval_s`` instead of starting the runs still queued in its pipe.
    """

    def loop() -> None:
        while True:
            if os.getppid() != parent_pid:
                os._exit(75)
            time.sleep(interval_s)

    threading.Thread(target=loop, name="slamcli-watch-parent", daemon=True).start()


def start_worker(parent_pid: int) -> None:
    """Pool-worker initializer: :func:`watch_parent`, and NumPy's submodules that no run uses deferred as in the
    ``slamcli`` command (:func:`slamcli.api.startup.defer_unused_numpy_submodules`)."""
    from slamcli.api.startup import defer_unused_numpy_submodules

    defer_unused_numpy_submodules()
    watch_parent(parent_pid)


class LocalPool:
    """A spawn ``ProcessPoolExecutor`` whose workers die with the coordinator and that can be rebuilt.

    When a worker dies (``kill -9``, out of memory, ``os._exit``), ``concurrent.futures`` breaks the whole
    pool and fails every pending future; :meth:`rebuild` starts a fresh pool and tells which worker processes
    died on their own (not terminated by the executor while it broke the pool).

    Several sweeps may share one pool from several threads (``reproduce`` overlaps its sections): the pool
    is rebuilt once per break, by whichever sweep asks first; once shut down it is never rebuilt.
    """

    def __init__(self, workers: int) -> None:
        self.workers = workers
        self._procs: dict[int, Any] = {}
        self._lock = threading.Lock()
        self._closed = False
        self._last_dead: dict[int, int] = {}
        self._start()

    def _start(self) -> None:
        import multiprocessing

        self.ex = cf.ProcessPoolExecutor(max_workers=self.workers, mp_context=multiprocessing.get_context("spawn"),
                                         initializer=start_worker, initargs=(os.getpid(),))
        self._procs = {}

    def submit(self, fn: Callable[..., Any], /, *args: Any) -> cf.Future:
        with self._lock:
            if self._closed:
                raise RuntimeError("the worker pool is shut down")
            fut = self.ex.submit(fn, *args)
            self._procs.update(getattr(self.ex, "_processes", None) or {})  # pid -> Process, spawned on submit
        return fut

    def shutdown(self, wait: bool = True, *, cancel_futures: bool = False) -> None:
        with self._lock:
            self._closed = True
        self.ex.shutdown(wait=wait, cancel_futures=cancel_futures)

    def terminate(self) -> None:
        """SIGTERM every live worker of the current pool (its runs are abandoned, not recorded); the pool is
        not rebuilt after."""
        with self._lock:
            self._closed = True
        for proc in (getattr(self.ex, "_processes", None) or {}).values():
            if proc.is_alive():
                proc.terminate()

    def rebuild(self) -> dict[int, int]:
        """Shut the broken pool down, start a new one; returns ``{pid: exit code}`` of workers that died.

        A sweep sharing the pool that asks after another one rebuilt it gets the same answer, and the new pool
        is left running. Raises ``RuntimeError`` once the pool is shut down (the coordinator is stopping).
        """
        with self._lock:
            if self._closed:
                raise RuntimeError("the worker pool is shut down")
            if not getattr(self.ex, "_broken", True):  # rebuilt already, for another sweep's futures
                return dict(self._last_dead)
            self.ex.shutdown(wait=True, cancel_futures=True)  # joins the manager thread: exit codes are final
            dead = {}
            for pid, proc in self._procs.items():
                code = proc.exitcode
                if code not in (None, 0, -signal.SIGTERM):  # the executor SIGTERMs the survivors of a broken pool
                    dead[int(pid)] = int(code)
            self._start()
            self._last_dead = dead
            return dict(dead)


def describe_exit(code: int) -> str:
    if code < 0:
        try:
            return f"was killed by signal {-code} ({signal.Signals(-code).name})"
        except ValueError:
            return f"was killed by signal {-code}"
    return f"exited with code {code}"


def _tmp_pids(base: Path, stem: str) -> dict[int, Path]:
    """``{pid: path}`` of the temporary entries ``.<stem>.tmp-<pid>-<rand>`` in ``base``."""
    out = {}
    prefix = f".{stem}.tmp-"
    if base.is_dir():
        for p in base.iterdir():
            if p.name.startswith(prefix):
                with contextlib.suppress(ValueError, IndexError):
                    out[int(p.name[len(prefix):].split("-")[0])] = p
    return out


@contextlib.contextmanager
def make_executor(kind: str, workers: int, scheduler: str | None = None) -> Iterator[cf.Executor | None]:
    """``None`` (in-process, serial) for one local worker; a spawn ``ProcessPoolExecutor``; or a Dask executor.

    Dask: ``Client(scheduler)`` for an existing cluster (slamcli must be installed there at the same version)
    or a throw-away ``LocalCluster(processes=True, threads_per_worker=1, dashboard_address=None)``; then
    ``client.get_executor()``, a ``concurrent.futures.Executor`` whose futures work with ``cf.as_completed``.
    """
    if kind not in ("local", "dask"):
        raise ConfigError(f"--executor: {kind!r} is not one of local, dask")
    if workers < 1:
        raise ConfigError(f"--workers: must be >= 1, got {workers}")
    if kind == "local":
        if scheduler:
            raise ConfigError("--scheduler: only meaningful with --executor dask")
        if workers == 1:
            yield None
            return
        # the pool spawns its workers on demand (at submit, again after a rebuild): the one-thread BLAS
        # environment they inherit must last the pool's whole life, not only its construction
        with single_threaded_blas():
            ex = LocalPool(workers)
            try:
                yield ex
            except BaseException:
                # Ctrl-C (or an error) in the coordinator: the runs already handed to a worker's pipe cannot be
                # cancelled and would run to the end while shutdown waits for them; stop the workers instead
                # (their unfinished runs leave only hidden temporary directories, cleared by the next resume)
                ex.terminate()
                raise
            finally:
                ex.shutdown(wait=True, cancel_futures=True)
        return
    try:
        from dask.distributed import Client, LocalCluster
    except ImportError:
        raise ConfigError("--executor dask: dask.distributed is not installed (pip install 'slamcli[dask]')") from None
    cluster = None
    if scheduler:
        try:
            client = Client(scheduler, timeout="20s")
        except (OSError, TimeoutError) as exc:
            raise ConfigError(f"--scheduler {scheduler}: cannot connect: {exc}") from None
    else:
        with single_threaded_blas():
            cluster = LocalCluster(
                n_workers=workers, threads_per_worker=1, processes=True, dashboard_address=None
            )
        client = Client(cluster)
    try:
        yield client.get_executor(pure=False)
    finally:
        client.close()
        if cluster is not None:
            cluster.close()


ProgressCallback = Callable[[Counts], None]


def progress_lines(label: str, write: Callable[[str], None]) -> ProgressCallback:
    """A :data:`ProgressCallback` that writes plain lines at a bounded rate
    (:class:`slamcli.progress.ProgressLines`): finished runs of the total, the done / failed / skipped counts,
    the rate and ETA of the runs this sweep executes (skipped runs are not counted as work)."""
    from slamcli.progress import ProgressLines

    lines = ProgressLines(label, write, unit="runs")

    def report(c: Counts) -> None:
        lines(c.finished, c.total, f"{c.done} done, {c.failed} failed, {c.skipped} skipped")

    return report


def run_sweep(
    expansion: Expansion,
    out_dir: str | Path,
    *,
    pipeline: Pipeline | None = None,
    executor: str = "local",
    workers: int = 1,
    scheduler: str | None = None,
    resume: bool = True,
    progress: ProgressCallback | None = None,
    pool: cf.Executor | None = None,
) -> SweepSummary:
    """Run every pending run of ``expansion`` under ``out_dir/<experiment>/`` and write the tables.

    ``pool``: an executor the caller opened with :func:`make_executor` and shares across several sweeps (its
    workers start once); ``executor``, ``workers`` and ``scheduler`` then go unused. ``None``: this sweep opens
    its own.

    Returns a :class:`SweepSummary`; failures are recorded, never raised. ``KeyboardInterrupt`` stops the
    sweep after writing the tables of what finished (``summary.interrupted``), then re-raises.
    """
    pipeline = pipeline if pipeline is not None else WorkflowPipeline()
    # absolute before anything is handed to a worker: a Dask worker's working directory is its own, not ours
    exp_dir = Path(os.path.abspath(out_dir)) / expansion.experiment.name
    expansion = _paths_for_workers(expansion)
    if exp_dir.is_symlink() or (exp_dir.exists() and not exp_dir.is_dir()):
        raise ConfigError(f"{exp_dir}: exists and is not a directory; remove it or use another --out")
    try:
        exp_dir.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise ConfigError(f"{exp_dir}: cannot create the results folder ({exc.strerror})") from None
    if not os.access(exp_dir, os.W_OK | os.X_OK):
        raise ConfigError(f"{exp_dir}: results folder is not writable")
    with sweep_lock(exp_dir):
        opened = contextlib.nullcontext(pool) if pool is not None else make_executor(executor, workers, scheduler)
        return _run_locked(expansion, exp_dir, pipeline, opened, resume, progress)


#: ``[evaluate]`` options that name a file (relative to the directory the sweep is started from)
PATH_OPTIONS = ("against",)


def _paths_for_workers(expansion: Expansion) -> Expansion:
    """``expansion`` with every file-valued run option made absolute against this process's working directory.

    The run ids are kept (they hash the options as written); ``config.json`` records the absolute path, the
    one the worker read.
    """
    import dataclasses

    def absolute(run: RunSpec) -> RunSpec:
        paths = {k: os.path.abspath(v) for k in PATH_OPTIONS if isinstance(v := run.evaluate.get(k), str | os.PathLike)}
        return dataclasses.replace(run, evaluate={**run.evaluate, **paths}) if paths else run

    return dataclasses.replace(expansion, runs=tuple(absolute(r) for r in expansion.runs))


def _run_locked(expansion, exp_dir, pipeline, opened, resume, progress) -> SweepSummary:
    clean_temporaries(exp_dir)
    since = utc_now()
    t0 = time.perf_counter()
    counts = Counts(total=len(expansion.runs))
    pending: list[RunSpec] = []
    for r in expansion.runs:
        if resume and run_status(exp_dir, r.run_id) == COMPLETED:
            counts.skipped += 1
        else:
            pending.append(r)
    groups = expansion.groups(pending)
    summary = SweepSummary(expansion.experiment.name, exp_dir, counts)
    if progress:
        progress(counts)
    by_id = {r.run_id: r for r in expansion.runs}
    # a run that starts from another pending run's result waits for it: init run id -> [(run, dataset error)]
    unfinished = {r.run_id for r in pending}
    waiting: dict[str, list[tuple[RunSpec, str | None]]] = {}

    def record(records: list[dict]) -> None:
        for rec in records:
            unfinished.discard(rec["run_id"])
            for r, ds_error in waiting.pop(rec["run_id"], []):
                submit_run(r, ds_error)
            if rec["status"] == COMPLETED:
                counts.done += 1
            else:
                counts.failed += 1
                r = by_id[rec["run_id"]]
                summary.failures.append(
                    {"run_id": r.run_id, "label": r.label, "replicate": r.replicate, "error": rec.get("error")}
                )
        if progress:
            progress(counts)

    def run_failed(run: RunSpec, exc: BaseException) -> dict:
        # the worker itself died (killed, out of memory, broken pool): the run is recorded as failed
        return {"run_id": run.run_id, "status": FAILED, "error": f"worker failed: {type(exc).__name__}: {exc}"}

    try:
        with opened as ex:
            if ex is None:
                for g in groups:  # in this process: simulate once, then record run by run (progress per run)
                    ds_path, ds_error = _ensure_dataset(g.dataset, exp_dir, pipeline, not resume)
                    for r in g.runs:
                        record([execute_run(r, exp_dir, ds_path, pipeline, ds_error)])
            else:
                # Phase 1 simulates each shared dataset once; as soon as one exists, its runs are submitted
                # one task each, so the runs of a single dataset still spread over every worker.
                futures: dict[cf.Future, tuple[str, Any]] = {}
                attempts: dict[str, int] = {}

                def submit(kind: str, obj: Any, fn: Callable[..., Any], *args: Any) -> None:
                    futures[ex.submit(fn, *args)] = (kind, obj)

                def submit_run(r: RunSpec, ds_error: str | None) -> None:
                    try:
                        submit("run", r, execute_single, r, str(exp_dir), pipeline, ds_error)
                    except Exception as exc:  # noqa: BLE001 - e.g. a broken pool
                        record([run_failed(r, exc)])

                def submit_sim(g: Any) -> None:
                    submit("sim", g, simulate_dataset, g.dataset, str(exp_dir), pipeline, not resume)

                def finished_sim(g: Any, ds_error: str | None) -> None:
                    for r in g.runs:
                        if r.init_run in unfinished:
                            waiting.setdefault(r.init_run, []).append((r, ds_error))
                        else:
                            submit_run(r, ds_error)

                for g in groups:
                    submit_sim(g)
                try:
                    while futures:
                        done, _ = cf.wait(list(futures), return_when=cf.FIRST_COMPLETED)
                        broken = [f for f in done if _is_broken(f)]
                        if broken and hasattr(ex, "rebuild"):
                            # one worker died: every pending future fails; wait for all, then sort them out
                            cf.wait(list(futures))
                            lost, sims_done = [], []
                            for fut in list(futures):
                                kind, obj = futures.pop(fut)
                                if _is_broken(fut):
                                    lost.append((kind, obj))
                                elif kind == "sim":
                                    sims_done.append((obj, _sim_outcome(fut)))
                                else:
                                    record([_run_outcome(fut, obj, run_failed)])
                            dead = ex.rebuild()
                            for g, ds_error in sims_done:
                                finished_sim(g, ds_error)
                            _recover(lost, dead, exp_dir, since, attempts, record, submit_sim, submit_run)
                            continue
                        for fut in done:
                            kind, obj = futures.pop(fut)
                            if kind == "sim":
                                finished_sim(obj, _sim_outcome(fut))
                            else:
                                record([_run_outcome(fut, obj, run_failed)])
                except BaseException:
                    for f in futures:
                        f.cancel()
                    raise
    except KeyboardInterrupt:
        summary.interrupted = True
        raise
    finally:
        summary.wall_time_s = time.perf_counter() - t0
        summary.tables = write_tables(expansion, exp_dir)
    return summary


def _is_broken(fut: cf.Future) -> bool:
    from concurrent.futures.process import BrokenProcessPool

    return not fut.cancelled() and isinstance(fut.exception(), BrokenProcessPool)


def _sim_outcome(fut: cf.Future) -> str | None:
    try:
        return fut.result()
    except Exception as exc:  # noqa: BLE001
        return f"worker failed: {type(exc).__name__}: {exc}"


def _run_outcome(fut: cf.Future, run: RunSpec, run_failed: Callable[[RunSpec, BaseException], dict]) -> dict:
    try:
        return fut.result()
    except Exception as exc:  # noqa: BLE001
        return run_failed(run, exc)


#: a run (or dataset) whose worker pool broke this often without its own worker being identified as the one
#: that died is recorded as failed rather than retried forever
MAX_POOL_BREAKS = 2


def _recover(lost, dead: dict[int, int], exp_dir: Path, since: str, attempts: dict[str, int], record, submit_sim,
             submit_run) -> None:
    """Sort out the tasks of a broken pool (already rebuilt): fail only the ones whose worker died.

    Each task leaves a temporary entry named with its worker's pid (``.<run_id>.tmp-<pid>-…`` for a run,
    ``datasets/.<id>.h5.tmp-<pid>-…`` for a dataset), so the task of a worker in ``dead`` is known. Its run
    is recorded as failed (``status.json`` on disk says which process died and how); every other lost task
    is resubmitted to the new pool. Runs that completed just before the break are taken from disk.
    """
    for kind, obj in lost:
        if kind == "run":
            run = obj
            st = read_json(exp_dir / run.run_id / "status.json") or {}
            tmps = _tmp_pids(exp_dir, run.run_id)
            if not tmps and st.get("run_id") == run.run_id and str(st.get("started_utc", "")) >= since:
                # finished (renamed into place) by this sweep just before the pool broke
                record([{"run_id": run.run_id, "status": st.get("status"), "error": st.get("error")}])
                continue
            culprit = [pid for pid in tmps if pid in dead]
            for p in tmps.values():
                _remove(p)
            key = f"run:{run.run_id}"
            attempts[key] = attempts.get(key, 0) + bool(tmps)
            if culprit or attempts[key] > MAX_POOL_BREAKS:
                why = (f"worker failed: process {culprit[0]} {describe_exit(dead[culprit[0]])} during this run"
                       if culprit else f"worker failed: the process pool broke {attempts[key]} times during this run")
                log.warning("run %s: %s", run.run_id, why)
                record([record_dead_run(run, exp_dir, why)])
            else:
                submit_run(run, None)
        else:
            g = obj
            ds_dir = exp_dir / "datasets"
            tmps = _tmp_pids(ds_dir, f"{g.dataset.dataset_id}.h5")
            culprit = [pid for pid in tmps if pid in dead]
            for p in tmps.values():
                _remove(p)
            key = f"sim:{g.dataset.dataset_id}"
            attempts[key] = attempts.get(key, 0) + bool(tmps)
            if culprit or attempts[key] > MAX_POOL_BREAKS:
                why = (f"worker failed: process {culprit[0]} {describe_exit(dead[culprit[0]])} while simulating"
                       if culprit else f"worker failed: the process pool broke {attempts[key]} times while simulating")
                for run in g.runs:
                    record([record_dead_run(run, exp_dir, f"dataset {g.dataset.dataset_id}: {why}")])
            else:
                submit_sim(g)


# -- tables --------------------------------------------------------------------------------------------------------------


def _scalar_items(d: dict[str, Any], prefix: str = "") -> Iterator[tuple[str, Any]]:
    for k, v in d.items():
        if isinstance(v, dict):
            yield from _scalar_items(v, f"{prefix}{k}.")
        elif v is None or isinstance(v, (bool, int, float, str)):
            yield f"{prefix}{k}", v


def _cell(v: Any) -> Any:
    if isinstance(v, (list, tuple, dict)):
        return canonical_json(v)
    return v


def manifest_rows(expansion: Expansion, exp_dir: Path) -> list[dict[str, Any]]:
    """One row per run of the expansion: ids, labels, seeds, sweep point and on-disk status."""
    rows = []
    facts: dict[str, dict[str, Any]] = {}
    with_init = any(r.init_run for r in expansion.runs)  # the column only then: other tables stay as they were
    for r in expansion.runs:
        st = read_json(exp_dir / r.run_id / "status.json") or {}
        status = run_status(exp_dir, r.run_id)
        ds = r.dataset
        if ds.dataset_id not in facts:
            facts[ds.dataset_id] = read_json(dataset_path(exp_dir, ds).with_suffix(".json")) or {}
        row: dict[str, Any] = {
            "run_id": r.run_id,
            "experiment": r.experiment,
            "label": r.label,
            "method": r.method,
            "data": ds.label,
            "data_kind": ds.kind,  # a recording, graph or file is one replicate (the first id)
            "reference": facts[ds.dataset_id].get("reference", "truth" if ds.simulated else ""),
            "replicate": r.replicate,
            "dataset_id": ds.dataset_id,
            "scenario": ds.scenario,
            "dataset_seed": ds.seed if ds.simulated else None,
            "solver_seed": r.seed,
            "status": status,
            "solver_status": st.get("solver_status", ""),
            "error": st.get("error", "") if status == FAILED else "",
            "wall_time_s": st.get("wall_time_s"),
            "solve_time_s": st.get("solve_time_s"),
            "solve_cpu_s": st.get("solve_cpu_s"),  # CPU time of the worker process (a loaded machine's wall
            # time overstates the cost)
            "path": r.run_id,  # relative to the sweep folder: the same for -j 1, -j 2 and a moved folder
        }
        if with_init:
            row["init_run"] = r.init_run
        for axis in expansion.axes:
            row[axis] = _cell(r.point.get(axis))
        rows.append(row)
    return rows


def write_tables(expansion: Expansion, exp_dir: Path) -> dict[str, Path]:
    """``manifest.csv`` and the tidy ``results.csv`` (+ ``results.parquet`` when pyarrow is importable)."""
    from slamcli.metrics.aggregate import typed_frame

    rows = manifest_rows(expansion, exp_dir)
    manifest = typed_frame(rows)  # an int parameter absent for some solvers stays Int64 (10, not 10.0)
    out: dict[str, Path] = {}
    out["manifest"] = _write_csv(manifest, exp_dir / "manifest.csv")
    tidy_rows = []
    for row in rows:
        full = dict(row)
        if row["status"] == COMPLETED:
            metrics = read_json(exp_dir / row["run_id"] / "metrics.json") or {}
            for k, v in _scalar_items(metrics):
                v = _relative(v, exp_dir) if k.endswith("_path") else v
                if k not in full:
                    full[k] = v
                else:
                    full[f"metric.{k}"] = v
        tidy_rows.append(full)
    tidy = typed_frame(tidy_rows)
    out["results"] = _write_csv(tidy, exp_dir / "results.csv")
    try:
        import pyarrow  # noqa: F401
    except ImportError:
        return out
    pq = exp_dir / "results.parquet"
    # mixed-type object columns (e.g. None and str) are stored as strings so Arrow accepts them
    safe = tidy.copy()
    for col in safe.columns:
        if safe[col].dtype == object:
            kinds = {type(v) for v in safe[col] if v is not None and not (isinstance(v, float) and math.isnan(v))}
            if len(kinds) > 1:
                safe[col] = safe[col].map(lambda v: None if v is None else str(v))
    write_bytes_atomic(pq, safe.to_parquet(None, index=False))
    out["parquet"] = pq
    return out


def _write_csv(df, path: Path) -> Path:
    write_bytes_atomic(path, df.to_csv(index=False).encode())
    return path


def _relative(v: Any, exp_dir: Path) -> Any:
    """A path inside ``exp_dir`` as a path relative to it (``<run_id>/result.h5``); anything else unchanged."""
    if not isinstance(v, str) or not v:
        return v
    real, root = os.path.realpath(v), os.path.realpath(exp_dir)
    return os.path.relpath(real, root) if real.startswith(root + os.sep) else v


def load_results(exp_dir: str | Path):
    """The tidy table of a finished sweep as a DataFrame; its path columns (``path``, ``*_path``), stored
    relative to the sweep folder, are returned joined onto ``exp_dir``."""
    import pandas as pd

    exp_dir = Path(exp_dir)
    df = pd.read_csv(exp_dir / "results.csv")
    for col in df.columns:
        if col == "path" or col.endswith("_path"):
            df[col] = [v if not isinstance(v, str) or os.path.isabs(v) else str(exp_dir / v) for v in df[col]]
    return df
