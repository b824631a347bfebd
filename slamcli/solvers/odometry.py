"""``odometry``: the dead-reckoning baseline (no correction, no covariances).

Poses are the encoder odometry re-anchored at the known start pose ``x0`` (paper 000 §3 assumes it known)::

    x̂_t = x0 ⊕ (x̃_0⁻¹ ⊕ x̃_t)            (= x0 chained with every increment d_k of eq. 16, k ≤ t)

which equals ``odometry_xyt`` itself when the encoder frame starts at ``x0``.

Landmarks come from inverse observations on those poses, ``m̂_i = h⁻¹(x̂_{t_i}, z_i)``, averaged per label::

    m̂_j = (1/|A_j|) Σ_{i ∈ A_j} h⁻¹(x̂_{t_i}, z_i)

Labels (association) are, in order of preference:

1. the sensor-reported identity (``observations.reported_id ≥ 0``, a measurement, not ground truth), when
   ``use_reported_ids`` is set and the row has one;
2. otherwise greedy nearest neighbour in landmark space, in time order: a row joins the closest landmark
   (running mean of its inverse observations up to the previous step) when the Euclidean distance is
   ≤ ``nn_threshold`` metres, else it starts a new landmark (which later rows of the same step may join; see
   :func:`greedy_nearest_neighbour`). Rows that carry a reported id seed the landmark set first.

Labels seen by fewer than ``min_support`` rows are dropped (their rows get −1), then labels are renumbered
0..L'−1 in order of first sighting. This solver uses no randomness and ignores ``init``.
"""

from __future__ import annotations

import time

import numpy as np

from slamcli.models import se2
from slamcli.models.observation import inverse_range_bearing
from slamcli.solvers.base import BaseSolver, ProgressFn
from slamcli.solvers.frontend import compact_labels
from slamcli.solvers.odometry_params import OdometryParams
from slamcli.types import SlamInputs, SolverResult, Status


def dead_reckoning(x0: np.ndarray, odometry_xyt: np.ndarray) -> np.ndarray:
    """Odometry poses re-anchored at ``x0``: ``x̂_t = x0 ⊕ (x̃_0⁻¹ ⊕ x̃_t)``, ``(T+1, 3)``."""
    odo = np.asarray(odometry_xyt, float)
    return se2.compose(np.asarray(x0, float), se2.between(odo[0], odo))


#: rows of a step's new landmarks clustered one by one below this count (the exact sequential definition)
_SEQUENTIAL_BELOW = 8
#: entries of one (rows, landmarks) distance block in the gate against the previous step's landmarks
_BLOCK_ENTRIES = 1 << 22
#: rows of one step from which equal rows are gated once
_DEDUPLICATE_FROM = 64
_EPS = float(np.finfo(float).eps)


def greedy_nearest_neighbour(
    points_xy: np.ndarray,
    threshold: float,
    labels: np.ndarray | None = None,
    steps: np.ndarray | None = None,
    progress: ProgressFn | None = None,
) -> np.ndarray:
    """Greedy NN labelling of landmark-space points, in time order.

    Rows are processed one time step at a time. Each row of a step joins the nearest landmark as it stood at the
    end of the previous step (running mean of its points) if that is within ``threshold``. The remaining rows of
    the step are clustered greedily in row order (:func:`leader_clusters`): each joins the nearest landmark
    created earlier in the same step within ``threshold``, or creates a new one. Without ``steps`` every row is
    its own step (purely sequential greedy NN).

    Parameters
    ----------
    points_xy : ndarray (N, 2)    inverse observations.
    threshold : float             gate in metres.
    labels : ndarray (N,) int64   optional pre-set labels (≥ 0 kept, −1 to be decided). Pre-labelled rows
                                  seed the landmark means before the greedy pass.
    steps : ndarray (N,) int64    optional, sorted time step of each row.

    Returns
    -------
    ndarray (N,) int64, every row labelled.
    """
    pts = np.asarray(points_xy, float).reshape(-1, 2)
    N = pts.shape[0]
    out = np.full(N, -1, np.int64) if labels is None else np.asarray(labels, np.int64).copy()
    seeded = out >= 0
    K = int(out[seeded].max()) + 1 if seeded.any() else 0
    sums = np.zeros((max(16, 2 * K), 2))
    counts = np.zeros(sums.shape[0])
    if K:
        np.add.at(sums, out[seeded], pts[seeded])
        counts[:K] = np.bincount(out[seeded], minlength=K)
    thr2 = threshold * threshold
    todo = np.flatnonzero(~seeded)
    if steps is None:
        bounds = np.arange(todo.size + 1)
    else:
        st = np.asarray(steps)[todo]
        bounds = np.concatenate([[0], np.flatnonzero(np.diff(st)) + 1, [todo.size]])
    for g in range(bounds.size - 1):
        rows = todo[bounds[g] : bounds[g + 1]]
        matched = _gate_previous(pts[rows], sums[:K], counts[:K], thr2) if K else np.full(rows.size, -1)
        new = rows[matched < 0]
        if new.size:
            local = leader_clusters(pts[new], threshold)
            n_new = int(local.max()) + 1
            if K + n_new > sums.shape[0]:  # grow the buffers geometrically
                cap = max(2 * sums.shape[0], K + n_new)
                sums = np.concatenate([sums, np.zeros((cap - sums.shape[0], 2))])
                counts = np.concatenate([counts, np.zeros(cap - counts.shape[0])])
            out[new] = K + local
            np.add.at(sums, out[new], pts[new])  # in row order, as a row-by-row running sum adds them
            np.add.at(counts, out[new], 1.0)
            K += n_new
        hit = matched >= 0
        if hit.any():
            out[rows[hit]] = matched[hit]
            np.add.at(sums, matched[hit], pts[rows[hit]])
            np.add.at(counts, matched[hit], 1.0)
        if progress is not None and g % 256 == 0:
            progress(int(bounds[g]), int(todo.size))
    return out


def _gate_previous(P: np.ndarray, sums: np.ndarray, counts: np.ndarray, thr2: float) -> np.ndarray:
    """``(g,)`` index of the nearest live landmark (mean ``sums / counts``) within ``√thr2`` of each row of
    ``P (g, 2)``, −1 where none is; ties go to the lowest index. Equal rows are gated once; blocks of rows
    bound the distance matrix."""
    if P.shape[0] >= _DEDUPLICATE_FROM:
        order = np.lexsort((P[:, 1], P[:, 0]))
        Ps = P[order]
        first = np.r_[True, (Ps[1:] != Ps[:-1]).any(axis=1)]  # NaN rows stay apart; ±0 gate alike
        if not first.all():
            inverse = np.empty(P.shape[0], np.int64)
            inverse[order] = np.cumsum(first) - 1
            return _gate_previous(Ps[first], sums, counts, thr2)[inverse]
    live = counts > 0
    means = sums / np.where(live, counts, 1.0)[:, None]
    out = np.full(P.shape[0], -1, np.int64)
    block = max(1, _BLOCK_ENTRIES // max(1, means.shape[0]))
    for a in range(0, P.shape[0], block):
        d2 = ((P[a : a + block, None, :] - means[None, :, :]) ** 2).sum(-1)  # (b, K)
        d2[:, ~live] = np.inf
        j = np.argmin(d2, axis=1)
        ok = d2[np.arange(j.size), j] <= thr2
        out[a : a + block][ok] = j[ok]
    return out


def leader_clusters(P: np.ndarray, threshold: float) -> np.ndarray:
    """Sequential leader clustering of ``P (n, 2)``: in row order, each row joins the cluster whose running mean
    is nearest within ``threshold`` (lowest index on ties) or starts a new one. ``(n,)`` labels, numbered by
    first row.

    Computed part by part: a cluster's mean stays within ``threshold`` of its latest member, so a row can only
    join a cluster with a member within ``2·threshold``; gaps wider than that along x or y (plus a rounding
    margin) split the rows into independent parts. A part whose bounding box fits inside ``threshold`` is one
    cluster; any other part runs the sequential definition (:func:`_leader_sequential`).
    """
    n = P.shape[0]
    if n < _SEQUENTIAL_BELOW or not np.isfinite(P).all():
        return _leader_sequential(P, threshold * threshold)
    slack = 8.0 * n * _EPS * (float(np.abs(P).max()) + threshold)  # bound on the rounding of running means
    gap = 2.0 * threshold * (1 + 1e-9) + slack
    part = np.zeros(n, np.int64)
    for _ in range(2):  # x, y, x, y: later rounds split what the first ones joined
        part = _split_by_gaps(P[:, 1], _split_by_gaps(P[:, 0], part, gap), gap)
    n_parts = int(part.max()) + 1
    order = np.argsort(part, kind="stable")
    starts = np.flatnonzero(np.r_[True, part[order][1:] != part[order][:-1]])
    lo, hi = np.minimum.reduceat(P[order], starts), np.maximum.reduceat(P[order], starts)
    diag = np.hypot(*(hi - lo).T) * (1 + 1e-12)
    tight = diag + slack < threshold * (1 - 1e-9)
    lab = np.zeros(n, np.int64)  # label inside the part
    for p in np.flatnonzero(~tight):
        rows = order[starts[p] : (starts[p + 1] if p + 1 < starts.size else n)]
        lab[rows] = _leader_sequential(P[rows], threshold * threshold)
    n_lab = np.bincount(part, minlength=n_parts)  # upper bound on clusters per part
    code = np.concatenate([[0], np.cumsum(n_lab)[:-1]])[part] + lab
    first = np.full(int(n_lab.sum()), n, np.int64)
    np.minimum.at(first, code, np.arange(n))
    used = np.flatnonzero(first < n)
    rank = np.empty(first.size, np.int64)
    rank[used[np.argsort(first[used])]] = np.arange(used.size)
    return rank[code]


def _split_by_gaps(v: np.ndarray, part: np.ndarray, gap: float) -> np.ndarray:
    """Refine the partition ``part (n,)``: inside each part, sorted values ``v`` further apart than ``gap``
    start a new part. Parts are renumbered ``0..``."""
    order = np.lexsort((v, part))
    vs, ps = v[order], part[order]
    start = np.r_[True, (ps[1:] != ps[:-1]) | (np.diff(vs) > gap)]
    out = np.empty_like(part)
    out[order] = np.cumsum(start) - 1
    return out


def _leader_sequential(P: np.ndarray, thr2: float) -> np.ndarray:
    """The row-by-row definition behind :func:`leader_clusters` (``thr2``: the squared gate)."""
    lab = np.empty(P.shape[0], np.int64)
    sums = np.zeros((P.shape[0], 2))
    counts = np.zeros(P.shape[0])
    k = 0
    for i in range(P.shape[0]):
        best = -1
        if k:
            d2 = ((sums[:k] / counts[:k, None] - P[i]) ** 2).sum(axis=1)
            j = int(np.argmin(d2))
            if d2[j] <= thr2:
                best = j
        if best < 0:
            best, k = k, k + 1
        lab[i] = best
        sums[best] += P[i]
        counts[best] += 1.0
    return lab


def compact(assoc: np.ndarray, min_support: int) -> np.ndarray:
    """Drop labels with fewer than ``min_support`` rows and renumber 0..L'−1 by first sighting."""
    return compact_labels(assoc, min_support)[0]


class OdometrySolver(BaseSolver):
    """Dead reckoning + averaged inverse observations (the no-SLAM baseline)."""

    name = "odometry"
    Params = OdometryParams
    #: reads only the odometry poses (for a car: the importer's integration of the Ackermann model)
    motion_models = ("ddmr", "ackermann")

    def solve(
        self,
        inputs: SlamInputs,
        *,
        init: SolverResult | None = None,
        rng: np.random.Generator,
        progress: ProgressFn | None = None,
    ) -> SolverResult:
        t0 = time.perf_counter()
        p: OdometryParams = self.params
        obs = inputs.observations
        poses = dead_reckoning(inputs.x0, inputs.odometry_xyt)
        m_hat = inverse_range_bearing(poses[obs.step], obs.z).reshape(-1, 2)  # (N, 2)

        seed = np.full(len(obs), -1, np.int64)
        n_reported = 0
        if p.use_reported_ids and len(obs):
            rid = np.asarray(obs.reported_id, np.int64)
            has = rid >= 0
            n_reported = int(has.sum())
            if n_reported:
                _, dense = np.unique(rid[has], return_inverse=True)
                seed[has] = dense
        raw = greedy_nearest_neighbour(m_hat, p.nn_threshold, seed, obs.step, progress) if len(obs) else seed
        assoc = compact(raw, p.min_support)
        L = int(assoc.max()) + 1 if assoc.size and assoc.max() >= 0 else 0
        ok = assoc >= 0
        cnt = np.bincount(assoc[ok], minlength=L).astype(float)
        landmarks = np.stack(
            [np.bincount(assoc[ok], weights=m_hat[ok, 0], minlength=L) / np.maximum(cnt, 1.0),
             np.bincount(assoc[ok], weights=m_hat[ok, 1], minlength=L) / np.maximum(cnt, 1.0)], -1
        ).reshape(-1, 2)
        if progress is not None:
            progress(len(obs), len(obs))
        source = "reported ids" if n_reported == len(obs) and len(obs) else (
            f"greedy NN ≤ {p.nn_threshold:g} m" + (f" + {n_reported} reported ids" if n_reported else ""))
        return self.make_result(
            status=Status.COMPLETED,
            poses_xyt=poses,
            landmarks_xy=landmarks,
            assoc=assoc,
            t_start=t0,
            message=f"dead reckoning; {L} landmarks from {int(ok.sum())}/{len(obs)} observations ({source})",
            extra={"n_reported_rows": n_reported},
        )
