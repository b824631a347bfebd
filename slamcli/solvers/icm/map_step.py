"""Map node of ICM-SLAM: correspondences (eqs. 9, 10, 12, 13), the closed-form map (eq. 17), label fusion
within ϑ and the observation-count filter ς (paper 000, §4).

The map potential Φ_m of §4 makes every map with two points closer than ϑ infeasible; the paper's three-step
procedure (means → partition of the labels by ϑ → regroup and recompute the means) maps the unconstrained
means onto a feasible map. Labels are numbered by order of appearance (paper §3.2).
"""

from __future__ import annotations

import numpy as np
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components
from scipy.spatial import cKDTree


def nearest_labels(points_xy, landmarks_xy, Q, prev_labels=None) -> np.ndarray:
    """``argmin_l ‖p_i − m_l‖²_Q`` for every point (eqs. 12-13), via a KD-tree in Q-scaled coordinates.

    With ``prev_labels`` (the matchings of the previous sweep, indexing the same map) the exact triangle-
    inequality bound of Elkan's k-means is used first: if ``‖p − m_c‖ ≤ ½ min_{l≠c} ‖m_c − m_l‖`` then ``c`` is
    the nearest label, so only the remaining points go to the KD-tree. The result is identical.

    Parameters
    ----------
    points_xy : ndarray (N, 2)      h⁻¹(x_t, z_{t,i}).
    landmarks_xy : ndarray (L, 2)
    Q : (q0, q1)                    diagonal weights (Q = 0 is treated as identity for the matching).
    prev_labels : ndarray (N,) int64 or None

    Returns
    -------
    ndarray (N,) int64, ``-1`` when the map is empty.
    """
    points_xy = np.asarray(points_xy, float).reshape(-1, 2)
    landmarks_xy = np.asarray(landmarks_xy, float).reshape(-1, 2)
    N, L = points_xy.shape[0], landmarks_xy.shape[0]
    if L == 0 or N == 0:
        return np.full(N, -1, np.int64)
    iso = not any(Q) or Q[0] == Q[1]
    scale = np.ones(2) if iso else np.sqrt(np.asarray(Q, float))
    lm = landmarks_xy if iso else landmarks_xy * scale
    pts = points_xy if iso else points_xy * scale
    tree = cKDTree(lm)
    out = np.empty(N, np.int64)
    todo = np.ones(N, bool)
    if prev_labels is not None and L > 1:
        prev = np.asarray(prev_labels, np.int64)
        ok = (prev >= 0) & (prev < L)
        half = 0.5 * tree.query(lm, k=2)[0][:, 1]  # ½ distance to the nearest other map point
        c = np.where(ok, prev, 0)
        d = np.hypot(pts[:, 0] - lm[c, 0], pts[:, 1] - lm[c, 1])
        sure = ok & (d <= half[c])
        out[sure] = prev[sure]
        todo = ~sure
    if todo.any():
        _, idx = tree.query(pts[todo])
        out[todo] = idx
    return out


def label_means(points_xy, labels, n_labels: int, weights=None):
    """Closed-form map, eq. (17): each label's point is the mean of its observations' h⁻¹(x_t, z_{t,i}) (the
    ``weights``-weighted mean when given: the conditional mode under per-observation weights).

    Returns ``(means (n_labels, 2), counts (n_labels,))`` (counts = summed weights); labels without
    observations get NaN.
    """
    ok = labels >= 0
    lab = labels[ok]
    w = None if weights is None else np.asarray(weights, float)[ok]
    cnt = np.bincount(lab, weights=w, minlength=n_labels)[:n_labels].astype(float)
    wx = points_xy[ok, 0] if w is None else w * points_xy[ok, 0]
    wy = points_xy[ok, 1] if w is None else w * points_xy[ok, 1]
    sx = np.bincount(lab, weights=wx, minlength=n_labels)[:n_labels]
    sy = np.bincount(lab, weights=wy, minlength=n_labels)[:n_labels]
    with np.errstate(invalid="ignore", divide="ignore"):
        means = np.stack([sx / cnt, sy / cnt], -1)
    return means, cnt


def eq17(points_xy, labels):
    """Eq. (17) alone — the exact conditional mode of m given the matchings and poses: every label's point is
    the mean of its observations; labels left without observations (their observations were matched
    elsewhere) are dropped and the rest renumbered in order. Returns ``(labels (N,), landmarks_xy (L', 2))``."""
    labels = np.asarray(labels, np.int64)
    n_lab = int(labels.max()) + 1 if labels.size and labels.max() >= 0 else 0
    means, cnt = label_means(points_xy, labels, n_lab)
    keep = cnt > 0
    labels, _ = relabel_compact(labels, keep)
    return labels, means[keep].reshape(-1, 2)


def relabel_compact(labels, keep_mask):
    """Drop labels not in ``keep_mask``, renumber the rest 0.. in their old order. Returns ``(labels, old_of_new)``."""
    old_of_new = np.flatnonzero(keep_mask)
    new_of_old = np.full(keep_mask.shape[0] + 1, -1, np.int64)  # last entry: the -1 labels (also when L = 0)
    new_of_old[old_of_new] = np.arange(old_of_new.size)
    out = new_of_old[np.where(labels >= 0, labels, keep_mask.shape[0])]
    return out.astype(np.int64), old_of_new


def fusion_components(means_xy, radius: float) -> np.ndarray:
    """Partition of the labels by ϑ (§4, rules 1-2): connected components of the graph with an edge between
    labels closer than ϑ — single linkage cut at ϑ. Components are numbered by their smallest label.

    Returns ``comp (L,) int64``.
    """
    L = means_xy.shape[0]
    if L == 0:
        return np.zeros(0, np.int64)
    pairs = (
        cKDTree(means_xy).query_pairs(r=radius, output_type="ndarray")
        if radius > 0
        else np.zeros((0, 2), int)
    )
    if pairs.shape[0] == 0:
        return np.arange(L, dtype=np.int64)
    A = coo_matrix((np.ones(pairs.shape[0]), (pairs[:, 0], pairs[:, 1])), shape=(L, L))
    _, comp = connected_components(A, directed=False)
    # renumber components in order of their first (smallest) label: keeps numbering by appearance
    first = np.full(comp.max() + 1, L, np.int64)
    np.minimum.at(first, comp, np.arange(L))
    order = np.argsort(first, kind="stable")
    rank = np.empty_like(order)
    rank[order] = np.arange(order.size)
    return rank[comp].astype(np.int64)


def map_update(points_xy, labels, fusion_radius: float, min_count: int, *, max_passes: int = 10):
    """The three-step map update of §4 plus the ς filter.

    1. means by eq. (17);
    2. partition of the labels by ϑ (:func:`fusion_components`);
    3. regroup the observations by component and recompute the means (17) — repeated while regrouping leaves
       two points closer than ϑ (the paper makes one pass; one pass almost always suffices);
    4. remove map points seen fewer than ς times (their observations get label ``-1``).

    Parameters
    ----------
    points_xy : ndarray (N, 2)   h⁻¹(x_t, z_{t,i}) at the current poses.
    labels : ndarray (N,) int64  current matchings (``-1`` = out of the model).

    Returns
    -------
    labels : ndarray (N,) int64, landmarks_xy : ndarray (L', 2), info : dict (fused, removed counts)
    """
    labels = np.asarray(labels, np.int64).copy()
    n_lab = int(labels.max()) + 1 if labels.size and labels.max() >= 0 else 0
    means, cnt = label_means(points_xy, labels, n_lab)
    labels, _ = relabel_compact(labels, cnt > 0)
    means = means[cnt > 0]
    fused = 0
    for _ in range(max_passes):
        comp = fusion_components(means, fusion_radius)
        n_comp = int(comp.max()) + 1 if comp.size else 0
        if n_comp == means.shape[0]:
            break
        fused += means.shape[0] - n_comp
        labels = np.where(labels >= 0, comp[np.maximum(labels, 0)], -1)
        means, cnt = label_means(points_xy, labels, n_comp)
    n_lab = means.shape[0]
    cnt = np.bincount(labels[labels >= 0], minlength=n_lab)[:n_lab]
    keep = cnt >= max(int(min_count), 1)
    removed = int((~keep).sum())
    labels, old = relabel_compact(labels, keep)
    return labels, means[old], {"fused": fused, "removed": removed}


def map_change(prev_xy, new_xy) -> float:
    """Mean distance from each new map point to the nearest point of the previous map, m (paper Fig. 9d:
    the average norm of the map changes; nearest matching because fusion renumbers labels)."""
    if len(new_xy) == 0 or len(prev_xy) == 0:
        return 0.0 if len(new_xy) == len(prev_xy) else float("inf")
    d, _ = cKDTree(prev_xy).query(new_xy)
    return float(np.mean(d))


def feasible(landmarks_xy, radius: float) -> bool:
    """Φ_m feasibility: no two map points closer than ϑ."""
    if len(landmarks_xy) < 2 or radius <= 0:
        return True
    return cKDTree(landmarks_xy).query_pairs(r=radius, output_type="ndarray").shape[0] == 0
