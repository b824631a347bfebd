"""Initial poses of ``--method graph``: chained odometry, spanning tree, chordal relaxation, the robust and
the incremental (windowed) starts.

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

  Both are sparse linear systems (normal equations on one shared pattern and solver analysis,
  :class:`_PairSystem`), ``O(edges)`` to build.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from slamcli.errors import SolverError
from slamcli.models import motion, se2
from slamcli.models.angles import wrap_angle
from slamcli.solvers import frontend, nls
from slamcli.solvers.graph.build import build_gtsam_problem
from slamcli.solvers.graph.params import GraphParams
from slamcli.types import Observations, SlamInputs, Status


# ----------------------------------------------------------------------------------------------------------
# solver
# ----------------------------------------------------------------------------------------------------------
def odometry_initial_poses(inputs: SlamInputs) -> np.ndarray:
    """Odometry increments chained from the known start pose, ``(T+1, 3)`` (multi-robot: each robot's chain
    from its own start pose)."""
    team = inputs.robots
    if team is not None:
        from slamcli.types import solo_inputs

        return np.concatenate([odometry_initial_poses(solo_inputs(inputs, r)) for r in range(team.n_robots)])
    d = motion.odometry_increments(inputs.odometry_xyt)
    poses = np.empty((inputs.n_poses, 3))
    poses[0] = inputs.x0
    # compose sequentially (cumulative heading first, then rotate increments: vectorised)
    th = wrap_angle(inputs.x0[2] + np.concatenate([[0.0], np.cumsum(d[:, 2])]))
    c, s = np.cos(th[:-1]), np.sin(th[:-1])
    dx = c * d[:, 0] - s * d[:, 1]
    dy = s * d[:, 0] + c * d[:, 1]
    poses[1:, 0] = inputs.x0[0] + np.cumsum(dx)
    poses[1:, 1] = inputs.x0[1] + np.cumsum(dy)
    poses[:, 2] = th
    return poses


def pose_graph_edges(inputs: SlamInputs, use_edge_info: bool = True):
    """All pose-pose edges of a dataset: the odometry chain ``t → t+1`` then the between-factors.

    Returns
    -------
    ij : ndarray (E, 2) int64;  xyt : ndarray (E, 3) measured ``x_i⁻¹ ⊕ x_j``;  info : ndarray (E, 3, 3)
    """
    T = inputs.n_poses - 1
    d = motion.odometry_increments(inputs.odometry_xyt)
    c = inputs.constraints
    if c is not None and c.odometry_info is not None and use_edge_info:
        odo_info = np.asarray(c.odometry_info, float)
    else:
        odo_info = np.broadcast_to(np.diag(1.0 / np.square(np.maximum(inputs.noise.odometry_std, 1e-12))), (T, 3, 3))
    ij = [np.stack([np.arange(T), np.arange(1, T + 1)], axis=1)]
    xyt, info = [d.reshape(-1, 3)], [odo_info]
    if c is not None and c.n_between:
        ij.append(np.asarray(c.between_ij, np.int64).reshape(-1, 2))
        xyt.append(np.asarray(c.between_xyt, float).reshape(-1, 3))
        info.append(np.asarray(c.between_info, float).reshape(-1, 3, 3))
    return np.concatenate(ij).astype(np.int64), np.concatenate(xyt), np.concatenate(info)


def initial_poses(inputs: SlamInputs, method: str = "odometry") -> np.ndarray:
    """Initial poses ``(T+1, 3)``: chained odometry, chordal relaxation or spanning tree (below).

    Raises
    ------
    SolverError  unknown method, or a pose not connected to ``x_0`` (chordal / spanning tree).
    """
    if method == "odometry":
        return odometry_initial_poses(inputs)
    ij, xyt, info = pose_graph_edges(inputs)
    try:
        if method == "chordal":
            return chordal_poses(inputs.n_poses, ij, xyt, info, np.asarray(inputs.x0, float))
        if method == "spanning_tree":
            return spanning_tree_poses(inputs.n_poses, ij, xyt, np.asarray(inputs.x0, float))
    except ValueError as exc:
        raise SolverError(f"graph: init={method}: {exc}") from None
    raise SolverError(f"graph: unknown init {method!r} (odometry, chordal or spanning_tree)")


def robust_initial_poses(
    inputs: SlamInputs, assoc: np.ndarray, poses0: np.ndarray, params: GraphParams
) -> tuple[np.ndarray, nls.NlsResult]:
    """Initial poses ``(T+1, 3)`` from a robust solve: the ``gtsam``-model graph of ``assoc`` with GTSAM's
    Cauchy kernel (scale ``params.cauchy_k``) on the observation factors, started at ``poses0`` (landmarks
    at their mean inverse observation) and optimised with ``params``' method, tolerances and budget.

    Why: under the Gaussian model a wrong correspondence costs ``½ s²`` (s = its whitened residual), so a
    handful of them pull a whole drifted chain into a basin far from the optimum; the Cauchy cost
    ``½ k² log(1 + s²/k²)`` grows only logarithmically and its IRLS weight ``1/(1 + s²/k²)`` lets such a
    factor go, so the robust optimum sits where the consistent majority of the factors puts it — a start
    inside the Gaussian optimum's basin. Returns the poses and the robust solve's result (for its status,
    iterations and cost)."""
    lm0 = frontend.landmarks_from_observations(poses0, inputs.observations, assoc, int(assoc.max(initial=-1)) + 1)
    gp = build_gtsam_problem(inputs, assoc, poses0, lm0, params)
    res = nls.solve(gp.problem, gp.x0, params.nls_params("cauchy", params.cauchy_k))
    return gp.unpack(res.x)[0].copy(), res


def nearest_neighbour_association(poses, obs: Observations, inputs: SlamInputs, p: GraphParams) -> np.ndarray:
    """``graph``'s nearest-neighbour association of ``obs`` from ``poses`` (T+1, 3), with its parameters
    (gate, extra σ, drift-aware gating, segment distance); labels (N,), -1 = unassociated."""
    assoc, _ = frontend.associate_nearest_neighbour(
        poses,
        obs,
        inputs.noise.obs_cov,
        gate_prob=p.gate_prob,
        extra_std=p.nn_extra_std,
        odometry_std=inputs.noise.odometry_std if p.nn_drift else None,
        segment_dist=p.nn_segment_dist,
    )
    return assoc


def incremental_initial_poses(inputs: SlamInputs, poses0: np.ndarray, params: GraphParams) -> np.ndarray:
    """Initial poses ``(T+1, 3)`` for unknown correspondences, built incrementally.

    The batch front end associates every sighting on the dead-reckoned poses, whose drift grows without
    bound (26 m after 300 s of Victoria Park): revisited trees then fall outside their gates or into a
    neighbour's. Here the run is cut into windows of ``params.incremental_window`` s; at the end ``t_k`` of
    each window the sightings of steps ``≤ t_k`` are associated by the gated nearest-neighbour front end
    (:func:`slamcli.solvers.frontend.associate_nearest_neighbour`, same gate and drift model) on the
    current poses, and the ``gtsam``-model graph of those sightings is optimised (LM, Cauchy kernel on the
    sightings, started at the current poses; the poses after ``t_k`` carry only odometry factors, so the
    optimum continues them by dead reckoning from the optimised ``x_{t_k}``). The next window's sightings
    are thus projected from poses that drifted only since ``t_k``. Cost: one association and one warm-started
    optimisation per window.
    """
    obs = inputs.observations
    T = inputs.n_poses - 1
    poses = np.array(poses0, float, copy=True)
    if not len(obs) or T < 1:
        return poses
    win = max(1, int(round(params.incremental_window / max(inputs.dt, 1e-12))))
    # an initial guess: the final solve polishes
    nparams = params.nls_params("cauchy", params.cauchy_k, rel_cost_tol=max(params.rel_cost_tol, 1e-6))
    ends = list(range(win, T, win)) + [T]
    for t_end in ends:
        n = int(obs.offsets[t_end + 1])
        if n == 0:
            continue
        sub = Observations.from_rows(obs.step[:n], obs.z[:n], inputs.n_poses, sensor=obs.sensor[:n])
        a_sub = nearest_neighbour_association(poses, sub, inputs, params)
        assoc = np.full(len(obs), -1, np.int64)
        assoc[:n] = a_sub
        assoc, old_of_new = frontend.compact_labels(assoc, 1)
        if not old_of_new.size:
            continue
        lm0 = frontend.landmarks_from_observations(poses, obs, assoc, old_of_new.size)
        gp = build_gtsam_problem(inputs, assoc, poses, lm0, params)
        res = nls.solve(gp.problem, gp.x0, nparams)
        if res.status != Status.FAILED:
            poses = gp.unpack(res.x)[0].copy()
    return poses


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
    from scipy.sparse import csgraph  # imported when used (spanning-tree start only)

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


def component_roots(n: int, i: np.ndarray, j: np.ndarray) -> np.ndarray:
    """The smallest vertex of each vertex's connected component in the undirected graph with ``n`` vertices
    and edges ``(i[e], j[e])``: ``(n,)`` int64, so ``roots == 0`` marks the component of vertex 0.

    Label propagation with pointer jumping (Shiloach-Vishkin style): every round hooks the root of each edge's
    larger-labelled end onto the smaller root (roots only decrease, so no cycle forms), then compresses every
    pointer to its root; it stops when no edge joins two roots. A chain needs one round. Written in numpy
    because ``scipy.sparse.csgraph`` imports ``scipy.sparse.linalg`` (a start-up cost of every default
    pose-graph solve: benchmarks/results/design_notes.md); ``tests/solvers/test_graph_chordal_components.py`` checks
    it against csgraph.
    """
    i = np.asarray(i, np.int64)
    j = np.asarray(j, np.int64)
    roots = np.arange(n, dtype=np.int64)
    while True:
        ri, rj = roots[i], roots[j]
        joined = ri != rj
        if not joined.any():
            return roots
        lo = np.minimum(ri[joined], rj[joined])
        hooked = roots.copy()
        np.minimum.at(hooked, ri[joined], lo)
        np.minimum.at(hooked, rj[joined], lo)
        while True:  # pointer jumping until every vertex points at a root
            nxt = hooked[hooked]
            if np.array_equal(nxt, hooked):
                break
            hooked = nxt
        roots = hooked


class _PairSystem:
    """Linear least squares ``min Σ_e ‖B_j,e u_j − B_i,e u_i − c_e‖²`` over 2-vectors ``u (n, 2)`` with ``u_0``
    given, through its normal equations (symmetric positive definite when every pose is connected to pose 0).

    Both chordal systems (rotations, then translations) have this form on the same edges, so they share one
    :class:`slamcli.solvers.nls.Assembler` pattern (scatter positions computed once) and one analysis of the
    linear solver (CHOLMOD's ordering and symbolic factorisation when installed): each solve is one assembly
    and one numeric factorisation."""

    def __init__(self, n: int, i: np.ndarray, j: np.ndarray) -> None:
        self.n, self.i, self.j = n, i, j
        cols = np.concatenate([2 * i[:, None] + np.arange(2), 2 * j[:, None] + np.arange(2)], axis=1)
        self._terms: tuple = ()
        block = nls.FactorBlock("pair", cols, self._evaluate, np.eye(2))
        problem = nls.NlsProblem(2 * n, [block], fixed_cols=np.arange(2, dtype=np.int64))
        self.params = nls.NlsParams(pose_chart="world")
        self.asm = nls.Assembler(problem)
        self.lin = nls.make_linear_solver(self.asm, self.params)

    def _evaluate(self, v: np.ndarray):
        Bi, Bj, c = self._terms
        u = v.reshape(-1, 2)
        r = np.einsum("eab,eb->ea", Bj, u[self.j]) - np.einsum("eab,eb->ea", Bi, u[self.i]) - c
        return r, np.concatenate([-Bi, Bj], axis=2)

    def solve(self, Bi: np.ndarray, Bj: np.ndarray, c: np.ndarray, u0: np.ndarray) -> np.ndarray:
        """``u (n, 2)`` for blocks ``Bi``, ``Bj`` (E, 2, 2), right-hand sides ``c`` (E, 2) and the given ``u_0``.

        Raises
        ------
        numpy.linalg.LinAlgError   the normal equations are not numerically positive definite.
        """
        self._terms = (Bi, Bj, c)
        x = np.zeros(2 * self.n)
        x[:2] = u0
        _, lo, g = self.asm.linearize_lower(x, self.params)  # g = Jᵀ r at u_free = 0: the system is linear
        h = self.lin.solve(-g) if nls.factorize_lower(self.lin, self.asm, lo) else None
        if h is None:
            raise np.linalg.LinAlgError("chordal normal equations are not positive definite")
        return (x + h).reshape(self.n, 2)


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
    labels = component_roots(n_poses, ij[:, 0], ij[:, 1])
    if labels.any():
        bad = int(np.flatnonzero(labels)[0])
        raise ValueError(f"pose {bad} is not connected to pose 0 by any edge")
    i, j = ij[:, 0], ij[:, 1]
    E = ij.shape[0]
    system = _PairSystem(n_poses, i, j)

    # 1. rotations: sqrt(κ) (r_j − R(Δθ) r_i) = 0, r_0 = [cos θ_0, sin θ_0]
    kappa = np.sqrt(np.maximum(info[:, 2, 2], 1e-12))
    Bi = kappa[:, None, None] * se2.rot2(xyt[:, 2])  # (E, 2, 2)
    Bj = kappa[:, None, None] * np.broadcast_to(np.eye(2), (E, 2, 2))
    r = system.solve(Bi, Bj, np.zeros((E, 2)), np.array([np.cos(x0[2]), np.sin(x0[2])]))[1:]
    theta = np.concatenate([[x0[2]], np.arctan2(r[:, 1], r[:, 0])])

    # 2. translations: W_e (t_j − t_i − R(θ_i) Δt) = 0,  W_e = chol(Λ̄)ᵀ R(θ_i)ᵀ, t_0 given; Λ̄ = [[a, b], [b, d]] the
    # Schur complement of θ in Λ_e, its Cholesky factor [[l00, 0], [l10, l11]] in closed form (2×2), and
    # W_e R(θ_i) Δt = chol(Λ̄)ᵀ Δt
    i22 = np.maximum(info[:, 2, 2], 1e-300)
    a = info[:, 0, 0] - info[:, 0, 2] * info[:, 2, 0] / i22
    b = info[:, 0, 1] - info[:, 0, 2] * info[:, 2, 1] / i22
    d = info[:, 1, 1] - info[:, 1, 2] * info[:, 2, 1] / i22
    l00 = np.sqrt(a)
    l10 = b / l00
    l11 = np.sqrt(d - l10 * l10)
    ci, si = np.cos(theta[i]), np.sin(theta[i])
    W = np.empty((E, 2, 2))  # [[l00, l10], [0, l11]] · R(θ_i)ᵀ
    W[:, 0, 0], W[:, 0, 1] = l00 * ci - l10 * si, l00 * si + l10 * ci
    W[:, 1, 0], W[:, 1, 1] = -l11 * si, l11 * ci
    c = np.column_stack([l00 * xyt[:, 0] + l10 * xyt[:, 1], l11 * xyt[:, 1]])
    t = system.solve(W, W, c, np.asarray(x0[:2], float))[1:]
    poses = np.empty((n_poses, 3))
    poses[0] = x0
    poses[1:, :2] = t
    poses[1:, 2] = theta[1:]
    poses[:, 2] = wrap_angle(poses[:, 2])
    return poses
