"""FastSLAM 1.0 and 2.0: a Rao-Blackwellised particle filter over robot poses with one 2×2 EKF per landmark
per particle (paper 002 §14.3-14.5; Montemerlo et al. 2002/2003), vectorised over particles: poses
``x (P, 3)``, landmark means ``mu (P, C, 2)``, covariances ``sig (P, C, 2, 2)``, counters and existence flags
``(P, C)`` (``C`` slots). Letters as in filterpy: ``Q`` motion (process) noise, ``R`` measurement noise,
``S_n = H_m Σ H_mᵀ + R`` the innovation covariance of landmark n (Thrun's book calls them R, Q and Q_n).

* **1.0**: sample ``x_t ~ p(x_t | x_{t-1}, u_t)`` (eq. 14.18; controls + ``motion_std`` or odometry +
  ``odometry_std``), then per observation the landmark EKF update (eqs. 14.21-14.24) and the weight
  ``N(z; ẑ, S_n)``; unseen landmarks start at ``μ = h⁻¹(x, z)``, ``Σ = M_z R M_zᵀ``.
* **2.0** (Probabilistic Robotics §13.4): prior ``N(x̂, Q)``, ``Q = G_u M G_uᵀ`` (or ``J Σ_odo Jᵀ``); each
  observation of a mapped landmark refines the pose proposal by a Kalman update
  ``S = H_x Σ_x H_xᵀ + H_m Σ_m H_mᵀ + R``, ``K = Σ_x H_xᵀ S⁻¹`` and multiplies the weight by ``N(z; h(x̂, μ), S)``;
  the pose is then sampled from ``N(x̂, Σ_x)`` and the landmark EKFs updated there, reusing the proposal's
  linearisation shifted to first order (:func:`_shift_terms`).
* **Correspondences** (§14.4.2): ``association="known"`` uses ``observations.reported_id``; ``"ml"`` is
  per-particle maximum likelihood (eq. 14.30) with a new landmark below ``p0``; optional negative evidence
  drops landmarks predicted in view but not seen (Table 13.4).
* **Resampling** when ``ESS = 1/Σw² < resample_threshold · P`` (systematic by default); never at the last step.
* **Output**: poses as the weighted mean per step (circular heading) or the best particle's traced-back path;
  ``pose_cov`` the weighted moment-matched covariance; landmarks as the moment-matched mixture over particles
  (known association) or the best particle's map (ml); ``assoc`` the best particle's;
  ``extra["mean_nis"]`` the mean NIS over all particle updates (χ²(2) ⇒ ≈ 2).
"""

from __future__ import annotations

import dataclasses
import math
import time

import numpy as np

from slamcli.errors import SolverError
from slamcli.models import se2
from slamcli.models.ackermann import ackermann_jacobians, ackermann_step
from slamcli.models.angles import circular_mean, wrap_angle
from slamcli.models.motion import ddmr_step
from slamcli.models.observation import inverse_range_bearing, range_bearing
from slamcli.params import check_allocation
from slamcli.solvers.base import BaseSolver, ProgressFn
from slamcli.solvers.fastslam_params import FastSlamParams
from slamcli.solvers.frontend import group_detections, inside_declared_size
from slamcli.solvers.resampling import RESAMPLERS, effective_sample_size, normalise_log_weights
from slamcli.solvers.surface import declared_radius
from slamcli.types import SlamInputs, SolverResult, Status

LOG_2PI = math.log(2.0 * math.pi)
CHI2_2DOF_9999 = 18.420680743952367  # scipy.stats.chi2.ppf(0.9999, 2) = −2 ln(1e−4)
#: Batched kernels work on (P, k) arrays of at most this many float64 (64 KB): larger temporaries leave
#: glibc's heap for mmap, and their page faults cost more than the batching saves
#: (chosen by measurement: benchmarks/results/design_notes.md).
BATCH_ELEMENTS = 8192




# ---------------------------------------------------------------------------------------------------------
# Particle state
# ---------------------------------------------------------------------------------------------------------
@dataclasses.dataclass
class ParticleSet:
    """Mutable particle state, every array's first axis is the particle index.

    Attributes
    ----------
    x : ndarray (P, 3)          poses.
    mu : ndarray (P, C, 2)      landmark means (slots ``≥ n_slots`` or with ``exists`` False are unused).
    sig : ndarray (P, C, 2, 2)  landmark covariances.
    count : ndarray (P, C)      negative-evidence support counters (read only with ML association, the one
                                that removes landmarks; the known-association 1.0 update leaves them at 0).
    exists : ndarray (P, C)     slot holds a live landmark.
    n_slots : ndarray (P,)      slots used so far (ML association allocates new landmarks at ``n_slots``).
    log_w : ndarray (P,)        unnormalised log importance weights.
    hidden : ndarray (P, C)     live landmark left out of the reported map (``size_gate_hide``).
    """

    x: np.ndarray
    mu: np.ndarray
    sig: np.ndarray
    count: np.ndarray
    exists: np.ndarray
    n_slots: np.ndarray
    log_w: np.ndarray
    hidden: np.ndarray

    @classmethod
    def create(cls, x0: np.ndarray, n_particles: int, capacity: int) -> ParticleSet:
        P, C = n_particles, max(int(capacity), 1)
        return cls(
            x=np.tile(np.asarray(x0, float), (P, 1)),
            mu=np.zeros((P, C, 2)),
            sig=np.zeros((P, C, 2, 2)),
            count=np.zeros((P, C), np.int32),
            exists=np.zeros((P, C), bool),
            n_slots=np.zeros(P, np.int64),
            log_w=np.zeros(P),
            hidden=np.zeros((P, C), bool),
        )

    @property
    def n_particles(self) -> int:
        return int(self.x.shape[0])

    @property
    def capacity(self) -> int:
        return int(self.mu.shape[1])

    def take(self, idx: np.ndarray) -> ParticleSet:
        """Resampled copy: new particle ``j`` is old particle ``idx[j]``; weights reset to uniform.

        Fancy indexing allocates fresh arrays, so copies of one ancestor never share landmark storage.
        """
        idx = np.asarray(idx, np.int64)
        return ParticleSet(
            x=self.x[idx],
            mu=self.mu[idx],
            sig=self.sig[idx],
            count=self.count[idx],
            exists=self.exists[idx],
            n_slots=self.n_slots[idx],
            log_w=np.zeros(idx.shape[0]),
            hidden=self.hidden[idx],
        )

    def store(self, idx: tuple, mx, my, a, b, c) -> None:
        """Write landmark means ``(mx, my)`` and covariances ``[[a, b], [b, c]]`` at the slot index tuple ``idx``
        (``(particles, slots)``: any numpy index of the first two axes), component by component (cheaper than
        stacking the components first and writing once)."""
        self.mu[idx + (0,)], self.mu[idx + (1,)] = mx, my
        self.sig[idx + (0, 0)], self.sig[idx + (1, 1)] = a, c
        self.sig[idx + (0, 1)] = self.sig[idx + (1, 0)] = b

    def ensure_capacity(self, needed: int) -> None:
        """Grow the slot axis (doubling) so that ``needed`` slots fit."""
        C = self.capacity
        if needed <= C:
            return
        new_c = max(needed, 2 * C)
        P = self.n_particles
        pad = new_c - C
        self.mu = np.concatenate([self.mu, np.zeros((P, pad, 2))], axis=1)
        self.sig = np.concatenate([self.sig, np.zeros((P, pad, 2, 2))], axis=1)
        self.count = np.concatenate([self.count, np.zeros((P, pad), np.int32)], axis=1)
        self.exists = np.concatenate([self.exists, np.zeros((P, pad), bool)], axis=1)
        self.hidden = np.concatenate([self.hidden, np.zeros((P, pad), bool)], axis=1)


# ---------------------------------------------------------------------------------------------------------
# Component-wise kernels. Every quantity is an array over particles (and, for ML candidates, landmarks);
# explicit 2×2 / 3×3 algebra on component arrays is much faster than np.matmul on stacks of tiny matrices.
# ---------------------------------------------------------------------------------------------------------
@dataclasses.dataclass
class _ObsTerms:
    """Linearised range-bearing prediction of landmark(s) ``m`` from pose(s) ``x`` (component arrays).

    ``ν = z − h(x, m)`` (bearing wrapped), ``H_m = [[h11, h12], [h21, h22]] = ∂h/∂m`` (``H_x[:, :2] = −H_m``,
    ``H_x[1, 2] = −1``, see :func:`slamcli.models.observation.range_bearing_jacobians`), ``P = Σ H_mᵀ`` and
    ``S = H_m Σ H_mᵀ + R`` (eq. 14.29; symmetric, ``S12 = S21``).
    """

    nu_r: np.ndarray
    nu_b: np.ndarray
    h11: np.ndarray
    h12: np.ndarray
    h21: np.ndarray
    h22: np.ndarray
    p11: np.ndarray
    p12: np.ndarray
    p21: np.ndarray
    p22: np.ndarray
    S11: np.ndarray
    S12: np.ndarray
    S22: np.ndarray


def _obs_terms(x, y, th, mx, my, a, b, c, zr, zb, qr, qb) -> _ObsTerms:
    """Pose ``(x, y, θ)``, landmark mean ``(mx, my)`` and covariance ``[[a, b], [b, c]]``; measurement
    ``(zr, zb)``; noise variances ``qr, qb``."""
    dx = mx - x
    dy = my - y
    q = dx * dx + dy * dy
    r = np.sqrt(q)
    nu_r = zr - r
    nu_b = wrap_angle(zb - np.arctan2(dy, dx) + th)  # = wrap(z_b − wrap(atan2 − θ))
    h11, h12 = dx / r, dy / r
    h21, h22 = -dy / q, dx / q
    p11, p12 = a * h11 + b * h12, a * h21 + b * h22
    p21, p22 = b * h11 + c * h12, b * h21 + c * h22
    S11 = h11 * p11 + h12 * p21 + qr
    S12 = h11 * p12 + h12 * p22
    S22 = h21 * p12 + h22 * p22 + qb
    return _ObsTerms(nu_r, nu_b, h11, h12, h21, h22, p11, p12, p21, p22, S11, S12, S22)


def _components(mu: np.ndarray, sig: np.ndarray) -> tuple:
    """``(mx, my, a, b, c)`` of landmark means ``mu (..., 2)`` and covariances ``sig (..., 2, 2) = [[a, b], [b, c]]``
    (views)."""
    return mu[..., 0], mu[..., 1], sig[..., 0, 0], sig[..., 0, 1], sig[..., 1, 1]


def _row_sums(a: np.ndarray) -> np.ndarray:
    """``a.sum(axis=1)`` of a ``(P, k)`` array as ``k − 1`` column additions (the same left-to-right order):
    numpy's reduction over a short inner axis costs ≈ 13 µs at ``(1000, 2)``, the additions ≈ 2 µs."""
    out = a[:, 0].copy()
    for j in range(1, a.shape[1]):
        out += a[:, j]
    return out


def _inv_sym2(S11, S12, S22):
    """``S⁻¹`` components ``(i11, i12, i22)`` and ``det S`` of symmetric 2×2 matrices."""
    det = S11 * S22 - S12 * S12
    return S22 / det, -S12 / det, S11 / det, det


def _maha(nu_r, nu_b, i11, i12, i22):
    """Normalised innovation squared ``νᵀS⁻¹ν`` (NIS, χ²(2) for a consistent filter)."""
    return i11 * nu_r * nu_r + 2.0 * i12 * nu_r * nu_b + i22 * nu_b * nu_b


def _loglik(nu_r, nu_b, i11, i12, i22, det):
    """``log N(ν; 0, S) = −½ νᵀS⁻¹ν − log 2π − ½ log det S``."""
    return -0.5 * _maha(nu_r, nu_b, i11, i12, i22) - LOG_2PI - 0.5 * np.log(det)


def _ekf_terms(o: _ObsTerms, mx, my, a, b, c, with_ll: bool = True):
    """Landmark EKF update from :class:`_ObsTerms` (eqs. 14.22-14.24, 14.28).

    ``K = Σ H_mᵀ S⁻¹``, ``μ' = μ + K ν``, ``Σ' = Σ − K S Kᵀ = Σ − K (Σ H_mᵀ)ᵀ`` (the symmetric form of
    ``(I − K H) Σ``); returns ``(mx', my', a', b', c', log N(ν; 0, S), νᵀS⁻¹ν)`` (the last two ``None``
    unless ``with_ll``: FastSLAM 2.0 weights by the proposal's predictive likelihood instead).
    """
    i11, i12, i22, det = _inv_sym2(o.S11, o.S12, o.S22)
    K11 = o.p11 * i11 + o.p12 * i12
    K12 = o.p11 * i12 + o.p12 * i22
    K21 = o.p21 * i11 + o.p22 * i12
    K22 = o.p21 * i12 + o.p22 * i22
    mx_n = mx + K11 * o.nu_r + K12 * o.nu_b
    my_n = my + K21 * o.nu_r + K22 * o.nu_b
    a_n = a - (K11 * o.p11 + K12 * o.p12)
    b_n = b - (K11 * o.p21 + K12 * o.p22)
    c_n = c - (K21 * o.p21 + K22 * o.p22)
    if not with_ll:
        return mx_n, my_n, a_n, b_n, c_n, None, None
    maha = _maha(o.nu_r, o.nu_b, i11, i12, i22)
    return mx_n, my_n, a_n, b_n, c_n, -0.5 * maha - LOG_2PI - 0.5 * np.log(det), maha


def _proposal_terms(o: _ObsTerms, Sx):
    """FastSLAM 2.0 pose-proposal terms for pose covariance ``Sx (3, 3, ...)``.

    ``U = Σ_x H_xᵀ (3, 2, ...)`` and the predictive covariance ``S = H_x Σ_x H_xᵀ + H_m Σ_m H_mᵀ + R``.
    Returns ``(U, S11, S12, S22)``.
    """
    U = np.empty((3, 2) + np.broadcast_shapes(Sx.shape[2:], o.h11.shape))
    U[:, 0] = -(Sx[:, 0] * o.h11 + Sx[:, 1] * o.h12)  # H_x row 0 = [−h11, −h12, 0]
    U[:, 1] = -(Sx[:, 0] * o.h21 + Sx[:, 1] * o.h22 + Sx[:, 2])  # H_x row 1 = [−h21, −h22, −1]
    S11 = o.S11 - (o.h11 * U[0, 0] + o.h12 * U[1, 0])
    S12 = o.S12 - (o.h11 * U[0, 1] + o.h12 * U[1, 1])
    S22 = o.S22 - (o.h21 * U[0, 1] + o.h22 * U[1, 1] + U[2, 1])
    return U, S11, S12, S22


def _shift_terms(o: _ObsTerms, dx: np.ndarray) -> _ObsTerms:
    """Terms of :func:`_obs_terms` moved from the linearisation pose ``x_lin`` to ``x = x_lin + dx``
    (``dx (P, 3)``, heading difference wrapped here) to first order: ``ν(x) = ν(x_lin) − H_x dx`` with
    ``H_x = [[−h11, −h12, 0], [−h21, −h22, −1]]``; ``H_m``, ``Σ H_mᵀ`` and ``H_m Σ H_mᵀ + R`` are kept.

    FastSLAM 2.0 samples ``x`` from a proposal whose spread is ~σ of the measurement, so the neglected
    second-order terms (``|dx|² / r``) are far below the sensor noise; the landmark update then costs no
    ``sqrt``/``arctan2`` — the proposal's linearisation is reused (Montemerlo et al. 2003 use one
    linearisation for proposal, landmark update and weight).
    """
    dth = wrap_angle(dx[:, 2])
    nu_r = o.nu_r + o.h11 * dx[:, 0] + o.h12 * dx[:, 1]
    nu_b = o.nu_b + o.h21 * dx[:, 0] + o.h22 * dx[:, 1] + dth
    return dataclasses.replace(o, nu_r=nu_r, nu_b=nu_b)


def _mT(A: np.ndarray) -> np.ndarray:
    return np.swapaxes(A, -1, -2)


def landmark_ekf_update(x, mu, sig, z, obs_cov):
    """One landmark EKF measurement update per particle (paper 002 eqs. 14.21-14.24, 14.28-14.29).

    Parameters
    ----------
    x : ndarray (..., 3)      particle poses.
    mu : ndarray (..., 2)     landmark means before the update.
    sig : ndarray (..., 2, 2) landmark covariances before the update (symmetric).
    z : ndarray (2,)          measurement [range, bearing].
    obs_cov : ndarray (2, 2)  measurement noise covariance (diagonal; ``R`` in the kernels).

    Returns
    -------
    mu_new : ndarray (..., 2)       ``μ + K ν``, ``ν = z − h(x, μ)`` with the bearing wrapped.
    sig_new : ndarray (..., 2, 2)   ``(I − K H) Σ``.
    log_lik : ndarray (...)         ``log N(ν; 0, H Σ Hᵀ + R)`` — the FastSLAM 1.0 importance weight.
    """
    R = obs_cov  # R: the measurement covariance (Q: the motion covariance)
    x = np.asarray(x, float)
    mu = np.asarray(mu, float)
    sig = np.asarray(sig, float)
    comps = _components(mu, sig)
    o = _obs_terms(x[..., 0], x[..., 1], x[..., 2], *comps, z[0], z[1], R[0, 0], R[1, 1])
    mx, my, a, b, c, ll, _ = _ekf_terms(o, *comps)
    sig_new = np.stack([np.stack([a, b], -1), np.stack([b, c], -1)], -2)
    return np.stack([mx, my], -1), sig_new, ll


def _init_terms(x, y, th, zr, zb, qr, qb):
    """Landmark initialisation ``μ = h⁻¹(x, z)``, ``Σ = M_z R M_zᵀ`` as components ``(mx, my, a, b, c)``;
    ``M_z = [[cos φ, −r sin φ], [sin φ, r cos φ]]``, ``φ = θ + b`` (the pose is given within a particle)."""
    phi = th + zb
    cp, sp = np.cos(phi), np.sin(phi)
    r2qb = zr * zr * qb
    return (
        x + zr * cp,
        y + zr * sp,
        cp * cp * qr + sp * sp * r2qb,
        cp * sp * (qr - r2qb),
        sp * sp * qr + cp * cp * r2qb,
    )


def init_landmark(x, z, obs_cov):
    """Initialise landmark Gaussians from poses ``x (..., 3)`` and one measurement ``z (2,)``:
    ``μ = h⁻¹(x, z)``, ``Σ = M_z R M_zᵀ`` with ``R = obs_cov (2, 2)``. Returns ``mu (..., 2)``,
    ``sig (..., 2, 2)``."""
    R = obs_cov  # R: the measurement covariance
    x = np.asarray(x, float)
    mx, my, a, b, c = _init_terms(x[..., 0], x[..., 1], x[..., 2], z[0], z[1], R[0, 0], R[1, 1])
    return np.stack([mx, my], -1), np.stack([np.stack([a, b], -1), np.stack([b, c], -1)], -2)


def sample_pose(mean: np.ndarray, Sx: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """Draw ``x ~ N(mean (P, 3), Sx (3, 3, P))``; ``Sx`` may be singular (PSD).

    Component-wise Cholesky ``Sx = L Lᵀ`` in which a (numerically) zero pivot zeroes its column — exact for
    PSD matrices, so the rank-2 motion noise of the DDMR model (no lateral slip) is sampled correctly.
    """
    tiny = 1e-12

    def piv(v, scale):
        return np.sqrt(np.where(v > tiny * scale, v, 0.0))

    def div(n, d):
        return np.where(d > 0.0, n / np.where(d > 0.0, d, 1.0), 0.0)

    s00, s01, s02, s11, s12, s22 = Sx[0, 0], Sx[0, 1], Sx[0, 2], Sx[1, 1], Sx[1, 2], Sx[2, 2]
    L00 = piv(s00, s00)
    L10, L20 = div(s01, L00), div(s02, L00)
    L11 = piv(s11 - L10 * L10, s11)
    L21 = div(s12 - L20 * L10, L11)
    L22 = piv(s22 - L20 * L20 - L21 * L21, s22)
    e = rng.standard_normal((3, mean.shape[0]))
    out = mean.copy()
    out[:, 0] += L00 * e[0]
    out[:, 1] += L10 * e[0] + L11 * e[1]
    out[:, 2] = wrap_angle(out[:, 2] + L20 * e[0] + L21 * e[1] + L22 * e[2])
    return out


def _predict_controls(x, u, dt, std_v, std_w, Q):
    """FastSLAM 2.0 prior from the controls in one pass: ``x̂ = g(x, u)`` (:func:`ddmr_step`, Euler DDMR) and
    ``Q = G_u diag(σ_v², σ_ω²) G_uᵀ`` written into the nonzero entries of the buffer ``Q (3, 3, P)`` (its
    other entries must be 0); ``cos θ``, ``sin θ`` computed once for both."""
    th = x[:, 2]
    c, s = np.cos(th), np.sin(th)
    x_hat = np.empty_like(x)
    dv = dt * u[0]
    x_hat[:, 0] = x[:, 0] + dv * c
    x_hat[:, 1] = x[:, 1] + dv * s
    x_hat[:, 2] = wrap_angle(th + dt * u[1])
    kv = (dt * std_v) ** 2
    np.multiply(c * c, kv, out=Q[0, 0])
    np.multiply(s * s, kv, out=Q[1, 1])
    np.multiply(c * s, kv, out=Q[0, 1])
    Q[1, 0] = Q[0, 1]
    Q[2, 2] = (dt * std_w) ** 2
    return x_hat, Q


def _predict_ackermann(x, u, dt, vehicle, M_std, version, rng, Q):
    """Ackermann prior (:mod:`slamcli.models.ackermann`): 1.0 samples ``g(x, u + ε)``, ε ~ N(0, diag(M_std²));
    2.0 returns ``x̂ = g(x, u)`` and ``Q = G_u diag(M_std²) G_uᵀ`` as ``(3, 3, P)`` in the buffer ``Q``."""
    P = x.shape[0]
    if version == 1:
        return ackermann_step(x, u + M_std * rng.standard_normal((P, 2)), dt, vehicle), None
    _, G_u = ackermann_jacobians(x, u, dt, vehicle)  # (P, 3, 2)
    Q[...] = np.einsum("pij,j,pkj->ikp", G_u, np.square(M_std), G_u)
    return ackermann_step(x, u, dt, vehicle), Q


def _motion_cov_odometry(th, std):
    """``Q = J diag(σ_x², σ_y², σ_θ²) Jᵀ`` as ``(3, 3, P)``, ``J = ∂(x ⊕ d)/∂d = blkdiag(R(θ), 1)``."""
    c, s = np.cos(th), np.sin(th)
    vx, vy = std[0] ** 2, std[1] ** 2
    Q = np.zeros((3, 3, th.shape[0]))
    Q[0, 0], Q[1, 1], Q[2, 2] = c * c * vx + s * s * vy, s * s * vx + c * c * vy, std[2] ** 2
    Q[0, 1] = Q[1, 0] = c * s * (vx - vy)
    return Q


# ---------------------------------------------------------------------------------------------------------
# The solver
# ---------------------------------------------------------------------------------------------------------
class FastSlam(BaseSolver):
    """FastSLAM 1.0 / 2.0 with known or maximum-likelihood correspondences (see the module docstring).

    A one-pass filter: ``solve`` ignores ``init`` (there is nothing to warm-start) and always ends COMPLETED;
    every random draw (motion noise, proposal samples, resampling) comes from ``rng``. ``solve`` keeps no
    per-run state on the solver (it lives in a :class:`_Run`), so one instance may serve concurrent runs.
    """

    name = "fastslam"
    Params = FastSlamParams
    #: ackermann: proposal from slamcli.models.ackermann (controls) or the odometry increments
    motion_models = ("ddmr", "ackermann")

    def solve(
        self,
        inputs: SlamInputs,
        *,
        init: SolverResult | None = None,
        rng: np.random.Generator,
        progress: ProgressFn | None = None,
    ) -> SolverResult:
        """Filter every step of ``inputs``.

        Parameters
        ----------
        inputs : SlamInputs
            ``controls (T, 2)`` or ``odometry_xyt (T+1, 3)`` (``motion_source``), ``observations`` (N rows,
            ``offsets (T+2,)``), ``noise`` (``obs_cov (2, 2)``, ``motion_std (2,)`` / ``odometry_std (3,)``).
        init : ignored (a one-pass filter).
        rng : numpy.random.Generator
            The only source of randomness.
        progress : callable ``(done, total)`` or None.

        Returns
        -------
        SolverResult
            ``poses_xyt (T+1, 3)``, ``landmarks_xy (L, 2)``, ``assoc (N,)``, ``pose_cov (T+1, 3, 3)``,
            ``landmark_cov (L, 2, 2)``, ``extra`` (see the module docstring).
        """
        t_start = time.perf_counter()
        run = _Run(_setup(inputs, self.params), inputs, rng)
        T1 = inputs.n_poses
        every = max(1, T1 // 100)
        for t in range(T1):
            run.step(t)
            if progress is not None and (t % every == 0 or t == T1 - 1):
                progress(t + 1, T1)
        return self.make_result(status=Status.COMPLETED, t_start=t_start, **run.outputs())


@dataclasses.dataclass(frozen=True)
class _Setup:
    """What one run needs besides the data, resolved from the parameters and checked once.

    Attributes
    ----------
    p : FastSlamParams            with ``association`` resolved (never "auto").
    slot_of_obs : ndarray (N,) | None   known association: landmark slot of every row (−1 = no id).
    capacity : int                initial landmark slots.
    log_p0 : float                ML new-landmark log-likelihood.
    obs_cov : ndarray (2, 2)      measurement covariance (``R`` in the kernels).
    motion_std : ndarray (2,) | (3,)  scaled σ of the controls or of the odometry increment.
    increments : ndarray (T, 3) | None  odometry increments (``motion_source="odometry"``).
    rho : ndarray (N,) | None     declared landmark radius per row when the size gate applies (``ml``,
                                  ``size_gate``, sizes declared), else None.
    """

    p: FastSlamParams
    slot_of_obs: np.ndarray | None
    capacity: int
    log_p0: float
    obs_cov: np.ndarray
    motion_std: np.ndarray
    increments: np.ndarray | None
    rho: np.ndarray | None = None


def _setup(inputs: SlamInputs, p: FastSlamParams) -> _Setup:
    """Resolve the correspondences and the motion model; one-line :class:`SolverError` on unusable input."""
    obs = inputs.observations
    T1 = inputs.n_poses
    obs_cov = inputs.noise.obs_cov
    if len(obs.offsets) != T1 + 1:
        raise SolverError(f"observations.offsets: length {len(obs.offsets)}, expected n_poses+1 = {T1 + 1}")
    if p.association == "auto":
        from slamcli.solvers.frontend import resolve_association

        p = dataclasses.replace(p, association=resolve_association(p.association, obs.reported_id))
    if p.motion_source == "auto":
        from slamcli.solvers.frontend import resolve_motion_input

        p = dataclasses.replace(p, motion_source=resolve_motion_input(p.motion_source, inputs))
    slot_of_obs, capacity = None, 16
    if p.association == "known":
        rid = np.asarray(obs.reported_id, np.int64)
        ids = np.unique(rid[rid >= 0])
        if len(obs) > 0 and ids.size == 0:
            raise SolverError(
                "observations.reported_id: no sensor-reported landmark ids (all -1); use association=ml "
                "or solve with --oracle-association"
            )
        slot_of_obs = np.where(rid >= 0, np.searchsorted(ids, rid), -1)
        capacity = ids.size
    log_p0 = (
        math.log(p.p0)
        if p.p0 is not None
        else -0.5 * CHI2_2DOF_9999 - LOG_2PI - 0.5 * math.log(float(np.linalg.det(obs_cov)))
    )
    if p.motion_source == "controls":
        if inputs.controls.shape[0] < T1 - 1:
            raise SolverError(f"controls: {inputs.controls.shape[0]} rows, need {T1 - 1} for motion_source=controls")
        motion_std = np.asarray(inputs.noise.motion_std, float) * p.motion_noise_scale
        increments = None
    else:
        motion_std = np.asarray(inputs.noise.odometry_std, float) * p.motion_noise_scale
        increments = se2.between(inputs.odometry_xyt[:-1], inputs.odometry_xyt[1:])
    rho = declared_radius(inputs) if p.size_gate and p.association == "ml" else None
    return _Setup(p, slot_of_obs, capacity, log_p0, obs_cov, motion_std, increments, rho)


def _known_detections(obs, z_all: np.ndarray, slot_of_obs: np.ndarray, group: bool):
    """Every step's detections under known association, built once: ``(z (D, 2), slot (D,), offsets (T+2,))``,
    detections of step ``t`` = ``offsets[t]:offsets[t+1]``, slot −1 for rows without an id.

    Grouping by (sensor, reported id) does not depend on the state, so the detections equal
    :func:`slamcli.solvers.frontend.group_detections` called step by step; steps that report one row per
    landmark (every step of a point sensor) keep their rows as they are, the others go through that function.
    """
    off = np.asarray(obs.offsets, np.int64)
    if not group or len(obs) == 0:
        return z_all, slot_of_obs, off
    step, rid = np.asarray(obs.step, np.int64), np.asarray(obs.reported_id, np.int64)
    key = np.asarray(obs.sensor, np.int64) * (int(rid.max()) + 2) + rid
    order = np.lexsort((key, step))  # rows with an id, sorted by (step, key): repeats are neighbours
    order = order[rid[order] >= 0]
    rep = (step[order][1:] == step[order][:-1]) & (key[order][1:] == key[order][:-1])
    merge_steps = np.unique(step[order][1:][rep])
    if merge_steps.size == 0:
        return z_all, slot_of_obs, off
    z_parts, s_parts, counts = [], [], np.diff(off)
    done = 0
    for t in merge_steps.tolist():
        lo, hi = int(off[t]), int(off[t + 1])
        z_parts += [z_all[done:lo]]
        s_parts += [slot_of_obs[done:lo]]
        dets = group_detections(z_all, obs.sensor, rid, lo, hi, None, group=True, association="known",
                                group_dist=0.0)
        z_parts += [np.array([zd for zd, _ in dets]).reshape(-1, 2)]
        s_parts += [slot_of_obs[[int(g[0]) for _, g in dets]]]
        counts[t] = len(dets)
        done = hi
    z_parts += [z_all[done:]]
    s_parts += [slot_of_obs[done:]]
    offsets = np.concatenate([[0], np.cumsum(counts)])
    return np.concatenate(z_parts), np.concatenate(s_parts), offsets


class _Run:
    """The state of one :meth:`FastSlam.solve` call: particles, records and counters (re-entrancy: nothing
    of a run lives on the solver). ``step(t)`` advances one step, ``outputs()`` builds the result fields."""

    def __init__(self, setup: _Setup, inputs: SlamInputs, rng: np.random.Generator) -> None:
        p = setup.p
        self.setup, self.p, self.inputs, self.rng = setup, p, inputs, rng
        self._R = setup.obs_cov  # R: the measurement covariance in the kernels
        self._log_p0 = setup.log_p0
        self.known = p.association == "known"
        T1, P, N = inputs.n_poses, p.n_particles, len(inputs.observations)
        check_allocation("n_particles", P, 2.0 * P * (max(setup.capacity, 1) * 53 + 40),
                         "the particle maps (×2 for resampling)")
        self.ps = ParticleSet.create(inputs.x0, P, setup.capacity)
        self.resample = RESAMPLERS[p.resampling]
        self.mean_xyt = np.empty((T1, 3))
        self.pose_cov = np.zeros((T1, 3, 3))
        # anc[t][j]: the pre-resampling particle at t that post-resampling particle j copies
        self.anc = np.empty((T1, P), np.int32)
        self.pose_hist = np.empty((T1, P, 3)) if p.output == "best" else None
        self._z = inputs.observations.z  # (N, 2), built once (``Observations.z`` stacks on every access)
        # Known association: the detections do not depend on the state, so all of them are built once.
        self._dets = _known_detections(inputs.observations, self._z, setup.slot_of_obs, p.group_returns) \
            if self.known else None
        # Slot of every observation: with known association its reported id's, shared by all particles (N,) (the
        # size gate, which could unmap one, is ML-only); with ML association per particle (N, P), filled step by
        # step (pre-resampling; traced back through ``anc`` for the best particle).
        self.assoc_hist = setup.slot_of_obs.astype(np.int32) if self.known else np.full((N, P), -1, np.int32)
        self.Q_buf = np.zeros((3, 3, P))  # 2.0 motion covariance, rewritten each step (the proposal copies it)
        self.n_updates = self.n_resample = 0
        self.ess_sum = self._nis_sum = 0.0
        self._nis_n = 0
        self._sep: np.ndarray | None = None  # size gate: 2ρ per detection of the current step, or None
        self._gated: list[tuple[np.ndarray, np.ndarray]] = []  # (particles, slots) born inside a declared size
        self.n_size_gated = 0

    # ---- one step --------------------------------------------------------------------------------------
    def _prior(self, t: int):
        """Proposal prior of step ``t``: sampled poses (1.0, ``Q = None``) or ``x̂`` and ``Q (3, 3, P)`` (2.0)."""
        ps, p, inputs, rng, M_std = self.ps, self.p, self.inputs, self.rng, self.setup.motion_std
        P = ps.n_particles
        if t == 0:
            return ps.x.copy(), None
        if p.motion_source == "controls":
            u = inputs.controls[t - 1]
            if inputs.motion_model == "ackermann":  # car model of the tracked point, u = [v_e, α]
                return _predict_ackermann(ps.x, u, inputs.dt, inputs.vehicle, M_std, p.version, rng, self.Q_buf)
            if p.version == 1:  # eq. 14.18: x_t ~ p(x_t | x_{t-1}, u_t) with u + ε, ε ~ N(0, M)
                return ddmr_step(ps.x, u + M_std * rng.standard_normal((P, 2)), inputs.dt), None
            return _predict_controls(ps.x, u, inputs.dt, M_std[0], M_std[1], self.Q_buf)
        d = self.setup.increments[t - 1]
        if p.version == 1:  # x_t = x_{t-1} ⊕ (d + ε), ε ~ N(0, diag(odometry_std²))
            return se2.compose(ps.x, d + M_std * rng.standard_normal((P, 3))), None
        return se2.compose(ps.x, d), _motion_cov_odometry(ps.x[:, 2], M_std)

    def step(self, t: int) -> None:
        """Prior → measurement (1.0 / 2.0) → negative evidence → estimate → resampling, for step ``t``."""
        p, inputs = self.p, self.inputs
        z_all, slot_of_obs, groups = self._detections(t)
        x_hat, Q = self._prior(t)
        rows = range(len(z_all))  # detection k: measurement z_all[k], observation rows groups[k]
        # NaN from unused slots of particles that start a new landmark is masked out with np.where.
        with np.errstate(divide="ignore", invalid="ignore"):
            if Q is None:  # FastSLAM 1.0, or step 0 (x0 known)
                self.ps.x = x_hat
                step_slots, _ = self._measure_v1(self.ps, z_all, rows, slot_of_obs)
            else:
                step_slots, step_new, lin = self._proposal_v2(self.ps, x_hat, Q, z_all, rows, slot_of_obs, self.rng)
                # ---- landmark EKFs at the sampled pose ----------------------------------------------------
                for i, n in enumerate(rows):
                    if step_slots[i] is not None:
                        terms = None if lin[i] is None else _shift_terms(lin[i][1], self.ps.x - lin[i][0])
                        self._update_or_init(self.ps, step_slots[i], step_new[i], z_all[n], weight=False, terms=terms)
        if self._gated:
            step_slots = self._drop_gated(step_slots)
        if groups is None:  # known association: assoc_hist holds every row's slot already
            self.n_updates += self.ps.n_particles * int(np.count_nonzero(slot_of_obs >= 0))
        for i, g in enumerate(groups or ()):
            if step_slots[i] is not None:
                self.assoc_hist[g] = step_slots[i]
                self.n_updates += self.ps.n_particles
        if not self.known and p.remove_unsupported and len(rows) > 0:  # negative evidence (§14.4.2)
            self._negative_evidence(self.ps, step_slots, inputs.max_range)
        self._estimate_and_resample(t)

    def _detections(self, t: int):
        """Step ``t``'s detections: measurements ``z (k, 2)``, their slots ``(k,)`` (known association, else
        None) and observation rows ``[rows (m,) int64] * k`` — one row each, or merged returns
        (``group_returns``); the rows are None with known association (:func:`_known_detections`)."""
        if self._dets is not None:
            z, slots, offsets = self._dets
            a, b = offsets[t], offsets[t + 1]
            return z[a:b], slots[a:b], None
        obs, p = self.inputs.observations, self.p
        lo, hi = int(obs.offsets[t]), int(obs.offsets[t + 1])
        if not p.group_returns or hi - lo < 2:
            groups = [np.array([n], np.int64) for n in range(lo, hi)]
            z = self._z[lo:hi]
        else:
            x_r = self.mean_xyt[t - 1] if t > 0 else np.asarray(self.inputs.x0, float)
            dets = group_detections(self._z, np.asarray(obs.sensor), np.asarray(obs.reported_id), lo, hi, x_r,
                                    group=True, association=p.association, group_dist=p.group_dist)
            groups = [g for _, g in dets]
            z = np.array([zd for zd, _ in dets]).reshape(-1, 2)
        rho = self.setup.rho
        self._sep = None if rho is None else np.array([2.0 * float(rho[g].max()) for g in groups])
        return z, None, groups

    def _estimate_and_resample(self, t: int) -> None:
        """Weighted estimate at ``t`` (weights before resampling, EVALUATION-METHOD §A2); then resample if the
        ESS is low — never on the last step, so the final weights still rank the particles."""
        ps, T = self.ps, self.inputs.n_poses - 1
        w = normalise_log_weights(ps.log_w)
        m = self.mean_xyt[t]
        m[:2] = w @ ps.x[:, :2]
        m[2] = circular_mean(ps.x[:, 2], w)
        e = ps.x - m
        e[:, 2] = wrap_angle(e[:, 2])
        self.pose_cov[t] = (w[:, None] * e).T @ e
        if self.pose_hist is not None:
            self.pose_hist[t] = ps.x
        ess = effective_sample_size(w)
        self.ess_sum += ess
        if t < T and ess < self.p.resample_threshold * ps.n_particles:
            idx = self.resample(w, self.rng)
            self.ps = ps.take(idx)
            self.anc[t] = idx
            self.n_resample += 1
        else:
            self.anc[t] = np.arange(ps.n_particles)

    # ---- result ----------------------------------------------------------------------------------------
    def outputs(self) -> dict:
        """Result fields: the best final particle traced back through ``anc`` for paths / ML associations."""
        ps, p, known = self.ps, self.p, self.known
        T1 = self.inputs.n_poses
        N = len(self.inputs.observations)
        w = normalise_log_weights(ps.log_w)
        best = int(np.argmax(w))
        # Trace the best final particle back: its index at t (pre-resampling) → post-resampling index at t-1.
        lineage = np.empty(T1, np.int64)
        j = best
        for t in range(T1 - 1, -1, -1):
            lineage[t] = j
            if t > 0:
                j = int(self.anc[t - 1][j])
        obs_step = np.asarray(self.inputs.observations.step, np.int64)
        if known or N == 0:
            assoc_slots = self.assoc_hist.reshape(N, -1)[:, 0] if N else np.zeros(0, np.int64)
        else:
            assoc_slots = self.assoc_hist[np.arange(N), lineage[obs_step]]
        poses = self.pose_hist[np.arange(T1), lineage] if self.pose_hist is not None else self.mean_xyt
        live = ps.exists[best] & ~ps.hidden[best]
        if known:
            lm_xy, lm_cov = moment_matched_landmarks(ps.mu[:, live], ps.sig[:, live], w)
        else:
            lm_xy, lm_cov = ps.mu[best, live], ps.sig[best, live]
        row_of_slot = np.cumsum(live) - 1
        alive = (assoc_slots >= 0) & live[np.clip(assoc_slots, 0, None)]
        assoc = np.where(alive, row_of_slot[np.clip(assoc_slots, 0, None)], -1)
        extra = {
            "association": p.association,
            "motion_input": p.motion_source,
            "version": int(p.version),
            "n_resamples": self.n_resample,
            "n_size_gated": int(self.n_size_gated),
            "mean_ess": self.ess_sum / T1,
            "particle_landmark_updates": int(self.n_updates),
            "best_particle_weight": float(w[best]),
            "mean_nis": self._nis_sum / self._nis_n if self._nis_n else float("nan"),
            "landmark_cov_kind": "moment_matched" if known else "best_particle",
        }
        message = (f"FastSLAM {p.version}.0, {ps.n_particles} particles, {self.n_resample} resamplings, "
                   f"{len(lm_xy)} landmarks")
        return {"poses_xyt": poses, "landmarks_xy": lm_xy, "assoc": assoc, "message": message,
                "pose_cov": self.pose_cov, "landmark_cov": lm_cov, "extra": extra}

    # -----------------------------------------------------------------------------------------------------
    @staticmethod
    def _index(ps: ParticleSet, slots):
        """Index tuple selecting one landmark slot per particle: a basic slice for a shared slot (known
        association: views, no copies) or ``(arange(P), slots)`` fancy indexing."""
        if isinstance(slots, (int, np.integer)):
            return (slice(None), int(slots))
        return (np.arange(ps.n_particles), slots)

    def _gather_terms(self, ps: ParticleSet, idx, x, z):
        R = self._R
        comps = _components(ps.mu[idx], ps.sig[idx])
        o = _obs_terms(x[:, 0], x[:, 1], x[:, 2], *comps, z[0], z[1], R[0, 0], R[1, 1])
        return o, comps

    def _ml_candidates(self, ps: ParticleSet, x, Sx, z):
        """Per-particle log-likelihood ``(P, C)`` of measurement ``z`` for every live landmark (eq. 14.30),
        with predictive covariance ``H_m Σ H_mᵀ + R`` (+ ``H_x Σ_x H_xᵀ`` for the 2.0 proposal)."""
        live = ps.exists
        R = self._R
        xb = x[:, None, :]
        o = _obs_terms(xb[..., 0], xb[..., 1], xb[..., 2], *_components(ps.mu, ps.sig), z[0], z[1], R[0, 0], R[1, 1])
        S11, S12, S22 = o.S11, o.S12, o.S22
        if Sx is not None:
            _, S11, S12, S22 = _proposal_terms(o, Sx[..., None])
        i11, i12, i22, det = _inv_sym2(S11, S12, S22)
        ll = _loglik(o.nu_r, o.nu_b, i11, i12, i22, det)
        return np.where(live & np.isfinite(ll), ll, -np.inf)

    def _associate(self, ps: ParticleSet, n: int, slot_of_obs, x, Sx, z):
        """Slot(s) and new-landmark mask ``(P,)`` for observation row ``n``; allocates ML slots.

        Returns ``(slots, new)``: ``slots`` is an int (known association, shared by all particles), a
        ``(P,)`` array (ML), or ``None`` when the row is not used (no reported id)."""
        if slot_of_obs is not None:
            s = int(slot_of_obs[n])
            if s < 0:
                return None, None
            return s, ~ps.exists[:, s]
        ll = self._ml_candidates(ps, x, Sx, z)
        j = np.argmax(ll, axis=1)
        new = ~(ll[np.arange(ps.n_particles), j] >= self._log_p0)
        if new.any():
            gated = new & self._inside_size(ps, n, x, z)
            ps.ensure_capacity(int(ps.n_slots.max()) + 1)
            j = np.where(new, ps.n_slots, j)
            ps.n_slots = ps.n_slots + new
            if gated.any() and self.p.size_gate_hide:  # born as usual, never reported
                ps.hidden[gated, j[gated]] = True
            elif gated.any():  # born as usual (weight p0), removed at the end of the step (:meth:`_drop_gated`)
                self._gated.append((np.flatnonzero(gated), j[gated]))
            self.n_size_gated += int(np.count_nonzero(gated))
        return j, new

    def _inside_size(self, ps: ParticleSet, n: int, x, z) -> np.ndarray:
        """Size gate ``(P,)``: particles whose map has a live landmark within 2ρ of detection ``n``'s point
        ``h⁻¹(x^[k], z)`` (all False without the gate)."""
        if self._sep is None:
            return np.zeros(ps.n_particles, bool)
        pts = inverse_range_bearing(x, np.broadcast_to(z, (ps.n_particles, 2)))
        return inside_declared_size(ps.mu, pts, float(self._sep[n]), live=ps.exists)

    def _drop_gated(self, step_slots) -> list:
        """Remove the landmarks the size gate marked this step (their rows stay unassociated in those particles)
        and give their slots back; returns ``step_slots`` with −1 for the gated (particle, detection) pairs."""
        ps = self.ps
        n0 = ps.n_slots.copy()
        for k, s in self._gated:
            ps.exists[k, s] = False
            n0[k] = np.minimum(n0[k], s)  # lowest gated slot per particle (slots of one step only grow)
        self._gated = []
        ar = np.arange(ps.n_particles)
        out = [s if s is None or np.ndim(s) == 0 else np.where(ps.exists[ar, s], s, -1) for s in step_slots]
        # a slot is reused only when no live landmark was born after it in this step
        top = np.where(ps.exists, np.arange(ps.capacity), -1).max(axis=1) + 1
        ps.n_slots = np.where(n0 < ps.n_slots, np.maximum(n0, top), ps.n_slots)
        return out

    def _update_or_init(
        self, ps: ParticleSet, slots, new, z, *, weight: bool, terms: _ObsTerms | None = None
    ):
        """EKF-update existing landmarks / initialise new ones in ``slots``; optionally add the 1.0 weight
        ``log N(ν; 0, S_n)`` (eq. 14.28) of the updated particles. ``terms``: the linearisation at the poses
        ``ps.x`` when the caller already has it (FastSLAM 2.0, :func:`_shift_terms`; then ``new`` is all
        False)."""
        idx = self._index(ps, slots)
        x = ps.x
        R = self._R
        any_new = bool(new.any())
        if terms is not None:
            comps = _components(ps.mu[idx], ps.sig[idx])
            mx, my, a, b, c, ll, _ = _ekf_terms(terms, *comps, with_ll=weight)
        elif not new.all():
            o, comps = self._gather_terms(ps, idx, x, z)
            mx, my, a, b, c, ll, nis = _ekf_terms(o, *comps)
            if weight:  # 1.0: NIS of the measurement update (pose given)
                self._nis_sum += float(np.sum(nis, where=~new))
                self._nis_n += int(np.count_nonzero(~new))
        else:
            mx = my = a = b = c = ll = None
        if any_new:
            init = _init_terms(x[:, 0], x[:, 1], x[:, 2], z[0], z[1], R[0, 0], R[1, 1])
            if mx is None:
                mx, my, a, b, c = init
            else:
                mx, my, a, b, c = (np.where(new, i, u) for i, u in zip(init, (mx, my, a, b, c)))
        ps.store(idx, mx, my, a, b, c)
        ps.count[idx] = np.where(new, 1, ps.count[idx] + 1)
        ps.exists[idx] = True
        if weight and ll is not None:
            ps.log_w += np.where(new, 0.0, ll)

    def _measure_v1(self, ps, z_all, rows, slot_of_obs):
        """FastSLAM 1.0 measurement step at the already-sampled poses ``ps.x``."""
        if slot_of_obs is not None:
            return self._measure_v1_known(ps, z_all, rows, slot_of_obs)
        slots_l, new_l = [], []
        for n in rows:
            z = z_all[n]
            slots, new = self._associate(ps, n, slot_of_obs, ps.x, None, z)
            slots_l.append(slots)
            new_l.append(new)
            if slots is None:
                continue
            self._update_or_init(ps, slots, new, z, weight=True)
            if slot_of_obs is None:
                ps.log_w += np.where(new, self._log_p0, 0.0)  # new-landmark likelihood p0
        return slots_l, new_l

    def _measure_v1_known(self, ps, z_all, rows: range, slot_of_obs):
        """FastSLAM 1.0 with known association, batched over particles AND the landmarks of the step.

        Given the sampled poses, rows of distinct landmarks are independent (each updates its own 2×2 EKF,
        eqs. 14.22-14.24, and adds its own ``log N(ν; 0, S_n)`` to the weight, eq. 14.28), so all of them are
        one update on ``(P, k)`` component arrays. A landmark seen again in the same step goes to the next
        round (rows in order), as in the row-by-row filter. Every particle has mapped the same landmarks (the
        ids are shared; nothing removes a landmark under known association), so particle 0's ``exists`` splits
        a round into updated and initialised columns. Returns ``(slots per row (int | None), [None…])``.
        """
        s = np.asarray(slot_of_obs)
        slots_l = [v if v >= 0 else None for v in s.tolist()]
        use = s >= 0
        z, s = z_all[use], s[use]
        k_max = max(1, BATCH_ELEMENTS // ps.n_particles)
        while s.size:
            if s.size <= k_max and len(set(s.tolist())) == s.size:  # the usual case: one round, no repeat
                now_s, now_z, s, z = s, z, s[:0], z[:0]
            else:
                _, first = np.unique(s, return_index=True)
                first = first[:k_max]
                later = np.ones(s.size, bool)
                later[first] = False
                now_s, now_z, s, z = s[first], z[first], s[later], z[later]
            mapped = ps.exists[0, now_s]  # (k,)
            if mapped.all():
                self._update_known(ps, now_s, now_z)
                continue
            if mapped.any():
                self._update_known(ps, now_s[mapped], now_z[mapped])
            self._init_known(ps, now_s[~mapped], now_z[~mapped])
        return slots_l, [None] * len(slots_l)

    def _update_known(self, ps: ParticleSet, slots: np.ndarray, z: np.ndarray) -> None:
        """Landmark EKFs of the distinct mapped ``slots (k,)`` with measurements ``z (k, 2)`` in every particle
        at once, on ``(P, k)`` component arrays; adds ``Σ_k log N(ν; 0, S_n)`` to the log-weights."""
        R, x = self._R, ps.x
        # np.take gathers whole slots (faster than ``mu[:, slots]`` here)
        comps = _components(np.take(ps.mu, slots, axis=1), np.take(ps.sig, slots, axis=1))  # (P, k) each
        o = _obs_terms(x[:, None, 0], x[:, None, 1], x[:, None, 2], *comps, z[:, 0], z[:, 1], R[0, 0], R[1, 1])
        mx, my, a, b, c, ll, nis = _ekf_terms(o, *comps)
        self._nis_sum += float(np.sum(nis))  # 1.0: NIS of the measurement update (pose given)
        self._nis_n += nis.size
        ps.store((slice(None), slots), mx, my, a, b, c)
        ps.log_w += _row_sums(ll)

    def _init_known(self, ps: ParticleSet, slots: np.ndarray, z: np.ndarray) -> None:
        """First sighting of ``slots (k,)``: ``μ = h⁻¹(x, z)``, ``Σ = M_z R M_zᵀ`` in every particle."""
        R, x = self._R, ps.x
        mx, my, a, b, c = _init_terms(x[:, None, 0], x[:, None, 1], x[:, None, 2], z[:, 0], z[:, 1], R[0, 0], R[1, 1])
        ps.store((slice(None), slots), mx, my, a, b, c)
        ps.exists[:, slots] = True

    def _proposal_v2(self, ps, x_hat, Sx, z_all, rows, slot_of_obs, rng):
        """FastSLAM 2.0: refine ``N(x̂, Σ_x)`` (``Σ_x (3, 3, P)``) with every observation of a mapped landmark,
        weight by the predictive likelihood, then SAMPLE the new poses into ``ps.x``."""
        P = ps.n_particles
        ar = np.arange(P)
        x_hat = x_hat.copy()
        Sx = Sx.copy()
        R = self._R
        slots_l, new_l = [], []
        # lin[i] = (x_lin (P, 3), terms at x_lin) when row i's landmark EKF can reuse the proposal's
        # linearisation (every particle updates an existing landmark no earlier row of this step touched).
        lin: list[tuple[np.ndarray, _ObsTerms] | None] = []
        touched = np.zeros_like(ps.exists)
        born_now = np.zeros_like(ps.exists)  # landmarks created this step carry no prior information yet
        for n in rows:
            z = z_all[n]
            slots, new = self._associate(ps, n, slot_of_obs, x_hat, Sx, z)
            slots_l.append(slots)
            new_l.append(new)
            lin.append(None)
            if slots is None:
                continue
            if touched.shape != ps.exists.shape:  # capacity grew
                touched = np.pad(touched, ((0, 0), (0, ps.capacity - touched.shape[1])))
            if born_now.shape != ps.exists.shape:  # capacity grew
                born_now = np.pad(born_now, ((0, 0), (0, ps.capacity - born_now.shape[1])))
            idx = self._index(ps, slots)
            upd = ~new & ~born_now[idx]
            if upd.any():
                o, _ = self._gather_terms(ps, idx, x_hat, z)
                if upd.all() and not touched[idx].any():
                    lin[-1] = (x_hat, o)
                touched[idx] = True
                U, S11, S12, S22 = _proposal_terms(o, Sx)
                i11, i12, i22, det = _inv_sym2(S11, S12, S22)
                K0 = U[:, 0] * i11 + U[:, 1] * i12  # K = U S⁻¹, (3, 2, P) as two columns
                K1 = U[:, 0] * i12 + U[:, 1] * i22
                dx = K0 * o.nu_r + K1 * o.nu_b  # (3, P)
                nis = _maha(o.nu_r, o.nu_b, i11, i12, i22)  # 2.0: NIS of the predictive (pose + map)
                ll = -0.5 * nis - LOG_2PI - 0.5 * np.log(det)
                self._nis_sum += float(np.sum(nis, where=upd))
                self._nis_n += int(np.count_nonzero(upd))
                # x̂ ← x̂ + K ν (heading wrapped once, after sampling: only cos/sin/ν use it here; a new array,
                # the old x̂ stays the linearisation point in ``lin``); Σ_x ← Σ_x − K Uᵀ = Σ_x − U S⁻¹ Uᵀ.
                if upd.all():
                    x_hat = x_hat + dx.T
                    Sx -= K0[:, None] * U[None, :, 0]  # in place: Sx is this call's own copy
                    Sx -= K1[:, None] * U[None, :, 1]
                    ps.log_w += ll
                else:
                    x_hat = np.where(upd[:, None], x_hat + dx.T, x_hat)
                    Sx_new = Sx - (K0[:, None] * U[None, :, 0] + K1[:, None] * U[None, :, 1])
                    Sx = np.where(upd, Sx_new, Sx)
                    ps.log_w += np.where(upd, ll, 0.0)
            if slot_of_obs is None:
                ps.log_w += np.where(new, self._log_p0, 0.0)  # new-landmark likelihood p0
            if new.any():
                # Provisional landmark at the proposal mean so later rows of this step can associate with it;
                # it is initialised from the sampled pose in the landmark pass.
                sel = ar[new]
                sn = np.broadcast_to(np.asarray(slots), (P,))[new]
                xs = x_hat[new]
                mx, my, a, b, c = _init_terms(xs[:, 0], xs[:, 1], xs[:, 2], z[0], z[1], R[0, 0], R[1, 1])
                ps.store((sel, sn), mx, my, a, b, c)
                ps.exists[sel, sn] = True
                born_now[sel, sn] = True
        ps.x = sample_pose(x_hat, Sx, rng)  # SAMPLE from the proposal, not its mean
        # Landmarks born this step are initialised in the landmark pass: the first row of each is "new".
        seen = np.zeros_like(born_now)
        for i, slots in enumerate(slots_l):
            if slots is None:
                continue
            idx = self._index(ps, slots)
            first = born_now[idx] & ~seen[idx]
            new_l[i] = first
            seen[idx] |= first
        return slots_l, new_l, lin

    def _negative_evidence(self, ps: ParticleSet, step_slots, max_range: float) -> None:
        """Decrement support of live landmarks predicted inside range/FOV but not observed; drop if < 0."""
        P = ps.n_particles
        ar = np.arange(P)
        observed = np.zeros_like(ps.exists)
        for slots in step_slots:
            if slots is not None:
                ok = np.asarray(slots) >= 0  # −1: no landmark in that particle (size gate)
                observed[ar[ok], np.broadcast_to(slots, (P,))[ok]] = True
        live = ps.exists
        safe_mu = np.where(live[..., None], ps.mu, ps.x[:, None, :2] + 1.0)
        zh = range_bearing(ps.x[:, None, :], safe_mu)
        rng_lim = self.p.removal_range_frac * max_range
        visible = live & (zh[..., 0] <= rng_lim) & (np.abs(zh[..., 1]) <= 0.5 * self.p.fov_rad)
        missed = visible & ~observed
        ps.count = ps.count - missed.astype(np.int32)
        ps.exists = live & ~(ps.count < 0)



def moment_matched_landmarks(mu: np.ndarray, sig: np.ndarray, w: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Moment-matched Gaussian of a weighted particle mixture of landmark estimates (EVALUATION-METHOD §A2).

    ``μ̄_j = Σ_i w_i μ_j^(i)``, ``Σ̄_j = Σ_i w_i [Σ_j^(i) + (μ_j^(i) − μ̄_j)(μ_j^(i) − μ̄_j)ᵀ]``.

    Parameters
    ----------
    mu : ndarray (P, L, 2); sig : ndarray (P, L, 2, 2); w : ndarray (P,) normalised weights.

    Returns
    -------
    mean : ndarray (L, 2); cov : ndarray (L, 2, 2)
    """
    mean = np.einsum("p,pli->li", w, mu)
    d = mu - mean
    cov = np.einsum("p,plij->lij", w, sig) + np.einsum("p,pli,plj->lij", w, d, d)
    return mean, cov
