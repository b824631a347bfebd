"""``reproduce``'s overlapped sections (``report._run_sections_overlapped``) with stand-in sections: a "sweep"
waits with the turn given up, as :meth:`Reproduction.run` does while the shared pool works; a "drawing" holds
the turn, as figures and tables do."""

from __future__ import annotations

import functools
import threading
import time

import pytest

from slamcli.reproduce.report import Reproduction, _run_sections_overlapped

#: how long a stand-in waits for something that must happen while it waits (generous: a loaded machine)
WAIT_S = 10.0


class StandIn(Reproduction):
    """Sections ``s0`` … ``s{n-1}``; each plans, sweeps (turn given up) and draws (turn held). ``s0``'s sweep
    waits until ``s1``'s sweep has started; ``fail`` names a section whose sweep raises."""

    def __init__(self, n: int, fail: int | None = None) -> None:  # no registry, no output folder
        self.turn = None
        self._local = threading.local()
        self.log = lambda s: None
        self.fail_at = fail
        self._count = threading.Lock()
        self.holding = self.most_holding = 0  # sections doing coordinator work now / at most
        self.open = self.most_open = 0  # sections started and not ended now / at most
        self.s1_sweeping = threading.Event()
        self.s0_saw_s1_sweep = False
        for i in range(n):
            setattr(self, f"s{i}", functools.partial(self._section, i))

    def _add(self, name: str, by: int) -> None:
        with self._count:
            setattr(self, name, getattr(self, name) + by)
            most = "most_" + name
            setattr(self, most, max(getattr(self, most), getattr(self, name)))

    def _coordinator_work(self) -> None:
        self._add("holding", 1)
        time.sleep(0.02)
        self._add("holding", -1)

    def _section(self, i: int):
        from slamcli.reproduce.report import Section

        self._add("open", 1)
        try:
            self._coordinator_work()  # planning the sweep
            with self._turn_given_up():
                if i == 1:
                    self.s1_sweeping.set()
                if i == 0:
                    self.s0_saw_s1_sweep = self.s1_sweeping.wait(WAIT_S)
                if i == self.fail_at:
                    raise RuntimeError(f"section {i} broke in its sweep")
                time.sleep(0.02)
            self._coordinator_work()  # drawing
            return Section(f"s{i}", f"section {i}")
        finally:
            self._add("open", -1)


def test_next_section_sweeps_while_one_waits_and_the_report_keeps_its_order():
    rep = StandIn(5)
    todo = [(f"s{i}", f"s{i}") for i in range(5)]
    sections = _run_sections_overlapped(todo, rep, time.perf_counter(), in_flight=2)
    assert [s.key for s in sections] == [k for k, _ in todo]
    assert all(s.ok for s in sections)
    assert rep.s0_saw_s1_sweep  # s1's sweep started while s0's was still in the pool
    assert rep.most_holding == 1  # coordinator work: one section at a time
    assert rep.most_open == 2  # never more than in_flight sections open, and that many when one waits


def test_a_section_that_raises_fails_alone():
    rep = StandIn(4, fail=2)
    sections = _run_sections_overlapped([(f"s{i}", f"s{i}") for i in range(4)], rep, time.perf_counter(),
                                        in_flight=3)
    assert [s.key for s in sections] == ["s0", "s1", "s2", "s3"]
    assert [s.ok for s in sections] == [True, True, False, True]
    assert "section 2 broke in its sweep" in sections[2].problems[0]
    assert rep.most_holding == 1 and rep.most_open <= 3


#: report rows that carry a clock (they differ between any two runs)
TIMING_ROWS = ("wall time", "per sample", "per ICM iteration")


@pytest.mark.slow
def test_overlapped_sections_give_the_one_worker_report(tmp_path):
    """Fig. 5, the initialisation study and Fig. 7 (the two read Fig. 5's initial maps) and the NEES section
    through a two-worker pool (overlapped) and in this process (one worker): the same table rows, and both
    comparisons with Fig. 5 made."""
    from slamcli.reproduce.report import reproduce

    rows = []
    for workers in (2, 1):
        out = reproduce(tmp_path / str(workers), quick=True, workers=workers, only=["fig5", "init", "fig7", "nees"])
        assert out.ok, out.failed
        text = out.report.read_text()
        assert "not compared" not in text
        rows.append([r for r in text.splitlines() if r.startswith("| ") and not any(t in r for t in TIMING_ROWS)])
    assert len(rows[0]) >= 40 and rows[0] == rows[1]


class Reader(StandIn):
    """``s0`` finds a value while drawing, after ``s2`` has finished its sweep; ``s2`` reads it after its own
    sweep, through :meth:`Reproduction.found_by` (``wait=True``) or directly."""

    def __init__(self, wait: bool) -> None:
        super().__init__(3)
        self.wait = wait
        self.found = self.read = None
        self.s2_swept = threading.Event()

    def _section(self, i: int):
        from slamcli.reproduce.report import Section

        with self._turn_given_up():
            if i == 0:
                self.s2_swept.wait(WAIT_S)
        if i == 0:
            self.found = "s0's value"
        if i == 2:
            self.s2_swept.set()
            self.read = self.found_by("s0", "found") if self.wait else self.found
        return Section(f"s{i}", f"section {i}")


def test_a_section_reads_what_an_earlier_one_found_only_after_waiting_for_it():
    todo = [(f"s{i}", f"s{i}") for i in range(3)]
    for wait in (True, False):
        rep = Reader(wait)
        _run_sections_overlapped(todo, rep, time.perf_counter(), in_flight=3)
        assert rep.read == ("s0's value" if wait else None)  # without waiting it reads before s0 found it
