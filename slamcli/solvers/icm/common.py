"""What ICM's single-robot solver (:mod:`~slamcli.solvers.icm.solver`) and its multi-robot variant
(:mod:`~slamcli.solvers.icm.team`) share: the on-line initialisation (Algorithm 2 step 1, eqs. 9-11), the
labels from sensor-reported ids and the one stopping rule.

Both drivers import from here; ``solver`` dispatches to ``team`` for multi-robot data, so ``team`` must not
import ``solver`` (that was a cycle, hidden inside a function body).
"""

from __future__ import annotations

import math
import time

import numpy as np

from slamcli.models.angles import wrap_angle
from slamcli.models.observation import inverse_range_bearing
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
    """
    T, N = prob.T, prob.n_obs
    poses = np.empty((T + 1, 3))
    poses[0] = prob.x0
    kin = prob.kinematic_poses() if kinematic else None
    labels = np.full(N, -1, np.int64)
    msum = np.zeros((max(N, 1), 2))
    mcnt = np.zeros(max(N, 1))
    L = 0
    Wf = W.flat
    r2 = radius * radius
    off = prob.offsets
    step_s = np.empty(T + 1)
    U = prob.controls.tolist()
    LAT = prob.lat.tolist()
    D = prob.odo_inc.tolist()
    gps_st = en.gps_step_stats(prob, W)
    has_gps = np.zeros(T + 1, bool)
    has_gps[prob.gps_step] = W.K > 0
    for t in range(T + 1):
        t0 = time.perf_counter()
        a, b = int(off[t]), int(off[t + 1])
        if t == 0:
            xh = prob.x0.copy()
        elif kinematic:
            xh = kin[t].copy()
        else:
            xh = _predict(prob, poses[t - 1], U[t - 1], LAT[t - 1])
        n_t = b - a
        match = np.full(n_t, -1, np.int64)
        if n_t:
            match = _match_step(prob, xh, a, b, fixed_labels, msum, mcnt, L, r2)
        x = xh
        if t > 0 and not kinematic:
            ok = match >= 0
            st = _stats_one(prob.v_body[a:b][ok], msum[match[ok]] / mcnt[match[ok], None])
            if has_gps[t]:
                st = tuple(float(u + g) for u, g in zip(st, gps_st[:, t]))
            x = _minimise_pose(prob, poses[t - 1], xh, U[t - 1], D[t - 1], st, Wf, iters)  # (11)
        poses[t] = x
        if n_t:
            L = _absorb_step(prob, x, a, b, match, fixed_labels, msum, mcnt, L, r2)
            labels[a:b] = match
        step_s[t] = time.perf_counter() - t0
    with np.errstate(invalid="ignore", divide="ignore"):
        landmarks = msum[:L] / mcnt[:L, None]
    return poses, labels, landmarks, step_s


def _predict(prob, prev, u, lat) -> np.ndarray:
    """x̂_t = g(x_{t-1}, u_{t-1}) of the problem's model (Problem): ``prev`` the previous pose, ``u`` = (v, ω)
    the previous control, ``lat`` its lateral speed."""
    px, py, pth = prev
    v0, w0 = u
    l0, cp, sp = lat, math.cos(pth), math.sin(pth)  # g(x, u) of the problem's model (Problem)
    return np.array(
        [
            px + prob.dt * v0 * cp - prob.dt * l0 * sp,
            py + prob.dt * v0 * sp + prob.dt * l0 * cp,
            wrap_angle(pth + prob.dt * w0),
        ]
    )


def _match_step(prob, xh, a, b, fixed_labels, msum, mcnt, L, r2) -> np.ndarray:
    """The matchings (n_t,) of step t's observations ``a:b`` from the predicted pose ``xh``: the known label when
    its map point already exists, else the nearest running mean (17) within ϑ (eqs. 9-10); ``-1`` = none."""
    n_t = b - a
    match = np.full(n_t, -1, np.int64)
    if fixed_labels is not None:
        lab = fixed_labels[a:b]
        match = np.where(lab >= 0, lab, 0)
        match = np.where((lab >= 0) & (mcnt[match] > 0), lab, -1)
    elif L:
        pts = inverse_range_bearing(xh, prob.z[a:b])  # eqs. (9)-(10)
        means = msum[:L] / mcnt[:L, None]
        d2 = ((pts[:, None, :] - means[None, :, :]) ** 2).sum(-1)
        j = np.argmin(d2, axis=1)
        match = np.where(d2[np.arange(n_t), j] <= r2, j, -1)
    return match


def _minimise_pose(prob, prev, xh, u, d, st, Wf, iters) -> np.ndarray:
    """The minimisation (11) of step t's pose from ``xh``: ``prev`` the previous pose, ``u`` its control, ``d``
    its odometry increment, ``st`` the 14 statistics of the matched observations (plus the GPS fix's)."""
    px, py, pth = prev
    g = (xh[0], xh[1], pth + prob.dt * u[1])
    ctx = (
        px,
        py,
        pth,
        g[0],
        g[1],
        g[2],
        d[0],
        d[1],
        d[2],
        0.0,
        0.0,
        0.0,
        0.0,
        0.0,
        0.0,
        0.0,
        0.0,
        0.0,
        0.0,
    )
    return np.array(
        en.cond_minimise_scalar(xh[0], xh[1], xh[2], ctx, st, Wf, prob.dt, iters, 1e-10)
    )  # (11)


def _absorb_step(prob, x, a, b, match, fixed_labels, msum, mcnt, L, r2) -> int:
    """Add step t's observations ``a:b``, seen from the pose ``x``, to the running means (17) (``msum``,
    ``mcnt``, in place); an unmatched one gets its known label, the nearest mean within ϑ or a new label, written
    into ``match`` in place. Returns the new number of labels L."""
    pts = inverse_range_bearing(x, prob.z[a:b])
    ok = match >= 0
    np.add.at(msum, match[ok], pts[ok])
    np.add.at(mcnt, match[ok], 1.0)
    for i in np.flatnonzero(~ok):  # first sight: a new label (or one just created at this step)
        if fixed_labels is not None:
            lab = int(fixed_labels[a + i])
            if lab < 0:
                continue
            L = max(L, lab + 1)
        else:
            lab = -1
            if L:
                dd = ((msum[:L] / mcnt[:L, None] - pts[i]) ** 2).sum(-1)
                j = int(np.argmin(dd))
                if dd[j] <= r2:
                    lab = j
            if lab < 0:
                lab = L
                L += 1
        match[i] = lab
        msum[lab] += pts[i]
        mcnt[lab] += 1.0
    return L


def _stats_one(v, m):
    """The 14 sufficient statistics (see :func:`slamcli.solvers.icm.energy.step_stats`) of one step's matched observations."""
    if v.shape[0] == 0:
        return (0.0,) * 14
    vx, vy, mx, my = v[:, 0], v[:, 1], m[:, 0], m[:, 1]
    return (
        float(v.shape[0]),
        float(vx.sum()),
        float(vy.sum()),
        float(mx.sum()),
        float(my.sum()),
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

