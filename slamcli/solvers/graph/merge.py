"""Landmark merging: pairs of landmarks that pass the correspondence test at the optimum.
"""

from __future__ import annotations

import numpy as np

from slamcli.solvers import frontend
from slamcli.solvers.graph.build import GraphProblem, landmark_joint_covariance


def merge_candidates(
    gp: GraphProblem,
    information,
    landmarks_xy: np.ndarray,
    obs,
    assoc: np.ndarray,
    gate_prob: float,
    merge_dist: float = 0.0,
) -> np.ndarray:
    """Landmark pairs that pass GraphSLAM's correspondence test (Thrun, Burgard & Fox, *Probabilistic
    Robotics*, §11.5 "correspondence test"; seed 002, graph SLAM with unknown correspondences).

    For labels ``i < j`` never observed at the same pose, the difference ``Δ = m_i − m_j`` has the Laplace
    covariance ``Σ_Δ = Σ_ii + Σ_jj − Σ_ij − Σ_ji`` (joint marginal at the optimum, so drift between the two
    sightings is accounted for); the pair is a candidate if ``Δᵀ Σ_Δ⁻¹ Δ ≤ χ²₂(gate_prob)``. Pairs are taken
    greedily by increasing distance, each label at most once per call. Pairs closer than ``merge_dist`` (m)
    are candidates as well (paper 000's label fusion radius ϑ), again only if never co-observed — two
    distinct landmarks that close are almost always seen together, which protects them.

    Parameters
    ----------
    gp : GraphProblem;  information : sparse (D, D) H at the optimum;  landmarks_xy : ndarray (L, 2) optimum
    obs : Observations;  assoc : ndarray (N,) labels;  gate_prob : float;  merge_dist : float, m

    Returns
    -------
    ndarray (K, 2) int64 of ``(keep, drop)`` label pairs, ``keep < drop``.
    """
    import scipy.sparse as sp

    L = gp.n_landmarks
    none = np.zeros((0, 2), np.int64)
    if L < 2:
        return none
    thr = frontend.gate_threshold(gate_prob)
    ok = assoc >= 0
    M = sp.csr_matrix((np.ones(int(ok.sum())), (np.asarray(obs.step)[ok], assoc[ok])), shape=(gp.n_poses, L))
    co_seen = (M.T @ M).toarray() > 0
    iu, ju = np.triu_indices(L, 1)
    keep = ~co_seen[iu, ju]
    iu, ju = iu[keep], ju[keep]
    if not iu.size:
        return none
    cov = landmark_joint_covariance(gp, information).reshape(L, 2, L, 2)  # cov[i, :, j, :] = Σ_ij
    Sii = cov[iu, :, iu, :]
    Sjj = cov[ju, :, ju, :]
    Sij = cov[iu, :, ju, :]
    Sd = Sii + Sjj - Sij - np.swapaxes(Sij, 1, 2)  # (K, 2, 2)
    d = landmarks_xy[iu] - landmarks_xy[ju]  # (K, 2)
    det = Sd[:, 0, 0] * Sd[:, 1, 1] - Sd[:, 0, 1] * Sd[:, 1, 0]
    with np.errstate(divide="ignore", invalid="ignore"):
        d2 = (
            Sd[:, 1, 1] * d[:, 0] ** 2 - 2 * Sd[:, 0, 1] * d[:, 0] * d[:, 1] + Sd[:, 0, 0] * d[:, 1] ** 2
        ) / det
    close = np.einsum("ki,ki->k", d, d) <= merge_dist**2
    cand = np.flatnonzero(((det > 0) & (d2 <= thr)) | close)
    used: set[int] = set()
    out = []
    for c in cand[np.argsort(d2[cand], kind="stable")]:  # greedy, O(K log K); K is small after gating
        i, j = int(iu[c]), int(ju[c])
        if i in used or j in used:
            continue
        used.update((i, j))
        out.append((i, j))
    return np.asarray(out, np.int64).reshape(-1, 2)
