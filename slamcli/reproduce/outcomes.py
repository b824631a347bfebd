"""Outcome sentences of ``REPORT.md``, computed from a run's numbers.

Every function takes the measured numbers and returns one sentence whose wording follows from a stated
condition (the condition is part of the sentence, so a reader can check it against the tables). The ``*_claim``
functions judge a claim by the rule of :mod:`slamcli.reproduce.verdicts` and return its
:class:`~slamcli.reproduce.verdicts.Judgement`. Nothing here reads files; ``tests/reproduce/test_reproduce_outcomes.py``
and ``tests/reproduce/test_reproduce_claims.py`` feed numbers on both sides of every condition and check that the wording
and the verdict flip.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

from slamcli.reproduce import verdicts as vd


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


def pm_range(xs, digits: int = 3) -> str:
    """``"m ± s (min-max)"`` over the finite values, or ``"n/a"``."""
    v = _finite(xs)
    return "n/a" if not v else f"{pm(v, digits)} ({min(v):.{digits}f}-{max(v):.{digits}f})"


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
    b_txt, a_txt = vd.show(mb, ma)
    nums = f"{b_txt} → {a_txt} {unit} (mean over {n} {item}{'s' if n > 1 else ''})"
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
    m_txt, p_txt = vd.show(m, paper)
    return f"Our {what} {m_txt} ± {s:.3f} {unit} ({n} seed{'s' if n > 1 else ''}) is {rel} the paper's {p_txt} {unit}."


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
    d_txt, lim_txt = vd.show(d, rel_tol * ref)
    cond = f"mean |change| of the {what} {d_txt} m vs {100 * rel_tol:.0f} % of its initial {ref:.3f} m = {lim_txt} m"
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
    a_txt, b_txt = vd.show(ma, mb)
    return f"{name_a}'s {what} ({a_txt}) is {rel} {name_b}'s ({b_txt}), ratio {r:.2f}."


def nees_verdict(fraction_inside: float, mean_nees: float, lower: float, upper: float, label: str,
                 min_fraction: float = 0.9) -> str:
    """The NEES sentence: :func:`nees_note`'s word with the fraction of steps inside the 95 % band and the
    time-averaged NEES."""
    cond = (f"{100 * fraction_inside:.0f} % of steps inside [{lower:.2f}, {upper:.2f}], condition ≥ "
            f"{100 * min_fraction:.0f} %; time-average {mean_nees:.2f}")
    return f"`{label}` is {nees_note(fraction_inside, mean_nees, lower, upper, min_fraction)} ({cond})."


def section_status(ok: bool, problems: Sequence[str]) -> str:
    """The line every section ends with."""
    if ok:
        return "Section status: **ok** (every configured run completed)."
    return "Section status: **FAILED** — " + "; ".join(problems) + "."


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


# -- claims: each returns a verdicts.Judgement whose verdict is the rule of slamcli.reproduce.verdicts -----------


def _mean(xs) -> float:
    return mean_sd(xs)[0]


def lowers_claim(before: Sequence[float], after: Sequence[float], what: str, *, quantity: str = "mean landmark error",
                 kind: str = vd.PAPER, item: str = "seed", unit: str = "m",
                 condition: tuple[bool, str] | None = None) -> vd.Judgement:
    """"``after`` is lower than ``before``" per ``item`` (e_i = before_i − after_i); ``condition`` = (holds,
    its wording) of a condition the claim states, which makes the verdict "not reproduced" when it fails."""
    pairs = vd.paired(before, after)
    ev = vd.evidence(vd.drop_effects(before, after), condition_ok=None if condition is None else condition[0])
    if not pairs:
        return vd.judge(what, ev, f"no {item} has both numbers", unit=unit, kind=kind, item=item)
    b, a = vd.show(_mean([x for x, _ in pairs]), _mean([y for _, y in pairs]))
    numbers = f"{quantity} {b} → {a} {unit}, mean over {len(pairs)} {item}{'s' if len(pairs) != 1 else ''}"
    if condition is not None:
        numbers += f"; stated condition {condition[1]}: {'met' if condition[0] else 'FAILED'}"
    return vd.judge(what, ev, numbers, unit=unit, kind=kind, item=item)


def value_claim(values: Sequence[float], paper: float, what: str, *, kind: str = vd.PAPER,
                quantity: str = "final mean landmark error", unit: str = "m") -> vd.Judgement:
    """"our value is at most the paper's" per seed (e_i = paper − value_i)."""
    v = [float(x) for x in values if x is not None and math.isfinite(float(x))]
    ev = vd.evidence([paper - x for x in v])
    if not v:
        return vd.judge(what, ev, f"no seed gives a {quantity}", unit=unit, kind=kind)
    m, s, n = mean_sd(v)
    ms, ps = vd.show(m, paper)
    numbers = f"{quantity} {ms} ± {vd.show(s)[0]} {unit} over {n} seed{'s' if n != 1 else ''} vs the paper's {ps} {unit}"
    return vd.judge(what, ev, numbers, unit=unit, kind=kind)


def bound_claim(values: Sequence[float], bound: float, what: str, *, quantity: str, unit: str,
                kind: str = vd.PAPER) -> vd.Judgement:
    """"the value stays below ``bound``" per seed (e_i = bound − value_i)."""
    v = [float(x) for x in values if x is not None and math.isfinite(float(x))]
    ev = vd.evidence([bound - x for x in v])
    if not v:
        return vd.judge(what, ev, f"no completed run gives the {quantity}", unit=unit, kind=kind)
    mx, b = vd.show(max(v), bound, base=1)
    numbers = f"{quantity}: largest {mx} {unit} over {len(v)} seed{'s' if len(v) != 1 else ''}, bound {b} {unit}"
    return vd.judge(what, ev, numbers, unit=unit, kind=kind)


def faster_claim(iters_fast: Sequence[int | None], iters_slow: Sequence[int | None], name_fast: str,
                 name_slow: str, n_max: int, what: str, criterion: str, kind: str = vd.PAPER) -> vd.Judgement:
    """"``name_fast`` meets ``criterion`` in fewer iterations" per seed (e_i = slow_i − fast_i; a seed that never
    meets it counts as ``n_max + 1``)."""
    def cost(x):
        return n_max + 1 if x is None else int(x)

    pairs = [(cost(f), cost(s)) for f, s in zip(iters_fast, iters_slow)]
    ev = vd.evidence([s - f for f, s in pairs])
    if not pairs:
        return vd.judge(what, ev, "no seed ran both", unit="iterations", kind=kind)
    f, s = (sum(p[i] for p in pairs) / len(pairs) for i in (0, 1))
    numbers = (f"mean first iteration with {criterion}: {f:.1f} ({name_fast}) vs {s:.1f} ({name_slow}); a seed "
               f"that never reaches it counts as {n_max + 1}")
    return vd.judge(what, ev, numbers, unit="iterations", kind=kind)


def better_initial_claim(init_lower: Sequence[float], init_higher: Sequence[float], what: str, *,
                         names: tuple[str, str] = ("10 m laser", "full range"), reason: str = "",
                         kind: str = vd.PAPER) -> vd.Judgement:
    """"the first initial map is better than the second", paired by replicate (the same dataset seeds):
    e_i = higher_i − lower_i."""
    pairs = vd.paired(init_lower, init_higher)
    ev = vd.evidence([h - lo for lo, h in pairs])
    if not pairs:
        return vd.judge(what, ev, "not compared: the runs of both are needed (run the fig5 section in the same "
                        "invocation)", unit="m", kind=kind)
    a, b = vd.show(_mean([p[0] for p in pairs]), _mean([p[1] for p in pairs]))
    numbers = f"initial mean landmark error {a} m ({names[0]}) vs {b} m ({names[1]})" + (f"; {reason}" if reason else "")
    return vd.judge(what, ev, numbers, unit="m", kind=kind)


def stays_close_claim(before: Sequence[float], after: Sequence[float], rel_tol: float, what: str,
                      kind: str = vd.PAPER) -> vd.Judgement:
    """"the final error stays within ``rel_tol`` of the initial one" per seed (e_i = rel_tol·before_i −
    |after_i − before_i|)."""
    pairs = vd.paired(before, after)
    ev = vd.evidence([rel_tol * b - abs(a - b) for b, a in pairs])
    if not pairs:
        return vd.judge(what, ev, "no seed has both numbers", unit="m", kind=kind)
    b, a = vd.show(_mean([p[0] for p in pairs]), _mean([p[1] for p in pairs]))
    numbers = (f"mean landmark error {b} → {a} m, mean over {len(pairs)} seed{'s' if len(pairs) != 1 else ''}; "
               f"close = within {100 * rel_tol:.0f} % of the initial value")
    return vd.judge(what, ev, numbers, unit="m", kind=kind)


def falls_claim(series: Sequence[Sequence[float]], what: str, *, quantity: str, unit: str, frac: float = 0.25,
                kind: str = vd.PAPER) -> vd.Judgement:
    """"``quantity`` falls over the iterations" per seed: e_i = mean of the first ``frac`` of its values − mean
    of the last ``frac``."""
    firsts, lasts = [], []
    for s in series:
        v = [float(x) for x in s if x is not None and math.isfinite(float(x))]
        if len(v) >= 2:
            w = max(1, int(round(frac * len(v))))
            firsts.append(sum(v[:w]) / w)
            lasts.append(sum(v[-w:]) / w)
    ev = vd.evidence(vd.drop_effects(firsts, lasts))
    if not firsts:
        return vd.judge(what, ev, f"no seed has two or more values of the {quantity}", unit=unit, kind=kind)
    a, b = vd.show(_mean(firsts), _mean(lasts))
    numbers = (f"{quantity}, mean of the first {100 * frac:.0f} % of iterations {a} → last {100 * frac:.0f} % {b} "
               f"{unit}, mean over {len(firsts)} seed{'s' if len(firsts) != 1 else ''}")
    return vd.judge(what, ev, numbers, unit=unit, kind=kind)


def earlier_iterate_claim(series: Sequence[Sequence[float]], what: str, *, kind: str = vd.FINDING) -> vd.Judgement:
    """"an earlier iterate was closer to the truth than the final one" per seed: ``series`` = the mean landmark
    error after iterations 0 (the initialisation), 1, …, n; e_i = final − the lowest value after iterations
    1 … n−1 (so > 0 when stopping the sweeps earlier would have given a better map than ICM's end point)."""
    finals, bests, where = [], [], []
    for s in series:
        v = [float(x) for x in s]
        if len(v) >= 3 and all(math.isfinite(x) for x in v[1:]):
            k = min(range(1, len(v) - 1), key=lambda i: v[i])
            finals.append(v[-1])
            bests.append(v[k])
            where.append(k)
    ev = vd.evidence([f - b for f, b in zip(finals, bests)])
    if not finals:
        return vd.judge(what, ev, "no seed has two or more iterations", unit="m", kind=kind)
    f, b = vd.show(_mean(finals), _mean(bests))
    numbers = (f"final mean landmark error {f} m vs {b} m at the best earlier iteration (iterations "
               f"{', '.join(map(str, where))}), mean over {len(finals)} seed{'s' if len(finals) != 1 else ''}")
    return vd.judge(what, ev, numbers, unit="m", kind=kind)


def recovery_claim(init: Sequence[float], final: Sequence[float], missed: Sequence[float], n_true: float,
                   what: str, max_missed_frac: float = 0.05, kind: str = vd.PAPER) -> vd.Judgement:
    """Fig. 6: recovery from a very bad initialisation — the error falls (:func:`lowers_claim`) with the stated
    condition that at most ``max_missed_frac`` of the true landmarks are missed (mean over seeds)."""
    mm, _, nm = mean_sd(missed)
    ok = nm > 0 and n_true > 0 and mm <= max_missed_frac * n_true
    cond = (f"≤ {100 * max_missed_frac:.0f} % of the {n_true:.0f} true landmarks missed "
            f"({'n/a' if nm == 0 else f'{mm:.1f}'} missed)")
    return lowers_claim(init, final, what, condition=(ok, cond), kind=kind)


def postprocess_claim(per_base: dict[str, tuple[Sequence[float], Sequence[float]]], what: str) -> vd.Judgement:
    """Post-processing: ICM lowers the ATE of the base solvers' results, judged over every paired run of every
    base (e_i = ATE before − ATE after); the numbers say how many runs per base."""
    before, after, parts = [], [], []
    for base, (b, a) in per_base.items():
        pairs = vd.paired(b, a)
        parts.append(f"lower after `{base}` in {sum(y < x for x, y in pairs)} of {len(pairs)} runs")
        before += [x for x, _ in pairs]
        after += [y for _, y in pairs]
    j = lowers_claim(before, after, what, quantity="ATE RMSE", item="run")
    return vd.Judgement(j.what, j.kind, j.verdict, j.numbers + ("; " + ", ".join(parts) if parts else ""), j.rule)


def claims_status(judgements: Sequence[vd.Judgement], ok: bool, problems: Sequence[str]) -> str:
    """The closing line of a section that judges claims: runs completed or not, and the verdict count."""
    c = vd.count(judgements)
    parts = [f"{c[v]} {v}" for v in vd.VERDICTS if c[v]]
    text = ("paper claims: " + ", ".join(parts)) if parts else "no paper claim checked"
    if c[vd.FINDING]:
        text += f"; {c[vd.FINDING]} finding{'s' if c[vd.FINDING] != 1 else ''} of our own"
    if not ok:
        return "Section status: **FAILED** — " + "; ".join(problems) + f"; {text}."
    return f"Section status: every configured run completed; {text}."


def nees_note(fraction_inside: float, mean_nees: float, lower: float, upper: float,
              min_fraction: float = 0.9) -> str:
    """The NEES table's note: "consistent" when ≥ ``min_fraction`` of the steps lie inside the 95 % band, else
    over-/under-confident by the side the time-averaged NEES falls on ("inconsistent" when inside it)."""
    if fraction_inside >= min_fraction:
        return "consistent"
    return "overconfident" if mean_nees > upper else ("underconfident" if mean_nees < lower else "inconsistent")


def spread(a: Sequence[float], b: Sequence[float], name_a: str, name_b: str, what: str) -> str:
    """Paired difference per replicate of ``a − b`` against the replicate spread of
    :mod:`slamcli.reproduce.verdicts` (SPREAD_Z · s/√n, n ≥ 2): "exceeds" when |mean d| is larger."""
    ev = vd.evidence([x - y for x, y in vd.paired(a, b)])
    if ev.n < 2:
        return f"{name_a} and {name_b}: fewer than two paired replicates, the {what} difference is not tested."
    rel = "exceeds" if abs(ev.effect) > ev.spread else "is within"
    md, sp = vd.show(ev.effect, ev.spread)
    return (f"{name_a} − {name_b}, {what}: {'+' if ev.effect >= 0 else ''}{md} (paired over {ev.n} replicates) — "
            f"{rel} the replicate spread ({vd.SPREAD_Z:g} × standard error = {sp}).")
