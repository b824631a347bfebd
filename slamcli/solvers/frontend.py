"""Dataset-agnostic data association for batch solvers (graph SLAM, ICM post-processing).

Three sources of correspondences, all returning ``assoc (N,) int64`` (row of the landmark table for every
observation row, ``-1`` = not used) plus initial landmark positions ``landmarks_xy (L, 2)``:

* :func:`associate_reported` — the sensor reports identities (``Observations.reported_id ≥ 0``; MRCLAM
  barcodes, simulator option ``report_ids``). Identities are measurements, not ground truth.
* :func:`associate_nearest_neighbour` — incremental nearest neighbour over time with a χ² gate on the
  Mahalanobis distance between the inverse observation ``m̂ = h⁻¹(x_t, z)`` (landmark space) and the fused
  estimate of each known landmark, on given (dead-reckoned or initial) poses; observations outside every
  gate start a new landmark. Within one time step each landmark takes at most one detection (greedy in
  order of distance), as in maximum-likelihood association (seed 002, §14.7). Landmark covariances are
  inflated by the dead-reckoning drift since their last sighting (loop revisits gate correctly), and a
  laser's several returns from one post can be grouped into one detection (:func:`segment_returns`).
  Duplicates that remain are merged after optimisation by ``graph.merge_candidates``.
* :func:`associations_from_result` — copy the labels of another solver's result (``--init``).

:func:`landmarks_from_observations` averages inverse observations per label (vectorised, ``np.bincount``).
The filters' per-step front end is here too: :func:`group_detections` (a laser's returns of one landmark in one
step merged into one measurement) and :func:`inside_declared_size` (the declared-size test of their
``size_gate``), used by EKF and FastSLAM.
"""

from __future__ import annotations

import math

import numpy as np

from slamcli.errors import SolverError
from slamcli.models import observation
from slamcli.types import Observations, SolverResult


def gate_threshold(gate_prob: float) -> float:
    """χ²₂ quantile: ``d² ≤ −2 ln(1 − p)`` (closed form of the 2-DoF χ² inverse CDF)."""
    if not 0.0 < gate_prob < 1.0:
        raise SolverError(f"gate_prob must be in (0, 1), got {gate_prob}")
    return -2.0 * math.log1p(-gate_prob)


def landmarks_from_observations(
    poses_xyt: np.ndarray, obs: Observations, assoc: np.ndarray, n_landmarks: int
) -> np.ndarray:
    """Mean inverse observation ``m̂ = h⁻¹(x_t, z)`` of every label.

    Parameters
    ----------
    poses_xyt : ndarray (T+1, 3)
    obs : Observations (N rows)
    assoc : ndarray (N,) int64, label per row, -1 ignored
    n_landmarks : int, L

    Returns
    -------
    ndarray (L, 2); NaN for labels without observations.
    """
    assoc = np.asarray(assoc, np.int64)
    ok = assoc >= 0
    m = observation.inverse_range_bearing(np.asarray(poses_xyt)[obs.step[ok]], obs.z[ok])
    cnt = np.bincount(assoc[ok], minlength=n_landmarks).astype(float)
    sx = np.bincount(assoc[ok], weights=m[:, 0], minlength=n_landmarks)
    sy = np.bincount(assoc[ok], weights=m[:, 1], minlength=n_landmarks)
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.stack([sx / cnt, sy / cnt], -1)


def compact_labels(assoc: np.ndarray, min_obs: int = 1) -> tuple[np.ndarray, np.ndarray]:
    """Relabel ``assoc`` to ``0..L'-1`` in order of first appearance of the kept labels.

    Labels with fewer than ``min_obs`` observations are dropped (their rows become -1; the paper's ς filter).

    Returns
    -------
    assoc_new : ndarray (N,) int64
    old_of_new : ndarray (L',) int64   original label of each new label
    """
    assoc = np.asarray(assoc, np.int64)
    out = np.full_like(assoc, -1)
    ok = assoc >= 0
    if not ok.any():
        return out, np.zeros(0, np.int64)
    labels, first, counts = np.unique(assoc[ok], return_index=True, return_counts=True)
    keep = counts >= min_obs
    labels, first = labels[keep], first[keep]
    order = np.argsort(first, kind="stable")
    old_of_new = labels[order]
    new_of_sorted = np.empty(labels.size, np.int64)  # (a search in the sorted labels, never a table indexed
    new_of_sorted[order] = np.arange(labels.size)    # by label value: a label may be 2^62)
    vals = assoc[ok]
    pos = np.minimum(np.searchsorted(labels, vals), max(labels.size - 1, 0))
    found = (labels[pos] == vals) if labels.size else np.zeros(vals.shape, bool)
    out[ok] = np.where(found, new_of_sorted[pos] if labels.size else -1, -1)
    return out, old_of_new


def associate_reported(obs: Observations) -> np.ndarray:
    """Labels from sensor-reported identities (rows with ``reported_id < 0`` get -1), compacted.

    Returns
    -------
    assoc : ndarray (N,) int64, labels ``0..L-1`` in order of first sighting.
    """
    assoc, _ = compact_labels(np.asarray(obs.reported_id, np.int64))
    return assoc


def associate_nearest_neighbour(
    poses_xyt: np.ndarray,
    obs: Observations,
    obs_cov: np.ndarray,
    *,
    gate_prob: float = 0.99,
    extra_std: float = 0.0,
    odometry_std: np.ndarray | None = None,
    segment_dist: float = 0.0,
) -> tuple[np.ndarray, np.ndarray]:
    """Incremental gated nearest-neighbour association on fixed poses.

    Every observation gives ``m̂ = h⁻¹(x_t, z)`` with covariance ``C = M_z Σ_z M_zᵀ + σ_e² I``; landmark ``j`` keeps
    an information-fused estimate ``(μ_j, P_j)``, ``P⁺ = (P⁻¹ + C⁻¹)⁻¹, μ⁺ = P⁺(P⁻¹μ + C⁻¹m̂)``. Observation ``k``
    joins the closest landmark with ``d²_kj = (m̂_k − μ_j)ᵀ (C_k + P_j)⁻¹ (m̂_k − μ_j) ≤ χ²₂(gate_prob)`` (greedy over
    the pairs of one step, each landmark at most once), else creates one. With ``segment_dist > 0`` the unit is a
    detection (:func:`segment_returns`). With ``odometry_std`` the gate of landmark ``j`` (last updated at pose
    ``a``) grows by the dead-reckoning drift to pose ``t``: ``P_j ← P_j + M Σ_rel(a, t) Mᵀ``,
    ``M = [I₂, J(μ_j − p_t)]`` (``J`` the 90° rotation), ``Σ_rel = Σ_{k=a}^{t−1} G_k Q G_kᵀ``,
    ``G_k = [[R(θ_k), J(p_t − p_{k+1})], [0, 1]]``, ``Q = diag(odometry_std²)``, O(1) per pair from prefix sums.

    Parameters
    ----------
    poses_xyt : ndarray (T+1, 3)   poses the observations are projected from.
    obs : Observations (N rows)
    obs_cov : ndarray (2, 2)       covariance of ``[range, bearing]``.
    gate_prob : float              χ² gate probability.
    extra_std : float              σ_e, m (absorbs pose drift).
    odometry_std : ndarray (3,) or None   per-step odometry σ for the drift model (None = no drift).
    segment_dist : float           rows of one pose adjacent in bearing whose inverse observations are closer than
                                   this (m) form one detection; 0 = every row is its own detection.

    Returns
    -------
    assoc : ndarray (N,) int64;  landmarks_xy : ndarray (L, 2) fused estimates.
    """
    thr = gate_threshold(gate_prob)
    poses = np.asarray(poses_xyt, float)
    N = len(obs)
    assoc = np.full(N, -1, np.int64)
    if N == 0:
        return assoc, np.zeros((0, 2))
    m_all, C_all = _inverse_observations(poses, obs, obs_cov, extra_std)
    drift = _DriftModel(poses, odometry_std) if odometry_std is not None else None
    lm = _LandmarkMap()
    offsets = np.asarray(obs.offsets, np.int64)
    bearings = np.asarray(obs.bearing_rad, float)
    for t in range(offsets.size - 1):  # sequential by nature: each step sees the map built so far
        a, b = int(offsets[t]), int(offsets[t + 1])
        if a == b:
            continue
        seg, m, C = _step_detections(m_all[a:b], C_all[a:b], bearings[a:b], segment_dist)
        lab = np.full(m.shape[0], -1, np.int64)
        L = lm.size
        if L and drift is not None:
            lm.P[:L] += drift.landmark_cov(lm.last[:L], t, lm.mu[:L])
            lm.last[:L] = t
        if L:
            lab = _match_and_fuse(m, C, lm, thr)
        new = np.flatnonzero(lab < 0)
        if new.size:
            lab[new] = lm.add(m[new], C[new], t)
        assoc[a:b] = lab[seg]
    return assoc, lm.mu[: lm.size].copy()


def _inverse_observations(
    poses: np.ndarray, obs: Observations, obs_cov: np.ndarray, extra_std: float
) -> tuple[np.ndarray, np.ndarray]:
    """Inverse observations ``m̂ = h⁻¹(x_t, z) (N, 2)`` of all rows and their covariances
    ``C = M_z Σ_z M_zᵀ + σ_e² I (N, 2, 2)`` (see :func:`associate_nearest_neighbour`)."""
    m_all = observation.inverse_range_bearing(poses[obs.step], obs.z)  # (N, 2)
    _, Mz = observation.inverse_range_bearing_jacobians(poses[obs.step], obs.z)
    C_all = Mz @ np.asarray(obs_cov, float) @ np.swapaxes(Mz, 1, 2) + extra_std**2 * np.eye(2)
    return m_all, C_all


def _step_detections(
    m_rows: np.ndarray, C_rows: np.ndarray, bearings: np.ndarray, segment_dist: float
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The detections of one time step's rows (:func:`segment_returns`): ``seg (n,)`` detection of each
    row, the mean inverse observation ``m (ns, 2)`` of each detection and its covariance ``C (ns, 2, 2)``
    (the mean of its rows' covariances: one return's)."""
    seg = segment_returns(m_rows, bearings, segment_dist)  # (n,) detection of each row
    ns = int(seg.max()) + 1
    cnt = np.bincount(seg, minlength=ns).astype(float)
    m = np.stack([np.bincount(seg, m_rows[:, i], ns) for i in range(2)], -1) / cnt[:, None]
    C = (
        np.stack(
            [np.bincount(seg, C_rows[:, i, j], ns) for i in range(2) for j in range(2)], -1
        ).reshape(ns, 2, 2)
        / cnt[:, None, None]
    )  # one return's covariance (spread on a disc is systematic)
    return seg, m, C


def _match_and_fuse(m: np.ndarray, C: np.ndarray, lm: _LandmarkMap, thr: float) -> np.ndarray:
    """Gate the detections ``(m, C)`` of one step against the landmarks of ``lm``, choose greedily in order
    of ``d²`` (each detection and each landmark at most once) and fuse every matched pair into its landmark
    (``P⁺ = (P⁻¹ + C⁻¹)⁻¹, μ⁺ = P⁺(P⁻¹μ + C⁻¹m̂)``, in place). Returns ``lab (ns,)``: landmark of each
    detection, -1 = none admissible."""
    L = lm.size
    mu, P = lm.mu, lm.P
    lab = np.full(m.shape[0], -1, np.int64)
    diff = m[:, None, :] - mu[None, :L, :]  # (ns, L, 2)
    Sinv = _inv2(C[:, None] + P[None, :L])  # (ns, L, 2, 2)
    d2 = np.einsum("nli,nlij,nlj->nl", diff, Sinv, diff)
    cand = np.argwhere(d2 <= thr)
    if cand.size:
        order = np.argsort(d2[cand[:, 0], cand[:, 1]], kind="stable")
        used_lm = set()
        for i, j in cand[order]:  # greedy exclusive choice; candidates ≈ detections of the step
            if lab[i] >= 0 or j in used_lm:
                continue
            used_lm.add(int(j))
            lab[i] = j
        hit = np.flatnonzero(lab >= 0)
        if hit.size:  # information fusion of all matched pairs at once
            js = lab[hit]
            Pi, Ci = _inv2(P[js]), _inv2(C[hit])
            Pn = _inv2(Pi + Ci)
            mu[js] = np.einsum(
                "kij,kj->ki",
                Pn,
                np.einsum("kij,kj->ki", Pi, mu[js]) + np.einsum("kij,kj->ki", Ci, m[hit]),
            )
            P[js] = Pn
    return lab


class _LandmarkMap:
    """The front end's growing landmark table: fused estimates ``mu (L, 2)``, covariances ``P (L, 2, 2)``
    and the pose ``last (L,)`` each was last updated at (arrays of capacity ``cap ≥ L``, doubled as needed)."""

    def __init__(self, cap: int = 64) -> None:
        self.cap = cap
        self.mu = np.empty((cap, 2))
        self.P = np.empty((cap, 2, 2))
        self.last = np.zeros(cap, np.int64)
        self.size = 0

    def add(self, m: np.ndarray, C: np.ndarray, t: int) -> np.ndarray:
        """Append new landmarks at ``m (k, 2)`` with covariances ``C (k, 2, 2)``, seen at pose ``t``;
        returns their labels ``(k,)``."""
        L, k = self.size, m.shape[0]
        while L + k > self.cap:
            self.cap *= 2
            self.mu = np.resize(self.mu, (self.cap, 2))
            self.P = np.resize(self.P, (self.cap, 2, 2))
            self.last = np.resize(self.last, self.cap)
        self.mu[L : L + k] = m
        self.P[L : L + k] = C
        self.last[L : L + k] = t
        self.size = L + k
        return np.arange(L, L + k)


class _DriftModel:
    """Prefix sums for the dead-reckoning drift covariance ``Σ_rel(a, t)`` (see
    :func:`associate_nearest_neighbour`)."""

    _J = np.array([[0.0, -1.0], [1.0, 0.0]])

    def __init__(self, poses_xyt: np.ndarray, odometry_std: np.ndarray) -> None:
        q = np.square(np.asarray(odometry_std, float))
        p = np.asarray(poses_xyt, float)
        T = p.shape[0] - 1
        c, s = np.cos(p[:-1, 2]), np.sin(p[:-1, 2])
        A = np.empty((T, 2, 2))  # R(θ_k) diag(q_x, q_y) R(θ_k)ᵀ
        A[:, 0, 0] = q[0] * c * c + q[1] * s * s
        A[:, 1, 1] = q[0] * s * s + q[1] * c * c
        A[:, 0, 1] = A[:, 1, 0] = (q[0] - q[1]) * c * s
        nxt = p[1:, :2]
        z2 = np.zeros((1, 2))
        self.cA = np.concatenate([np.zeros((1, 2, 2)), np.cumsum(A, 0)])
        self.c0 = q[2] * np.arange(T + 1, dtype=float)
        self.c1 = np.concatenate([z2, np.cumsum(q[2] * nxt, 0)])
        self.c2 = np.concatenate(
            [np.zeros((1, 2, 2)), np.cumsum(q[2] * nxt[:, :, None] * nxt[:, None, :], 0)]
        )
        self.p = p

    def landmark_cov(self, a: np.ndarray, t: int, mu: np.ndarray) -> np.ndarray:
        """``M Σ_rel(a_j, t) Mᵀ (L, 2, 2)`` for landmarks ``mu (L, 2)`` last updated at poses ``a (L,)``."""
        J = self._J
        pt = self.p[t, :2]
        SA = self.cA[t] - self.cA[a]
        n0 = self.c0[t] - self.c0[a]
        s1 = self.c1[t] - self.c1[a]
        s2 = self.c2[t] - self.c2[a]
        W = n0[:, None, None] * np.outer(pt, pt) - pt[None, :, None] * s1[:, None, :]
        W = W - s1[:, :, None] * pt[None, None, :] + s2
        Spp = SA + J @ W @ J.T
        Spt = (n0[:, None] * pt - s1) @ J.T  # (L, 2) = J (n0 p_t − s1)
        v = (mu - pt) @ J.T  # J (μ − p_t)
        return (
            Spp
            + Spt[:, :, None] * v[:, None, :]
            + v[:, :, None] * Spt[:, None, :]
            + n0[:, None, None] * v[:, :, None] * v[:, None, :]
        )


def _inv2(A: np.ndarray) -> np.ndarray:
    """Closed-form inverse of 2×2 matrices ``(..., 2, 2)``."""
    det = A[..., 0, 0] * A[..., 1, 1] - A[..., 0, 1] * A[..., 1, 0]
    out = np.empty_like(A)
    out[..., 0, 0] = A[..., 1, 1] / det
    out[..., 1, 1] = A[..., 0, 0] / det
    out[..., 0, 1] = -A[..., 0, 1] / det
    out[..., 1, 0] = -A[..., 1, 0] / det
    return out


def segment_returns(
    points_xy: np.ndarray, bearing: np.ndarray, dist: float, max_dbearing: float = 0.1
) -> np.ndarray:
    """Split the returns of one pose into detections.

    Returns are ordered by bearing; neighbours at most ``max_dbearing`` rad apart in bearing (adjacent
    beams) whose points ``(n, 2)`` are closer than ``dist`` m share a detection (a scan segment). Returns
    ``seg (n,) int64`` with detections numbered ``0..K-1``.
    """
    n = points_xy.shape[0]
    if dist <= 0 or n < 2:
        return np.arange(n, dtype=np.int64)
    order = np.argsort(bearing, kind="stable")
    gaps = (np.linalg.norm(np.diff(points_xy[order], axis=0), axis=1) > dist) | (
        np.diff(bearing[order]) > max_dbearing
    )
    seg_sorted = np.concatenate([[0], np.cumsum(gaps)])
    seg = np.empty(n, np.int64)
    seg[order] = seg_sorted
    return seg


def associations_from_result(init: SolverResult, n_obs: int) -> tuple[np.ndarray, np.ndarray]:
    """Labels and landmarks of another result, checked against the number of observation rows."""
    assoc = np.asarray(init.assoc, np.int64)
    if assoc.shape != (n_obs,):
        raise SolverError(
            f"init result ({init.solver}) has {assoc.shape[0]} association labels, dataset has {n_obs} "
            "observations"
        )
    lm = np.asarray(init.landmarks_xy, float).reshape(-1, 2)
    if assoc.size and assoc.max() >= lm.shape[0]:
        raise SolverError(
            f"init result ({init.solver}) labels up to {int(assoc.max())} but has {lm.shape[0]} landmarks"
        )
    return assoc, lm


def resolve_association(mode: str, reported_id: np.ndarray, *, force_ml: bool = False) -> str:
    """The association a filter actually runs: ``"auto"`` → ``"known"`` when any observation row carries a
    sensor-reported id (``reported_id ≥ 0``), else ``"ml"`` (maximum likelihood); ``force_ml`` (e.g. an EKF
    provisional list, which only ML association uses) picks ``"ml"``. Explicit ``"known"``/``"ml"`` pass
    through unchanged."""
    if mode != "auto":
        return mode
    if force_ml:
        return "ml"
    return "known" if bool(np.any(np.asarray(reported_id) >= 0)) else "ml"


def resolve_motion_input(mode: str, inputs) -> str:
    """The motion input a filter or ICM actually uses: ``"auto"`` → the dataset's ``motion_source``
    (``"odometry"`` when its motion data are measured SE(2) increments, else ``"controls"``); an ackermann
    dataset's controls are its data, so ``auto`` keeps them there. Explicit ``"controls"``/``"odometry"`` pass
    through unchanged."""
    if mode != "auto":
        return mode
    if getattr(inputs, "motion_model", "ddmr") != "ddmr":
        return "controls"
    return "odometry" if getattr(inputs, "motion_source", "controls") == "odometry" else "controls"


def group_detections(z_all, sensor, rid, lo: int, hi: int, x_r, *, group: bool, association: str,
                     group_dist: float, range_offset: float = 0.0):
    """The detections of one step: ``[(z (2,), rows (k,) int64), ...]`` in row order (EKF's and FastSLAM's).

    Rows ``lo:hi`` of ``z_all (N, 2)``, ``sensor (N,)``, ``rid (N,)``; ``x_r (3,)`` an estimate of the pose.
    Without ``group`` (``group_returns``) every row is its own detection. With it, the rows of one landmark are merged
    into one measurement at their mean range and circular-mean bearing (a laser hits one post on several
    adjacent beams; fusing each hit as an independent measurement of the centre overweights that pose-landmark
    pair): ``known`` groups by (sensor, reported id); ``ml`` by single-linkage clusters of the inverse
    observations ``h⁻¹(x_r, z)`` closer than ``group_dist`` (same sensor).
    ``range_offset`` is added to every range first.
    """
    z = z_all[lo:hi]
    if range_offset:
        z = z + np.array([range_offset, 0.0])
    rows = np.arange(lo, hi, dtype=np.int64)
    if not group or hi - lo < 2:
        return [(z[k], rows[k : k + 1]) for k in range(hi - lo)]
    s = np.asarray(sensor[lo:hi], np.int64)
    if association == "known":
        r = np.asarray(rid[lo:hi], np.int64)
        # rows without an id stay single (they are discarded anyway)
        key = np.where(r >= 0, s * (int(r.max()) + 2) + r, -1 - np.arange(hi - lo))
        sorted_key = np.sort(key)
        if (sorted_key[1:] != sorted_key[:-1]).all():  # one row per landmark (a point sensor): nothing to merge
            return [(z[k], rows[k : k + 1]) for k in range(hi - lo)]
    else:
        from scipy.sparse import csr_matrix
        from scipy.sparse.csgraph import connected_components

        # single-linkage clusters of the landmark-space points m̂ = h⁻¹(x_r, z) of one sensor: O(k²), k ≲ 10²
        pts = observation.inverse_range_bearing(np.asarray(x_r, float)[None, :], z)
        near = np.linalg.norm(pts[:, None, :] - pts[None, :, :], axis=-1) < group_dist
        near &= s[:, None] == s[None, :]
        _, key = connected_components(csr_matrix(near), directed=False)
    out = []
    _, first, inv = np.unique(key, return_index=True, return_inverse=True)
    for k in np.argsort(first, kind="stable"):
        g = np.flatnonzero(inv == k)
        if g.size == 1:
            out.append((z[g[0]], rows[g]))
        else:
            b = math.atan2(float(np.sin(z[g, 1]).sum()), float(np.cos(z[g, 1]).sum()))
            out.append((np.array([float(z[g, 0].mean()), b]), rows[g]))
    return out


def inside_declared_size(landmarks_xy: np.ndarray, points_xy: np.ndarray, min_sep: float,
                         live: np.ndarray | None = None) -> np.ndarray:
    """Whether each point lies closer than ``min_sep`` (m) to one of its landmarks — the declared-size test
    (EKF's and FastSLAM's ``size_gate``): two posts of radius ρ cannot be closer than 2ρ, so a detection that
    matches no landmark but whose point is within 2ρ of one is a cut view of that post, not a new one.

    Parameters
    ----------
    landmarks_xy : ndarray (..., L, 2)   landmark means (one map, or one per particle).
    points_xy : ndarray (..., 2)         inverse observations ``h⁻¹(x, z)`` (one per map).
    min_sep : float                      m; ``≤ 0`` = no test (all False).
    live : ndarray (..., L) bool or None  landmarks that count (None = all).

    Returns
    -------
    ndarray (...) bool
    """
    lead = np.broadcast_shapes(np.shape(landmarks_xy)[:-2], np.shape(points_xy)[:-1])
    if not min_sep > 0 or np.shape(landmarks_xy)[-2] == 0:
        return np.zeros(lead, bool)
    d = np.asarray(landmarks_xy, float) - np.asarray(points_xy, float)[..., None, :]
    close = np.einsum("...i,...i->...", d, d) < min_sep * min_sep
    if live is not None:
        close &= live
    return close.any(-1)
