"""Gated on-line initialisation of ICM-SLAM (``init="gated"``, beyond the paper).

Algorithm 2's step 1 matches a sighting within a fixed radius ϑ and moves the pose with fixed weights; on a
long real run the drift outgrows ϑ. Here the pose carries a propagated covariance that sets gate and gain:

* **prediction** ``x̂_t = g(x_{t-1}, u_{t-1})``, ``P̂_t = F P_{t-1} Fᵀ + G_u Σ_u G_uᵀ``, ``Σ_u = diag(motion_std²)``
  (car model: :func:`slamcli.models.ackermann.ackermann_jacobians`);
* **gate** for ``p = h⁻¹(x̂, z)`` against label ``j``: ``ν = p − m_j``, ``S = J P̂ Jᵀ + Σ_z + C_j + Σ_z/n_j``,
  ``J = ∂h⁻¹/∂x``, ``Σ_z`` the world-frame covariance of ``h⁻¹``, ``C_j = J P Jᵀ`` frozen at the label's first
  sight; matched when ``νᵀ S⁻¹ ν ≤ χ²₂(gate_prob)``, a new label beyond ``χ²₂(birth_prob)``, unlabelled (−1)
  in between; one label per sighting and scan, nearest first;
* **gain**: the information-form update of ``N(x̂, P̂)`` with the matched sightings (two re-linearised
  iterations), ``P = (P̂⁻¹ + Σ Jᵀ S_j⁻¹ J)⁻¹``, its position block kept no smaller than the smallest ``C_j``
  (sightings of one landmark are not independent);
* **map points**: running means of ``h⁻¹(x_t, z)`` (eq. 17), so the rest of ICM is unchanged.

Labels are searched with a ``scipy.spatial.cKDTree`` rebuilt every :data:`REBUILD_EVERY` new labels.
"""

from __future__ import annotations

import math
import time

import numpy as np
from scipy.spatial import cKDTree

from slamcli.models.angles import wrap_angle_fast as wrap_angle
from slamcli.solvers.frontend import _inv2 as inv2x2  # closed-form 2×2 inverses
from slamcli.solvers.icm import energy as en
from slamcli.types import SlamInputs

#: new labels between two rebuilds of the KD-tree over the map points (the rest are checked directly)
REBUILD_EVERY = 64
#: Gauss-Newton iterations of the pose update at a step with matched sightings
UPDATE_ITERS = 2
#: upper bound of the search radius around a sighting, m (the χ² gate decides; this bounds the tree query)
MAX_SEARCH_M = 25.0
#: variance floor, m² / rad², of a motion step (keeps P̂ invertible on a car that stands still)
VAR_FLOOR = 1e-10


def chi2_2dof(prob: float) -> float:
    """Quantile of the χ² distribution with 2 degrees of freedom: ``−2 ln(1 − p)`` (closed form)."""
    return -2.0 * math.log1p(-prob)


def step_noise_body(inputs: SlamInputs, T: int) -> np.ndarray:
    """Actuation noise of each step in the body frame, ``G_u(0) Σ_u G_u(0)ᵀ`` ``(T, 3, 3)``.

    DDMR: ``G_u = dt·[[1, 0], [0, 0], [0, 1]]``; car model: the shared Jacobian at heading 0 (the body frame).
    Raises ValueError naming ``noise.motion_std`` when it is not positive.
    """
    ms = np.asarray(inputs.noise.motion_std, float)
    if not (ms.shape == (2,) and np.all(ms > 0)):
        raise ValueError(f"init=gated: noise.motion_std = {ms.tolist()} must be two positive values")
    dt = float(inputs.dt)
    if getattr(inputs, "motion_model", "ddmr") == "ackermann":
        from slamcli.models.ackermann import ackermann_jacobians

        u = np.asarray(inputs.controls, float).reshape(-1, 2)
        _, G_u = ackermann_jacobians(np.zeros(3), u, dt, inputs.vehicle)
    else:
        G_u = np.zeros((T, 3, 2))
        G_u[:, 0, 0] = dt
        G_u[:, 2, 1] = dt
    cov = np.einsum("tij,j,tkj->tik", G_u, ms**2, G_u)
    cov[:, [0, 1, 2], [0, 1, 2]] += VAR_FLOOR
    return cov


def _rot3(th: float) -> np.ndarray:
    c, s = math.cos(th), math.sin(th)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def sighting_cov(theta: float, z: np.ndarray, range_std: float, bearing_std: float) -> np.ndarray:
    """World-frame covariance ``(n, 2, 2)`` of ``h⁻¹(x, z)`` for fixed ``x``: ``σ_r`` along the beam of world
    angle ``θ + b``, ``r σ_b`` across it."""
    a = theta + z[:, 1]
    c, s = np.cos(a), np.sin(a)
    vr, vb = range_std**2, (z[:, 0] * bearing_std) ** 2
    out = np.empty((z.shape[0], 2, 2))
    out[:, 0, 0] = c * c * vr + s * s * vb
    out[:, 1, 1] = s * s * vr + c * c * vb
    out[:, 0, 1] = out[:, 1, 0] = c * s * (vr - vb)
    return out


def point_jacobian(theta: float, v_body: np.ndarray) -> np.ndarray:
    """``J = ∂h⁻¹(x, z)/∂x`` ``(n, 2, 3)`` with ``h⁻¹ = p + R(θ) v``: ``[I | R'(θ) v]``."""
    c, s = math.cos(theta), math.sin(theta)
    J = np.zeros((v_body.shape[0], 2, 3))
    J[:, 0, 0] = J[:, 1, 1] = 1.0
    J[:, 0, 2] = -s * v_body[:, 0] - c * v_body[:, 1]
    J[:, 1, 2] = c * v_body[:, 0] - s * v_body[:, 1]
    return J


def _floor_xy(P: np.ndarray, C: np.ndarray) -> np.ndarray:
    """``P`` with its position block raised to at least ``C`` (2, 2) in the Loewner order (``P_xy`` +
    the positive part of ``C − P_xy``)."""
    d = C - P[:2, :2]
    w, V = np.linalg.eigh(0.5 * (d + d.T))
    if w.max() <= 0.0:
        return P
    out = P.copy()
    out[:2, :2] += (V * np.clip(w, 0.0, None)) @ V.T
    return out


class _LabelIndex:
    """Running-mean map points with their first-sight covariance and a KD-tree for the neighbour search."""

    def __init__(self, n_max: int) -> None:
        n = max(n_max, 1)
        self.sum = np.zeros((n, 2))
        self.cnt = np.zeros(n)
        self.C = np.zeros((n, 2, 2))
        self.L = 0
        self.tree: cKDTree | None = None
        self.n_tree = 0

    def means(self, idx) -> np.ndarray:
        return self.sum[idx] / self.cnt[idx, None]

    def candidates(self, pts: np.ndarray, radius: np.ndarray) -> list[np.ndarray]:
        """Labels within ``radius[i]`` of each point: KD-tree over the labels at the last rebuild, plus every
        label born since (the running means move little after their first sightings; the χ² test that
        follows uses the current means)."""
        if self.L - self.n_tree >= REBUILD_EVERY or (self.tree is None and self.L):
            self.tree = cKDTree(self.means(np.arange(self.L)))
            self.n_tree = self.L
        recent = np.arange(self.n_tree, self.L)
        if self.tree is None:
            return [recent] * pts.shape[0]
        near = self.tree.query_ball_point(pts, radius)
        return [np.concatenate([np.asarray(n, np.int64), recent]) if recent.size else np.asarray(n, np.int64)
                for n in near]

    def add(self, lab: int, pt: np.ndarray) -> None:
        self.sum[lab] += pt
        self.cnt[lab] += 1.0

    def new(self, pt: np.ndarray, C: np.ndarray) -> int:
        lab = self.L
        self.sum[lab] = pt
        self.cnt[lab] = 1.0
        self.C[lab] = C
        self.L += 1
        return lab


def _associate(index: _LabelIndex, pts, Sz, JPJ, gate: float, birth: float):
    """Labels of one scan's sightings: ``>= 0`` matched, ``-2`` a birth, ``-1`` ambiguous (see module doc).
    Returns ``(match (n,), d2 (n,))``."""
    n = pts.shape[0]
    match = np.full(n, -1, np.int64)
    best_d2 = np.full(n, np.inf)
    if index.L == 0:
        match[:] = -2
        return match, best_d2
    spread = JPJ[:, 0, 0] + JPJ[:, 1, 1] + Sz[:, 0, 0] + Sz[:, 1, 1]
    c_max = float(np.max(index.C[: index.L, 0, 0] + index.C[: index.L, 1, 1]))
    radius = np.minimum(np.sqrt(birth * (spread * 2.0 + c_max)), MAX_SEARCH_M)
    cands = index.candidates(pts, radius)
    ii = np.repeat(np.arange(n), [c.size for c in cands])
    if ii.size == 0:
        match[:] = -2
        return match, best_d2
    jj = np.concatenate(cands)
    nu = pts[ii] - index.means(jj)
    S = JPJ[ii] + Sz[ii] * (1.0 + 1.0 / index.cnt[jj])[:, None, None] + index.C[jj]
    d2 = np.einsum("ki,kij,kj->k", nu, inv2x2(S), nu)
    np.minimum.at(best_d2, ii, d2)
    ok = d2 <= gate
    pairs = sorted(zip(d2[ok].tolist(), ii[ok].tolist(), jj[ok].tolist()))  # every gated pair (d², i, j)
    used: set[int] = set()
    for _d, i, j in pairs:  # one label per sighting and scan, nearest first
        if match[i] == -1 and j not in used:
            match[i] = j
            used.add(j)
    match[(match == -1) & (best_d2 > birth)] = -2
    return match, best_d2


def gated_init(prob: en.Problem, inputs: SlamInputs, *, gate_prob: float, birth_prob: float,
               fixed_labels: np.ndarray | None = None):
    """The gated on-line initialisation (module docstring), run causally over t = 0..T.

    Parameters
    ----------
    prob : energy.Problem        the ICM problem (motion model, sightings in the sensor frame).
    inputs : SlamInputs          for the noise model (``noise.motion_std``, ``range_std``, ``bearing_std``).
    gate_prob, birth_prob : float  χ² probabilities of the association gate and of the birth test
                                 (``gate_prob ≤ birth_prob``).
    fixed_labels : ndarray (N,) | None  known matchings (numbered by first appearance): no gate, the pose
                                 update and the covariance only.

    Returns
    -------
    poses_xyt (T+1, 3), labels (N,) int64 (``-1`` = unlabelled), landmarks_xy (L, 2) running means, the time per
    step, s (T+1,), and the pose covariances ``(T+1, 3, 3)`` of the init.
    """
    T, N, dt = prob.T, prob.n_obs, prob.dt
    gate, birth = chi2_2dof(gate_prob), chi2_2dof(birth_prob)
    nz = inputs.noise
    sr, sb = float(nz.range_std), float(nz.bearing_std)
    if not (sr > 0 and sb > 0):
        raise ValueError(f"init=gated: noise.range_std = {sr} and noise.bearing_std = {sb} must be positive")
    Qb = step_noise_body(inputs, T)
    poses = np.empty((T + 1, 3))
    poses[0] = prob.x0
    covs = np.zeros((T + 1, 3, 3))
    P = np.diag([VAR_FLOOR] * 3)
    labels = np.full(N, -1, np.int64)
    index = _LabelIndex(N)
    U, LAT, off = prob.controls, prob.lat, prob.offsets
    step_s = np.empty(T + 1)
    x = prob.x0.astype(float).copy()
    for t in range(T + 1):
        t0 = time.perf_counter()
        if t > 0:  # prediction: x̂ = g(x, u), P̂ = F P Fᵀ + R(θ) Σ_u,body R(θ)ᵀ
            v, w = U[t - 1]
            lat = LAT[t - 1]
            c, s = math.cos(x[2]), math.sin(x[2])
            F = np.array([[1.0, 0.0, -dt * (v * s + lat * c)], [0.0, 1.0, dt * (v * c - lat * s)], [0, 0, 1.0]])
            Rz = _rot3(x[2])
            x = np.array([x[0] + dt * (v * c - lat * s), x[1] + dt * (v * s + lat * c), wrap_angle(x[2] + dt * w)])
            P = F @ P @ F.T + Rz @ Qb[t - 1] @ Rz.T
        a, b = int(off[t]), int(off[t + 1])
        if b > a:
            x, P = _scan(prob, index, labels, a, b, x, P, sr, sb, gate, birth, fixed_labels)
        poses[t] = x
        covs[t] = P
        step_s[t] = time.perf_counter() - t0
    return poses, labels, index.means(np.arange(index.L)), step_s, covs


def _scan(prob, index: _LabelIndex, labels, a: int, b: int, x, P, sr, sb, gate, birth, fixed):
    """Associate, update the pose and the map points with the sightings ``a:b`` of one step."""
    z, vb = prob.z[a:b], prob.v_body[a:b]
    Sz = sighting_cov(x[2], z, sr, sb)
    J = point_jacobian(x[2], vb)
    JPJ = J @ P @ np.swapaxes(J, 1, 2)
    c, s = math.cos(x[2]), math.sin(x[2])
    pts = x[:2] + vb @ np.array([[c, s], [-s, c]])
    if fixed is not None:
        lab = fixed[a:b]
        match = np.where(lab >= 0, lab, -1)
        known = (match >= 0) & (match < index.L)
        known[known] = index.cnt[match[known]] > 0
        match = np.where(known, match, np.where(lab >= 0, -2, -1))
    else:
        match, _ = _associate(index, pts, Sz, JPJ, gate, birth)
    ok = np.flatnonzero(match >= 0)
    if ok.size:
        js = match[ok]
        m = index.means(js)
        Rj = Sz[ok] * (1.0 + 1.0 / index.cnt[js])[:, None, None] + index.C[js]
        Pi = np.linalg.inv(P)
        xh = x.copy()
        for _ in range(UPDATE_ITERS):  # Gauss-Newton on ‖x − x̂‖²_{P̂⁻¹} + Σ ‖m_j − h⁻¹(x, z)‖²_{R_j⁻¹}
            c, s = math.cos(x[2]), math.sin(x[2])
            p = x[:2] + vb[ok] @ np.array([[c, s], [-s, c]])
            Jk = point_jacobian(x[2], vb[ok])
            Wk = inv2x2(Rj)
            JtW = np.einsum("kai,kab->kib", Jk, Wk)
            H = Pi + np.einsum("kib,kbj->ij", JtW, Jk)
            r0 = x - xh
            r0[2] = wrap_angle(r0[2])
            g = Pi @ r0 - np.einsum("kib,kb->i", JtW, m - p)
            dx = -np.linalg.solve(H, g)
            x = x + dx
            x[2] = wrap_angle(x[2])
        P = np.linalg.inv(H)
        P = _floor_xy(0.5 * (P + P.T), index.C[js[np.argmin(np.trace(index.C[js], axis1=1, axis2=2))]])
    c, s = math.cos(x[2]), math.sin(x[2])
    pts = x[:2] + vb @ np.array([[c, s], [-s, c]])
    J = point_jacobian(x[2], vb)
    for i in range(b - a):
        if match[i] >= 0:
            index.add(int(match[i]), pts[i])
        elif match[i] == -2:
            if fixed is not None:
                lab = int(fixed[a + i])
                index.L = max(index.L, lab + 1)
                index.sum[lab], index.cnt[lab], index.C[lab] = pts[i], 1.0, J[i] @ P @ J[i].T
                match[i] = lab
            else:
                match[i] = index.new(pts[i], J[i] @ P @ J[i].T)
    labels[a:b] = match
    return x, P
