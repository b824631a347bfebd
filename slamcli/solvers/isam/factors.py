"""The keyframe factor graph of the incremental smoother: composed odometry between keyframes, the factor
store that grows per update, and the whitened linearisations of its factors (errors and Jacobians are
``graph``'s GTSAM-exact ones, :mod:`slamcli.solvers.graph.factors`).

Keyframes are the poses with sightings (plus the first and the last pose). The odometry increments
``d_t`` between two keyframes ``a < b`` are composed into one between factor,
``D = d_a ⊕ … ⊕ d_{b−1}``, with GTSAM's right-perturbation noise ``d_t ⊕ Exp(ε_t)``, ``ε_t ~ N(0, Q)``::

    Σ ← Ad(d_t⁻¹) Σ Ad(d_t⁻¹)ᵀ + Q          (appending d_t),   Ad(x, y, θ) = [[R(θ), (y, −x)ᵀ], [0, 0, 1]]

— the first-order covariance of ``Log(D⁻¹ ⊕ x_a⁻¹ ⊕ x_b)`` (GTSAM's ``Pose2::AdjointMap`` convention).
A pose without sightings carries only odometry factors, so the keyframe graph has the same landmark
information as the full graph; the final batch step (:mod:`slamcli.solvers.isam.solver`) solves the full
graph with every pose.
"""

from __future__ import annotations

import numpy as np

from slamcli.models import motion, se2
from slamcli.solvers import nls
from slamcli.solvers.graph import bearing_range_error, between_error, prior_error, sqrt_info_batch


def adjoint(p: np.ndarray) -> np.ndarray:
    """SE(2) adjoint ``(3, 3)`` of pose ``p = [x, y, θ]`` (GTSAM ``Pose2::AdjointMap``)."""
    c, s = np.cos(p[2]), np.sin(p[2])
    return np.array([[c, -s, p[1]], [s, c, -p[0]], [0.0, 0.0, 1.0]])


def keyframe_odometry(odometry_xyt: np.ndarray, kf_steps: np.ndarray, odo_std: np.ndarray):
    """Composed odometry between consecutive keyframes (module docstring).

    Returns ``meas (K−1, 3)`` and ``cov (K−1, 3, 3)``."""
    d = motion.odometry_increments(np.asarray(odometry_xyt, float))
    Q = np.diag(np.square(np.maximum(np.asarray(odo_std, float), 1e-12)))
    K = kf_steps.size
    meas = np.zeros((K - 1, 3))
    cov = np.zeros((K - 1, 3, 3))
    for i in range(K - 1):
        D, S = np.zeros(3), np.zeros((3, 3))
        for t in range(int(kf_steps[i]), int(kf_steps[i + 1])):
            A = adjoint(se2.inverse(d[t]))
            S = A @ S @ A.T + Q
            D = se2.compose(D, d[t])
        meas[i], cov[i] = D, S
    return meas, cov


class Rows:
    """A growable array of rows (capacity doubled as needed); ``view`` is the filled part."""

    def __init__(self, shape: tuple[int, ...], dtype=float) -> None:
        self.a = np.zeros((16,) + shape, dtype)
        self.n = 0

    def extend(self, rows: np.ndarray) -> np.ndarray:
        """Append ``rows`` and return their indices."""
        rows = np.asarray(rows, self.a.dtype).reshape((-1,) + self.a.shape[1:])
        k = rows.shape[0]
        while self.n + k > self.a.shape[0]:
            self.a = np.concatenate([self.a, np.zeros_like(self.a)])
        self.a[self.n : self.n + k] = rows
        self.n += k
        return np.arange(self.n - k, self.n)

    @property
    def view(self) -> np.ndarray:
        return self.a[: self.n]


class FactorStore:
    """Every factor of the keyframe graph: the prior on keyframe 0, between factors ``(k−1, k)`` (index
    ``k − 1``) and bearing-range factors ``(k, j, z)``; whitening ``L`` (``LᵀL = Σ⁻¹``)."""

    def __init__(self, x0: np.ndarray, prior_std, obs_cov: np.ndarray) -> None:
        self.x0 = np.asarray(x0, float)
        self.prior_L = np.diag(1.0 / np.asarray(prior_std, float))
        self.obs_L = np.linalg.cholesky(np.linalg.inv(np.asarray(obs_cov, float))).T
        self.bt_meas = Rows((3,))
        self.bt_L = Rows((3, 3))
        self.br_k = Rows((), np.int64)
        self.br_j = Rows((), np.int64)
        self.br_z = Rows((2,))

    def add_between(self, meas: np.ndarray, cov: np.ndarray) -> int:
        self.bt_meas.extend(meas)
        return int(self.bt_L.extend(sqrt_info_batch(np.linalg.inv(np.asarray(cov, float))[None]))[0])

    def add_sightings(self, k: int, labels: np.ndarray, z: np.ndarray) -> np.ndarray:
        self.br_k.extend(np.full(labels.size, k))
        self.br_j.extend(labels)
        return self.br_z.extend(z)


def kernel_weight(rw: np.ndarray, robust: str, k: float) -> np.ndarray | None:
    """IRLS weight ``(F,)`` of whitened residuals ``rw (F, d)`` (None = Gaussian)."""
    if robust == "none":
        return None
    return nls.robust_kernel(np.einsum("fk,fk->f", rw, rw), robust, k)[1]


def linearize_between(fs: FactorStore, ids: np.ndarray, poses: np.ndarray):
    """Whitened ``r (F, 3)``, ``J (F, 3, 6)`` of between factors ``ids`` at keyframe poses ``poses``."""
    e, Ji, Jj = between_error(poses[ids], poses[ids + 1], fs.bt_meas.view[ids])
    L = fs.bt_L.view[ids]
    return np.einsum("fij,fj->fi", L, e), L @ np.concatenate([Ji, Jj], axis=2)


def linearize_sightings(fs: FactorStore, ids: np.ndarray, poses, lms, robust: str, k: float):
    """Whitened (and IRLS-weighted) ``r (F, 2)``, ``J (F, 2, 5)`` of bearing-range factors ``ids``."""
    e, Jx, Jm = bearing_range_error(poses[fs.br_k.view[ids]], lms[fs.br_j.view[ids]], fs.br_z.view[ids])
    r = e @ fs.obs_L.T
    J = fs.obs_L @ np.concatenate([Jx, Jm], axis=2)
    w = kernel_weight(r, robust, k)
    if w is not None:
        sw = np.sqrt(w)
        r, J = r * sw[:, None], J * sw[:, None, None]
    return r, J


def linearize_prior(fs: FactorStore, x: np.ndarray):
    """Whitened ``r (3,)``, ``J (3, 3)`` of the prior on keyframe 0."""
    e, J = prior_error(x[None], fs.x0[None])
    return fs.prior_L @ e[0], fs.prior_L @ J[0]


def keyframe_problem(fs: FactorStore, n_kf: int, n_lm: int, bt_ids, br_ids, with_prior: bool):
    """The keyframe graph (or a subset of its factors) as an :class:`nls.NlsProblem` over poses ``3 n_kf``
    then landmarks ``2 n_lm`` (world coordinates)."""
    P = 3 * n_kf
    pc = np.arange(P, dtype=np.int64).reshape(-1, 3)
    lc = P + np.arange(2 * n_lm, dtype=np.int64).reshape(-1, 2)
    blocks = []
    if with_prior:
        blocks.append(nls.FactorBlock("prior", pc[:1], lambda x: prior_error(x[:3][None], fs.x0[None]), fs.prior_L))
    bt_ids = np.asarray(bt_ids, np.int64)
    if bt_ids.size:
        meas = fs.bt_meas.view[bt_ids].copy()

        def ev_bt(x):
            p = x[:P].reshape(-1, 3)
            e, Ji, Jj = between_error(p[bt_ids], p[bt_ids + 1], meas)
            return e, np.concatenate([Ji, Jj], axis=2)

        blocks.append(nls.FactorBlock("odometry", np.concatenate([pc[bt_ids], pc[bt_ids + 1]], 1), ev_bt,
                                      fs.bt_L.view[bt_ids].copy()))
    br_ids = np.asarray(br_ids, np.int64)
    if br_ids.size:
        kk, jj, z = fs.br_k.view[br_ids].copy(), fs.br_j.view[br_ids].copy(), fs.br_z.view[br_ids].copy()

        def ev_br(x):
            e, Jx, Jm = bearing_range_error(x[:P].reshape(-1, 3)[kk], x[P:].reshape(-1, 2)[jj], z)
            return e, np.concatenate([Jx, Jm], axis=2)

        blocks.append(nls.FactorBlock("bearing_range", np.concatenate([pc[kk], lc[jj]], 1), ev_br, fs.obs_L,
                                      robust=True))
    return nls.NlsProblem(n_vars=P + 2 * n_lm, blocks=blocks, angle_cols=pc[:, 2].copy(), se2_poses=n_kf)
