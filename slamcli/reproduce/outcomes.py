"""Outcome sentences of ``REPORT.md``, computed from a run's numbers.

Every function takes the measured numbers and returns one sentence whose verdict follows from a stated
condition (the condition is part of the sentence, so a reader can check it against the tables). Nothing here
reads files or knows the paper's wording; ``tests/test_reproduce_outcomes.py`` feeds numbers on both sides of
every condition and checks that the wording flips.
"""

from __future__ import annotations

import math
from collections.abc import Sequence


def _finite(xs) -> list[float]:
    return [float(x) for x in xs if x is not None and math.isfinite(float(x))]


def mean_sd(xs) -> tuple[float, float, int]:
    """Mean, population standard deviation and count of the finite values (NaN, NaN, 0 when none)."""
    v = _finite(xs)
    if not v:
        return math.nan, math.nan, 0
    m = sum(v) / len(v)
    return m, math.sqrt(sum((a - m) ** 2 for a in v) / len(v)), len(v)


def pm(xs, digits: int = 3) -> str:
    """``"m ± s"`` over the finite values, or ``"n/a"``."""
    m, s, n = mean_sd(xs)
    return "n/a" if n == 0 else f"{m:.{digits}f} ± {s:.{digits}f}"


def lowers(before: Sequence[float], after: Sequence[float], what: str, who: str = "ICM", unit: str = "m",
           item: str = "seed") -> str:
    """Paired comparison per ``item`` (seed or run): "lowers" when ``after < before`` in every one, "does not
    lower" when in none, "lowers in k of N" otherwise."""
    pairs = [(float(b), float(a)) for b, a in zip(before, after)
             if b is not None and a is not None and math.isfinite(float(b)) and math.isfinite(float(a))]
    n = len(pairs)
    if n == 0:
        return f"No {item} has both numbers, so whether {who} lowers the {what} cannot be said."
    k = sum(a < b for b, a in pairs)
    mb, _, _ = mean_sd([b for b, _ in pairs])
    ma, _, _ = mean_sd([a for _, a in pairs])
    nums = f"{mb:.3f} → {ma:.3f} {unit} (mean over {n} {item}{'s' if n > 1 else ''})"
    if k == n:
        verdict = f"{who} lowers the {what} in every {item}"
    elif k == 0:
        verdict = f"{who} does not lower the {what} in any {item}"
    else:
        verdict = f"{who} lowers the {what} in {k} of {n} {item}s only"
    return f"{verdict}: {nums}."


def versus_paper(ours: Sequence[float], paper: float, what: str, unit: str = "m") -> str:
    """Our mean against the paper's single value: below / above / equal (to the printed precision)."""
    m, s, n = mean_sd(ours)
    if n == 0:
        return f"No completed run gives a {what} to compare with the paper's {paper:g} {unit}."
    rel = "below" if m < paper else ("above" if m > paper else "equal to")
    return f"Our {what} {m:.3f} ± {s:.3f} {unit} ({n} seed{'s' if n > 1 else ''}) is {rel} the paper's {paper:g} {unit}."


def faster(iters_a: Sequence[int | None], iters_b: Sequence[int | None], name_a: str, name_b: str,
           criterion: str, n_max: int) -> str:
    """Which configuration meets ``criterion`` in fewer iterations (seed means; a seed that never meets it
    counts as ``n_max + 1``). "faster" needs a strictly smaller mean."""
    def cost(xs):
        v = [n_max + 1 if x is None else int(x) for x in xs]
        return (sum(v) / len(v) if v else math.nan), sum(x is None for x in xs), len(v)

    a, na, la = cost(iters_a)
    b, nb, lb = cost(iters_b)
    if la == 0 or lb == 0:
        return f"No completed runs of both {name_a} and {name_b}; convergence speed not compared."
    if na == la and nb == lb:
        return (f"Neither {name_a} nor {name_b} reaches {criterion} within {n_max} iterations, so neither "
                "converges faster by this measure.")
    detail = (f"mean first iteration with {criterion}: {a:.1f} vs {b:.1f} (a seed that never reaches it counts "
              f"as {n_max + 1})")
    if a < b:
        return f"{name_a} converges faster than {name_b} ({detail})."
    if a > b:
        return f"{name_a} converges slower than {name_b} ({detail})."
    return f"{name_a} and {name_b} converge equally fast ({detail})."


def stays_close(before: Sequence[float], after: Sequence[float], rel_tol: float, what: str) -> str:
    """"stays close to its initialisation" when the mean |after − before| ≤ rel_tol · mean(before)."""
    pairs = [(float(b), float(a)) for b, a in zip(before, after)
             if b is not None and a is not None and math.isfinite(float(b)) and math.isfinite(float(a))]
    if not pairs:
        return "No seed has both numbers; whether ICM stays close to its initialisation cannot be said."
    d = sum(abs(a - b) for b, a in pairs) / len(pairs)
    ref = sum(b for b, _ in pairs) / len(pairs)
    cond = f"mean |change| of the {what} {d:.3f} m vs {100 * rel_tol:.0f} % of its initial {ref:.3f} m"
    if d <= rel_tol * ref:
        return f"ICM converges close to its initialisation ({cond})."
    return f"ICM moves away from its initialisation ({cond})."


def within_bound(values: Sequence[float], bound: float, what: str, unit: str) -> str:
    """"stays below" when the largest value over seeds is < bound."""
    v = _finite(values)
    if not v:
        return f"No completed run gives the {what}."
    mx = max(v)
    if mx < bound:
        return f"The {what} stays below the paper's {bound:g} {unit} in every seed (largest {mx:.3g} {unit})."
    k = sum(x >= bound for x in v)
    return f"The {what} reaches or exceeds the paper's {bound:g} {unit} in {k} of {len(v)} seeds (largest {mx:.3g} {unit})."


def ratio(a: Sequence[float], b: Sequence[float], name_a: str, name_b: str, what: str) -> str:
    """``mean(a) / mean(b)``: "lower" / "higher" / "equal"."""
    ma, _, na = mean_sd(a)
    mb, _, nb = mean_sd(b)
    if na == 0 or nb == 0 or mb == 0:
        return f"{name_a} and {name_b} cannot be compared on the {what} (no completed runs of both)."
    r = ma / mb
    rel = "lower than" if ma < mb else ("higher than" if ma > mb else "equal to")
    return f"{name_a}'s {what} ({ma:.3f}) is {rel} {name_b}'s ({mb:.3f}), ratio {r:.2f}."


def nees_verdict(fraction_inside: float, mean_nees: float, lower: float, upper: float, label: str,
                 min_fraction: float = 0.9) -> str:
    """Consistent when ≥ ``min_fraction`` of the steps lie inside the 95 % band, else over-/under-confident
    by the side the time-averaged NEES falls on."""
    cond = (f"{100 * fraction_inside:.0f} % of steps inside [{lower:.2f}, {upper:.2f}], condition ≥ "
            f"{100 * min_fraction:.0f} %; time-average {mean_nees:.2f}")
    if fraction_inside >= min_fraction:
        return f"`{label}` is consistent ({cond})."
    side = "overconfident" if mean_nees > upper else ("underconfident" if mean_nees < lower else "inconsistent")
    return f"`{label}` is {side} ({cond})."


def section_status(ok: bool, problems: Sequence[str]) -> str:
    """The line every section ends with."""
    if ok:
        return "Section status: **ok** (every configured run completed)."
    return "Section status: **FAILED** — " + "; ".join(problems) + "."
