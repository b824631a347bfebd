"""Initial poses for pose graphs with loop closures: odometry chain, spanning tree, chordal relaxation.

A pose graph is a set of relative-pose measurements ``d_e = x_i⁻¹ ⊕ x_j`` (edges ``e = (i, j)``, SE(2), with
information ``Λ_e``) over poses ``x_0..x_{n-1}``; ``x_0`` is known (the gauge). Local optimisers (GN / LM)
started from the chained odometry are known to stall in local minima on large loops (Manhattan M3500,
City10000), because the heading error accumulated along the chain is far outside the basin of convergence.
Two standard initialisations avoid that:

* **spanning tree** (g2o's and TORO's default): compose the measurements along a breadth-first spanning tree
  rooted at ``x_0`` (fewest edges to every pose, so loop closures shortcut the long odometry chain).
* **chordal relaxation** (Martinec & Pajdla 2007; Carlone, Tron, Daniilidis & Dellaert, "Initialization
  techniques for 3D SLAM: a survey on rotation estimation and its use in pose graph optimization",
  ICRA 2015, §IV; in 2-D the same as LAGO's rotation step without the integer unwrapping):

  1. rotations — relax ``R_i ∈ SO(2)`` to ``r_i = [cos θ_i, sin θ_i] ∈ ℝ²`` and solve the linear least
     squares ``min Σ_e κ_e ‖r_j − R(Δθ_e) r_i‖²`` (``‖R_j − R_i R_e‖²_F = 2 ‖r_j − R(Δθ_e) r_i‖²``) with
     ``r_0`` fixed, ``κ_e = Λ_e[θ, θ]``; project: ``θ_i = atan2(r_i[1], r_i[0])``.
  2. translations — with the rotations fixed the problem is linear:
     ``min Σ_e ‖t_j − t_i − R(θ_i) Δt_e‖²_{Ω_e}``, ``Ω_e = R(θ_i) Λ̄_e R(θ_i)ᵀ`` with ``Λ̄_e`` the translation
     information of the edge (Schur complement of the rotation in ``Λ_e``), ``t_0`` fixed.

  Both are sparse linear systems (normal equations, one sparse LU each), ``O(edges)`` to build.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla
from scipy.sparse import csgraph

from slamcli.models import se2
from slamcli.models.angles import wrap_angle


def spanning_tree_poses(
    n_poses: int, ij: np.ndarray, xyt: np.ndarray, x0: np.ndarray
) -> np.ndarray:
    """Poses ``(n, 3)`` composed along a breadth-first spanning tree of the edges from ``x_0``.

    Parameters
    ----------
    n_poses : n;  ij : ndarray (E, 2) int  edge endpoints;  xyt : ndarray (E, 3)  ``x_i⁻¹ ⊕ x_j`` measured;
    x0 : ndarray (3,)  the root pose.

    Raises
    ------
    ValueError  when a pose is not connected to ``x_0``.
    """
    ij = np.asarray(ij, np.int64).reshape(-1, 2)
    xyt = np.asarray(xyt, float).reshape(-1, 3)
    E = ij.shape[0]
    first: dict[tuple[int, int], int] = {}
    for e in range(E):
        first.setdefault((int(ij[e, 0]), int(ij[e, 1])), e)
    order, pred = csgraph.breadth_first_order(
        sp.csr_matrix((np.ones(E), (ij[:, 0], ij[:, 1])), shape=(n_poses, n_poses)),
        0,
        directed=False,
        return_predecessors=True,
    )
    if order.size != n_poses:
        missing = np.setdiff1d(np.arange(n_poses), order)
        raise ValueError(f"pose {int(missing[0])} is not connected to pose 0 by any edge")
    poses = np.empty((n_poses, 3))
    poses[0] = x0
    for v in order[1:]:
        u = int(pred[v])
        e = first.get((u, int(v)))
        if e is not None:
            d = xyt[e]
        else:
            d = se2.inverse(xyt[first[(int(v), u)]])
        poses[v] = se2.compose(poses[u], d)
    poses[:, 2] = wrap_angle(poses[:, 2])
    return poses


def _solve_normal(A: sp.csr_matrix, b: np.ndarray) -> np.ndarray:
    """Least squares ``min ‖A x − b‖`` through the normal equations ``AᵀA x = Aᵀb`` (symmetric positive
    definite: SuperLU in symmetric mode, minimum-degree ordering, no off-diagonal pivoting = sparse Cholesky)."""
    At = A.T.tocsr()
    lu = spla.splu(
        (At @ A).tocsc(), permc_spec="MMD_AT_PLUS_A", diag_pivot_thresh=0.0, options={"SymmetricMode": True}
    )
    return lu.solve(At @ b)


def chordal_poses(
    n_poses: int, ij: np.ndarray, xyt: np.ndarray, info: np.ndarray, x0: np.ndarray
) -> np.ndarray:
    """Poses ``(n, 3)`` from the chordal relaxation of the rotations, then linear translations (module doc).

    Parameters
    ----------
    n_poses : n;  ij : ndarray (E, 2) int;  xyt : ndarray (E, 3)  measured ``x_i⁻¹ ⊕ x_j``;
    info : ndarray (E, 3, 3)  information of each edge;  x0 : ndarray (3,)  the fixed first pose.

    Raises
    ------
    ValueError  when a pose is not connected to ``x_0`` (singular system).
    """
    ij = np.asarray(ij, np.int64).reshape(-1, 2)
    xyt = np.asarray(xyt, float).reshape(-1, 3)
    info = np.asarray(info, float).reshape(-1, 3, 3)
    n_comp, labels = csgraph.connected_components(
        sp.coo_matrix((np.ones(len(ij)), (ij[:, 0], ij[:, 1])), shape=(n_poses, n_poses)), directed=False
    )
    if n_comp > 1:
        bad = int(np.flatnonzero(labels != labels[0])[0])
        raise ValueError(f"pose {bad} is not connected to pose 0 by any edge")
    i, j = ij[:, 0], ij[:, 1]
    E = ij.shape[0]
    m = n_poses - 1  # unknown poses 1..n-1 → columns 2(k-1), 2(k-1)+1

    def assemble(blocks_i, blocks_j, rhs_fixed):
        """Rows ``B_j u_j − B_i u_i = c`` (2 per edge) with u_0 known: returns A (2E, 2m), b (2E,)."""
        rows = np.arange(2 * E).reshape(E, 2)
        r_list, c_list, v_list = [], [], []
        b = rhs_fixed.copy()
        for who, B, sign in ((j, blocks_j, 1.0), (i, blocks_i, -1.0)):
            free = who > 0
            cols = 2 * (who[:, None] - 1) + np.arange(2)[None, :]  # (E, 2)
            rr = np.broadcast_to(rows[:, :, None], (E, 2, 2))
            cc = np.broadcast_to(cols[:, None, :], (E, 2, 2))
            r_list.append(rr[free].ravel())
            c_list.append(cc[free].ravel())
            v_list.append((sign * B)[free].ravel())
        A = sp.csr_matrix(
            (np.concatenate(v_list), (np.concatenate(r_list), np.concatenate(c_list))), shape=(2 * E, 2 * m)
        )
        return A, b

    # 1. rotations: sqrt(κ) (r_j − R(Δθ) r_i) = 0
    kappa = np.sqrt(np.maximum(info[:, 2, 2], 1e-12))
    Rd = se2.rot2(xyt[:, 2])  # (E, 2, 2)
    I2 = np.broadcast_to(np.eye(2), (E, 2, 2))
    Bj = kappa[:, None, None] * I2
    Bi = kappa[:, None, None] * Rd
    r0 = np.array([np.cos(x0[2]), np.sin(x0[2])])
    # known u_0 moves to the right-hand side: + B_i r_0 where i = 0, − B_j r_0 where j = 0
    rhs = np.zeros((E, 2))
    rhs[i == 0] += np.einsum("eab,b->ea", Bi[i == 0], r0)
    rhs[j == 0] -= np.einsum("eab,b->ea", Bj[j == 0], r0)
    A, b = assemble(Bi, Bj, rhs.ravel())
    r = _solve_normal(A, b).reshape(m, 2)
    theta = np.concatenate([[x0[2]], np.arctan2(r[:, 1], r[:, 0])])

    # 2. translations: W_e (t_j − t_i − R(θ_i) Δt) = 0,  W_e = chol(Λ̄)ᵀ R(θ_i)ᵀ
    Ltt = info[:, :2, :2] - info[:, :2, 2:3] @ info[:, 2:3, :2] / np.maximum(info[:, 2:3, 2:3], 1e-300)
    Lc = np.linalg.cholesky(Ltt)  # Λ̄ = Lc Lcᵀ → whitening Lcᵀ
    Ri = se2.rot2(theta[i])
    W = np.swapaxes(Lc, 1, 2) @ np.swapaxes(Ri, 1, 2)
    c = np.einsum("eab,eb->ea", W, np.einsum("eab,eb->ea", Ri, xyt[:, :2]))
    t0 = np.asarray(x0[:2], float)
    rhs = c.copy()
    rhs[i == 0] += np.einsum("eab,b->ea", W[i == 0], t0)
    rhs[j == 0] -= np.einsum("eab,b->ea", W[j == 0], t0)
    A, b = assemble(W, W, rhs.ravel())
    t = _solve_normal(A, b).reshape(m, 2)
    poses = np.empty((n_poses, 3))
    poses[0] = x0
    poses[1:, :2] = t
    poses[1:, 2] = theta[1:]
    poses[:, 2] = wrap_angle(poses[:, 2])
    return poses
