"""A finished sweep folder read by a section's renderer: ``results.csv`` rows and each run's files.

Renderers of ``slamcli reproduce`` never solve; they read what ``slamcli sweep`` wrote, the way ``evo_res``
reads result files.
"""

from __future__ import annotations

from pathlib import Path


class SweepRuns:
    """One finished sweep folder read the way ``evo_res`` reads result files: its ``results.csv`` rows by solver
    label, data entry and replicate, and each run's ``result.h5`` / ``dataset.h5``."""

    def __init__(self, exp_dir: Path) -> None:
        from slamcli.sweep.runner import load_results

        self.table = load_results(exp_dir)

    def rows(self, label: str, data: str | None = None, completed: bool = True):
        """Rows of solver ``label`` (and data entry ``data``), by replicate; only completed runs by default."""
        t = self.table[self.table["label"] == label]
        if data is not None:
            t = t[t["data"] == data]
        if completed:
            t = t[t["status"] == "completed"]
        return t.sort_values("replicate")

    def one(self, label: str, data: str | None = None, replicate: int | None = None, completed: bool = True):
        """The row of one run (the first replicate when ``replicate`` is None); KeyError when absent."""
        t = self.rows(label, data, completed)
        if replicate is not None:
            t = t[t["replicate"] == replicate]
        if t.empty:
            raise KeyError(f"no {'completed ' if completed else ''}run {label!r} {data or ''} {replicate or ''}")
        return t.iloc[0]

    def result(self, label: str, data: str | None = None, replicate: int | None = None, completed: bool = True):
        from slamcli.io import read_result

        return read_result(Path(self.one(label, data, replicate, completed)["path"]) / "result.h5")

    def dataset(self, label: str, data: str | None = None, replicate: int | None = None, completed: bool = True):
        from slamcli.io import read_dataset

        return read_dataset(Path(self.one(label, data, replicate, completed)["path"]) / "dataset.h5")


def run_experiments(rep, sec, names, expected_failures: frozenset[str] = frozenset()) -> dict[str, Path]:
    """Run the shipped experiments ``names`` with ``rep.run`` (the
    :class:`~slamcli.reproduce.report.Reproduction`: resumable, ``-j N``), noting missing solvers and failed runs
    in section ``sec`` (not the failures of an experiment in ``expected_failures``); returns ``{name: sweep
    folder}``."""
    dirs = {}
    for name in names:
        outcome = rep.run(f"{name}.toml")
        rep._missing_note(sec, outcome)
        if name not in expected_failures:
            rep._failures_note(sec, outcome)
        dirs[name] = outcome.exp_dir
    return dirs


def finish_section(sec, text: str | None, ok: bool, why: str):
    """Add a renderer's markdown ``text`` (None: nothing rendered) to section ``sec``, fail it with ``why`` when
    not ``ok``, and mark a failed section's title; returns ``sec``."""
    if text is not None:
        sec.add(text.strip())
    if not ok:
        sec.fail(why)
    if not sec.ok:
        sec.title += " — FAILED"
    return sec
