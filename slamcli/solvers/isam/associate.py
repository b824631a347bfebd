"""Per-update data association of the incremental smoother: the detections of one keyframe and their
χ²-gated nearest-neighbour labels against the current estimate.

Detections are built as ``graph``'s front end builds them (:func:`slamcli.solvers.frontend.segment_returns`:
returns of one pose adjacent in bearing and closer than ``segment_dist`` are one detection) and are measured
as ``graph``'s grouped factors are (mean range, circular-mean bearing). The gate is the one of ``graph``'s
front end (:func:`slamcli.solvers.frontend.gate_threshold`, χ²₂), applied to the innovation of each
detection against each landmark near the pose::

    ν = z − h(x_k, m_j),   S = [J_x J_m] Σ_{(x_k, m_j)} [J_x J_m]ᵀ + R,   d² = νᵀ S⁻¹ ν ≤ χ²₂(gate_prob)

with ``Σ`` the smoother's joint covariance of the current pose and an active landmark (a block of the
window's ``H⁻¹``, the prior included), and for a marginalised landmark its frozen marginal with no
cross-covariance. Each detection takes the closest admissible landmark, greedily in order of ``d²`` with
every landmark at most once per keyframe (as in ``graph``'s front end); the others start new landmarks.
"""

from __future__ import annotations

import numpy as np

from slamcli.models import observation
from slamcli.models.angles import wrap_angle
from slamcli.solvers import frontend

#: m. Landmarks farther than the longest detection plus this margin from the pose are not gated
CANDIDATE_MARGIN_M = 10.0


def detections(pose: np.ndarray, z_rows: np.ndarray, segment_dist: float):
    """``(seg (n,), z (d, 2))``: detection of each row and each detection's mean ``[range, bearing]``."""
    m = observation.inverse_range_bearing(np.broadcast_to(pose, (z_rows.shape[0], 3)), z_rows)
    seg = frontend.segment_returns(m, z_rows[:, 1], segment_dist)
    nd = int(seg.max()) + 1
    cnt = np.bincount(seg, minlength=nd).astype(float)
    r = np.bincount(seg, z_rows[:, 0], nd) / cnt
    b = np.arctan2(np.bincount(seg, np.sin(z_rows[:, 1]), nd), np.bincount(seg, np.cos(z_rows[:, 1]), nd))
    return seg, np.stack([r, wrap_angle(b)], -1)


def gate_and_match(pose, z, cand, lm_xy, cov_xx, cov_xm, cov_mm, R, thr):
    """Labels ``(d,)`` of detections ``z (d, 2)`` among candidate landmarks ``cand (c,)`` at ``lm_xy (c, 2)``
    (−1 = none admissible); ``cov_xx (3, 3)``, ``cov_xm (c, 3, 2)``, ``cov_mm (c, 2, 2)`` the joint covariance."""
    lab = np.full(z.shape[0], -1, np.int64)
    if not cand.size:
        return lab
    P = np.broadcast_to(pose, (cand.size, 3))
    zh = observation.range_bearing(P, lm_xy)
    Jx, Jm = observation.range_bearing_jacobians(P, lm_xy)
    S = (Jx @ cov_xx @ np.swapaxes(Jx, 1, 2) + Jx @ cov_xm @ np.swapaxes(Jm, 1, 2)
         + Jm @ np.swapaxes(cov_xm, 1, 2) @ np.swapaxes(Jx, 1, 2) + Jm @ cov_mm @ np.swapaxes(Jm, 1, 2) + R)
    Si = np.linalg.inv(S)
    nu = z[:, None, :] - zh[None, :, :]
    nu[..., 1] = wrap_angle(nu[..., 1])
    d2 = np.einsum("dci,cij,dcj->dc", nu, Si, nu)
    pairs = np.argwhere(d2 <= thr)
    if pairs.size:
        used = set()
        for i, c in pairs[np.argsort(d2[pairs[:, 0], pairs[:, 1]], kind="stable")]:
            if lab[i] < 0 and c not in used:
                used.add(int(c))
                lab[i] = cand[c]
    return lab
