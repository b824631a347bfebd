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
    the step are clustered greedily in row order: each joins the nearest landmark created earlier in the same
    step within ``threshold``, or creates a new one. Without ``steps`` every row is its own step (purely
    sequential greedy NN).

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
    cap = max(16, 2 * K)
    sums = np.zeros((cap, 2))
    counts = np.zeros(cap)
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
        P = pts[rows]
        matched = np.zeros(rows.size, bool)
        if K:
            live = counts[:K] > 0
            means = sums[:K] / np.where(live, counts[:K], 1.0)[:, None]
            d2 = ((P[:, None, :] - means[None, :, :]) ** 2).sum(-1)  # (g, K)
            d2[:, ~live] = np.inf
            j = np.argmin(d2, axis=1)
            matched = d2[np.arange(rows.size), j] <= thr2
            out[rows[matched]] = j[matched]
        first_new = K
        for i in rows[~matched]:  # rows outside every gate: greedy among this step's new landmarks
            best = -1
            if K > first_new:
                nm = sums[first_new:K] / counts[first_new:K, None]
                d2n = ((nm - pts[i]) ** 2).sum(axis=1)
                k = int(np.argmin(d2n))
                if d2n[k] <= thr2:
                    best = first_new + k
            if best < 0:
                if K == cap:  # grow the buffers geometrically
                    cap *= 2
                    sums = np.concatenate([sums, np.zeros_like(sums)])
                    counts = np.concatenate([counts, np.zeros_like(counts)])
                best = K
                K += 1
            out[i] = best
            sums[best] += pts[i]
            counts[best] += 1.0
        if matched.any():
            np.add.at(sums, out[rows[matched]], P[matched])
            np.add.at(counts, out[rows[matched]], 1.0)
        if progress is not None and g % 256 == 0:
            progress(int(bounds[g]), int(todo.size))
    return out


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
