"""FastSLAM 1.0 and 2.0: a Rao-Blackwellised particle filter over robot poses with one 2×2 EKF per landmark
per particle (paper 002 §14.3-14.5, Algorithm 1; paper 003 "FastSLAM" slides; Montemerlo et al. 2002/2003).

Posterior factorisation (paper 002, eq. 14.4)::

    p(x_{1:t}, m | z_{1:t}, u_{1:t}, c_{1:t}) = p(x_{1:t} | z, u, c) · Π_n p(m_n | x_{1:t}, z, c)

Each particle ``k`` carries a pose ``x^[k]`` and, for every landmark ``n``, a Gaussian ``(μ_n^[k], Σ_n^[k])``
(eq. 14.17). Everything is vectorised over particles: poses ``x (P, 3)``, landmark means ``mu (P, C, 2)``,
covariances ``sig (P, C, 2, 2)``, support counters ``count (P, C)`` and existence flags ``exists (P, C)``
(``C`` = slot capacity). The only Python loops are over time steps and over the observations of one step.

One step ``t`` (pose ``t-1`` → ``t``, observations ``z_{t,1..n}``):

**FastSLAM 1.0** (paper 002 §14.4.1)
  1. sample ``x_t^[k] ~ p(x_t | x_{t-1}^[k], u_t)`` (eq. 14.18; commanded controls + ``motion_std`` or
     odometry increments + ``odometry_std``);
  2. per observation: landmark EKF update (eqs. 14.21-14.24) and importance weight
     ``w ∝ N(z; ẑ, Q_n)``, ``Q_n = H_m Σ H_mᵀ + Q`` (eqs. 14.28-14.29); unseen landmarks are initialised
     with the inverse model ``μ = h⁻¹(x, z)``, ``Σ = M_z Q M_zᵀ``.

**FastSLAM 2.0** (Montemerlo et al., IJCAI 2003; Thrun et al., *Probabilistic Robotics* §13.4)
  1. Gaussian prior ``N(x̂, R)``: ``x̂ = g(x_{t-1}^[k], u_t)``, ``R = G_u M G_uᵀ`` (or ``J Σ_odo Jᵀ``);
  2. per observation associated with an already-mapped landmark, a Kalman update of the *pose* proposal::

         S = H_x Σ_x H_xᵀ + H_m Σ_m H_mᵀ + Q,   K = Σ_x H_xᵀ S⁻¹
         x̂ ← x̂ + K (z − h(x̂, μ)),             Σ_x ← (I − K H_x) Σ_x (I − K H_x)ᵀ + K Q_n Kᵀ

     and the importance weight is multiplied by the linearised predictive likelihood ``N(z; h(x̂, μ), S)``
     — the ratio target / proposal ``p(z_t | x_{t-1}^[k], u_t, m^[k])`` of the improved proposal;
  3. SAMPLE ``x_t^[k] ~ N(x̂, Σ_x)`` (not its mean), then update the landmark EKFs at the sampled pose as in 1.0.

**Correspondences** (§14.4.2): ``association="known"`` uses ``observations.reported_id`` (a sensor-reported
identity; the caller may have filled it from ground truth with ``--oracle-association``, which the result
file records); ``"ml"`` is per-particle maximum likelihood (eq. 14.30): the landmark maximising the
predictive likelihood, or a new landmark when no likelihood reaches ``p0`` (the new-landmark weight is
``p0``). Optional removal of unsupported landmarks by negative evidence: a counter starts at 1, gains 1 when
the landmark is observed and loses 1 when it is predicted inside the sensor's range/field of view but not
observed; the landmark is dropped when the counter falls below 0 (Thrun et al. Table 13.4).

**Resampling** when ``ESS = 1/Σw² < resample_threshold · P`` (systematic by default), by fancy indexing so
every particle owns its landmark arrays (no shared mutable state between copies). The last step is never
resampled, so the final weights still rank the particles.

**Output.** ``poses_xyt``: weighted mean per step (circular mean heading) or the best final particle's path
(traced back through the resampling ancestry). ``pose_cov (T+1, 3, 3)``: weighted moment-matched covariance
of the particle poses about the weighted mean, full 3×3 (EVALUATION-METHOD §A2). Landmarks: with known
association the weighted moment-matched mixture ``μ̄ = Σ w μ``, ``Σ̄ = Σ w [Σ + (μ − μ̄)(μ − μ̄)ᵀ]``
over particles; with ML association particles do not share landmark identities, so the best particle's map
and its own EKF covariances are returned. ``assoc``: the best particle's association of every observation.
"""

from __future__ import annotations

import dataclasses
import math
import time
from typing import Literal

import numpy as np

from slamcli.errors import SolverError
from slamcli.models import se2
from slamcli.models.angles import circular_mean, wrap_angle
from slamcli.models.motion import ddmr_jacobians, ddmr_step
from slamcli.models.observation import (
    inverse_range_bearing,
    inverse_range_bearing_jacobians,
    measurement_residual,
    range_bearing,
    range_bearing_jacobians,
)
from slamcli.solvers.base import BaseSolver, ProgressFn
from slamcli.solvers.resampling import RESAMPLERS, effective_sample_size, normalise_log_weights
from slamcli.types import SlamInputs, SolverResult, Status

LOG_2PI = math.log(2.0 * math.pi)
CHI2_2DOF_9999 = 18.420680743952367  # scipy.stats.chi2.ppf(0.9999, 2) = −2 ln(1e−4)


@dataclasses.dataclass(frozen=True)
class FastSlamParams:
    """Parameters of :class:`FastSlam`.

    Attributes
    ----------
    n_particles : int
        Number of particles P.
    version : 1 | 2
        1 = proposal from the motion model; 2 = proposal improved by the observations (sampled, not its mean).
    association : "known" | "ml"
        ``known`` uses ``observations.reported_id``; ``ml`` = per-particle maximum likelihood (eq. 14.30).
    motion_source : "controls" | "odometry"
        Motion model used for the proposal: commanded controls with ``noise.motion_std`` (DDMR, paper 000
        §4), or the encoder odometry increments (eq. 16) with ``noise.odometry_std``.
    motion_noise_scale : float
        Multiplies the motion noise standard deviations (``>1`` = stabilising noise; 1 = as specified).
    resampling : "systematic" | "multinomial"
    resample_threshold : float
        Resample when ``ESS < resample_threshold · P`` (0 = never, 1 = every step).
    output : "mean" | "best"
        Reported path: weighted mean per step, or the best final particle's path.
    p0 : float | None
        ML association: new-landmark likelihood (a density in measurement space). ``None`` = the Gaussian
        density of the sensor noise ``Q`` at Mahalanobis² = χ²₂(0.9999) = 18.42.
    remove_unsupported : bool
        ML association: drop landmarks by negative evidence inside the sensor's range / field of view.
    fov_rad : float
        Sensor field of view used by the negative-evidence test (full width, rad; 2π = omnidirectional).
    removal_range_frac : float
        Negative evidence only counts for landmarks predicted within ``removal_range_frac · max_range``
        (misses right at the range edge are expected).
    """

    n_particles: int = 100
    version: Literal[1, 2] = 2
    association: Literal["known", "ml"] = "known"
    motion_source: Literal["controls", "odometry"] = "controls"
    motion_noise_scale: float = 1.0
    resampling: Literal["systematic", "multinomial"] = "systematic"
    resample_threshold: float = 0.5
    output: Literal["mean", "best"] = "mean"
    p0: float | None = None
    remove_unsupported: bool = False
    fov_rad: float = 2.0 * math.pi
    removal_range_frac: float = 0.95

    def __post_init__(self) -> None:
        if self.n_particles < 1:
            raise ValueError(f"n_particles must be ≥ 1, got {self.n_particles}")
        if self.version not in (1, 2):
            raise ValueError(f"version must be 1 or 2, got {self.version}")
        if self.association not in ("known", "ml"):
            raise ValueError(f"association must be 'known' or 'ml', got {self.association!r}")
        if self.motion_source not in ("controls", "odometry"):
            raise ValueError(f"motion_source must be 'controls' or 'odometry', got {self.motion_source!r}")
        if self.resampling not in RESAMPLERS:
            raise ValueError(f"resampling must be one of {', '.join(RESAMPLERS)}, got {self.resampling!r}")
        if self.output not in ("mean", "best"):
            raise ValueError(f"output must be 'mean' or 'best', got {self.output!r}")
        if not 0.0 <= self.resample_threshold <= 1.0:
            raise ValueError(f"resample_threshold must be in [0, 1], got {self.resample_threshold}")
        if not self.motion_noise_scale > 0.0:
            raise ValueError(f"motion_noise_scale must be > 0, got {self.motion_noise_scale}")
        if self.p0 is not None and not self.p0 > 0.0:
            raise ValueError(f"p0 must be > 0, got {self.p0}")
        if not self.fov_rad > 0.0:
            raise ValueError(f"fov_rad must be > 0, got {self.fov_rad}")
        if not 0.0 < self.removal_range_frac <= 1.0:
            raise ValueError(f"removal_range_frac must be in (0, 1], got {self.removal_range_frac}")


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
    count : ndarray (P, C)      negative-evidence support counters.
    exists : ndarray (P, C)     slot holds a live landmark.
    n_slots : ndarray (P,)      slots used so far (ML association allocates new landmarks at ``n_slots``).
    log_w : ndarray (P,)        unnormalised log importance weights.
    """

    x: np.ndarray
    mu: np.ndarray
    sig: np.ndarray
    count: np.ndarray
    exists: np.ndarray
    n_slots: np.ndarray
    log_w: np.ndarray

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
        )

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


# ---------------------------------------------------------------------------------------------------------
# Small batched linear algebra (explicit 2×2 inverses are much faster than np.linalg.inv on small batches)
# ---------------------------------------------------------------------------------------------------------
def _inv2(A: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Inverse and determinant of symmetric-or-not 2×2 matrices ``(..., 2, 2)``."""
    a, b, c, d = A[..., 0, 0], A[..., 0, 1], A[..., 1, 0], A[..., 1, 1]
    det = a * d - b * c
    inv = np.empty_like(A)
    inv[..., 0, 0] = d / det
    inv[..., 0, 1] = -b / det
    inv[..., 1, 0] = -c / det
    inv[..., 1, 1] = a / det
    return inv, det


def _mT(A: np.ndarray) -> np.ndarray:
    return np.swapaxes(A, -1, -2)


def _gauss_loglik(nu: np.ndarray, S_inv: np.ndarray, S_det: np.ndarray) -> np.ndarray:
    """``log N(ν; 0, S) = −½ νᵀS⁻¹ν − log 2π − ½ log det S`` for 2-D innovations ``ν (..., 2)``."""
    maha = np.einsum("...i,...ij,...j->...", nu, S_inv, nu)
    return -0.5 * maha - LOG_2PI - 0.5 * np.log(S_det)


def landmark_ekf_update(x, mu, sig, z, Q):
    """One landmark EKF measurement update per particle (paper 002 eqs. 14.21-14.24, 14.28-14.29).

    Parameters
    ----------
    x : ndarray (..., 3)      particle poses.
    mu : ndarray (..., 2)     landmark means before the update.
    sig : ndarray (..., 2, 2) landmark covariances before the update.
    z : ndarray (2,)          measurement [range, bearing].
    Q : ndarray (2, 2)        measurement noise covariance.

    Returns
    -------
    mu_new : ndarray (..., 2)       ``μ + K ν``, ``ν = z − h(x, μ)`` with the bearing wrapped.
    sig_new : ndarray (..., 2, 2)   Joseph form ``(I − K H) Σ (I − K H)ᵀ + K Q Kᵀ`` (= ``(I − K H) Σ``).
    log_lik : ndarray (...)         ``log N(ν; 0, H Σ Hᵀ + Q)`` — the FastSLAM 1.0 importance weight.
    """
    z_hat = range_bearing(x, mu)
    _, H = range_bearing_jacobians(x, mu)
    nu = measurement_residual(z, z_hat)
    S = H @ sig @ _mT(H) + Q  # eq. 14.29
    S_inv, S_det = _inv2(S)
    K = sig @ _mT(H) @ S_inv  # eq. 14.22
    mu_new = mu + np.einsum("...ij,...j->...i", K, nu)  # eq. 14.23
    IKH = np.eye(2) - K @ H
    sig_new = IKH @ sig @ _mT(IKH) + K @ Q @ _mT(K)  # eq. 14.24, Joseph form keeps Σ symmetric PSD
    sig_new = 0.5 * (sig_new + _mT(sig_new))
    return mu_new, sig_new, _gauss_loglik(nu, S_inv, S_det)


def init_landmark(x, z, Q):
    """Initialise landmark Gaussians from poses ``x (..., 3)`` and one measurement ``z (2,)``:
    ``μ = h⁻¹(x, z)``, ``Σ = M_z Q M_zᵀ`` (the pose is given within a particle)."""
    z_b = np.broadcast_to(np.asarray(z, float), np.shape(x)[:-1] + (2,))
    mu = inverse_range_bearing(x, z_b)
    _, Mz = inverse_range_bearing_jacobians(x, z_b)
    return mu, Mz @ Q @ _mT(Mz)


def sample_gaussian(mean: np.ndarray, cov: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """Draw one sample per row from ``N(mean (P, d), cov (P, d, d))``; ``cov`` may be singular (PSD).

    Uses the symmetric square root ``V diag(√λ) Vᵀ`` so rank-deficient motion noise (the DDMR model has no
    lateral noise) is handled exactly.
    """
    lam, V = np.linalg.eigh(0.5 * (cov + _mT(cov)))
    L = V * np.sqrt(np.clip(lam, 0.0, None))[..., None, :]
    eps = rng.standard_normal(mean.shape)
    return mean + np.einsum("...ij,...j->...i", L, eps)


# ---------------------------------------------------------------------------------------------------------
# The solver
# ---------------------------------------------------------------------------------------------------------
class FastSlam(BaseSolver):
    """FastSLAM 1.0 / 2.0 with known or maximum-likelihood correspondences (see the module docstring)."""

    name = "fastslam"
    Params = FastSlamParams

    def solve(
        self,
        inputs: SlamInputs,
        *,
        init: SolverResult | None = None,
        rng: np.random.Generator,
        progress: ProgressFn | None = None,
    ) -> SolverResult:
        t_start = time.perf_counter()
        p: FastSlamParams = self.params
        obs = inputs.observations
        T1 = inputs.n_poses
        T = T1 - 1
        P = p.n_particles
        Q = inputs.noise.obs_cov
        z_all = obs.z
        N = len(obs)
        if len(obs.offsets) != T1 + 1:
            raise SolverError(
                f"observations.offsets: length {len(obs.offsets)}, expected n_poses+1 = {T1 + 1}"
            )

        # ---- correspondences -----------------------------------------------------------------------------
        known = p.association == "known"
        if known:
            rid = np.asarray(obs.reported_id, np.int64)
            ids = np.unique(rid[rid >= 0])
            if N > 0 and ids.size == 0:
                raise SolverError(
                    "observations.reported_id: no sensor-reported landmark ids (all -1); use association=ml "
                    "or solve with --oracle-association"
                )
            slot_of_obs = np.where(rid >= 0, np.searchsorted(ids, rid), -1)
            capacity = ids.size
        else:
            slot_of_obs = None
            capacity = 16
        log_p0 = (
            math.log(p.p0)
            if p.p0 is not None
            else -0.5 * CHI2_2DOF_9999 - LOG_2PI - 0.5 * math.log(float(np.linalg.det(Q)))
        )

        # ---- motion model --------------------------------------------------------------------------------
        if p.motion_source == "controls":
            if inputs.controls.shape[0] < T:
                raise SolverError(
                    f"controls: {inputs.controls.shape[0]} rows, need {T} for motion_source=controls"
                )
            M_std = np.asarray(inputs.noise.motion_std, float) * p.motion_noise_scale
            increments = None
        else:
            M_std = np.asarray(inputs.noise.odometry_std, float) * p.motion_noise_scale
            increments = se2.between(inputs.odometry_xyt[:-1], inputs.odometry_xyt[1:])

        ps = ParticleSet.create(inputs.x0, P, capacity)
        resample = RESAMPLERS[p.resampling]

        # ---- records -------------------------------------------------------------------------------------
        mean_xyt = np.empty((T1, 3))
        pose_cov = np.zeros((T1, 3, 3))
        # anc[t][j]: the pre-resampling particle at t that post-resampling particle j copies
        anc = np.empty((T1, P), np.int32)
        keep_path = p.output == "best"
        pose_hist = np.empty((T1, P, 3)) if keep_path else None
        assoc_hist = np.full((N, P), -1, np.int32)  # slot per particle of every observation (pre-resampling)
        arP = np.arange(P)
        n_updates = 0
        n_resample = 0
        ess_sum = 0.0
        every = max(1, T1 // 100)

        for t in range(T1):
            # ---- 1. proposal prior -----------------------------------------------------------------------
            if t == 0:
                x_hat = ps.x.copy()
                R = np.zeros((P, 3, 3))
            elif p.motion_source == "controls":
                u = inputs.controls[t - 1]
                if p.version == 1:  # eq. 14.18: sample the motion model directly
                    u_k = u + M_std * rng.standard_normal((P, 2))
                    x_hat = ddmr_step(ps.x, u_k, inputs.dt)
                else:
                    x_hat = ddmr_step(ps.x, u, inputs.dt)
                    _, G_u = ddmr_jacobians(ps.x, u, inputs.dt)
                    R = G_u @ np.diag(M_std**2) @ _mT(G_u)
            else:
                d = increments[t - 1]
                if p.version == 1:
                    x_hat = se2.compose(ps.x, d + M_std * rng.standard_normal((P, 3)))
                else:
                    x_hat = se2.compose(ps.x, d)
                    J = np.zeros((P, 3, 3))  # ∂(x ⊕ d)/∂d = blkdiag(R(θ), 1)
                    J[:, :2, :2] = se2.rot2(ps.x[:, 2])
                    J[:, 2, 2] = 1.0
                    R = J @ np.diag(M_std**2) @ _mT(J)

            rows = range(int(obs.offsets[t]), int(obs.offsets[t + 1]))
            # NaN from unused slots of particles that start a new landmark is masked out with np.where.
            with np.errstate(divide="ignore", invalid="ignore"):
                if p.version == 1 or t == 0:
                    ps.x = x_hat
                    step_slots, step_new = self._associate_and_weight_v1(
                        ps, z_all, rows, slot_of_obs, Q, log_p0
                    )
                else:
                    step_slots, step_new = self._proposal_v2(
                        ps, x_hat, R, z_all, rows, slot_of_obs, Q, log_p0, rng
                    )

            # ---- 3. landmark EKFs (v2: at the sampled pose; v1 already done) -------------------------------
            if p.version == 2 and t > 0:
                for i, n in enumerate(rows):
                    if step_slots[i] is None:
                        continue
                    self._update_or_init(ps, step_slots[i], step_new[i], z_all[n], Q, weight=False)
            for i, n in enumerate(rows):
                if step_slots[i] is not None:
                    assoc_hist[n] = step_slots[i]
                    n_updates += P

            # ---- negative evidence (§14.4.2) ---------------------------------------------------------------
            if not known and p.remove_unsupported and len(rows) > 0:
                self._negative_evidence(ps, step_slots, inputs.max_range)

            # ---- estimate at t (weights before resampling) -------------------------------------------------
            w = normalise_log_weights(ps.log_w)
            mean_xyt[t, :2] = w @ ps.x[:, :2]
            mean_xyt[t, 2] = circular_mean(ps.x[:, 2], w)
            e = ps.x - mean_xyt[t]
            e[:, 2] = wrap_angle(e[:, 2])
            pose_cov[t] = (w[:, None] * e).T @ e  # EVALUATION-METHOD §A2
            if keep_path:
                pose_hist[t] = ps.x
            ess = effective_sample_size(w)
            ess_sum += ess

            # ---- resampling (never on the last step, so the final weights still rank particles) -------------
            if t < T and ess < p.resample_threshold * P:
                idx = resample(w, rng)
                ps = ps.take(idx)
                anc[t] = idx
                n_resample += 1
            else:
                anc[t] = arP
            if progress is not None and (t % every == 0 or t == T):
                progress(t + 1, T1)

        # ---- outputs -------------------------------------------------------------------------------------
        w = normalise_log_weights(ps.log_w)
        best = int(np.argmax(w))
        # Trace the best final particle back: its index at t (pre-resampling) → post-resampling index at t-1.
        lineage = np.empty(T1, np.int64)
        j = best
        for t in range(T, -1, -1):
            lineage[t] = j
            if t > 0:
                j = int(anc[t - 1][j])
        obs_step = np.asarray(obs.step, np.int64)
        assoc_slots = assoc_hist[np.arange(N), lineage[obs_step]] if N else np.zeros(0, np.int64)
        poses = pose_hist[np.arange(T1), lineage] if keep_path else mean_xyt

        if known:
            live = ps.exists[best]
            lm_xy, lm_cov = moment_matched_landmarks(ps.mu[:, live], ps.sig[:, live], w)
        else:
            live = ps.exists[best]
            lm_xy, lm_cov = ps.mu[best, live], ps.sig[best, live]
        row_of_slot = np.cumsum(live) - 1
        alive = (assoc_slots >= 0) & live[np.clip(assoc_slots, 0, None)]
        assoc = np.where(alive, row_of_slot[np.clip(assoc_slots, 0, None)], -1)

        extra = {
            "association": p.association,
            "version": int(p.version),
            "n_resamples": n_resample,
            "mean_ess": ess_sum / T1,
            "particle_landmark_updates": int(n_updates),
            "best_particle_weight": float(w[best]),
            "landmark_cov_kind": "moment_matched" if known else "best_particle",
        }
        return self.make_result(
            status=Status.COMPLETED,
            poses_xyt=poses,
            landmarks_xy=lm_xy,
            assoc=assoc,
            t_start=t_start,
            message=f"FastSLAM {p.version}.0, {P} particles, {n_resample} resamplings, {len(lm_xy)} landmarks",
            pose_cov=pose_cov,
            landmark_cov=lm_cov,
            extra=extra,
        )

    # -----------------------------------------------------------------------------------------------------
    def _ml_candidates(self, ps: ParticleSet, x, Sx, z, Q):
        """Per-particle log-likelihood ``(P, C)`` of measurement ``z`` for every live landmark (eq. 14.30),
        with predictive covariance ``H_m Σ H_mᵀ + Q`` (+ ``H_x Σ_x H_xᵀ`` for the 2.0 proposal)."""
        live = ps.exists
        mu = np.where(live[..., None], ps.mu, x[:, None, :2] + 1.0)  # dummy position away from the pose
        xb = x[:, None, :]
        z_hat = range_bearing(xb, mu)
        Hx, Hm = range_bearing_jacobians(xb, mu)
        S = Hm @ ps.sig @ _mT(Hm) + Q
        if Sx is not None:
            S = S + Hx @ Sx[:, None] @ _mT(Hx)
        S = np.where(live[..., None, None], S, np.eye(2))
        S_inv, S_det = _inv2(S)
        ll = _gauss_loglik(measurement_residual(z, z_hat), S_inv, S_det)
        return np.where(live, ll, -np.inf)

    def _associate(self, ps: ParticleSet, n: int, slot_of_obs, x, Sx, z, Q, log_p0):
        """Slots ``(P,)`` and new-landmark mask ``(P,)`` for observation row ``n``; allocates ML slots.

        Returns ``(slots, new, log_lik_or_None)``; ``None`` slots = observation not used (no reported id)."""
        P = ps.n_particles
        if slot_of_obs is not None:
            s = int(slot_of_obs[n])
            if s < 0:
                return None, None, None
            slots = np.full(P, s, np.int64)
            return slots, ~ps.exists[:, s], None
        ll = self._ml_candidates(ps, x, Sx, z, Q)
        j = np.argmax(ll, axis=1)
        ll_best = ll[np.arange(P), j]
        new = ~(ll_best >= log_p0)
        if new.any():
            ps.ensure_capacity(int(ps.n_slots.max()) + 1)
            j = np.where(new, ps.n_slots, j)
            ps.n_slots = ps.n_slots + new
        return j, new, ll_best

    def _update_or_init(self, ps: ParticleSet, slots, new, z, Q, *, weight: bool):
        """EKF-update existing landmarks / initialise new ones in ``slots (P,)``; optionally add the 1.0
        weight ``log N(ν; 0, Q_n)`` for the updated particles."""
        ar = np.arange(ps.n_particles)
        any_new = bool(new.any())
        if not new.all():
            with np.errstate(divide="ignore", invalid="ignore"):  # unused slots of new particles give NaN
                mu_u, sig_u, ll = landmark_ekf_update(ps.x, ps.mu[ar, slots], ps.sig[ar, slots], z, Q)
        else:
            mu_u, sig_u, ll = ps.mu[ar, slots], ps.sig[ar, slots], np.zeros(ps.n_particles)
        if any_new:
            mu_i, sig_i = init_landmark(ps.x, z, Q)
            mu_u = np.where(new[:, None], mu_i, mu_u)
            sig_u = np.where(new[:, None, None], sig_i, sig_u)
        ps.mu[ar, slots] = mu_u
        ps.sig[ar, slots] = sig_u
        ps.count[ar, slots] = np.where(new, 1, ps.count[ar, slots] + 1)
        ps.exists[ar, slots] = True
        if weight:
            ps.log_w += np.where(new, 0.0, ll)
        return ll

    def _associate_and_weight_v1(self, ps, z_all, rows, slot_of_obs, Q, log_p0):
        """FastSLAM 1.0 measurement step at the already-sampled poses ``ps.x``."""
        slots_l, new_l = [], []
        for n in rows:
            z = z_all[n]
            slots, new, _ = self._associate(ps, n, slot_of_obs, ps.x, None, z, Q, log_p0)
            slots_l.append(slots)
            new_l.append(new)
            if slots is None:
                continue
            self._update_or_init(ps, slots, new, z, Q, weight=True)
            if slot_of_obs is None:
                ps.log_w += np.where(new, log_p0, 0.0)  # new-landmark likelihood p0
        return slots_l, new_l

    def _proposal_v2(self, ps, x_hat, R, z_all, rows, slot_of_obs, Q, log_p0, rng):
        """FastSLAM 2.0: refine ``N(x̂, Σ_x)`` with every observation of a mapped landmark, weight by the
        predictive likelihood, then sample the new poses into ``ps.x``."""
        P = ps.n_particles
        ar = np.arange(P)
        Sx = R.copy()
        x_hat = x_hat.copy()
        slots_l, new_l = [], []
        born_now = np.zeros_like(ps.exists)  # landmarks created this step carry no prior information yet
        for n in rows:
            z = z_all[n]
            slots, new, _ = self._associate(ps, n, slot_of_obs, x_hat, Sx, z, Q, log_p0)
            slots_l.append(slots)
            new_l.append(new)
            if slots is None:
                continue
            if born_now.shape != ps.exists.shape:  # capacity grew
                born_now = np.pad(born_now, ((0, 0), (0, ps.capacity - born_now.shape[1])))
            mu_j, sig_j = ps.mu[ar, slots], ps.sig[ar, slots]
            with np.errstate(divide="ignore", invalid="ignore"):  # unused slots of new particles give NaN
                z_hat = range_bearing(x_hat, mu_j)
                Hx, Hm = range_bearing_jacobians(x_hat, mu_j)
                nu = measurement_residual(z, z_hat)
                Qn = Hm @ sig_j @ _mT(Hm) + Q
                S = Hx @ Sx @ _mT(Hx) + Qn
                S_inv, S_det = _inv2(S)
                ll = _gauss_loglik(nu, S_inv, S_det)
            K = Sx @ _mT(Hx) @ S_inv  # (P, 3, 2)
            # Landmarks born earlier in this step carry no prior information yet: no proposal update.
            upd = ~new & ~born_now[ar, slots]
            dx = np.einsum("pij,pj->pi", K, nu)
            x_new = x_hat + dx
            x_new[:, 2] = wrap_angle(x_new[:, 2])
            IKH = np.eye(3) - K @ Hx
            Sx_new = IKH @ Sx @ _mT(IKH) + K @ Qn @ _mT(K)
            Sx_new = 0.5 * (Sx_new + _mT(Sx_new))
            x_hat = np.where(upd[:, None], x_new, x_hat)
            Sx = np.where(upd[:, None, None], Sx_new, Sx)
            ps.log_w += np.where(upd, ll, 0.0)
            if slot_of_obs is None:
                ps.log_w += np.where(new, log_p0, 0.0)  # new-landmark likelihood p0
            if new.any():
                # Provisional landmark at the proposal mean so later rows of this step can associate with it;
                # it is re-initialised from the sampled pose in the landmark pass.
                mu_i, sig_i = init_landmark(x_hat, z, Q)
                sn = slots[new]
                ps.mu[ar[new], sn] = mu_i[new]
                ps.sig[ar[new], sn] = sig_i[new]
                ps.exists[ar[new], sn] = True
                born_now[ar[new], sn] = True
        ps.x = sample_gaussian(x_hat, Sx, rng)
        ps.x[:, 2] = wrap_angle(ps.x[:, 2])
        # Landmarks born this step are initialised in the landmark pass: undo the provisional state there by
        # treating the first observation of each as "new".
        seen = np.zeros_like(born_now)
        for i, slots in enumerate(slots_l):
            if slots is None:
                continue
            first = born_now[ar, slots] & ~seen[ar, slots]
            new_l[i] = first
            seen[ar, slots] |= first
        return slots_l, new_l

    def _negative_evidence(self, ps: ParticleSet, step_slots, max_range: float) -> None:
        """Decrement support of live landmarks predicted inside range/FOV but not observed; drop if < 0."""
        P = ps.n_particles
        ar = np.arange(P)
        observed = np.zeros_like(ps.exists)
        for slots in step_slots:
            if slots is not None:
                observed[ar, slots] = True
        live = ps.exists
        safe_mu = np.where(live[..., None], ps.mu, ps.x[:, None, :2] + 1.0)
        zh = range_bearing(ps.x[:, None, :], safe_mu)
        rng_lim = self.params.removal_range_frac * max_range
        visible = live & (zh[..., 0] <= rng_lim) & (np.abs(zh[..., 1]) <= 0.5 * self.params.fov_rad)
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
