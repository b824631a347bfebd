"""The counterexample of paper 001 §II.D (Figs. 1-2): why "localise first, then map" needs the frequentist map.

Two poses s1, s2 with belief b = (b1, b2); three cells q1 (empty), q2 (occupied), q3 (occluded behind q2);
a perfect range sensor. From s1 the robot reads z1 (q1 empty, q2 occupied), from s2 it reads z2. Under the
map estimate P = (p1, p2, p3) the likelihoods are

    p(z1|s1) = (1−p1) p2,   p(z1|s2) = (1−p1)(1−p2) p3,   p(z2|s1) = p1,   p(z2|s2) = (1−p1) p2,

so (eq. 22)  c1(z1) = 0,  c1(z2) = b1 p1 / p(z2|b),  c2(z1) = (1−p1) p2 b1 / p(z1|b),  c2(z2) = 1,
and with identity observation matrices (perfect sensor) the frequentist update is eq. (23)

    p_i ← (1 − γ_t) p_i + γ_t c_i(b, z_t, P),   γ_t = 1/(a t).

The naive Bayesian update (eq. 24) of p2 after z1 is ``p(z1|b, q2=O) p2 / (… + p(z1|b, q2=E)(1−p2))`` with
``p(z1|b, q2=O) = (1−p1) b1`` and ``p(z1|b, q2=E) = (1−p1) p3 b2``; at the true map it gives b1/(b1 + p3 b2) < 1.
q3 is never observed empty; its estimate p3 stays at its initial value here.
"""

from __future__ import annotations

import numpy as np


def likelihoods(p1: float, p2: float, p3: float, b1: float, b2: float) -> tuple[float, float]:
    """``(p(z1|b), p(z2|b))`` under the map estimate."""
    pz1 = (1 - p1) * p2 * b1 + (1 - p1) * (1 - p2) * p3 * b2
    pz2 = p1 * b1 + (1 - p1) * p2 * b2
    return pz1, pz2


def frequentist_c(z: int, p1: float, p2: float, p3: float, b1: float, b2: float) -> tuple[float, float]:
    """``(c1, c2)`` of eq. (22) for the reading ``z`` (1 or 2)."""
    pz1, pz2 = likelihoods(p1, p2, p3, b1, b2)
    if z == 1:
        return 0.0, ((1 - p1) * p2 * b1 / pz1 if pz1 > 0 else p2)
    return (b1 * p1 / pz2 if pz2 > 0 else p1), 1.0


def run_frequentist(p0: tuple[float, float], n_steps: int, rng: np.random.Generator, b1: float = 0.4,
                    p3: float = 0.5, a: float = 1.0) -> np.ndarray:
    """Eq. (23) from ``p0 = (p1, p2)``: the true pose is s1 with probability b1 (then the reading is z1), else
    s2 (reading z2). Returns the trajectory ``(n_steps + 1, 2)`` in the p1-p2 plane."""
    b2 = 1.0 - b1
    p1, p2 = float(p0[0]), float(p0[1])
    out = np.empty((n_steps + 1, 2))
    out[0] = p1, p2
    zs = np.where(rng.random(n_steps) < b1, 1, 2)
    for t in range(1, n_steps + 1):
        c1, c2 = frequentist_c(int(zs[t - 1]), p1, p2, p3, b1, b2)
        g = 1.0 / (a * t)
        p1, p2 = (1 - g) * p1 + g * c1, (1 - g) * p2 + g * c2
        out[t] = p1, p2
    return out


def naive_bayes_p2_after_z1(p1: float, p2: float, p3: float, b1: float) -> float:
    """Eq. (24) for q2 after the reading z1 (independent cells, pose marginalised)."""
    b2 = 1.0 - b1
    lo, le = (1 - p1) * b1, (1 - p1) * p3 * b2
    return lo * p2 / (lo * p2 + le * (1 - p2))


def naive_bayes_p2_after_z1_as_printed(p1: float, p2: float, p3: float, b1: float) -> float:
    """The paper's printed evaluation of eq. (24) for q2 after z1: ``(1−p1) p2 b1 / ((1−p1) p2 b1 + p3 b2)``.

    It equals the strict update (:func:`naive_bayes_p2_after_z1`) only with the empty branch's prior
    ``p(q2 = E)`` taken as 1; at the true map (p1, p2) = (0, 1) it gives ``b1 / (b1 + p3 b2) < 1``."""
    b2 = 1.0 - b1
    num = (1 - p1) * p2 * b1
    return num / (num + p3 * b2)


def pose_conditioned_p2_after_z1(p21: float, p22: float, p1: float, b1: float) -> float:
    """Eqs. (25)-(27): cells correlated with the pose but not with each other. After z1, from s1
    ``p(q2=O|s1) = (1−p1) p21 / ((1−p1) p21 + 0)`` and from s2 ``p(q2=O|s2) = 0`` (z1 from s2 needs q2 empty);
    the marginal ``p(q2) = b1 p(q2=O|s1) + b2 p(q2=O|s2)`` (eq. 26)."""
    b2 = 1.0 - b1
    p_s1 = 1.0 if (1 - p1) * p21 > 0 else 0.0
    p_s2 = 0.0
    return b1 * p_s1 + b2 * p_s2
