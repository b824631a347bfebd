"""Functions a reader can hold in view: every function of ``slamcli/`` over :data:`LIMIT` lines, and whose room it
is in (issue 21: "no function in slamcli/ over 120 lines except where its docstring says why").

``python tests/meta/test_function_length.py`` prints the list. The tests check the lister on hand-written sources,
and fail when a function over the limit appears in the restructuring's own rooms (:data:`ARCH_ROOMS`) without a
docstring sentence ``Long because ...``; the other rooms' long drivers are listed, not failed, so that their
owners split them on their own branches.
"""

from __future__ import annotations

import ast
import sys
from pathlib import Path

SLAMCLI = Path(__file__).resolve().parents[2] / "slamcli"
LIMIT = 120
EXCUSE = "Long because"

#: path prefix (relative to slamcli/) -> the room that owns the file (the session's room list); first match wins
ROOMS: tuple[tuple[str, str], ...] = (
    ("solvers/nls", "graph"), ("solvers/graph", "graph"), ("solvers/frontend.py", "graph"),
    ("solvers/pose_init.py", "graph"), ("datasets/g2o.py", "graph"),
    ("solvers/icm", "icm-sim / icm-real"),
    ("solvers/ekf.py", "filters"), ("solvers/fastslam.py", "filters"), ("solvers/odometry.py", "filters"),
    ("solvers/resampling.py", "filters"),
    ("solvers/cuik", "papers"), ("solvers/hybrid", "papers"), ("sim/bounded.py", "papers"),
    ("reproduce/paper001.py", "papers"), ("reproduce/paper004.py", "papers"),
    ("reproduce/real", "icm-real"),
    ("datasets/victoria_park.py", "faults"), ("datasets/carpark.py", "faults"),
    ("plots", "figures"), ("metrics", "figures"),
    ("", "arch"),
)
ARCH_ROOMS = ("arch",)


def long_functions(root: Path, limit: int = LIMIT) -> list[tuple[int, str, str, bool]]:
    """``(lines, file relative to root, qualified name, excused)`` of every function (methods and nested
    functions too) longer than ``limit`` lines, longest first; ``excused``: its docstring says why."""
    out = []
    for path in sorted(root.rglob("*.py")):
        rel = path.relative_to(root).as_posix()

        def walk(node: ast.AST, prefix: str) -> None:
            for ch in ast.iter_child_nodes(node):
                if isinstance(ch, ast.FunctionDef | ast.AsyncFunctionDef):
                    n = ch.end_lineno - ch.lineno + 1
                    if n > limit:
                        out.append((n, rel, prefix + ch.name, EXCUSE in (ast.get_docstring(ch) or "")))
                    walk(ch, f"{prefix}{ch.name}.")
                elif isinstance(ch, ast.ClassDef):
                    walk(ch, f"{prefix}{ch.name}.")

        walk(ast.parse(path.read_text(), filename=str(path)), "")
    return sorted(out, key=lambda r: (-r[0], r[1], r[2]))


def room_of(rel: str) -> str:
    return next(room for prefix, room in ROOMS if rel.startswith(prefix))


def test_lister_counts_def_to_last_line_of_methods_and_nested_functions(tmp_path):
    body = "\n".join(f"    x{i} = {i}" for i in range(5))
    body8 = "\n".join(f"        y{i} = {i}" for i in range(5))
    (tmp_path / "m.py").write_text(
        f"def short():\n{body}\n\n"  # 6 lines
        f"class C:\n    def method(self):\n        '''Long because the test says so.'''\n{body8}\n{body8}\n\n"
        f"def outer():\n    def inner():\n{body8}\n{body8}\n    return inner\n")
    got = long_functions(tmp_path, limit=6)
    # by hand: method = def + docstring + 10 lines = 12; inner = def + 10 = 11; outer = def + inner + return = 13
    assert got == [(13, "m.py", "outer", False), (12, "m.py", "C.method", True), (11, "m.py", "outer.inner", False)]


def test_no_unexcused_long_function_in_the_arch_rooms():
    bad = [f"{rel}:{name} ({n} lines)" for n, rel, name, excused in long_functions(SLAMCLI)
           if room_of(rel) in ARCH_ROOMS and not excused]
    assert bad == []


def main() -> int:
    rows = long_functions(SLAMCLI)
    for n, rel, name, excused in rows:
        print(f"{n:4d}  {room_of(rel):18s}  slamcli/{rel}:{name}{'  (docstring says why)' if excused else ''}")
    print(f"{len(rows)} function(s) over {LIMIT} lines")
    return 0


if __name__ == "__main__":
    sys.exit(main())
