"""Docstrings say what a thing is in a few lines, and the code carries no issue history.

Every module, class and function docstring under ``slamcli/`` is at most :data:`MAX_LINES` lines, and no
source line names an issue ("issue 22", "(Issue 25)", "issues 21/22"); measurements and history live in
``benchmarks/results/*.md`` and the commit log. ``python tests/meta/test_docstrings.py`` prints the offenders.
"""

from __future__ import annotations

import ast
import re
import sys
from pathlib import Path

SLAMCLI = Path(__file__).resolve().parents[2] / "slamcli"
MAX_LINES = 25
ISSUE = re.compile(r"\bissues?\s*#?\d", re.IGNORECASE)



def _docstring_nodes(tree: ast.Module):
    """``(qualified name, node)`` of the module ("" ) and of every class and function, nested ones too."""
    yield "", tree
    todo = [("", tree)]
    while todo:
        prefix, node = todo.pop()
        for child in ast.iter_child_nodes(node):
            if isinstance(child, ast.ClassDef | ast.FunctionDef | ast.AsyncFunctionDef):
                name = prefix + child.name
                yield name, child
                todo.append((name + ".", child))


def long_docstrings(root: Path, max_lines: int = MAX_LINES) -> list[str]:
    """``"file:QualName (n lines)"`` of every docstring over ``max_lines`` lines under ``root``."""
    out = []
    for path in sorted(root.rglob("*.py")):
        rel = path.relative_to(root).as_posix()
        for qualname, node in _docstring_nodes(ast.parse(path.read_text(), filename=str(path))):
            doc = ast.get_docstring(node)  # cleaned: no leading/trailing blank lines
            if doc is None:
                continue
            n = len(doc.splitlines())
            if n > max_lines:
                out.append(f"{rel}:{qualname or '<module>'} ({n} lines)")
    return out


def issue_mentions(root: Path) -> list[str]:
    """``"file:line: text"`` of every source line under ``root`` that names an issue by number."""
    out = []
    for path in sorted(root.rglob("*.py")):
        rel = path.relative_to(root).as_posix()
        for i, line in enumerate(path.read_text().splitlines(), 1):
            if ISSUE.search(line):
                out.append(f"{rel}:{i}: {line.strip()}")
    return out


def test_checker_counts_docstring_lines_of_modules_classes_and_nested_functions(tmp_path):
    five = '"""a\nb\nc\nd\ne"""'
    (tmp_path / "m.py").write_text(
        f"{five}\n\nclass C:\n    {five}\n\n    def f(self):\n        def g():\n            {five}\n"
        "\n\ndef short():\n    '''one\n    two'''\n")
    assert long_docstrings(tmp_path, max_lines=4) == [
        "m.py:<module> (5 lines)", "m.py:C (5 lines)", "m.py:C.f.g (5 lines)"]
    assert long_docstrings(tmp_path, max_lines=5) == []


def test_checker_finds_issue_numbers_in_any_spelling(tmp_path):
    (tmp_path / "m.py").write_text(
        "x = 1  # issue 22\n# (Issue 25)\n'''see issues 21/22'''\n# issue #7\n# an issue with 3 files\n")
    assert [s.split(":")[1] for s in issue_mentions(tmp_path)] == ["1", "2", "3", "4"]


def test_no_docstring_in_slamcli_over_the_limit():
    assert long_docstrings(SLAMCLI) == []


def test_no_issue_numbers_in_slamcli():
    assert issue_mentions(SLAMCLI) == []


def main() -> int:
    rows = long_docstrings(SLAMCLI) + issue_mentions(SLAMCLI)
    print("\n".join(rows))
    print(f"{len(rows)} finding(s)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
