"""Narrowing operators (contractors) for the edges of a kinematic graph, built from codac primitives.

A *box* is a list of :class:`codac.Interval` (outward-rounded); a contractor narrows its variables in place
and satisfies paper 004 Def. 4.1: ``f(X) ⊆ X``, ``X ∩ ρ ⊆ f(X)`` and idempotence up to ``tol``
(:meth:`Contractor.contract` iterates to a local fixpoint).

Edges (θ from +x, counter-clockwise; paper 004 Fig. 2's convention is converted once in
``slamcli.sim.bounded.heading_from_paper004``):

* odometry, turn then move (``odometry_model = "turn_move"``), measured ``(d̃, α̃)``, half-widths ``(h_d, h_α)``::

      θ_{t+1} − θ_t ∈ [α̃ ± h_α],   (x_{t+1} − x_t, y_{t+1} − y_t) = d·(cos θ_{t+1}, sin θ_{t+1}),
      d ∈ [d̃ ± h_d] ∩ [0, ∞)

* observation of landmark j from pose t, measured ``(r̃, b̃)``, half-widths ``(h_r, h_b)``::

      (l_x − x_t, l_y − y_t) = r·(cos φ, sin φ),   φ = θ_t + b,  b ∈ [b̃ ± h_b],  r ∈ [r̃ ± h_r] ∩ [0, ∞)

The polar relation is codac's ``CtcPolar`` (2π-periodic, so headings stay unwrapped); sums and differences
are narrowed forward and backward (``SubOp.bwd``/``AddOp.bwd``). ``narrow_theta=False`` is paper 004's set
(§6: headings only from the turn chain, never narrowed by the polar relations); ``True`` lets them narrow θ.
"""

from __future__ import annotations

import contextlib
import ctypes
import ctypes.util
import sys


def _fenv():
    """``fegetround``/``fesetround`` of the C library (C99 <fenv.h>)."""
    lib = ctypes.CDLL(ctypes.util.find_library("m") or ctypes.util.find_library("c"))
    return lib.fegetround, lib.fesetround


_fegetround, _fesetround = _fenv()
#: the process's ordinary rounding mode (round to nearest, 0 on x86-64 and aarch64)
NORMAL_ROUNDING = 0 if "codac" in sys.modules else int(_fegetround())

import codac  # noqa: E402

#: the mode codac's interval library (gaol) sets at import: round upward. Its outward rounding relies on it.
INTERVAL_ROUNDING = int(_fegetround())
# codac leaves the whole process rounding upward, which silently changes every other float computation
# (float("1.2") parses to 1.2000000000000002) and crashes a later `import h5py` (libhdf5's float-format
# detection). Give the process its ordinary mode back; cuik switches per solve (:func:`interval_rounding`).
_fesetround(NORMAL_ROUNDING)


@contextlib.contextmanager
def rounding_mode(mode: int):
    """Run the block in the C library's rounding ``mode``, then restore the caller's mode."""
    prev = int(_fegetround())
    _fesetround(mode)
    try:
        yield
    finally:
        _fesetround(prev)


def interval_rounding():
    """Run codac interval code in the rounding mode it needs, then restore the caller's mode."""
    return rounding_mode(INTERVAL_ROUNDING)


Interval = codac.Interval
_POLAR = codac.CtcPolar()
_NONNEG = Interval(0.0, codac.oo)


def unbounded() -> codac.Interval:
    """``(-∞, +∞)``: the domain of a variable nothing is known about yet."""
    return Interval(-codac.oo, codac.oo)


def moved(old: codac.Interval, new: codac.Interval, tol: float) -> bool:
    """True when ``new`` (⊆ old) is empty or has a bound that moved inwards by more than ``tol``."""
    if new.is_empty():
        return True
    return new.lb() > old.lb() + tol or new.ub() < old.ub() - tol


class Contractor:
    """Base class: ``vars`` are box indices; :meth:`step` narrows once, :meth:`contract` to a local fixpoint."""

    vars: tuple[int, ...] = ()
    #: observation rows of the readings the operator uses, in its own order (empty = not recorded). The LP
    #: relaxation (:mod:`~slamcli.solvers.cuik.linear`) gives each row one range and one bearing variable shared
    #: by every operator that uses it; a band's last entry is the row whose true range is the band's edge
    readings: tuple[int, ...] = ()
    #: a band's tolerance on that range (ties within it are allowed; the solver's ``recovery_slack``)
    band_slack: float = 0.0
    #: local fixpoint iterations at most (the steps converge geometrically; this bounds the worst case)
    max_inner: int = 50

    def step(self, box: list, narrow_theta: bool) -> None:  # pragma: no cover - interface
        raise NotImplementedError

    def contract(self, box: list, narrow_theta: bool = True, tol: float = 1e-9) -> list[int] | None:
        """Narrow ``box`` in place; return the indices whose bounds moved by more than ``tol``, or None when
        a variable became empty (the constraint has no solution in the box)."""
        vs = self.vars
        start = prev = [(box[v].lb(), box[v].ub()) for v in vs]
        for _ in range(self.max_inner):
            self.step(box, narrow_theta)
            cur = [(box[v].lb(), box[v].ub()) for v in vs]
            if any(lo != lo for lo, _hi in cur):  # an empty interval has NaN bounds
                for v in vs:
                    box[v] = Interval.empty()
                return None
            if not any(c[0] > p[0] + tol or c[1] < p[1] - tol for c, p in zip(cur, prev)):
                break
            prev = cur
        return [v for v, c, p in zip(vs, cur, start) if c[0] > p[0] + tol or c[1] < p[1] - tol]


def _polar_sub(box: list, ix0: int, iy0: int, ix1: int, iy1: int, rho: codac.Interval, phi: codac.Interval):
    """Narrow ``(x1 − x0, y1 − y0) = ρ·(cos φ, sin φ)``; returns the contracted ``(φ, ρ)`` (the caller decides
    whether they may narrow a heading / a leg). The four position intervals are narrowed in place."""
    dx = box[ix1] - box[ix0]
    dy = box[iy1] - box[iy0]
    rho = Interval(rho)
    phi = Interval(phi)
    _POLAR.contract(dx, dy, rho, phi)
    if dx.is_empty() or dy.is_empty() or rho.is_empty():
        box[ix1] = Interval.empty()
        return phi, rho
    codac.SubOp.bwd(dx, box[ix1], box[ix0])  # x1 ∩= dx + x0,  x0 ∩= x1 − dx
    codac.SubOp.bwd(dy, box[iy1], box[iy0])
    return phi, rho


class OdometryTurnMove(Contractor):
    """Edge pose t → t+1 of the turn-and-move robot (see the module docstring).

    With ``leg = (i_d, i_α)`` the leg's distance and turn are variables of the box (initial domains
    :attr:`D`, :attr:`A`) that the full operator set narrows — so a local-frame cycle
    (:class:`SharedLandmarkLeg`) can tighten them; the paper set reads the constant measurement intervals.
    """

    def __init__(self, pose_from: tuple[int, int, int], pose_to: tuple[int, int, int], d: float, alpha: float,
                 h_d: float, h_alpha: float, leg: tuple[int, int] | None = None) -> None:
        self.p0, self.p1 = pose_from, pose_to
        self.leg = leg
        self.vars = (*pose_from, *pose_to) + (tuple(leg) if leg is not None else ())
        self.D = (Interval(d) + Interval(-h_d, h_d)) & _NONNEG  # outward-rounded d̃ ± h_d
        self.A = Interval(alpha) + Interval(-h_alpha, h_alpha)

    def step(self, box: list, narrow_theta: bool) -> None:
        (x0, y0, t0), (x1, y1, t1) = self.p0, self.p1
        use_leg = self.leg is not None and narrow_theta
        D = box[self.leg[0]] if use_leg else self.D
        A = box[self.leg[1]] if use_leg else self.A
        # θ_{t+1} − θ_t ∈ A, forward and backward (paper set included: this is the odometry turn chain)
        box[t1] = box[t1] & (box[t0] + A)
        box[t0] = box[t0] & (box[t1] - A)
        phi, rho = _polar_sub(box, x0, y0, x1, y1, D, box[t1])
        if narrow_theta:
            box[t1] = box[t1] & phi
        if use_leg:
            box[self.leg[0]] = box[self.leg[0]] & rho
            box[self.leg[1]] = box[self.leg[1]] & (box[t1] - box[t0])


class SharedLandmarkLeg(Contractor):
    """A cycle of the kinematic graph written in the frame of pose t: poses t and t+1 see the same landmark.

    With ``q_t = r_t·(cos b_t, sin b_t)`` the landmark in frame t, ``q_s`` the same landmark in frame t+1 and
    the leg ``(d, α)`` (turn α, then move d along the new heading), ``q_t = R(α)·(d·e_x + q_s)``, i.e. in the
    frame turned by α::

        r_t·(cos(b_t − α), sin(b_t − α)) = (d + q_s,x, q_s,y)

    Each unknown appears once (α only in φ = b_t − α, d only in the x component), so the polar relation pins
    the leg to about the sensor's precision, whatever the absolute boxes of the poses (no wrapping through
    world-frame boxes). Variables: the leg ``(i_d, i_α)``; the readings are intervals ``[r̃ ± h_r]``,
    ``[b̃ ± h_b]``. Full operator set only (the paper's set has no such operator).
    """

    def __init__(self, leg: tuple[int, int], z_t: tuple[float, float], z_s: tuple[float, float], h_r: float,
                 h_b: float) -> None:
        self.leg = leg
        self.vars = tuple(leg)
        self.Rt = (Interval(z_t[0]) + Interval(-h_r, h_r)) & _NONNEG
        self.Bt = Interval(z_t[1]) + Interval(-h_b, h_b)
        rs = self.Rs = (Interval(z_s[0]) + Interval(-h_r, h_r)) & _NONNEG
        self.Bs = Interval(z_s[1]) + Interval(-h_b, h_b)
        qx, qy, phi = unbounded(), unbounded(), Interval(self.Bs)
        _POLAR.contract(qx, qy, Interval(rs), phi)  # q_s, a constant box
        self.qsx, self.qsy = qx, qy

    def step(self, box: list, narrow_theta: bool) -> None:
        if not narrow_theta:
            return
        i_d, i_a = self.leg
        gx, gy, rt = box[i_d] + self.qsx, Interval(self.qsy), Interval(self.Rt)
        phi = self.Bt - box[i_a]
        _POLAR.contract(gx, gy, rt, phi)
        box[i_d] = box[i_d] & (gx - self.qsx)
        box[i_a] = box[i_a] & (self.Bt - phi)


class RangeBearing(Contractor):
    """Observation edge pose t → landmark j (see the module docstring)."""

    def __init__(self, pose: tuple[int, int, int], landmark: tuple[int, int], r: float, b: float, h_r: float,
                 h_b: float) -> None:
        self.pose, self.landmark = pose, landmark
        self.vars = (*pose, *landmark)
        self.R = (Interval(r) + Interval(-h_r, h_r)) & _NONNEG
        self.B = Interval(b) + Interval(-h_b, h_b)

    def step(self, box: list, narrow_theta: bool) -> None:
        (x, y, t), (lx, ly) = self.pose, self.landmark
        phi = box[t] + self.B
        phi, _rho = _polar_sub(box, x, y, lx, ly, self.R, phi)
        if narrow_theta:
            box[t] = box[t] & (phi - self.B)  # θ ∩= φ − B  (backward step of φ = θ + b)


class OutsideBand(Contractor):
    """Negative information of the closest-landmark sensor: landmark m is NOT in the visible band closer than
    what the sensor reported from pose t.

    Paper 004 §6: the robot "does notice the closest landmark" only (``NoiseBounds.closest_only``; 360° field
    of view, ranges ``[r_min, r_max]``). If pose t reported a landmark at true range ``r ∈ R = [r̃ ± h_r]``,
    every other landmark m — of any type, seen before or after t — is either invisible (closer than
    ``r_min``) or not closer than the reported one (ties allowed: the sensor picks one of equals)::

        ‖l_m − p_t‖ ∉ [r_min, R.lb)     ⇔   ‖l_m − p_t‖² ∈ [0, r_min²] ∪ [R.lb², ∞)

    A pose that reported nothing saw no landmark in range: ``‖l_m − p_t‖ ∉ [r_min, r_max]``, i.e. the
    band's upper end is ``r_max`` and the outer set is ``(r_max, ∞)`` (closed here: sound).

    Forward: ``s = (l_x − x)² + (l_y − y)²``; each allowed piece narrows a copy backward (``AddOp``,
    ``SqrOp``, ``SubOp``) and the result is the hull of the surviving pieces — empty when neither survives.
    The outer piece is non-convex in (x, y), so the operator mostly refutes (a box certainly inside the
    band) and trims boxes only where one coordinate alone decides.
    """

    def __init__(self, pose: tuple[int, int, int], landmark: tuple[int, int], band_lo: float, band_hi: float) -> None:
        self.pose, self.landmark = pose, landmark
        self.vars = (pose[0], pose[1], *landmark)
        self.pieces = _band_pieces(band_lo, band_hi)  # outward rounding: enlarged, never shrunk
        # quick exit: boxes certainly farther apart than this (with a relative margin that dwarfs the
        # rounding of the float test) satisfy the constraint everywhere — nothing to refute or narrow
        self._far2 = band_hi * band_hi * (1.0 + 1e-9) + 1e-12

    def _far(self, box: list) -> bool:
        """The boxes are certainly farther apart than the band (float test with a margin): nothing to do.
        Skipping an operator is always sound (it only narrows less)."""
        (x, y, _t), (lx, ly) = self.pose, self.landmark
        bx, by, blx, bly = box[x], box[y], box[lx], box[ly]
        gx = max(0.0, blx.lb() - bx.ub(), bx.lb() - blx.ub())
        gy = max(0.0, bly.lb() - by.ub(), by.lb() - bly.ub())
        return gx * gx + gy * gy > self._far2

    def contract(self, box: list, narrow_theta: bool = True, tol: float = 1e-9) -> list[int] | None:
        if self._far(box):  # the common case: most landmarks are far from most poses
            return []
        return super().contract(box, narrow_theta, tol)

    #: one pass suffices: the pieces' hull is re-queued by the propagation when its variables move
    max_inner = 2

    def step(self, box: list, narrow_theta: bool) -> None:
        if self._far(box):
            return
        (x, y, _t), (lx, ly) = self.pose, self.landmark
        bx, by, blx, bly = box[x], box[y], box[lx], box[ly]
        hull = None
        for dx, dy in _outside_pieces(blx - bx, bly - by, self.pieces):
            v = [Interval(box[i]) for i in (x, y, lx, ly)]
            codac.SubOp.bwd(dx, v[2], v[0])
            codac.SubOp.bwd(dy, v[3], v[1])
            if any(iv.is_empty() for iv in v):
                continue
            hull = v if hull is None else [a | b for a, b in zip(hull, v)]
        if hull is None:
            for i in (x, y, lx, ly):
                box[i] = Interval.empty()
            return
        for i, iv in zip((x, y, lx, ly), hull):
            box[i] = box[i] & iv


def _band_pieces(band_lo: float, band_hi: float) -> list:
    """The allowed values of ``‖δ‖²`` outside the band ``[band_lo, band_hi)``, enlarged outwards (sound)."""
    lo2 = (Interval(band_lo) * Interval(band_lo)).ub() if band_lo > 0 else None
    return ([Interval(0.0, lo2)] if lo2 is not None else []) + [
        Interval((Interval(band_hi) * Interval(band_hi)).lb(), codac.oo)]


def _outside_pieces(dx: codac.Interval, dy: codac.Interval, pieces: list) -> list:
    """``δ = (dx, dy)`` narrowed to ``‖δ‖² ∈ piece``, for each piece that leaves it non-empty."""
    sx, sy = codac.sqr(dx), codac.sqr(dy)
    s = sx + sy
    out = []
    for piece in pieces:
        sk = s & piece
        if sk.is_empty():
            continue
        sxk, syk, dxk, dyk = Interval(sx), Interval(sy), Interval(dx), Interval(dy)
        codac.AddOp.bwd(sk, sxk, syk)
        codac.SqrOp.bwd(sxk, dxk)
        codac.SqrOp.bwd(syk, dyk)
        if not (dxk.is_empty() or dyk.is_empty()):
            out.append((dxk, dyk))
    return out


def _outside(dx: codac.Interval, dy: codac.Interval, pieces: list):
    """The hull of :func:`_outside_pieces`; None when no piece survives."""
    hull = None
    for dxk, dyk in _outside_pieces(dx, dy, pieces):
        hull = (dxk, dyk) if hull is None else (hull[0] | dxk, hull[1] | dyk)
    return hull


class OutsideBandLocal(Contractor):
    """:class:`OutsideBand` for a landmark seen from the pose next to the reporting one, written in a local
    frame (like :class:`SharedLandmarkLeg`), so only the leg ``(d, α)`` between the two poses and a reading
    enter — the world-frame boxes of the pose and the landmark (metres wide after a long chain) do not.

    ``from_next=False``: pose t reported a landmark at range ``r``; landmark m was seen from pose t−1 at
    ``z = (r_m, b_m)``. In the frame of pose t−1, ``l_m − p_t = r_m·e(b_m) − d·e(α)``.
    ``from_next=True``: pose t−1 reported a landmark at range ``r``; landmark m was seen from pose t at ``z``.
    In the frame of pose t, ``l_m − p_{t−1} = (d + r_m cos b_m, r_m sin b_m)``.
    Either way ``‖l_m − p‖ ∉ [band_lo, band_hi)``. Variables: the leg ``(i_d, i_α)``."""

    def __init__(self, leg: tuple[int, int], z: tuple[float, float], h_r: float, h_b: float, band_lo: float,
                 band_hi: float, from_next: bool) -> None:
        self.leg, self.from_next = leg, from_next
        self.vars = tuple(leg)
        self.Rm = (Interval(z[0]) + Interval(-h_r, h_r)) & _NONNEG
        self.Bm = Interval(z[1]) + Interval(-h_b, h_b)
        qx, qy, phi = unbounded(), unbounded(), Interval(self.Bm)
        _POLAR.contract(qx, qy, Interval(self.Rm), phi)  # the sighting of m in its pose's frame, a constant box
        self.qx, self.qy = qx, qy
        self.pieces = _band_pieces(band_lo, band_hi)

    max_inner = 3

    def step(self, box: list, narrow_theta: bool) -> None:
        i_d, i_a = self.leg
        if self.from_next:
            out = _outside(box[i_d] + self.qx, Interval(self.qy), self.pieces)
            box[i_d] = Interval.empty() if out is None else box[i_d] & (out[0] - self.qx)
            return
        px, py, rho, phi = unbounded(), unbounded(), Interval(box[i_d]), Interval(box[i_a])
        _POLAR.contract(px, py, rho, phi)  # P = d·e(α)
        out = _outside(self.qx - px, self.qy - py, self.pieces)
        if out is None or not narrow_theta:
            if out is None:
                box[i_d] = Interval.empty()
                box[i_a] = Interval.empty()
            return
        px, py = px & (self.qx - out[0]), py & (self.qy - out[1])
        _POLAR.contract(px, py, rho, phi)
        box[i_d] = box[i_d] & rho
        box[i_a] = box[i_a] & phi


class Separated(Contractor):
    """A declared map prior (not a sensor fact): two distinct landmarks are at least ``s`` apart,
    ``‖l_a − l_b‖ ≥ s`` (``NoiseBounds.min_separation``; 0 = nothing declared, no operator). Refutes a
    hypothesis that would need two labels for one physical landmark once their boxes are certainly closer
    than ``s``."""

    def __init__(self, a: tuple[int, int], b: tuple[int, int], s: float) -> None:
        self.a, self.b = a, b
        self.vars = (*a, *b)
        self.piece = Interval((Interval(s) * Interval(s)).lb(), codac.oo)

    def step(self, box: list, narrow_theta: bool) -> None:
        (ax, ay), (bx, by) = self.a, self.b
        dx, dy = box[bx] - box[ax], box[by] - box[ay]
        sx, sy = codac.sqr(dx), codac.sqr(dy)
        s = (sx + sy) & self.piece
        if s.is_empty():
            for i in self.vars:
                box[i] = Interval.empty()
            return
        codac.AddOp.bwd(s, sx, sy)
        codac.SqrOp.bwd(sx, dx)
        codac.SqrOp.bwd(sy, dy)
        codac.SubOp.bwd(dx, box[bx], box[ax])
        codac.SubOp.bwd(dy, box[by], box[ay])


class SeparatedLocal(Contractor):
    """The separation prior written in the frame of pose t−1 (like :class:`SharedLandmarkLeg`): pose t−1 sees
    landmark a at ``z_a``, pose t sees a *different* label b at ``z_b``. In the frame turned by the leg's α::

        q_a = r_a·(cos(b_a − α), sin(b_a − α)),   q_b = (d + r_b cos b_b, r_b sin b_b),   ‖q_a − q_b‖ ≥ s

    The world-frame :class:`Separated` cannot refute a duplicate label once the absolute boxes are wider than
    ``s`` (wrapping); here only the leg ``(d, α)`` and the two readings enter, so "the landmark seen from two
    consecutive poses is two landmarks" is refuted whenever the readings place them closer than ``s``.
    Refutation only (the box is returned unchanged or emptied): sound, since it never removes a point that
    satisfies the constraint. Variables: the leg ``(i_d, i_α)``."""

    def __init__(self, leg: tuple[int, int], z_a: tuple[float, float], z_b: tuple[float, float], h_r: float,
                 h_b: float, s: float) -> None:
        self.leg = leg
        self.vars = tuple(leg)
        self.Ra = (Interval(z_a[0]) + Interval(-h_r, h_r)) & _NONNEG
        self.Ba = Interval(z_a[1]) + Interval(-h_b, h_b)
        rb = (Interval(z_b[0]) + Interval(-h_r, h_r)) & _NONNEG
        bb = Interval(z_b[1]) + Interval(-h_b, h_b)
        self.qbx, self.qby = rb * codac.cos(bb), rb * codac.sin(bb)
        self.s2 = (Interval(s) * Interval(s)).lb()

    max_inner = 1

    def step(self, box: list, narrow_theta: bool) -> None:
        i_d, i_a = self.leg
        phi = self.Ba - box[i_a]
        dx = self.Ra * codac.cos(phi) - box[i_d] - self.qbx
        dy = self.Ra * codac.sin(phi) - self.qby
        if (codac.sqr(dx) + codac.sqr(dy)).ub() < self.s2:
            box[i_d] = Interval.empty()
            box[i_a] = Interval.empty()
