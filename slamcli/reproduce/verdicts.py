"""Verdict rules of ``REPORT.md``: when a claim counts as reproduced, partly reproduced or not reproduced.

A claim is judged over n replicates (seeds or runs). Replicate i gives an effect e_i signed so that e_i > 0
means the claimed effect holds there (``e_i = error_before − error_after`` for "ICM lowers the error",
``e_i = bound − value`` for "the value stays below the bound"); k = #{i : e_i > 0}. With ē the mean effect and
s the sample standard deviation of the e_i:

* **reproduced**: k ≥ HOLDS_FRACTION · n, and the effect exceeds the replicate spread, ē > SPREAD_Z · s / √n
  (needs n ≥ 2), and ē ≥ the effect size the claim states when it states one;
* **partly reproduced**: not reproduced, but k > n / 2 (holds in a majority; this covers an effect that holds in
  ≥ 80 % of the replicates but is smaller than the spread or than the stated size);
* **not reproduced**: otherwise, with no replicate, or when a condition the claim states fails.

Only a paper's claims, judged on the paper's own configuration, get these verdicts. Our own hypotheses, and a
paper's claim judged on a configuration beyond the paper, are *findings*: the same rule, worded supported /
partly supported / not supported and counted apart. Everything here is a pure function of numbers.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Sequence
from dataclasses import dataclass

REPRODUCED, PARTLY, NOT_REPRODUCED = "reproduced", "partly reproduced", "not reproduced"
VERDICTS = (REPRODUCED, PARTLY, NOT_REPRODUCED)
#: finding wording of each verdict (our own hypotheses)
FINDING_WORDS = {REPRODUCED: "supported", PARTLY: "partly supported", NOT_REPRODUCED: "not supported"}
PAPER, FINDING = "paper", "finding"
#: fraction of replicates in which the effect must hold for "reproduced"
HOLDS_FRACTION = 0.8
#: the mean effect exceeds the replicate spread when ē > SPREAD_Z · s/√n (2 ≈ the normal two-sided 95 % quantile)
SPREAD_Z = 2.0
#: most decimals :func:`show` uses to tell two different numbers apart
MAX_DIGITS = 6


@dataclass(frozen=True)
class Evidence:
    """The numbers a verdict is computed from: k of n replicates hold, mean effect ē, spread SPREAD_Z·s/√n
    (NaN when n < 2), a stated condition's outcome (None = the claim states none) and a stated effect size."""

    n_hold: int
    n: int
    effect: float
    spread: float
    condition_ok: bool | None = None
    stated_effect: float | None = None


def _finite(x) -> bool:
    return x is not None and math.isfinite(float(x))


def evidence(effects: Iterable[float | None], *, holds: Sequence[bool] | None = None,
             condition_ok: bool | None = None, stated_effect: float | None = None) -> Evidence:
    """Evidence from per-replicate effects (non-finite ones dropped); ``holds`` overrides the e_i > 0 test."""
    e = [float(x) for x in effects if _finite(x)]
    n = len(e)
    k = sum(bool(h) for h in holds) if holds is not None else sum(x > 0 for x in e)
    mean = sum(e) / n if n else math.nan
    spread = math.nan
    if n >= 2:
        sd = math.sqrt(sum((x - mean) ** 2 for x in e) / (n - 1))
        spread = SPREAD_Z * sd / math.sqrt(n)
    return Evidence(k, n, mean, spread, condition_ok, stated_effect)


def paired(before: Sequence[float | None], after: Sequence[float | None]) -> list[tuple[float, float]]:
    """The (before, after) pairs where both numbers are finite, in order."""
    return [(float(b), float(a)) for b, a in zip(before, after) if _finite(b) and _finite(a)]


def drop_effects(before: Sequence[float | None], after: Sequence[float | None]) -> list[float]:
    """e_i = before_i − after_i over the finite pairs: > 0 where the quantity went down."""
    return [b - a for b, a in paired(before, after)]


def verdict(ev: Evidence) -> str:
    """The verdict of the module docstring's rule."""
    if ev.n == 0 or ev.condition_ok is False:
        return NOT_REPRODUCED
    large = math.isfinite(ev.spread) and ev.effect > ev.spread and (
        ev.stated_effect is None or ev.effect >= ev.stated_effect)
    if ev.n_hold >= HOLDS_FRACTION * ev.n and large:
        return REPRODUCED
    return PARTLY if 2 * ev.n_hold > ev.n else NOT_REPRODUCED


def worded(v: str, kind: str) -> str:
    """A verdict as printed: the verdict itself for a paper claim, supported / … for a finding."""
    return v if kind == PAPER else FINDING_WORDS[v]


def rule_text(ev: Evidence, unit: str, item: str = "seed") -> str:
    """Why the rule gave its verdict: the fraction holding and the mean effect against the spread ("" when no
    replicate has the numbers; the claim's own numbers then say so)."""
    if ev.n == 0:
        return ""
    items = f"{item}s" if ev.n != 1 else item
    text = f"holds in {ev.n_hold} of {ev.n} {items}"
    if math.isfinite(ev.spread):
        e, s = show(ev.effect, ev.spread)
        rel = ">" if ev.effect > ev.spread else "≤"
        text += f"; mean effect {e} {rel} spread {s} {unit} ({SPREAD_Z:g} × standard error)"
    else:
        text += f"; mean effect {show(ev.effect)[0]} {unit}, spread not measurable with one {item}"
    if ev.stated_effect is not None:
        text += f"; stated effect {show(ev.stated_effect)[0]} {unit}"
    return text


def digits_to_show(values: Sequence[float], base: int = 3) -> int:
    """The fewest decimals ≥ ``base`` (at most MAX_DIGITS) that print different finite values differently and
    no non-zero value as zero."""
    v = [float(x) for x in values if _finite(x)]
    for d in range(base, MAX_DIGITS + 1):
        shown: dict[str, float] = {}
        if all(shown.setdefault(f"{x:.{d}f}", x) == x and (x == 0 or float(f"{x:.{d}f}") != 0) for x in v):
            return d
    return MAX_DIGITS


def show(*values: float, base: int = 3) -> list[str]:
    """``values`` printed with :func:`digits_to_show` decimals ("n/a" for non-finite ones)."""
    d = digits_to_show(values, base)
    return [f"{float(x):.{d}f}" if _finite(x) else "n/a" for x in values]


@dataclass(frozen=True)
class Judgement:
    """One judged claim: what it says, paper claim or finding, its verdict (one of VERDICTS) and the numbers
    it rests on (``numbers``: measured values; ``rule``: :func:`rule_text`)."""

    what: str
    kind: str
    verdict: str
    numbers: str
    rule: str = ""

    @property
    def label(self) -> str:
        return worded(self.verdict, self.kind)

    def line(self) -> str:
        """The claim's line in its section: ``**Paper claim — what: verdict** (numbers; rule).``"""
        head = "Paper claim" if self.kind == PAPER else "Finding"
        basis = "; ".join(x for x in (self.numbers, self.rule) if x)
        return f"**{head} — {self.what}: {self.label}** ({basis})."


def judge(what: str, ev: Evidence, numbers: str, *, unit: str, kind: str = PAPER, item: str = "seed") -> Judgement:
    """A :class:`Judgement` whose verdict is the rule's on ``ev``."""
    return Judgement(what, kind, verdict(ev), numbers, rule_text(ev, unit, item))


def count(judgements: Iterable[Judgement]) -> dict[str, int]:
    """Paper claims per verdict, and the number of findings (key FINDING)."""
    out = {v: 0 for v in VERDICTS} | {FINDING: 0}
    for j in judgements:
        out[FINDING if j.kind == FINDING else j.verdict] += 1
    return out


def count_line(judgements: Iterable[Judgement]) -> str:
    """``Verdicts: 1 reproduced / 6 partly reproduced / 4 not reproduced paper claims; 2 findings.``"""
    c = count(judgements)
    return (f"Verdicts: {c[REPRODUCED]} reproduced / {c[PARTLY]} partly reproduced / {c[NOT_REPRODUCED]} not "
            f"reproduced paper claims; {c[FINDING]} finding{'s' if c[FINDING] != 1 else ''} of our own.")
