"""Execute an :class:`~slamcli.sweep.expand.Expansion`: resumable, fail-soft, local process pool or Dask.

On disk (``results/<experiment>/``)::

    datasets/<dataset_id>.h5       one simulated dataset per (scenario config, replicate), shared by its runs
    <run_id>/config.json           the resolved run configuration (+ run id, dataset id, sweep point)
    <run_id>/dataset.h5            hard link to datasets/<dataset_id>.h5 (a copy where links are impossible)
    <run_id>/result.h5             solver result
    <run_id>/metrics.json          scalar metrics (plus whatever tidy CSVs the evaluation writes)
    <run_id>/status.json           {"status": "completed" | "failed", "traceback": ..., times, host}
    <run_id>/run.log               log of the run
    manifest.csv                   one row per run of the expansion: ids, labels, sweep point, status
    results.csv / results.parquet  the tidy table: manifest columns + every scalar metric, one row per run

Atomicity: a run is built in a hidden temporary directory ``.<run_id>.tmp-<pid>-<rand>/`` and renamed onto
``<run_id>/`` only when ``status.json`` (written last) is in place, so an interrupted sweep (Ctrl-C,
``kill -9``) leaves either nothing or a complete run directory; datasets are written under a temporary name
and ``os.replace``-d. Leftover temporary entries are removed when the next sweep of the experiment starts.

Resume: a run is skipped when ``<run_id>/status.json`` says ``completed`` for the same run id and every
artefact exists. Failed and missing runs are (re)done. ``resume=False`` redoes everything.

Parallel execution has two phases: each shared dataset is simulated once (one task per dataset, written under
a temporary name and renamed), and as soon as it exists its runs are submitted one task each, so the runs of
one dataset spread over every worker. Workers never share an open HDF5 file: each task opens its own files
(the dataset read-only, its result under a temporary directory); the local pool uses the ``spawn`` start
method (EVALUATION-METHOD.md B7). The coordinator opens no HDF5 file; it only reads the small JSON files to
build the tables.
"""

from __future__ import annotations

import concurrent.futures as cf
import contextlib
import functools
import json
import logging
import math
import os
import platform
import shutil
import subprocess
import time
import traceback
import uuid
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from datetime import UTC, datetime
from pathlib import Path
from typing import Any, Protocol

from slamcli.errors import ConfigError
from slamcli.sweep.expand import DatasetSpec, Expansion, RunSpec, canonical_json

ARTEFACTS = ("config.json", "dataset.h5", "result.h5", "metrics.json", "status.json", "run.log")
COMPLETED = "completed"
FAILED = "failed"
MISSING = "missing"

log = logging.getLogger(__name__)


# -- the pipeline a run executes ------------------------------------------------------------------------------


class Pipeline(Protocol):
    """What one run does; injectable so tests can exercise the runner with a trivial picklable pipeline."""

    def simulate(self, dataset: DatasetSpec, out_path: Path) -> None:
        """Write the dataset for ``dataset`` to ``out_path`` (the runner handles atomic renaming)."""

    def solve(self, run: RunSpec, dataset_path: Path, result_path: Path) -> None:
        """Solve ``dataset_path`` with the run's solver configuration, writing ``result_path``."""

    def evaluate(self, run: RunSpec, dataset_path: Path, result_path: Path, out_dir: Path) -> dict[str, Any]:
        """Evaluate the result; may write tidy files into ``out_dir``; returns the scalar metrics."""


class WorkflowPipeline:
    """The real pipeline: ``slamcli.api.simulate`` → ``slamcli.api.solve`` → ``slamcli.api.evaluate``."""

    def simulate(self, dataset: DatasetSpec, out_path: Path) -> None:
        from slamcli.api.simulate import simulate_to_file

        simulate_to_file(
            scenario=dataset.scenario, seed=dataset.seed, overrides=dict(dataset.overrides), out_path=out_path
        )

    def solve(self, run: RunSpec, dataset_path: Path, result_path: Path) -> None:
        from slamcli.api.solve import solve_file

        solve_file(
            dataset_path,
            run.method,
            dict(run.param_overrides),
            result_path,
            seed=run.seed,
            oracle_association=run.oracle_association,
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


def _utc_now() -> str:
    return datetime.now(UTC).isoformat(timespec="seconds")


def _json_default(obj: Any) -> Any:
    if hasattr(obj, "tolist"):
        return obj.tolist()
    if hasattr(obj, "value"):
        return obj.value
    return str(obj)


def write_json(path: Path, obj: Any) -> None:
    """Write JSON under a temporary name in the same directory, then ``os.replace``."""
    tmp = path.with_name(f".{path.name}.tmp-{os.getpid()}-{uuid.uuid4().hex[:8]}")
    with tmp.open("w") as fh:
        json.dump(obj, fh, indent=2, sort_keys=True, default=_json_default, allow_nan=True)
        fh.write("\n")
    os.replace(tmp, path)


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
    st = read_json(d / "status.json")
    if st is None or st.get("run_id") != run_id:
        return MISSING
    if st.get("status") == COMPLETED and all((d / a).exists() for a in ARTEFACTS):
        return COMPLETED
    return FAILED if st.get("status") == FAILED else MISSING


def clean_temporaries(exp_dir: Path) -> int:
    """Remove leftovers of interrupted runs (hidden ``*.tmp-*`` entries); returns how many were removed."""
    n = 0
    for base in (exp_dir, exp_dir / "datasets"):
        if not base.is_dir():
            continue
        for p in base.iterdir():
            if p.name.startswith(".") and ".tmp-" in p.name:
                if p.is_dir():
                    shutil.rmtree(p, ignore_errors=True)
                else:
                    p.unlink(missing_ok=True)
                n += 1
    return n


# -- worker side ----------------------------------------------------------------------------------------------------


@contextlib.contextmanager
def _run_log(path: Path) -> Iterator[logging.Logger]:
    """Send every log record of this process to ``path`` while the run lasts."""
    handler = logging.FileHandler(path, mode="a", encoding="utf-8")
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
    if path.exists() and not fresh:
        return path, None
    tmp = ds_dir / f".{path.name}.tmp-{os.getpid()}-{uuid.uuid4().hex[:8]}"
    try:
        pipeline.simulate(dataset, tmp)
        os.replace(tmp, path)
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
    started = _utc_now()
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
    write_json(tmp / "config.json", {"run_id": run.run_id, "point": run.point, **run.config()})
    with _run_log(tmp / "run.log") as rlog:
        rlog.info("run %s (%s, replicate %d) on dataset %s", run.run_id, run.label, run.replicate, dataset_path)
        try:
            if dataset_error is not None:
                raise RuntimeError(
                    f"simulating dataset {run.dataset.dataset_id} failed:\n{dataset_error.rstrip()}"
                )
            _link_or_copy(dataset_path, tmp / "dataset.h5")
            t1 = time.perf_counter()
            pipeline.solve(run, dataset_path, tmp / "result.h5")
            t2 = time.perf_counter()
            rlog.info("solve (%s) took %.3f s", run.method, t2 - t1)
            metrics = pipeline.evaluate(run, dataset_path, tmp / "result.h5", tmp)
            rlog.info("evaluate took %.3f s", time.perf_counter() - t2)
            # paths that point into the temporary directory must name the final one
            metrics = {
                k: v.replace(str(tmp), str(final)) if isinstance(v, str) else v for k, v in metrics.items()
            }
            write_json(tmp / "metrics.json", metrics)
            status.update(status=COMPLETED, solve_time_s=t2 - t1)
        except Exception as exc:  # noqa: BLE001 - fail-soft by design
            tb = traceback.format_exc()
            rlog.error("run failed:\n%s", tb)
            last = str(exc).strip().splitlines()
            status.update(status=FAILED, error=f"{type(exc).__name__}: {last[-1] if last else ''}", traceback=tb)
    status.update(finished_utc=_utc_now(), wall_time_s=time.perf_counter() - t0)
    write_json(tmp / "status.json", status)
    if final.exists():
        shutil.rmtree(final)
    os.replace(tmp, final)
    return {k: status.get(k) for k in ("run_id", "status", "error", "wall_time_s")}


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
        import multiprocessing

        with _single_threaded_blas():
            ex = cf.ProcessPoolExecutor(max_workers=workers, mp_context=multiprocessing.get_context("spawn"))
        try:
            yield ex
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
        with _single_threaded_blas():
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


@contextlib.contextmanager
def _single_threaded_blas() -> Iterator[None]:
    """Child processes inherit one BLAS/OpenMP thread each (no oversubscription with N workers)."""
    keys = ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS")
    old = {k: os.environ.get(k) for k in keys}
    for k in keys:
        os.environ.setdefault(k, "1")
    try:
        yield
    finally:
        for k, v in old.items():
            if v is None:
                os.environ.pop(k, None)
            else:
                os.environ[k] = v


ProgressCallback = Callable[[Counts], None]


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
) -> SweepSummary:
    """Run every pending run of ``expansion`` under ``out_dir/<experiment>/`` and write the tables.

    Returns a :class:`SweepSummary`; failures are recorded, never raised. ``KeyboardInterrupt`` stops the
    sweep after writing the tables of what finished (``summary.interrupted``), then re-raises.
    """
    pipeline = pipeline if pipeline is not None else WorkflowPipeline()
    exp_dir = Path(out_dir) / expansion.experiment.name
    exp_dir.mkdir(parents=True, exist_ok=True)
    clean_temporaries(exp_dir)
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

    def record(records: list[dict]) -> None:
        for rec in records:
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
        with make_executor(executor, workers, scheduler) as ex:
            if ex is None:
                for g in groups:  # in this process: simulate once, then record run by run (progress per run)
                    ds_path, ds_error = _ensure_dataset(g.dataset, exp_dir, pipeline, not resume)
                    for r in g.runs:
                        record([execute_run(r, exp_dir, ds_path, pipeline, ds_error)])
            else:
                # Phase 1 simulates each shared dataset once; as soon as one exists, its runs are submitted
                # one task each, so the runs of a single dataset still spread over every worker.
                futures: dict[cf.Future, tuple[str, Any]] = {}

                def submit_run(r: RunSpec, ds_error: str | None) -> None:
                    try:
                        futures[ex.submit(execute_single, r, str(exp_dir), pipeline, ds_error)] = ("run", r)
                    except Exception as exc:  # noqa: BLE001 - e.g. a broken pool
                        record([run_failed(r, exc)])

                for g in groups:
                    futures[ex.submit(simulate_dataset, g.dataset, str(exp_dir), pipeline, not resume)] = ("sim", g)
                try:
                    while futures:
                        done, _ = cf.wait(list(futures), return_when=cf.FIRST_COMPLETED)
                        for fut in done:
                            kind, obj = futures.pop(fut)
                            if kind == "sim":
                                try:
                                    ds_error = fut.result()
                                except Exception as exc:  # noqa: BLE001
                                    ds_error = f"worker failed: {type(exc).__name__}: {exc}"
                                for r in obj.runs:
                                    submit_run(r, ds_error)
                            else:
                                try:
                                    record([fut.result()])
                                except Exception as exc:  # noqa: BLE001
                                    record([run_failed(obj, exc)])
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
    for r in expansion.runs:
        st = read_json(exp_dir / r.run_id / "status.json") or {}
        status = run_status(exp_dir, r.run_id)
        row: dict[str, Any] = {
            "run_id": r.run_id,
            "experiment": r.experiment,
            "label": r.label,
            "method": r.method,
            "replicate": r.replicate,
            "dataset_id": r.dataset.dataset_id,
            "scenario": r.dataset.scenario,
            "dataset_seed": r.dataset.seed,
            "solver_seed": r.seed,
            "status": status,
            "error": st.get("error", "") if status == FAILED else "",
            "wall_time_s": st.get("wall_time_s"),
            "solve_time_s": st.get("solve_time_s"),
            "path": str(exp_dir / r.run_id),
        }
        for axis in expansion.axes:
            row[axis] = _cell(r.point.get(axis))
        rows.append(row)
    return rows


def write_tables(expansion: Expansion, exp_dir: Path) -> dict[str, Path]:
    """``manifest.csv`` and the tidy ``results.csv`` (+ ``results.parquet`` when pyarrow is importable)."""
    from slamcli.sweep.aggregate import typed_frame

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
    tmp = pq.with_name(f".{pq.name}.tmp-{os.getpid()}")
    # mixed-type object columns (e.g. None and str) are stored as strings so Arrow accepts them
    safe = tidy.copy()
    for col in safe.columns:
        if safe[col].dtype == object:
            kinds = {type(v) for v in safe[col] if v is not None and not (isinstance(v, float) and math.isnan(v))}
            if len(kinds) > 1:
                safe[col] = safe[col].map(lambda v: None if v is None else str(v))
    safe.to_parquet(tmp, index=False)
    os.replace(tmp, pq)
    out["parquet"] = pq
    return out


def _write_csv(df, path: Path) -> Path:
    tmp = path.with_name(f".{path.name}.tmp-{os.getpid()}")
    df.to_csv(tmp, index=False)
    os.replace(tmp, path)
    return path


def load_results(exp_dir: str | Path):
    """The tidy table of a finished sweep as a DataFrame."""
    import pandas as pd

    return pd.read_csv(Path(exp_dir) / "results.csv")
