"""``python -m benchmarks.faults``: the fault campaign of issue 23, with its totals (cases, clean errors,
tracebacks, data loss) printed and written to ``benchmarks/results/faults.csv``.

The cases live in ``tests/bad_input/fault_campaign.py`` (the test suite runs the same campaign, see
``tests/bad_input/test_bad_input_faults.py``); this entry point only runs them outside pytest.
"""

from __future__ import annotations

import sys
import tempfile
from pathlib import Path

TESTS = Path(__file__).resolve().parent.parent / "tests" / "bad_input"


def run(quick: bool = False) -> list[dict]:
    sys.path.insert(0, str(TESTS))
    from fault_campaign import report, run_campaign

    with tempfile.TemporaryDirectory() as d:
        t = run_campaign(Path(d))
    print(report(t))
    for line in t["problems"]:
        print(" ", line)
    return [{"cases": t["cases"], **{f"family_{k}": v for k, v in t["families"].items()},
             "clean_errors": t["clean"], "tracebacks": t["traceback"], "data_loss": t["loss"],
             "other_problems": t["unclear"], "peak_rss_mb": round(t["peak_mb"], 1), "tmpfs": t["tmpfs"],
             "wall_s": round(t["wall_s"], 1)}]


if __name__ == "__main__":
    from benchmarks.__main__ import write_rows

    rows = run()
    print(f"wrote {write_rows('faults', rows)}")
    sys.exit(0 if rows[0]["tracebacks"] == rows[0]["data_loss"] == rows[0]["other_problems"] == 0 else 1)
