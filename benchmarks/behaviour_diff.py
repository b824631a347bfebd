"""Behaviour diff: solve a fixed set of runs and compare two such sets file by file (issue 21).

A restructuring is "behaviour unchanged" when the same commands on the same inputs write the same files.
``run`` builds a fixed set of datasets with fixed seeds — the simulated ``loop``, ``paper-sim1``,
``cuik-room`` and ``hybrid-map1`` scenarios, the intel pose-graph excerpt and the MRCLAM excerpt of
``tests/data`` — and solves each with every registered solver through the command line (``python -m slamcli``,
so the CLI shells, the api and the solvers are all exercised). A solver that refuses a dataset with a one-line
error is recorded as such (``<dataset>__<solver>.refused.txt`` holds the line), not as a failure of the
harness. ``compare A B`` runs :func:`slamcli.io.diff.diff_files` (``slamcli diff``) on every pair of result
and dataset files, compares the refusal lines as text, prints one table row per file and exits 1 when any
differs or is missing on one side.

Runs that would take longer than ~20 s are shortened with ``--set`` (simulator) or ``-p`` (solver); the
whole set takes a few CPU minutes. Files record absolute paths (a result its dataset's, an import its source
folder), so every run works in one fixed scratch folder, :data:`SCRATCH` under the system's temporary
directory, with copies of the two excerpts, and copies the files into ``--out`` at the end: runs from two
clones then write the same paths. One run at a time (a second refuses while the first is alive). ``--quick`` keeps ``loop``, ``cuik-room`` and the two excerpts only (a
smoke check; compare a quick run only with a quick run).

Usage::

    python -m benchmarks.behaviour_diff run --out DIR [--quick]
    python -m benchmarks.behaviour_diff compare A B
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass, field
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
DATA = ROOT / "tests" / "data"
MANIFEST = "manifest.json"
#: the fixed working folder of every run (see the module docstring)
SCRATCH = Path(tempfile.gettempdir()) / "slamcli-behaviour-diff"


@dataclass(frozen=True)
class Case:
    """One dataset of the fixed set: the CLI arguments that make it, and per-solver ``-p`` shortenings."""

    name: str
    make: tuple[str, ...]  # slamcli arguments before ``-o PATH``
    solver_params: dict[str, tuple[str, ...]] = field(default_factory=dict)
    quick: bool = True


CASES: tuple[Case, ...] = (
    Case("loop", ("simulate", "-s", "loop", "--seed", "3")),
    Case(
        "paper-sim1",
        ("simulate", "-s", "paper-sim1", "--seed", "1", "--set", "n_steps=300"),
        {"icm": ("max_sweeps=10",), "fastslam": ("n_particles=10",)},
        quick=False,
    ),
    Case("cuik-room", ("simulate", "-s", "cuik-room", "--seed", "2")),
    Case(
        "hybrid-map1",
        # paper001's quick variant of Map 1 (40 x 40 m, 60 beams, 1 m cells), one lap
        ("simulate", "-s", "hybrid-map1", "--seed", "1", "--set", "walls.width=40", "--set", "walls.height=40",
         "--set", "walls.corridor=8", "--set", "walls.resolution=1.0", "--set", "sensor.n_beams=60",
         "--set", "walls.laps=1"),
        {"fastslam": ("n_particles=10",), "icm": ("max_sweeps=10",)},
        quick=False,
    ),
    Case("intel", ("import", "g2o", str(SCRATCH / "inputs" / "intel_excerpt.g2o"))),
    Case("mrclam", ("import", "mrclam", str(SCRATCH / "inputs" / "mrclam_excerpt"), "--robot", "1")),
)

SOLVER_SEED = "0"


def _slamcli(args: list[str]) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "slamcli", *args], capture_output=True, text=True, cwd=ROOT)


def _one_line(proc: subprocess.CompletedProcess, out: Path) -> str:
    """The last non-empty line of the output, with the run's own folder replaced by ``OUT`` (so that two runs
    written to different folders compare equal)."""
    lines = [ln for ln in (proc.stderr + proc.stdout).splitlines() if ln.strip()]
    line = lines[-1].strip() if lines else f"exit {proc.returncode} with no message"
    return line.replace(str(out), "OUT")


def _solver_names() -> list[str]:
    from slamcli.solvers.registry import names

    return names()


def _claim_scratch() -> None:
    """Empty :data:`SCRATCH` and put fresh copies of the excerpts in it; refuse while another run lives."""
    pid_file = SCRATCH / "pid"
    if pid_file.exists():
        try:
            os.kill(int(pid_file.read_text()), 0)
            raise SystemExit(f"error: {SCRATCH} is in use by process {pid_file.read_text().strip()}")
        except (ProcessLookupError, ValueError):
            pass
    shutil.rmtree(SCRATCH, ignore_errors=True)
    (SCRATCH / "inputs").mkdir(parents=True)
    pid_file.write_text(str(os.getpid()))
    shutil.copy2(DATA / "intel_excerpt.g2o", SCRATCH / "inputs")
    shutil.copytree(DATA / "mrclam_excerpt", SCRATCH / "inputs" / "mrclam_excerpt")


def run(out: Path, quick: bool) -> int:
    """Make every dataset of the set, solve it with every solver in :data:`SCRATCH`, then copy the files and a
    manifest of timings into ``out``."""
    out.mkdir(parents=True, exist_ok=True)
    _claim_scratch()
    try:
        return _run_all(quick)
    finally:
        for f in SCRATCH.iterdir():
            if f.suffix in (".h5", ".txt", ".json"):
                shutil.copy2(f, out / f.name)
        shutil.rmtree(SCRATCH, ignore_errors=True)


def _run_all(quick: bool) -> int:
    work = SCRATCH
    solvers = _solver_names()
    manifest: dict[str, dict] = {}
    bad = 0
    for case in CASES:
        if quick and not case.quick:
            continue
        data = work / f"{case.name}.h5"
        t0 = time.perf_counter()
        proc = _slamcli([*case.make, "-q", "-o", str(data)])
        manifest[case.name] = {"args": list(case.make), "exit": proc.returncode,
                               "wall_s": round(time.perf_counter() - t0, 2)}
        print(f"{case.name:12s} {'':9s} exit {proc.returncode}  {manifest[case.name]['wall_s']:7.1f} s", flush=True)
        if proc.returncode != 0:
            print(f"  error: {_one_line(proc, work)}", file=sys.stderr)
            bad += 1
            continue
        for solver in solvers:
            key = f"{case.name}__{solver}"
            params = [a for p in case.solver_params.get(solver, ()) for a in ("-p", p)]
            t0 = time.perf_counter()
            proc = _slamcli(["solve", str(data), "-m", solver, *params, "--seed", SOLVER_SEED, "-q",
                             "-o", str(work / f"{key}.h5")])
            wall = round(time.perf_counter() - t0, 2)
            entry = {"params": params, "exit": proc.returncode, "wall_s": wall}
            if proc.returncode != 0:
                line = _one_line(proc, work)
                entry["refused"] = line
                (work / f"{key}.refused.txt").write_text(line + "\n")
                if "Traceback" in proc.stderr:
                    bad += 1
            manifest[key] = entry
            status = "ok" if proc.returncode == 0 else f"refused: {entry['refused'][:70]}"
            print(f"{case.name:12s} {solver:9s} exit {proc.returncode}  {wall:7.1f} s  {status}", flush=True)
    (work / MANIFEST).write_text(json.dumps(manifest, indent=1) + "\n")
    return 1 if bad else 0


def _compare_file(a: Path, b: Path) -> tuple[bool, str]:
    if not a.exists() or not b.exists():
        return False, f"only in {'A' if a.exists() else 'B'}"
    if a.suffix == ".txt":
        same = a.read_text() == b.read_text()
        return same, "same refusal" if same else f"{a.read_text().strip()!r} vs {b.read_text().strip()!r}"
    from slamcli.io.diff import diff_files

    d = diff_files(a, b)
    return d.same, d.summary("A", "B") if not d.same else f"all {d.n_compared} fields equal"


def compare(a_dir: Path, b_dir: Path) -> int:
    """One row per file of either run; exit 1 if any pair differs or a file is missing on one side."""
    names = sorted({p.name for d in (a_dir, b_dir) for p in d.iterdir() if p.suffix in (".h5", ".txt")})
    if not names:
        print(f"error: no result files in {a_dir} or {b_dir}", file=sys.stderr)
        return 2
    n_diff = 0
    width = max(len(n) for n in names)
    for name in names:
        same, why = _compare_file(a_dir / name, b_dir / name)
        n_diff += not same
        print(f"{name:{width}s}  {'identical' if same else 'DIFFERENT'}  {why}")
    print(f"{len(names) - n_diff} of {len(names)} files identical")
    return 1 if n_diff else 0


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="python -m benchmarks.behaviour_diff", description=__doc__.split("\n")[0])
    sub = ap.add_subparsers(dest="cmd", required=True)
    r = sub.add_parser("run", help="make and solve the fixed set of runs")
    r.add_argument("--out", type=Path, required=True)
    r.add_argument("--quick", action="store_true", help="loop, cuik-room and the two excerpts only")
    c = sub.add_parser("compare", help="diff two runs file by file")
    c.add_argument("a", type=Path)
    c.add_argument("b", type=Path)
    args = ap.parse_args(argv)
    if args.cmd == "run":
        return run(args.out, args.quick)
    return compare(args.a, args.b)


if __name__ == "__main__":
    raise SystemExit(main())
