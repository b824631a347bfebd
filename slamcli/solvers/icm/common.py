"""What ICM's single-robot solver (:mod:`~slamcli.solvers.icm.solver`) and its multi-robot variant
(:mod:`~slamcli.solvers.icm.team`) share: the on-line initialisation (Algorithm 2 step 1, eqs. 9-11), the
labels from sensor-reported ids and the one stopping rule.

Both drivers import from here; ``solver`` dispatches to ``team`` for multi-robot data, so ``team`` must not
import ``solver`` (that was a cycle, hidden inside a function body).
"""

from __future__ import annotations

import math
import time
from itertools import chain, repeat

import numpy as np

from slamcli.models.angles import TWO_PI
from slamcli.solvers.frontend import compact_labels
from slamcli.solvers.icm import energy as en


def stop_decision(E_before: float, E_after: float, rtol: float) -> str:
    """The one stopping rule. ``E_before`` / ``E_after``: energies at the start and end of a sweep over the same
    observations. Returns ``"increase"`` when the energy rose (reported, never a stop), ``"converged"`` when it
    fell by a relative amount in ``[0, rtol]``, else ``"continue"``."""
    d = E_before - E_after
    if d < 0:
        return "increase"
    return "converged" if d <= rtol * max(abs(E_before), 1e-300) else "continue"


def reported_labels(reported_id) -> np.ndarray:
    """Labels 0.. by order of first appearance of each sensor-reported id; ``-1`` stays ``-1``."""
    return compact_labels(reported_id)[0]


def online_init(
    prob: en.Problem,
    W: en.Weights,
    *,
    radius: float,
    kinematic: bool = False,
    iters: int = 5,
    fixed_labels: np.ndarray | None = None,
):
    """Algorithm 2, step 1 (eqs. 9-11), run causally over t = 0..T.

    Parameters
    ----------
    radius : float               ϑ: an observation starts a new label when no map point lies within it.
    kinematic : bool             poses from g(x, u) only (paper Fig. 6), skipping the minimisation (11).
    fixed_labels : ndarray (N,)  known matchings (used instead of the nearest-point rule); labels must be
                                 numbered by first appearance.

    Returns
    -------
    poses_xyt (T+1, 3), labels (N,) int64, landmarks_xy (L, 2) — the running means (17) — and the time spent
    per step, s (T+1,).

    The nearest running mean of a sighting is looked up through :class:`MeanGrid` (a uniform grid hash of cell
    side ϑ), so a step costs O(sightings) instead of O(sightings × L): the labels and every float equal those
    of comparing each sighting with every mean.
    """
    T, N = prob.T, prob.n_obs
    jit = en.compiled_kernels() if T + 1 >= en.JIT_MIN_POSES and not kinematic else None
    minimise = en.cond_minimise_scalar if jit is None else jit.cond_minimise_scalar  # the same floats
    poses = np.empty((T + 1, 3))
    poses[0] = prob.x0
    kin = prob.kinematic_poses() if kinematic else None
    labels = np.full(N, -1, np.int64)
    grid = MeanGrid(N, radius if fixed_labels is None else math.inf)  # known labels: no lookups, no grid
    Wf = W.flat
    off = prob.offsets.tolist()
    step_s = np.empty(T + 1)
    U = prob.controls.tolist()
    LAT = prob.lat.tolist()
    D = prob.odo_inc.tolist()
    rng, brg = np.ascontiguousarray(prob.z[:, 0]), np.ascontiguousarray(prob.z[:, 1])
    gps_st = en.gps_step_stats(prob, W)
    has_gps = np.zeros(T + 1, bool)
    has_gps[prob.gps_step] = W.K > 0
    has_gps = has_gps.tolist()
    for t in range(T + 1):
        t0 = time.perf_counter()
        a, b = off[t], off[t + 1]
        if t == 0:
            xh = tuple(prob.x0.tolist())
        elif kinematic:
            xh = tuple(kin[t].tolist())
        else:
            xh = _predict(prob.dt, poses[t - 1].tolist(), U[t - 1], LAT[t - 1])
        if b == a:
            match = np.zeros(0, np.int64)
        elif fixed_labels is not None:
            match = _known_matches(fixed_labels[a:b], grid.cnt)
        else:
            match = grid.nearest(_points(xh, rng[a:b], brg[a:b]))  # eqs. (9)-(10)
        x = xh
        if t > 0 and not kinematic:
            ok = match >= 0
            st = _stats_one(prob.v_body[a:b][ok], grid.means(match[ok]))
            if has_gps[t]:
                st = tuple(float(u + g) for u, g in zip(st, gps_st[:, t]))
            x = _minimise_pose(minimise, prob.dt, poses[t - 1], xh, U[t - 1], D[t - 1], st, Wf, iters)  # (11)
        poses[t] = x
        if b > a:
            _absorb_step(grid, _points(x, rng[a:b], brg[a:b]), match,
                         None if fixed_labels is None else fixed_labels[a:b])
            labels[a:b] = match
        step_s[t] = time.perf_counter() - t0
    return poses, labels, grid.landmarks(), step_s


def _predict(dt, prev, u, lat) -> tuple[float, float, float]:
    """x̂_t = g(x_{t-1}, u_{t-1}) of the problem's model (Problem): ``prev`` the previous pose, ``u`` = (v, ω)
    the previous control, ``lat`` its lateral speed (plain floats)."""
    px, py, pth = prev
    v0, w0 = u
    cp, sp = math.cos(pth), math.sin(pth)  # g(x, u) of the problem's model (Problem)
    return (px + dt * v0 * cp - dt * lat * sp, py + dt * v0 * sp + dt * lat * cp, _wrap_float(pth + dt * w0))


def _wrap_float(a: float) -> float:
    """:func:`slamcli.models.angles.wrap_angle` of one Python float, bit for bit, without numpy's scalar cost."""
    w = a - TWO_PI * math.floor((a + math.pi) / TWO_PI)
    if w >= math.pi:
        w -= TWO_PI
    if w < -math.pi:
        w += TWO_PI
    return w


def _points(x, rng, brg) -> np.ndarray:
    """``h⁻¹(x, z) (n, 2)`` of one pose ``x = (x, y, θ)`` (floats) and its ranges / bearings ``(n,)``: the
    arithmetic of :func:`slamcli.models.observation.inverse_range_bearing`, bit for bit, without its
    broadcasting set-up (it runs twice per step of the on-line init)."""
    a = x[2] + brg
    out = np.empty((a.shape[0], 2))
    out[:, 0] = x[0] + rng * np.cos(a)
    out[:, 1] = x[1] + rng * np.sin(a)
    return out


def _known_matches(lab, cnt) -> np.ndarray:
    """Known labels ``lab (n_t,)`` of one step whose map point already exists (``cnt > 0``), else ``-1``."""
    match = np.where(lab >= 0, lab, 0)
    return np.where((lab >= 0) & (cnt[match] > 0), lab, -1)


class MeanGrid:
    """The running means (17) of the map points, ``sum / cnt`` per label, with a uniform grid hash over them.

    Each label sits in the grid cell of its current mean; the cell side is a hair over ϑ, so every mean within
    ϑ of a point lies in the 3×3 block of cells around the point's cell. :meth:`nearest` compares a point with
    the labels of that block only, in label order, with the arithmetic of a full scan: it returns the label a
    comparison with every mean returns (nearest, ties to the lowest label, none beyond ϑ). A label moves cell
    when its mean crosses a cell border. ϑ ≤ 0 or not finite: no grid, every label is a candidate.
    """

    _SPAN = 2**30  # cell indices are clipped to ±_SPAN: far points share border cells, a superset stays exact
    #: relative margin of the cell side over ϑ: a point within ϑ of a mean stays within one cell of it whatever
    #: the rounding of ``floor(p / h)`` (coordinates up to ~1e12 ϑ)
    _CELL_SLACK = 1e-3

    def __init__(self, n_max: int, radius: float):
        n = max(int(n_max), 1)
        self.sum = np.zeros((n, 2))
        self.cnt = np.zeros(n)
        self.L = 0
        self.r2 = radius * radius
        self.inv_h = 1.0 / (radius * (1.0 + self._CELL_SLACK)) if 0.0 < radius < math.inf else None
        self.key = np.full(n, np.iinfo(np.int64).min, np.int64)  # cell of each label (min: not placed)
        self.cells: dict[int, list[int]] = {}
        d = np.arange(-1, 2, dtype=np.int64)
        self._block = (d[:, None] * (1 << 32) + d[None, :]).ravel()

    def means(self, labels) -> np.ndarray:
        return self.sum[labels] / self.cnt[labels, None]

    def landmarks(self) -> np.ndarray:
        with np.errstate(invalid="ignore", divide="ignore"):
            return self.sum[: self.L] / self.cnt[: self.L, None]

    def _keys(self, pts) -> np.ndarray:
        k = np.floor(pts * self.inv_h)
        np.minimum(np.maximum(k, -self._SPAN, out=k), self._SPAN, out=k)  # NaN: any cell, it matches nothing
        k = k.astype(np.int64)
        return k[:, 0] * (1 << 32) + k[:, 1]

    def candidates(self, pts) -> np.ndarray:
        """Labels, ascending, whose mean may lie within ϑ of any of the points ``pts (n, 2)``."""
        if self.inv_h is None:
            return np.arange(self.L)
        keys = set((self._keys(pts)[:, None] + self._block).ravel().tolist())
        found = chain.from_iterable(map(self.cells.get, keys, repeat(())))
        return np.array(sorted(found), np.int64)

    def nearest(self, pts) -> np.ndarray:
        """The label of the nearest mean within ϑ of each point ``pts (n, 2)`` (eqs. 9-10), ``-1`` = none."""
        cand = self.candidates(pts)
        if cand.size == 0:
            return np.full(pts.shape[0], -1, np.int64)
        d2 = ((pts[:, None, :] - self.means(cand)[None, :, :]) ** 2).sum(-1)
        j = np.argmin(d2, axis=1)
        return np.where(d2[np.arange(pts.shape[0]), j] <= self.r2, cand[j], -1)

    def add(self, labels, pts) -> None:
        """Add the points ``pts (n, 2)`` to the means of ``labels (n,)`` (eq. 17) and move the labels whose
        mean changed cell."""
        np.add.at(self.sum, labels, pts)
        np.add.at(self.cnt, labels, 1.0)
        if self.inv_h is None or labels.size == 0:
            return
        new = self._keys(self.means(labels))
        moved = (new != self.key[labels]).nonzero()[0]
        for j, k in zip(labels[moved].tolist(), new[moved].tolist()):  # a repeated label moves twice, to one cell
            old = int(self.key[j])
            if old in self.cells:
                self.cells[old].remove(j)
            self.cells.setdefault(k, []).append(j)
            self.key[j] = k


def _minimise_pose(minimise, dt, prev, xh, u, d, st, Wf, iters):
    """The minimisation (11) of step t's pose from ``xh`` by ``minimise`` (:func:`~slamcli.solvers.icm.energy.
    cond_minimise_scalar` or its compiled copy): ``prev`` the previous pose, ``u`` its control, ``d`` its
    odometry increment, ``st`` the 14 statistics of the matched observations (plus the GPS fix's)."""
    px, py, pth = float(prev[0]), float(prev[1]), float(prev[2])
    ctx = (px, py, pth, xh[0], xh[1], pth + dt * u[1], d[0], d[1], d[2], 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0,
           0.0, 0.0)
    return minimise(xh[0], xh[1], xh[2], ctx, st, Wf, dt, iters, 1e-10)  # (11)


def _absorb_step(grid: MeanGrid, pts, match, known) -> None:
    """Add step t's observations, seen as the points ``pts (n_t, 2)``, to the running means (17) of ``grid``
    (in place); an unmatched one gets its known label (``known``, or None for the nearest-point rule), the
    nearest mean within ϑ or a new label, written into ``match`` in place."""
    ok = match >= 0
    grid.add(match[ok], pts[ok])
    for i in (~ok).nonzero()[0].tolist():  # first sight: a new label (or one just created at this step)
        if known is not None:
            lab = int(known[i])
            if lab < 0:
                continue
            grid.L = max(grid.L, lab + 1)
        else:
            lab = int(grid.nearest(pts[i : i + 1])[0])
            if lab < 0:
                lab = grid.L
                grid.L += 1
        match[i] = lab
        grid.add(np.array([lab]), pts[i : i + 1])


_sum = np.add.reduce  # ndarray.sum without its Python wrapper: the same pairwise sum


def _stats_one(v, m):
    """The 14 sufficient statistics (see :func:`slamcli.solvers.icm.energy.step_stats`) of one step's matched observations."""
    if v.shape[0] == 0:
        return (0.0,) * 14
    vx, vy, mx, my = v[:, 0], v[:, 1], m[:, 0], m[:, 1]
    return (
        float(v.shape[0]),
        float(_sum(vx)),
        float(_sum(vy)),
        float(_sum(mx)),
        float(_sum(my)),
        float(vx @ vx),
        float(vx @ vy),
        float(vy @ vy),
        float(vx @ mx),
        float(vx @ my),
        float(vy @ mx),
        float(vy @ my),
        float(mx @ mx),
        float(my @ my),
    )

