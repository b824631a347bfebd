"""Label merge of ICM-SLAM (``merge=true``, beyond the paper).

The paper's Φ_m fuses labels whose map points lie within a fixed radius ϑ and has no cost per landmark, so a
map split into duplicates has a lower energy than the true one (each duplicate fits its own sightings). Two
remedies, both here:

* **χ² test between labels** — labels ``i`` and ``j`` with map points ``m_i, m_j`` (means of ``n_i, n_j``
  sightings) are the same landmark when ``d² = Δᵀ (Σ_i + Σ_j)⁻¹ Δ ≤ χ²₂(merge_prob)``, ``Δ = m_i − m_j``,
  ``Σ_i`` the mean world-frame covariance of label ``i``'s sightings divided by ``n_i`` (the covariance of a
  mean, the noise model's σ_r, σ_b). Two labels seen in the same scan are never merged (one scan cannot
  see one landmark twice). Pairs are merged nearest first (union-find), and a merged group keeps the
  co-observation exclusion of all its members.
* **cost per landmark** — :func:`label_cost_energy` adds ``λ·L`` to the energy (``label_cost``): a label is then
  worth keeping only when it lowers the observation energy by more than λ. For weights from the noise model
  (``weights=information``, Q = Σ⁻¹) merging ``i`` and ``j`` raises the observation energy by exactly
  ``n_i n_j / (n_i + n_j) · ΔᵀQΔ`` — the ``d²`` above — so merging by the χ² test with ``λ = χ²₂(merge_prob)``
  is the same as merging when it lowers ``H + λ·L``.
"""

from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree

from slamcli.solvers.icm.init_gated import chi2_2dof, inv2x2, sighting_cov

#: candidate pairs are searched within this many standard deviations of the larger label spread
SEARCH_SIGMAS = 6.0


def label_covariances(step, z, poses_xyt, labels, n_labels: int, range_std: float, bearing_std: float):
    """Covariance ``(L, 2, 2)`` of each label's mean map point and its sighting count ``(L,)``: the mean of its
    sightings' world-frame covariances (:func:`~slamcli.solvers.icm.init_gated.sighting_cov`) over ``n``."""
    ok = labels >= 0
    th = poses_xyt[step[ok], 2]
    cov = sighting_cov(0.0, np.column_stack([z[ok, 0], z[ok, 1] + th]), range_std, bearing_std)
    cnt = np.bincount(labels[ok], minlength=n_labels).astype(float)
    out = np.zeros((n_labels, 2, 2))
    for a in range(2):
        for b in range(2):
            out[:, a, b] = np.bincount(labels[ok], weights=cov[:, a, b], minlength=n_labels)
    safe = np.maximum(cnt, 1.0)
    return out / (safe * safe)[:, None, None], cnt


def merge_labels(landmarks_xy, labels, step, label_cov, *, merge_prob: float):
    """Merge labels that pass the χ² test and were never seen in one scan (module docstring).

    Parameters
    ----------
    landmarks_xy : ndarray (L, 2)      map points (eq. 17 means).
    labels : ndarray (N,) int64        matchings (``-1`` = none).
    step : ndarray (N,) int64          pose index (scan) of each sighting.
    label_cov : ndarray (L, 2, 2)      covariance of each map point (:func:`label_covariances`).
    merge_prob : float                 χ² probability of the test (2 dof).

    Returns
    -------
    new_labels (N,) int64 (compact, by first appearance of the merged group), the number of merges, and the
    group of each old label ``(L,)``.
    """
    L = landmarks_xy.shape[0]
    group = np.arange(L)
    if L < 2:
        return labels, 0, group
    thr = chi2_2dof(merge_prob)
    spread = np.sqrt(np.max(label_cov[:, [0, 1], [0, 1]]))
    pairs = cKDTree(landmarks_xy).query_pairs(max(SEARCH_SIGMAS * spread, 1e-9) * np.sqrt(2.0), output_type="ndarray")
    if pairs.size == 0:
        return labels, 0, group
    i, j = pairs[:, 0], pairs[:, 1]
    d = landmarks_xy[i] - landmarks_xy[j]
    d2 = np.einsum("ka,kab,kb->k", d, inv2x2(label_cov[i] + label_cov[j]), d)
    keep = d2 <= thr
    i, j, d2 = i[keep], j[keep], d2[keep]
    ok = labels >= 0
    scans = {}  # label -> set of scans it was seen in
    for lab, st in zip(labels[ok].tolist(), step[ok].tolist()):
        scans.setdefault(lab, set()).add(st)
    members = {k: {k} for k in range(L)}
    merges = 0

    def root(k):
        while group[k] != k:
            group[k] = group[group[k]]
            k = group[k]
        return k

    for a, b in zip(i[np.argsort(d2)].tolist(), j[np.argsort(d2)].tolist()):
        ra, rb = root(a), root(b)
        if ra == rb or not scans.get(ra, set()).isdisjoint(scans.get(rb, set())):
            continue
        group[rb] = ra
        scans[ra] = scans.get(ra, set()) | scans.pop(rb, set())
        members[ra] |= members.pop(rb)
        merges += 1
    roots = np.array([root(k) for k in range(L)])
    out = labels.copy()
    out[ok] = roots[labels[ok]]
    # compact, by first appearance
    _, first = np.unique(out[ok], return_index=True)
    order = np.unique(out[ok])[np.argsort(first)]
    remap = np.full(L, -1, np.int64)
    remap[order] = np.arange(order.size)
    out[ok] = remap[out[ok]]
    return out, merges, remap[roots]


def label_cost_energy(n_labels: int, label_cost: float) -> float:
    """``λ·L``: the per-landmark cost added to the energy (0 when ``label_cost`` is 0, the paper's Φ_m)."""
    return float(label_cost) * int(n_labels)
