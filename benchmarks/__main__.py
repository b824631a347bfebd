"""Run benchmarks and write a small results table per benchmark (CSV) plus a printed summary."""

from __future__ import annotations

import argparse
import csv
import importlib
import pkgutil
import sys
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent


def discover() -> list[str]:
    return sorted(m.name[len("bench_"):] for m in pkgutil.iter_modules([str(HERE)]) if m.name.startswith("bench_"))


def write_rows(name: str, rows: list[dict]) -> Path:
    out_dir = HERE / "results"
    out_dir.mkdir(exist_ok=True)
    path = out_dir / f"{name}.csv"
    tmp = path.with_suffix(".csv.tmp")
    keys: list[str] = []
    for r in rows:
        keys += [k for k in r if k not in keys]
    with tmp.open("w", newline="") as fh:
        w = csv.DictWriter(fh, fieldnames=keys)
        w.writeheader()
        w.writerows(rows)
    tmp.replace(path)
    return path


def _fmt(v) -> str:
    return f"{v:.4g}" if isinstance(v, float) else str(v)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="python -m benchmarks")
    ap.add_argument("names", nargs="*", help=f"benchmarks to run (default: all of {', '.join(discover())})")
    ap.add_argument("--quick", action="store_true", help="smaller problem sizes (smoke check)")
    args = ap.parse_args(argv)
    names = args.names or discover()
    unknown = [n for n in names if n not in discover()]
    if unknown:
        print(f"error: unknown benchmark(s) {', '.join(unknown)}; available: {', '.join(discover())}", file=sys.stderr)
        return 2
    from rich.console import Console

    console = Console()
    for name in names:
        mod = importlib.import_module(f"benchmarks.bench_{name}")
        t0 = time.perf_counter()
        rows = mod.run(quick=args.quick)
        path = write_rows(name, rows)
        console.rule(f"[bold]{name}[/]  {time.perf_counter() - t0:.1f} s  →  {path.relative_to(HERE.parent)}")
        # Benchmark rows are wide (many measured columns): print one "key = value" block per row so that the
        # summary stays readable in any terminal; the CSV holds the same numbers for machines.
        for i, r in enumerate(rows):
            cells = [f"{k}={_fmt(v)}" for k, v in r.items() if v not in ("", None)]
            console.print(f"[{i}] " + "  ".join(cells), highlight=False, soft_wrap=False)
    return 0


if __name__ == "__main__":
    sys.exit(main())
