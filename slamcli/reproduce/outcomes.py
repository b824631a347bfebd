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


# -- paper-claim verdicts (issue 22): each returns (verdict, sentence); the verdict is one of the three below ---
REPRODUCED, PARTLY, NOT_REPRODUCED = "reproduced", "partly reproduced", "not reproduced"
#: a paired difference "exceeds the replicate spread" when |mean d| > SPREAD_Z · sd(d)/√n (≈ 95 %, normal)
SPREAD_Z = 2.0


def _pairs(a, b) -> list[tuple[float, float]]:
    return [(float(x), float(y)) for x, y in zip(a, b)
            if x is not None and y is not None and math.isfinite(float(x)) and math.isfinite(float(y))]


def claim(what: str, verdict: str, reason: str) -> str:
    """One claim line of REPORT.md: ``**Paper claim — what: verdict** (reason).``"""
    return f"**Paper claim — {what}: {verdict}** ({reason})."


def paper_value_claim(exact: Sequence[float], aware: Sequence[float], paper: float, what: str) -> tuple[str, str]:
    """Fig. 5: reproduced when the paper-exact mean ≤ ``paper``; partly when only the surface-aware mean is."""
    me, se, ne = mean_sd(exact)
    ma, sa, na = mean_sd(aware)
    if ne == 0:
        return NOT_REPRODUCED, claim(what, NOT_REPRODUCED, "no completed paper-exact run")
    nums = f"paper-exact {me:.3f} ± {se:.3f} m over {ne} seed(s) vs the paper's {paper:g} m"
    if na:
        nums += f"; surface-aware {ma:.3f} ± {sa:.3f} m over {na} seed(s)"
    if me <= paper:
        return REPRODUCED, claim(what, REPRODUCED, nums)
    if na and ma <= paper:
        return PARTLY, claim(what, PARTLY, nums + ": only once the laser's surface bias is modelled")
    return NOT_REPRODUCED, claim(what, NOT_REPRODUCED, nums)


def crossing_radius(radii: Sequence[float], errs: Sequence[float], level: float) -> float | None:
    """The radius where the (radius-sorted) mean errors first reach ``level``, by linear interpolation between
    neighbouring radii; None when no neighbouring pair brackets it."""
    pts = sorted((float(r), float(e)) for r, e in zip(radii, errs) if math.isfinite(float(e)))
    for (r0, e0), (r1, e1) in zip(pts, pts[1:]):
        if (e0 - level) * (e1 - level) <= 0 and e0 != e1:
            return r0 + (level - e0) * (r1 - r0) / (e1 - e0)
    return None


def sensitivity_sentence(rows: Sequence[dict], paper: float) -> str:
    """Fig. 5 sensitivity study: mean error per post radius for each model (``rows``: dicts with ``rho``,
    ``model`` ("exact" / "surface"), ``err``) and the radius at which paper-exact ICM meets the paper's value."""
    by: dict[tuple[str, float], list[float]] = {}
    for r in rows:
        by.setdefault((str(r["model"]), float(r["rho"])), []).append(float(r["err"]))
    radii = sorted({rho for _, rho in by})
    if not radii:
        return "The sensitivity study has no completed run."

    def means(model):
        return [mean_sd(by.get((model, rho), []))[0] for rho in radii]

    ex, aw = means("exact"), means("surface")

    def num(e):
        return f"{e:.3f} m" if math.isfinite(e) else "no landmark estimated"

    part = "; ".join(f"ρ = {rho:.2f} m: {num(e)}" + (f" (surface-aware {num(a)})" if (("surface", rho) in by) else "")
                     for rho, e, a in zip(radii, ex, aw))
    cross = crossing_radius(radii, ex, paper)
    if cross is not None:
        where = f"paper-exact ICM meets the paper's {paper:g} m at a post radius of ≈ {cross:.3f} m"
    elif all(e > paper for e in ex if math.isfinite(e)):
        where = f"paper-exact ICM stays above the paper's {paper:g} m at every radius studied"
    else:
        where = f"paper-exact ICM stays at or below the paper's {paper:g} m at every radius studied"
    return f"Final mean landmark error against the post radius (mean over seeds) — {part}: {where}."


def map_not_worse_claim(init: Sequence[float], final: Sequence[float], what: str) -> tuple[str, str]:
    """Fig. 9: ICM should not make the map worse than its initialisation, per seed."""
    pairs = _pairs(init, final)
    if not pairs:
        return NOT_REPRODUCED, claim(what, NOT_REPRODUCED, "no seed has both numbers")
    worse = sum(f > i for i, f in pairs)
    mi, _, n = mean_sd([i for i, _ in pairs])
    mf, _, _ = mean_sd([f for _, f in pairs])
    nums = f"mean landmark error init {mi:.3f} m → final {mf:.3f} m; ICM made the map worse in {worse} of {n} seed(s)"
    verdict = REPRODUCED if worse == 0 else (NOT_REPRODUCED if worse == n else PARTLY)
    return verdict, claim(what, verdict, nums)


def falls(series: Sequence[Sequence[float]], what: str, frac: float = 0.25) -> str:
    """"falls" in a seed when the mean of the last ``frac`` of its values is below the mean of the first."""
    k = n = 0
    for s in series:
        v = _finite(s)
        if len(v) < 2:
            continue
        w = max(1, int(round(frac * len(v))))
        n += 1
        k += (sum(v[-w:]) / w) < (sum(v[:w]) / w)
    if n == 0:
        return f"No seed has two or more values of the {what}."
    if k == n:
        return f"The {what} falls in every seed (mean of the last {100 * frac:.0f} % of sweeps below the first's, {n} seeds)."
    return f"The {what} falls in {k} of {n} seeds only (mean of the last {100 * frac:.0f} % of sweeps vs the first)."


def better_initial_claim(init_short: Sequence[float], init_long: Sequence[float], what: str,
                         reason: str = "") -> tuple[str, str]:
    """Fig. 7: the shorter laser should give a lower initial mean landmark error than the long one."""
    ms, ss, ns = mean_sd(init_short)
    ml, sl, nl = mean_sd(init_long)
    if ns == 0 or nl == 0:
        return NOT_REPRODUCED, claim(what, NOT_REPRODUCED, "not compared: the runs of both lasers are needed "
                                     "(run the fig5 section in the same invocation)")
    nums = f"initial mean landmark error {ms:.3f} ± {ss:.3f} m (10 m laser) vs {ml:.3f} ± {sl:.3f} m (full range)"
    if ms < ml:
        return REPRODUCED, claim(what, REPRODUCED, nums)
    return NOT_REPRODUCED, claim(what, NOT_REPRODUCED, nums + (f"; {reason}" if reason else ""))


def recovery_claim(init: Sequence[float], final: Sequence[float], missed: Sequence[float], n_true: float,
                   what: str, max_missed_frac: float = 0.05) -> tuple[str, str]:
    """Fig. 6: recovery from a very bad init — the error falls in every seed and at most ``max_missed_frac`` of
    the true landmarks are missed; partly when the error falls in some seed; not when in none."""
    pairs = _pairs(init, final)
    mm, _, nm = mean_sd(missed)
    if not pairs:
        return NOT_REPRODUCED, claim(what, NOT_REPRODUCED, "no seed has both numbers")
    k = sum(f < i for i, f in pairs)
    mi, _, n = mean_sd([i for i, _ in pairs])
    mf, _, _ = mean_sd([f for _, f in pairs])
    miss_ok = nm > 0 and n_true > 0 and mm <= max_missed_frac * n_true
    nums = (f"mean landmark error {mi:.3f} → {mf:.3f} m, lower in {k} of {n} seed(s); {mm:.1f} of {n_true:.0f} "
            f"true landmarks missed (condition ≤ {100 * max_missed_frac:.0f} %)")
    verdict = REPRODUCED if (k == n and miss_ok) else (PARTLY if k > 0 else NOT_REPRODUCED)
    return verdict, claim(what, verdict, nums)


def spread(a: Sequence[float], b: Sequence[float], name_a: str, name_b: str, what: str) -> str:
    """Paired difference per replicate of ``a − b`` against its spread: "exceeds the replicate spread" when
    |mean d| > SPREAD_Z · sd(d)/√n (n ≥ 2)."""
    d = [x - y for x, y in _pairs(a, b)]
    md, sd, n = mean_sd(d)
    if n < 2:
        return f"{name_a} and {name_b}: fewer than two paired replicates, the {what} difference is not tested."
    se = sd * math.sqrt(n / (n - 1)) / math.sqrt(n)  # sample sd / √n
    rel = "exceeds" if abs(md) > SPREAD_Z * se else "is within"
    return (f"{name_a} − {name_b}, {what}: {md:+.3f} (paired over {n} replicates, standard error {se:.3f}) — "
            f"{rel} the replicate spread (|mean| vs {SPREAD_Z:g} × standard error = {SPREAD_Z * se:.3f}).")


def postprocess_claim(per_base: dict[str, tuple[Sequence[float], Sequence[float]]], what: str) -> tuple[str, str]:
    """Post-processing: reproduced when ICM lowers the ATE in every run of every base solver; partly when in
    some; not when in none. ``per_base``: base → (ATE before, ATE after) per run."""
    parts, k_all, n_all = [], 0, 0
    for base, (before, after) in per_base.items():
        pairs = _pairs(before, after)
        k = sum(a < b for b, a in pairs)
        parts.append(f"after `{base}` in {k} of {len(pairs)} runs")
        k_all, n_all = k_all + k, n_all + len(pairs)
    if n_all == 0:
        return NOT_REPRODUCED, claim(what, NOT_REPRODUCED, "no paired run")
    verdict = REPRODUCED if k_all == n_all else (PARTLY if k_all else NOT_REPRODUCED)
    return verdict, claim(what, verdict, "ICM lowers the ATE " + ", ".join(parts))


def claims_status(verdicts: Sequence[str], ok: bool, problems: Sequence[str]) -> str:
    """The closing line of a paper-claim section: runs completed or not, and the count of each verdict —
    never "ok" when a claim was not reproduced."""
    counts = [f"{sum(v == w for v in verdicts)} {w}" for w in (REPRODUCED, PARTLY, NOT_REPRODUCED)
              if any(v == w for v in verdicts)]
    claims = ("paper claims: " + ", ".join(counts)) if counts else "no paper claim checked"
    if not ok:
        return "Section status: **FAILED** — " + "; ".join(problems) + f"; {claims}."
    return f"Section status: every configured run completed; {claims}."
