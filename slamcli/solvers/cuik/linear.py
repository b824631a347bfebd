"""An affine-relaxation (LP) contractor on the whole constraint system of one kinematic graph.

The per-edge operators of :mod:`~slamcli.solvers.cuik.contractors` each see one constraint and lose the
coupling around the loop. Here every edge is enclosed over the current box by linear inequalities, and each
target variable is minimised / maximised over all of them at once with HiGHS (``scipy.optimize.linprog``):

* a polar relation ``(u, v) = ρ·(cos φ, sin φ)`` (odometry leg, observation, local landmark cycle) becomes,
  at a few expansion points, ``u − a_ρ·ρ − a_φ·φ ∈ [h]`` (and for ``v``), ``[h]`` a second-order Taylor
  enclosure with an interval Hessian — valid for any float coefficients ``a``;
* the turn chain and the offsets ``φ − θ ∈ B`` are linear already;
* the closest-landmark information ``‖l_m − p_t‖ ≥ r`` gives a chord cut where the disc holds box corners.

Rigour: the bound used is Neumaier & Shcherbina's safe dual bound ``cᵀz ≥ yᵀb + min_{z ∈ box} (c − Aᵀy)ᵀz``
for HiGHS's multipliers ``y ≤ 0``, evaluated in outward-rounded interval arithmetic; an infeasible
relaxation refutes the box only through the same bound on a phase-one LP being > 0. Call inside
:func:`~slamcli.solvers.cuik.contractors.interval_rounding`; HiGHS runs in the ordinary rounding mode.
"""

from __future__ import annotations

import math

import numpy as np

from slamcli.solvers.cuik.contractors import (
    NORMAL_ROUNDING,
    Interval,
    OdometryTurnMove,
    OutsideBand,
    OutsideBandLocal,
    RangeBearing,
    SharedLandmarkLeg,
    codac,
    rounding_mode,
)

#: width (rad) of φ above which a polar relation gets two more expansion points (φ's ends), besides the centre
EXTRA_POINTS_WIDTH = 0.05
#: bound used for the phase-one slack variable (m): larger than any violation the relaxation can show
SLACK_BOUND = 1e6


def _finite(iv) -> bool:
    return not iv.is_empty() and math.isfinite(iv.lb()) and math.isfinite(iv.ub())


class Relaxation:
    """Linear rows ``lo ≤ Σ a_k z_k ≤ hi`` enclosing a graph's constraints over one box.

    LP variables ``0 .. len(box)−1`` are the box's; auxiliary ones (a reading's range and angle, a constant
    leg, the far sighting of a local cycle) follow, each with its own interval. ``rows`` holds
    ``(dict var → coefficient, lo, hi)``.
    """

    def __init__(self, box: list, edges, narrow_theta: bool) -> None:
        self.bounds = [Interval(x) for x in box]
        self.rows: list[tuple[dict[int, float], float, float]] = []
        self._reads: dict[int, tuple[int, int]] = {}
        for e in edges:
            if isinstance(e, OdometryTurnMove):
                self._odometry(e, narrow_theta)
            elif isinstance(e, RangeBearing):
                self._observation(e)
            elif isinstance(e, SharedLandmarkLeg) and narrow_theta:
                self._local_cycle(e)
            elif isinstance(e, OutsideBand):
                self._band(e)
            elif isinstance(e, OutsideBandLocal) and narrow_theta:
                self._band_local(e)
            # other operators (the separation priors) are left out: dropping a constraint is sound

    # -- building blocks ------------------------------------------------------------------------------------
    def reading(self, i: int, R, B) -> tuple[int, int]:
        """The range and bearing variables of observation row ``i`` (made on first use, with intervals R, B)."""
        if i not in self._reads:
            self._reads[i] = (self.aux(R), self.aux(B))
        return self._reads[i]

    def sighting(self, i: int, R, B, qx, qy) -> tuple[int, int]:
        """Variables for the sighting ``r_i·e(b_i)`` of row ``i`` in its pose's frame, tied to its reading."""
        i_r, i_b = self.reading(i, R, B)
        jx, jy = self.aux(qx), self.aux(qy)
        self.polar({jx: 1.0}, {jy: 1.0}, i_r, i_b)
        return jx, jy

    def aux(self, iv) -> int:
        self.bounds.append(Interval(iv))
        return len(self.bounds) - 1

    def row(self, coef: dict[int, float], rhs) -> None:
        """``Σ coef·z ∈ rhs`` (an Interval, already outward-rounded)."""
        if rhs.is_empty():
            self.rows.append(({}, 1.0, -1.0))  # 0 ∈ ∅: the box holds no solution
            return
        self.rows.append((coef, rhs.lb(), rhs.ub()))

    def polar(self, u: dict[int, float], v: dict[int, float], i_rho: int, i_phi: int) -> None:
        """Rows enclosing ``Σu = ρ cos φ`` and ``Σv = ρ sin φ`` over the box of ``(ρ, φ)``.

        For each expansion angle ``φ_c`` (the centre of φ's interval, and its ends when it is wide) the pair is
        written in the frame turned by ``φ_c``, with ``ψ = φ − φ_c``: the lateral part
        ``−sin φ_c·u + cos φ_c·v = ρ sin ψ = ρ_c ψ + (ρ − ρ_c) sin ψ + ρ_c (sin ψ − ψ)`` and the longitudinal
        part ``cos φ_c·u + sin φ_c·v = ρ cos ψ = ρ + ρ (cos ψ − 1)``; the non-linear terms are enclosed in
        interval arithmetic (``|sin ψ − ψ| ≤ |ψ|³/6`` with the sign of −ψ), so each row is exact up to a
        remainder of third order in ψ (first order in ρ's width)."""
        R, F = self.bounds[i_rho], self.bounds[i_phi]
        if not (_finite(R) and _finite(F)):
            return
        rc = R.mid()
        points = [F.mid()] + ([F.lb(), F.ub()] if F.diam() > EXTRA_POINTS_WIDTH else [])
        dr = R - Interval(rc)
        for fc in points:
            psi = F - Interval(fc)
            s0, c0 = codac.sin(Interval(fc)), codac.cos(Interval(fc))
            sn, cs = s0.mid(), c0.mid()
            # the float rotation (cs, sn) differs from the exact one by ~1e-16: its residual times (u, v) is
            # enclosed through ρ·(cos φ, sin φ) over the box, as (cs − c0)·u + (sn − s0)·v
            U, V = R * codac.cos(F), R * codac.sin(F)
            err_lat = (Interval(-sn) + s0) * U + (Interval(cs) - c0) * V
            err_lon = (Interval(cs) - c0) * U + (Interval(sn) - s0) * V
            cube_hi = Interval(max(-psi.lb(), 0.0)) ** 3 / Interval(6.0)
            cube_lo = Interval(max(psi.ub(), 0.0)) ** 3 / Interval(6.0)
            sin_minus = Interval(-cube_lo.ub(), cube_hi.ub())  # sin ψ − ψ
            lat = dr * codac.sin(psi) + Interval(rc) * sin_minus + err_lat - Interval(rc) * Interval(fc)
            coef = {k: -sn * a for k, a in u.items()}
            for k, a in v.items():
                coef[k] = coef.get(k, 0.0) + cs * a
            coef[i_phi] = coef.get(i_phi, 0.0) - rc
            self.row(coef, lat)
            lon = R * (codac.cos(psi) - Interval(1.0)) + err_lon
            coef = {k: cs * a for k, a in u.items()}
            for k, a in v.items():
                coef[k] = coef.get(k, 0.0) + sn * a
            coef[i_rho] = coef.get(i_rho, 0.0) - 1.0
            self.row(coef, lon)

    # -- the operators ----------------------------------------------------------------------------------------
    def _odometry(self, e: OdometryTurnMove, narrow_theta: bool) -> None:
        (x0, y0, t0), (x1, y1, t1) = e.p0, e.p1
        if e.leg is not None and narrow_theta:
            i_d, i_a = e.leg
            self.row({t1: 1.0, t0: -1.0, i_a: -1.0}, Interval(0.0))
        else:
            i_d = self.aux(e.D)
            self.row({t1: 1.0, t0: -1.0}, e.A)
        self.polar({x1: 1.0, x0: -1.0}, {y1: 1.0, y0: -1.0}, i_d, t1)

    def _observation(self, e: RangeBearing) -> None:
        (x, y, t), (lx, ly) = e.pose, e.landmark
        th = self.bounds[t]
        if not _finite(th):
            return
        i_f = self.aux(th + e.B)
        if e.readings:
            i_r, i_b = self.reading(e.readings[0], e.R, e.B)
            self.row({i_f: 1.0, t: -1.0, i_b: -1.0}, Interval(0.0))
        else:
            i_r = self.aux(e.R)
            self.row({i_f: 1.0, t: -1.0}, e.B)
        self.polar({lx: 1.0, x: -1.0}, {ly: 1.0, y: -1.0}, i_r, i_f)

    def _local_cycle(self, e: SharedLandmarkLeg) -> None:
        i_d, i_a = e.leg
        i_f = self.aux(e.Bt - self.bounds[i_a])
        if e.readings:
            i_r, i_b = self.reading(e.readings[0], e.Rt, e.Bt)
            self.row({i_f: 1.0, i_a: 1.0, i_b: -1.0}, Interval(0.0))
            qx, qy = self.sighting(e.readings[1], e.Rs, e.Bs, e.qsx, e.qsy)
        else:
            i_r = self.aux(e.Rt)
            self.row({i_f: 1.0, i_a: 1.0}, e.Bt)
            qx, qy = self.aux(e.qsx), self.aux(e.qsy)
        self.polar({i_d: 1.0, qx: 1.0}, {qy: 1.0}, i_r, i_f)

    def _band(self, e: OutsideBand) -> None:
        """The chord cut of ``‖l − p‖² ≥ r²`` (see the module docstring); nothing when it does not apply."""
        (x, y, _t), (lx, ly) = e.pose, e.landmark
        self._chord({lx: 1.0, x: -1.0}, {ly: 1.0, y: -1.0}, e.pieces, self._band_range(e, e.readings[-1:]))

    def _band_local(self, e: OutsideBandLocal) -> None:
        """The chord cut of :class:`OutsideBandLocal`, through aux variables for the sighting and ``d·e(α)``."""
        i_d, i_a = e.leg
        if e.readings:
            qx, qy = self.sighting(e.readings[0], e.Rm, e.Bm, e.qx, e.qy)
        else:
            qx, qy = self.aux(e.qx), self.aux(e.qy)
        rho = self._band_range(e, e.readings[1:])
        if e.from_next:  # δ = (d + q_x, q_y)
            self._chord({i_d: 1.0, qx: 1.0}, {qy: 1.0}, e.pieces, rho)
            return
        b = self.bounds
        if not (_finite(b[i_d]) and _finite(b[i_a])):
            return
        px = self.aux(b[i_d] * codac.cos(b[i_a]))
        py = self.aux(b[i_d] * codac.sin(b[i_a]))
        self.polar({px: 1.0}, {py: 1.0}, i_d, i_a)  # P = d·e(α)
        self._chord({qx: 1.0, px: -1.0}, {qy: 1.0, py: -1.0}, e.pieces, rho)

    def _band_range(self, e, rows: tuple[int, ...]):
        """``(range variable, slack)`` of the reading whose true range is the band's edge, when it has one."""
        if not rows or rows[0] not in self._reads:
            return None
        return self._reads[rows[0]][0], e.band_slack

    def _chord(self, u: dict[int, float], v: dict[int, float], pieces: list, rho=None) -> None:
        """``δ = (Σu, Σv)`` with ``‖δ‖² ∈ ∪ pieces``: the chord cut of the outer piece when δ's box (from the
        variables' bounds) cannot reach the inner one; with ``rho = (i_ρ, slack)`` also the cut of
        ``‖δ‖ ≥ ρ − slack`` with the reading's own range ρ: ``‖δ‖ − g·δ`` is convex, so with ``g`` the unit
        vector to the box centre and ``a`` its largest value at a corner, ``ρ − g·δ ≤ a + slack``."""
        b = self.bounds
        dx = sum((Interval(a) * b[k] for k, a in u.items()), Interval(0.0))
        dy = sum((Interval(a) * b[k] for k, a in v.items()), Interval(0.0))
        if not (_finite(dx) and _finite(dy)):
            return
        if len(pieces) > 1 and (codac.sqr(dx) + codac.sqr(dy)).lb() <= pieces[0].ub():
            return  # the inner piece may hold δ: no cut
        if rho is not None:
            self._radius_cut(u, v, dx, dy, *rho)
        cut = chord_cut(dx, dy, pieces[-1].lb())
        if cut is not None:
            (nx, ny), k = cut
            coef: dict[int, float] = {}
            for lin, n in ((u, nx), (v, ny)):
                for j, a in lin.items():
                    coef[j] = coef.get(j, 0.0) + n * a  # a = ±1: exact
            self.row(coef, Interval(k, codac.oo))


    def _radius_cut(self, u: dict[int, float], v: dict[int, float], dx, dy, i_rho: int, slack: float) -> None:
        cx, cy = dx.mid(), dy.mid()
        norm = math.hypot(cx, cy)
        if not norm > 0:
            return
        gx, gy = cx / norm, cy / norm
        a = -math.inf
        for px in (dx.lb(), dx.ub()):
            for py in (dy.lb(), dy.ub()):
                P, Q = Interval(px), Interval(py)
                f = codac.sqrt(codac.sqr(P) + codac.sqr(Q)) - (Interval(gx) * P + Interval(gy) * Q)
                a = max(a, f.ub())
        coef: dict[int, float] = {i_rho: 1.0}
        for lin, g in ((u, gx), (v, gy)):
            for j, c in lin.items():
                coef[j] = coef.get(j, 0.0) - g * c  # c = ±1: exact
        self.row(coef, Interval(-codac.oo, (Interval(a) + Interval(slack)).ub()))


def chord_cut(dx, dy, r2: float):
    """A half-plane ``n·δ ≥ k`` holding every point of the box ``dx × dy`` with ``‖δ‖² ≥ r2``, or None.

    The box corners strictly inside the disc (proved in interval arithmetic) must be 1-3 consecutive ones;
    the circle leaves the box on the two edges from that chain to the outside corners, at points moved slightly
    back towards the chain and proved inside the disc. Those points and the inside corners span a convex
    polygon inside the disc; ``k`` is a lower bound of ``n`` at the two points, and the cut is kept only when
    every outside corner provably satisfies it (then the excluded part of the box lies in the polygon)."""
    xs, ys = (dx.lb(), dx.ub()), (dy.lb(), dy.ub())
    corners = [(xs[0], ys[0]), (xs[1], ys[0]), (xs[1], ys[1]), (xs[0], ys[1])]  # cyclic order

    def inside(p) -> bool:
        return (codac.sqr(Interval(p[0])) + codac.sqr(Interval(p[1]))).ub() < r2

    ins = [inside(c) for c in corners]
    n_in = sum(ins)
    if n_in == 0 or n_in == 4:
        return None
    # the chain of inside corners: start after an outside corner
    start = next(i for i in range(4) if ins[i] and not ins[i - 1])
    chain = [(start + k) % 4 for k in range(n_in)]
    if not all(ins[i] for i in chain):
        return None  # not consecutive
    pts = []
    for c_in, c_out in ((chain[0], (chain[0] - 1) % 4), (chain[-1], (chain[-1] + 1) % 4)):
        p, q = np.array(corners[c_in]), np.array(corners[c_out])
        s = _exit(p, q - p, r2)
        if s is None:
            return None
        s *= 1.0 - 1e-9
        pt = (float(p[0] + s * (q[0] - p[0])), float(p[1] + s * (q[1] - p[1])))
        if not inside(pt):
            return None
        pts.append(pt)
    (ax, ay), (bx, by) = pts
    nx, ny = -(by - ay), bx - ax
    norm = math.hypot(nx, ny)
    if not norm > 0:
        return None
    nx, ny = nx / norm, ny / norm
    cx, cy = corners[chain[0]]
    if nx * cx + ny * cy > nx * ax + ny * ay:  # orient n away from the inside corners
        nx, ny = -nx, -ny

    def dot(p):
        return Interval(nx) * Interval(p[0]) + Interval(ny) * Interval(p[1])

    k = min(dot(pts[0]).lb(), dot(pts[1]).lb())
    if any(not ins[i] and dot(corners[i]).lb() < k for i in range(4)):
        return None
    return (nx, ny), k


def _exit(p: np.ndarray, d: np.ndarray, r2: float) -> float | None:
    """The ``s ∈ [0, 1]`` where ``‖p + s·d‖² = r2`` leaves the disc (``p`` inside, ``p + d`` outside)."""
    a, b, c = float(d @ d), 2.0 * float(p @ d), float(p @ p) - r2
    disc = b * b - 4.0 * a * c
    if not (a > 0 and disc >= 0):
        return None
    s = (-b + math.sqrt(disc)) / (2.0 * a)
    return s if 0.0 <= s <= 1.0 else None


class LinearProgram:
    """The relaxation as ``A z ≤ b`` with the box bounds, and rigorous bounds of linear objectives on it."""

    def __init__(self, rel: Relaxation) -> None:
        n = len(rel.bounds)
        rows, rhs = [], []
        for coef, lo, hi in rel.rows:
            if math.isfinite(hi):
                rows.append(coef)
                rhs.append(hi)
            if math.isfinite(lo):
                rows.append({k: -a for k, a in coef.items()})
                rhs.append(-lo)
        self.n, self.rows, self.b = n, rows, np.asarray(rhs, float)
        self.A = np.zeros((len(rows), n))
        for i, coef in enumerate(rows):
            for k, a in coef.items():
                self.A[i, k] += a
        self.box = rel.bounds
        self.lp_bounds = [(x.lb() if math.isfinite(x.lb()) else None, x.ub() if math.isfinite(x.ub()) else None)
                          for x in rel.bounds]

    def _solve(self, c: np.ndarray, A: np.ndarray, bounds):
        from scipy.optimize import linprog

        with rounding_mode(NORMAL_ROUNDING):  # HiGHS is not written for round-upward
            res = linprog(c, A_ub=A, b_ub=self.b, bounds=bounds, method="highs")
        return res

    def safe_bound(self, c: dict[int, float], y: np.ndarray, box: list) -> float:
        """``inf (yᵀb + Σ_j (c − Aᵀy)_j · box_j)`` in interval arithmetic, for multipliers ``y ≤ 0``."""
        r = [Interval(c.get(j, 0.0)) for j in range(len(box))]
        total = Interval(0.0)
        for i in np.flatnonzero(y):
            yi = Interval(float(y[i]))
            total = total + yi * Interval(float(self.b[i]))
            for k, a in self.rows[i].items():
                r[k] = r[k] - yi * Interval(a)
        for j, rj in enumerate(r):
            if rj.lb() == 0.0 and rj.ub() == 0.0:
                continue
            total = total + rj * box[j]
        return total.lb()

    def minimum(self, c: dict[int, float]) -> float | None:
        """A rigorous lower bound of ``Σ c·z`` over the relaxation; −inf when none is found, None when the
        relaxation is proved infeasible."""
        cv = np.zeros(self.n)
        for k, a in c.items():
            cv[k] = a
        res = self._solve(cv, self.A, self.lp_bounds)
        if res.status == 0:
            y = np.minimum(res.ineqlin.marginals, 0.0)
            return self.safe_bound(c, y, self.box)
        if res.status == 2 and self.infeasible():
            return None
        return -math.inf

    def infeasible(self) -> bool:
        """Phase one: ``min s`` s.t. ``Az − s ≤ b``; infeasible when its rigorous lower bound is > 0."""
        A = np.hstack([self.A, -np.ones((len(self.rows), 1))])
        s = self.n
        cv = np.zeros(self.n + 1)
        cv[s] = 1.0
        res = self._solve(cv, A, self.lp_bounds + [(0.0, SLACK_BOUND)])
        if res.status != 0:
            return False
        y = np.minimum(res.ineqlin.marginals, 0.0)
        saved = self.rows
        self.rows = [{**r, s: -1.0} for r in saved]
        try:
            return self.safe_bound({s: 1.0}, y, self.box + [Interval(0.0, SLACK_BOUND)]) > 0.0
        finally:
            self.rows = saved


def lp_contract(box: list, edges, targets: list[int], *, narrow_theta: bool) -> bool:
    """Narrow both ends of every ``targets`` variable to the rigorous LP bounds over the relaxation of ``box``
    (one relaxation for all targets). Sound; returns False when the box is proved to hold no solution."""
    lp = LinearProgram(Relaxation(box, edges, narrow_theta))
    if lp.A.shape[0] == 0:
        return True
    for v in targets:
        lo = lp.minimum({v: 1.0})
        if lo is None:
            return False
        hi = lp.minimum({v: -1.0})
        if hi is None:
            return False
        hi = -hi
        new = box[v] & Interval(lo if lo > -math.inf else -codac.oo, hi if hi < math.inf else codac.oo)
        if new.is_empty():
            return False
        box[v] = new
    return True


def lp_end(box: list, edges, target: int, side: int, *, narrow_theta: bool) -> float | None:
    """The rigorous LP bound of one end of ``box[target]`` (lower end for ``side`` 0, upper for 1), never
    looser than the box's own; None when the relaxation proves the box empty."""
    lp = LinearProgram(Relaxation(box, edges, narrow_theta))
    if lp.A.shape[0] == 0:
        return box[target].lb() if side == 0 else box[target].ub()
    m = lp.minimum({target: 1.0 if side == 0 else -1.0})
    if m is None:
        return None
    return max(m, box[target].lb()) if side == 0 else min(-m, box[target].ub())
