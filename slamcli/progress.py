"""Progress for a log: plain text lines at a bounded rate, for long work whose output is not a terminal.

A live progress bar redraws one line in place, which a file or a pipe cannot show (the log stays empty until
the end). :class:`ProgressLines` instead writes a line such as::

    solve ekf: 40% (400/1000) 35.2/s, 11 s elapsed, ETA 17 s

when the work starts, each time it crosses another ``every_frac`` of its total (default every 10 %) or ``every_s`` seconds
(default 10 s) after the previous line, whichever comes first, and once at the end. Rate and ETA count only
the work done since the first report, so work skipped at the start (a resumed sweep) does not inflate them.
Standard library only.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable

#: a line when the work has advanced by this fraction of its total since the last line
EVERY_FRAC = 0.1
#: rounding slack on the fraction test (ten reports of 1/10 add up to slightly less than 1/10 each)
FRAC_SLACK = 1e-12
#: s. A line when this long has passed since the last one (a report is needed to print it)
EVERY_S = 10.0


def format_duration(seconds: float) -> str:
    """``7 s``, ``3 min 05 s``, ``2 h 04 min``: a duration rounded to what a reader of a log needs."""
    s = max(0, int(round(seconds)))
    if s < 60:
        return f"{s} s"
    if s < 3600:
        return f"{s // 60} min {s % 60:02d} s"
    return f"{s // 3600} h {s % 3600 // 60:02d} min"


class ProgressLines:
    """A ``progress(done, total, note="")`` callback that writes a plain line at a bounded rate.

    Parameters
    ----------
    label : text that starts every line (``solve ekf``, ``sweep compare``).
    write : called with each line (no trailing newline), e.g. ``lambda s: print(s, file=sys.stderr)``.
    unit : noun after the counts (``runs``); empty for unnamed steps.
    every_frac, every_s : the two triggers of a new line (see the module docstring).
    clock : monotonic seconds (injectable for tests).
    """

    def __init__(self, label: str, write: Callable[[str], None], *, unit: str = "", every_frac: float = EVERY_FRAC,
                 every_s: float = EVERY_S, clock: Callable[[], float] = time.monotonic) -> None:
        self.label, self.write, self.unit = label, write, unit
        self.every_frac, self.every_s, self.clock = every_frac, every_s, clock
        self._start: tuple[float, int] | None = None  # (time, done) of the first report
        self._last: tuple[float, float] | None = None  # (time, fraction) of the last line written
        self._ended = False

    def __call__(self, done: int, total: int, note: str = "") -> None:
        now = self.clock()
        if self._start is None:
            self._start = (now, done)
        if self._ended or total <= 0:
            return
        frac = min(done / total, 1.0)
        end = done >= total
        due = self._last is None or end or (
            frac - self._last[1] >= self.every_frac - FRAC_SLACK or now - self._last[0] >= self.every_s)
        if not due:
            return
        self._last = (now, frac)
        self._ended = end
        self.write(self.line(done, total, now, note))

    def line(self, done: int, total: int, now: float, note: str = "") -> str:
        """The text of one line at time ``now`` (``rate = work since the first report / time since it``)."""
        t0, done0 = self._start if self._start is not None else (now, 0)
        elapsed = now - t0
        rate = (done - done0) / elapsed if elapsed > 0 else math.nan
        unit = f" {self.unit}" if self.unit else ""
        counts = f"{done}/{total}{unit}" + (f"; {note}" if note else "")
        text = f"{self.label}: {math.floor(100 * done / total):d}% ({counts})"
        if rate > 0:
            text += f" {rate:.0f}{unit}/s" if rate >= 100 else f" {rate:.3g}{unit}/s"
        text += f", {format_duration(elapsed)} elapsed"
        if done >= total:
            return text + ", done"
        if rate > 0:
            text += f", ETA {format_duration((total - done) / rate)}"
        return text
