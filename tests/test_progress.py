"""Plain progress lines for logs (:mod:`slamcli.progress`): when a line is written, and its rate and ETA, checked
against a fake clock whose rate and remaining time are known in closed form."""

from __future__ import annotations

import re

import pytest

from slamcli.progress import EVERY_S, ProgressLines, format_duration

LINE_RE = re.compile(r"^(?P<label>.+): (?P<pct>\d+)% \((?P<done>\d+)/(?P<total>\d+)")


class Clock:
    def __init__(self) -> None:
        self.t = 0.0

    def __call__(self) -> float:
        return self.t


def _run(reports, **kw):
    """Feed ``(time, done, total)`` reports; returns the lines written."""
    clock, lines = Clock(), []
    progress = ProgressLines("solve ekf", lines.append, clock=clock, **kw)
    for t, done, total in reports:
        clock.t = t
        progress(done, total)
    return lines


def test_a_steady_job_gets_a_line_per_tenth_with_its_rate_and_eta():
    # 1000 steps at exactly 100 steps/s, reported every step: rate 100/s, ETA (1000 - done) / 100 s
    lines = _run((0.01 * i, i, 1000) for i in range(1001))
    pcts = [int(LINE_RE.match(ln)["pct"]) for ln in lines]
    assert pcts == [0, 10, 20, 30, 40, 50, 60, 70, 80, 90, 100]
    for ln in lines[1:-1]:
        done = int(LINE_RE.match(ln)["done"])
        assert " 100/s," in ln
        assert ln.endswith(f"ETA {format_duration((1000 - done) / 100)}")
    assert lines[-1] == "solve ekf: 100% (1000/1000) 100/s, 10 s elapsed, done"


def test_a_slow_job_gets_a_line_every_interval_and_no_more():
    # one step per second of 1000: the 10 % trigger never fires within 95 s, the time trigger every EVERY_S
    lines = _run((float(i), i, 1000) for i in range(96))
    assert len(lines) == 1 + int(95 // EVERY_S)
    times = [int(LINE_RE.match(ln)["done"]) for ln in lines]  # done == seconds here
    assert all(b - a == EVERY_S for a, b in zip(times, times[1:]))
    assert "1/s" in lines[-1] and lines[-1].endswith(f"ETA {format_duration(1000 - times[-1])}")


def test_rate_counts_only_work_after_the_first_report_and_the_end_is_written_once():
    # a resumed sweep: 6 of 16 runs skipped at start, then 10 runs in 200 s → 0.05 runs/s
    clock, lines = Clock(), []
    progress = ProgressLines("sweep x", lines.append, unit="runs", clock=clock)
    progress(6, 16, "6 skipped")
    clock.t = 100.0
    progress(11, 16)
    clock.t = 200.0
    progress(16, 16)
    progress(16, 16)
    assert lines == ["sweep x: 37% (6/16 runs; 6 skipped), 0 s elapsed",
                     "sweep x: 68% (11/16 runs) 0.05 runs/s, 1 min 40 s elapsed, ETA 1 min 40 s",
                     "sweep x: 100% (16/16 runs) 0.05 runs/s, 3 min 20 s elapsed, done"]


@pytest.mark.parametrize(("seconds", "text"), [(0.4, "0 s"), (59.4, "59 s"), (60, "1 min 00 s"),
                                               (3599, "59 min 59 s"), (3600 + 5 * 60 + 29, "1 h 05 min")])
def test_format_duration(seconds, text):
    assert format_duration(seconds) == text
