"""The ICM-SLAM Gibbs energy (paper 000, eqs. 3-5, 16) and its conditional modes.

Energy of a configuration (poses ``x``, map ``m``, matchings ``c``), with diagonal weight matrices R, S, Q
and ``‖a‖²_Σ = aᵀ Σ a``::

    H(x, m, c) = Σ_{t=1..T} ‖g(x_{t-1}, u_{t-1}) − x_t‖²_R                         motion, eq. (3)
               + Σ_{t=1..T} ‖τ(θ_{t-1})(x_t − x_{t-1}) − τ(θ̃_{t-1})(x̃_t − x̃_{t-1})‖²_S   odometry, eq. (16)
               + Σ_{t,i: c_{t,i} ≥ 0} ‖h⁻¹(x_t, z_{t,i}) − m_{c_{t,i}}‖²_Q        observations, eq. (5)
               + Σ_{t ∈ T_gps} ‖p(x_t) − y_t‖²_K                                GPS (§4, "sensory fusion")

(the map potential Φ_m is a feasibility constraint — no two map points within ϑ — enforced by the map step,
see :mod:`slamcli.solvers.icm.map_step`). Observations labelled ``-1`` are out of the energy. A zero weight drops
its potential (paper §3.1). The GPS potential is the one paper 000 writes down in §4 and then leaves out of its
experiments ("to highlight the ICM ability to solve SLAM ... regardless of the GPS data availability");
K = k·I is a design matrix like R, S, Q. ``Weights.obs_model = "range_bearing"``: :func:`range_bearing_energy`.

Three independent evaluations of the same function live here:

* :func:`energy_terms` — vectorised, built on :mod:`slamcli.models.potentials` (the reference);
* :func:`cond_cost` / :func:`cond_system` — the 3-D conditional of one pose (eq. 14), written once in plain
  arithmetic so it runs on Python floats (sequential ICM) *and* on numpy arrays (parallel coding scheme). The
  observation part uses per-step sufficient statistics, so a pose update is O(1) whatever the number of
  observations at that step;
* :func:`joint_system` — the whole-problem whitened Jacobian (sparse), used by the joint Gauss-Newton step,
  the MAP reference and the Laplace covariances.
"""

from __future__ import annotations

import dataclasses
import functools
import math
import os
import types
import warnings
from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from slamcli.models import motion, observation, potentials, se2
from slamcli.models.ackermann import ackermann_jacobians, ackermann_step, centre_twist, integrate_ackermann
from slamcli.models.angles import wrap_angle, wrap_angle_fast
from slamcli.solvers.nls import factorize_information
from slamcli.solvers.nls.marginals import block_marginals
from slamcli.types import SlamInputs

PI = math.pi
TWO_PI = 2.0 * math.pi


_wrap = wrap_angle_fast  # floats and arrays alike, no numpy scalar overhead in the per-pose loops
_cos, _sin = math.cos, math.sin  # the scalar kernels' trigonometry (a name numba compiles as well)


# ------------------------------------------------------------------------------------------------------------
# problem data
# ------------------------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class Weights:
    """Diagonals of the design matrices R (3,), S (3,), Q (2,) (paper §3.1)."""

    R: tuple[float, float, float]
    S: tuple[float, float, float]
    Q: tuple[float, float]
    K: float = 0.0  # GPS weight, K = k·I (0 drops the GPS potential)
    #: the observation potential of H: ``"cartesian"`` (eq. 5, weight Q) or ``"range_bearing"``
    #: (:func:`range_bearing_energy`, σ ``obs_sigma`` and Cauchy scale ``cauchy_k``; Q then only weights the
    #: sweep's pose conditionals, a surrogate)
    obs_model: str = "cartesian"
    obs_sigma: tuple[float, float] = (0.0, 0.0)  # σ_r m, σ_b rad of the range_bearing potential
    cauchy_k: float = 0.0  # Cauchy scale of the range_bearing potential, whitened units

    @property
    def range_bearing(self) -> bool:
        return self.obs_model == "range_bearing"

    @staticmethod
    def from_params(R, S, Q, K: float = 0.0) -> Weights:
        """Each argument: one value (scalar × identity) or the full diagonal."""

        def diag(v, k, name):
            v = tuple(float(a) for a in v) if isinstance(v, (tuple, list)) else (float(v),)
            if len(v) == 1:
                v = v * k
            if len(v) != k:
                raise ValueError(f"{name} needs 1 or {k} diagonal values, got {len(v)}")
            if any(a < 0 or not math.isfinite(a) for a in v):
                raise ValueError(f"{name} must be finite and non-negative, got {v}")
            return v

        k = float(K)
        if k < 0 or not math.isfinite(k):
            raise ValueError(f"K must be finite and non-negative, got {K}")
        return Weights(diag(R, 3, "R"), diag(S, 3, "S"), diag(Q, 2, "Q"), k)

    @property
    def flat(self) -> tuple[float, ...]:
        """``(r0, r1, r2, s0, s1, s2, q0, q1)``."""
        return self.R + self.S + self.Q

    @property
    def use_motion(self) -> bool:
        return any(self.R)

    @property
    def use_odometry(self) -> bool:
        return any(self.S)

    def gps_obs_weight(self) -> float:
        """``w = k / q``: a GPS fix enters the pose conditional as a pseudo-observation (v = 0, m = y) of
        weight w in the sufficient statistics, exact when Q = q·I (then ``q·w·‖p − y‖² = k‖p − y‖²``)."""
        if self.K == 0.0:
            return 0.0
        q0, q1 = self.Q
        if not (q0 == q1 and q0 > 0):
            raise ValueError(f"a GPS potential (K = {self.K}) needs an isotropic positive Q, got Q = {self.Q}")
        return self.K / q0


def information_weights(inputs: SlamInputs) -> Weights:
    """R, S, Q, K from the dataset's noise model (inverse covariances; beyond the paper's identity matrices).

    With the Gibbs temperature of :func:`laplace_covariances` (P ∝ exp(−H/2)) a residual of covariance Σ gets
    the weight ``Σ⁻¹``; H then is twice the Gaussian negative log-likelihood up to a constant. Diagonal
    approximations (the energy has diagonal weights):

    * R: the actuation noise [σ_v, σ_ω] of one step of length dt moves the pose by ``dt·σ_v`` along the
      heading and turns it by ``dt·σ_ω``; R = diag((dt σ_v)⁻², (dt σ_v)⁻², (dt σ_ω)⁻²) (isotropic in x, y
      because the residual is in the world frame). Car model (controls ``[v_e, α]``, σ = ``[σ_v, σ_α]``): the
      step covariance is ``G_u diag(σ²) G_uᵀ`` (:func:`slamcli.models.ackermann.ackermann_jacobians`), which
      depends on speed and steering; R uses the median over the moving steps of its mean x/y variance and
      of its heading variance.
    * S = diag(σ_odo)⁻² (body-frame odometry increments, eq. 16 — the same frame as the noise model).
    * Q: h⁻¹(x, z) − m has covariance σ_r² along the beam and (r σ_b)² across it; the isotropic
      Q = q·I with ``q = 2 / (σ_r² + r̃² σ_b²)`` (mean of the two variances, r̃ = median measured range).
    * K = σ_gps⁻² when the dataset has GPS fixes, else 0.

    Raises ValueError naming the field when a needed σ is not positive.
    """
    nz = inputs.noise
    dt = float(inputs.dt)
    ms = np.asarray(nz.motion_std, float)
    os_ = np.asarray(nz.odometry_std, float)
    for name, v in (("noise.motion_std", ms), ("noise.odometry_std", os_),
                    ("noise.range_std", np.array([nz.range_std]))):
        if not np.all(v > 0):
            raise ValueError(f"weights=information: {name} = {v.tolist()} must be positive")
    R = (1.0 / (dt * ms[0]) ** 2, 1.0 / (dt * ms[0]) ** 2, 1.0 / (dt * ms[1]) ** 2)
    if getattr(inputs, "motion_model", "ddmr") == "ackermann":
        u = np.asarray(inputs.controls, float).reshape(-1, 2)
        _, G_u = ackermann_jacobians(np.zeros(3), u, dt, inputs.vehicle)  # (T, 3, 2), heading 0: body frame
        cov = np.einsum("tij,j,tkj->tik", G_u, ms**2, G_u)
        moving = np.abs(u[:, 0]) > 0
        if not moving.any():
            raise ValueError("weights=information: the car never moves (all speeds are 0)")
        var_xy = float(np.median(0.5 * (cov[moving, 0, 0] + cov[moving, 1, 1])))
        var_th = float(np.median(cov[moving, 2, 2]))
        R = (1.0 / var_xy, 1.0 / var_xy, 1.0 / var_th)
    S = tuple(float(a) for a in 1.0 / os_**2)
    r = np.asarray(inputs.observations.range_m, float)
    r_med = float(np.median(r)) if r.size else 0.0
    q = 2.0 / (nz.range_std**2 + (r_med * float(nz.bearing_std)) ** 2)
    K = 1.0 / inputs.gps_std**2 if len(inputs.gps_step) and inputs.gps_std > 0 else 0.0
    return Weights(R, S, (q, q), K)


@dataclass(frozen=True)
class Problem:
    """Inputs of the energy in solver-friendly arrays.

    Attributes
    ----------
    T : int                      number of motion steps (poses are 0..T).
    dt : float
    x0 : ndarray (3,)            known start pose (fixed).
    controls : ndarray (T, 2)    u_{t-1} drives x_{t-1} → x_t, as the body twist ``[v, ω]`` of the tracked point
                                 (DDMR: the dataset's controls; car model: see ``lateral``).
    odo_inc : ndarray (T, 3)     τ(θ̃_{t-1})(x̃_t − x̃_{t-1}) (eq. 16), row t-1 for step t.
    step : ndarray (N,) int64    pose index of each observation.
    z : ndarray (N, 2)           [range, bearing].
    v_body : ndarray (N, 2)      r·[cos b, sin b]: the observation in the robot frame, h⁻¹(x, z) = p + R(θ) v.
    offsets : ndarray (T+2,)     CSR rows of pose t.
    gps_step : ndarray (G,) int64  pose index of each GPS fix (empty: no GPS potential).
    gps_xy : ndarray (G, 2)      GPS positions y_t, m.
    lateral : ndarray (T,) | None  lateral body speed v_y of step t-1 (None = 0, DDMR). The car model
                                 (``motion_model="ackermann"``, :mod:`slamcli.models.ackermann`) moves the
                                 tracked point (a, b) by ``dt·R(φ)[v_c − ω b, ω a]`` and turns it by ``dt·ω``, so
                                 with ``controls = [v_c − ω b, ω]`` and ``lateral = ω a`` every motion term is
                                 ``g(x, u) = p + dt·R(φ)[v, v_y], φ + dt·ω`` — DDMR is the case v_y = 0.
    car_controls : ndarray (T, 2) | None  the dataset's ``[v_e, α]`` and ``vehicle`` its geometry (car model
                                 only): the reference energy :func:`energy_terms`, the joint Jacobian and the
                                 kinematic init evaluate the shared model :func:`ackermann_step` itself.
    """

    T: int
    dt: float
    x0: np.ndarray
    controls: np.ndarray
    odo_inc: np.ndarray
    step: np.ndarray
    z: np.ndarray
    v_body: np.ndarray
    offsets: np.ndarray
    gps_step: np.ndarray = dataclasses.field(default_factory=lambda: np.zeros(0, np.int64))
    gps_xy: np.ndarray = dataclasses.field(default_factory=lambda: np.zeros((0, 2)))
    lateral: np.ndarray | None = None
    car_controls: np.ndarray | None = None
    vehicle: object = None

    @staticmethod
    def from_inputs(inputs: SlamInputs, range_offset: float = 0.0, use_gps: bool = True,
                    motion_input: str = "controls") -> Problem:
        """``range_offset`` (m) is added to every measured range (beyond the paper: laser returns from the
        surface of a post, see :attr:`slamcli.solvers.icm.solver.IcmParams.range_offset`). ``motion_input =
        "odometry"`` (DDMR data): the motion terms follow the odometry increments ``d`` instead of the controls,
        ``controls = [d_x, d_θ]/dt`` and ``lateral = d_y/dt``, so ``g(x, u) = x ⊕ d`` exactly."""
        obs = inputs.observations
        z = obs.z
        if range_offset:
            z = z + np.array([float(range_offset), 0.0])
        v = np.stack([z[:, 0] * np.cos(z[:, 1]), z[:, 0] * np.sin(z[:, 1])], -1)
        odo = np.asarray(inputs.odometry_xyt, float)
        controls = np.asarray(inputs.controls, float)
        car = {}
        if getattr(inputs, "motion_model", "ddmr") == "ackermann":
            veh = inputs.vehicle
            v_c, w = centre_twist(controls, veh)
            car = dict(lateral=w * veh.ref_x_m, car_controls=controls, vehicle=veh)
            controls = np.column_stack([v_c - w * veh.ref_y_m, w])
        elif getattr(inputs, "motion_model", "ddmr") != "ddmr":
            raise ValueError(f"motion model {inputs.motion_model!r} is not implemented")
        elif motion_input == "odometry":
            inc = se2.between(odo[:-1], odo[1:]) / float(inputs.dt)
            controls, car = inc[:, [0, 2]].copy(), dict(lateral=inc[:, 1].copy())
        return Problem(
            T=int(inputs.n_poses - 1),
            dt=float(inputs.dt),
            x0=np.asarray(inputs.x0, float).copy(),
            controls=controls,
            odo_inc=se2.between(odo[:-1], odo[1:]),
            step=np.asarray(obs.step, np.int64),
            z=z,
            v_body=v,
            offsets=np.asarray(obs.offsets, np.int64),
            gps_step=np.asarray(inputs.gps_step if use_gps else np.zeros(0), np.int64),
            gps_xy=np.asarray(inputs.gps_xy if use_gps else np.zeros((0, 2)), float).reshape(-1, 2),
            **car,
        )

    @property
    def lat(self) -> np.ndarray:
        """``lateral`` with None read as zeros ``(T,)``."""
        return np.zeros(self.T) if self.lateral is None else self.lateral

    def motion_prediction(self, poses_prev):
        """``g(x_{t-1}, u_{t-1}) (T, 3)`` by the dataset's own model (reference path: ``ddmr_step`` or
        ``ackermann_step``); ``poses_prev (T, 3)``."""
        if self.car_controls is not None:
            return ackermann_step(poses_prev, self.car_controls, self.dt, self.vehicle)
        if self.lateral is not None:  # odometry increments: x ⊕ d
            return wrap_angle_last(_motion(np.asarray(poses_prev, float), self.controls, self.dt, self.lateral))
        return motion.ddmr_step(poses_prev, self.controls, self.dt)

    def kinematic_poses(self) -> np.ndarray:
        """Poses ``(T+1, 3)`` from x_0 and the controls only (the paper's Fig. 6 initialisation)."""
        if self.car_controls is not None:
            return integrate_ackermann(self.x0, self.car_controls, self.dt, self.vehicle)
        if self.lateral is not None:  # odometry increments: the chain x_0 ⊕ d_1 ⊕ …
            inc = self.dt * np.column_stack([self.controls[:, 0], self.lateral, self.controls[:, 1]])
            return motion.chain_increments(self.x0, inc)
        return motion.integrate(self.x0, self.controls, self.dt)

    @property
    def n_obs(self) -> int:
        return int(self.step.shape[0])

    def landmark_points(self, poses_xyt: np.ndarray) -> np.ndarray:
        """``h⁻¹(x_t, z_{t,i}) (N, 2)`` for every observation."""
        return observation.inverse_range_bearing(poses_xyt[self.step], self.z)


# ------------------------------------------------------------------------------------------------------------
# reference energy (vectorised, from slamcli.models.potentials)
# ------------------------------------------------------------------------------------------------------------
def energy_terms(prob: Problem, W: Weights, poses_xyt, landmarks_xy, labels) -> dict[str, float]:
    """The three sums of H (eq. 5) and their total.

    Parameters
    ----------
    poses_xyt : ndarray (T+1, 3)    row 0 is the fixed start pose.
    landmarks_xy : ndarray (L, 2)
    labels : ndarray (N,) int64     c_{t,i}; ``-1`` = out of the energy.
    """
    poses = np.asarray(poses_xyt, float)
    out = {"motion": 0.0, "odometry": 0.0, "observation": 0.0, "gps": gps_energy(prob, W, poses)}
    if W.use_motion and prob.T > 0:
        r = wrap_angle_last(prob.motion_prediction(poses[:-1]) - poses[1:])
        out["motion"] = potentials.weighted_sq(r, np.diag(W.R))
    if W.use_odometry and prob.T > 0:
        r = wrap_angle_last(se2.between(poses[:-1], poses[1:]) - prob.odo_inc)
        out["odometry"] = potentials.weighted_sq(r, np.diag(W.S))
    ok = np.asarray(labels) >= 0
    if ok.any() and W.range_bearing:
        out["observation"] = range_bearing_energy(prob, W, poses, landmarks_xy, labels)
    elif ok.any():
        r = potentials.observation_residual(
            poses[prob.step[ok]], prob.z[ok], np.asarray(landmarks_xy, float)[np.asarray(labels)[ok]]
        )
        out["observation"] = potentials.weighted_sq(r, np.diag(W.Q))
    out["total"] = out["motion"] + out["odometry"] + out["observation"] + out["gps"]
    return out


def range_bearing_energy(prob: Problem, W: Weights, poses_xyt, landmarks_xy, labels) -> float:
    """The ``"range_bearing"`` observation potential (beyond the paper)::

        Σ_{t,i: c_{t,i} ≥ 0} k² log(1 + s²/k²),   s² = ((r̂ − r)/σ_r)² + (wrap(b̂ − b)/σ_b)²,  [r̂, b̂] = h(x_t, m_c)

    twice ``graph``'s Cauchy kernel on its whitened bearing-range factors, so that it equals ``Σ s²`` (the
    Gaussian ``rᵀ Σ⁻¹ r`` on H's scale, see :func:`information_weights`) for small residuals. 0 without
    matched observations."""
    ok = np.asarray(labels) >= 0
    if not ok.any():
        return 0.0
    e = potentials.range_bearing_residual(np.asarray(poses_xyt, float)[prob.step[ok]], prob.z[ok],
                                          np.asarray(landmarks_xy, float)[np.asarray(labels)[ok]])
    e = e / np.asarray(W.obs_sigma, float)
    return potentials.cauchy_sum(np.einsum("ij,ij->i", e, e), W.cauchy_k)


def observation_term(prob: Problem, W: Weights, poses_xyt, points_xy, labels, landmarks_xy) -> float:
    """The observation part of H: :func:`observation_energy` of the precomputed ``points_xy = h⁻¹(x_t, z)``
    (eq. 5) or, with ``W.range_bearing``, :func:`range_bearing_energy` of ``poses_xyt``."""
    if W.range_bearing:
        return range_bearing_energy(prob, W, poses_xyt, landmarks_xy, labels)
    return observation_energy(points_xy, labels, landmarks_xy, W.Q)


def gps_energy(prob: Problem, W: Weights, poses_xyt) -> float:
    """``Σ_{t ∈ T_gps} k ‖p(x_t) − y_t‖²`` (paper 000 §4's GPS potential with K = k·I); 0 without fixes."""
    if W.K == 0.0 or prob.gps_step.size == 0:
        return 0.0
    d = np.asarray(poses_xyt, float)[prob.gps_step, :2] - prob.gps_xy
    return float(W.K * np.einsum("ij,ij->", d, d))


def gps_step_stats(prob: Problem, W: Weights) -> np.ndarray:
    """GPS fixes as weighted pseudo-observations (v = 0, m = y) in the sufficient statistics ``(14, T+1)``
    of :func:`step_stats` (see :meth:`Weights.gps_obs_weight`); zeros without fixes."""
    K = prob.T + 1
    out = np.zeros((14, K))
    w = W.gps_obs_weight() if prob.gps_step.size else 0.0
    if w == 0.0:
        return out
    st, y = prob.gps_step, prob.gps_xy
    for row, val in ((0, np.ones(len(st))), (3, y[:, 0]), (4, y[:, 1]), (12, y[:, 0] ** 2), (13, y[:, 1] ** 2)):
        out[row] = np.bincount(st, weights=w * val, minlength=K)[:K]
    return out


def wrap_angle_last(e):
    e = np.array(e, float, copy=True)
    e[..., 2] = wrap_angle(e[..., 2])
    return e


def energy(prob: Problem, W: Weights, poses_xyt, landmarks_xy, labels) -> float:
    """Total energy H (eq. 5 without the constant map potential)."""
    return energy_terms(prob, W, poses_xyt, landmarks_xy, labels)["total"]


def chain_energy(prob: Problem, W: Weights, poses) -> float:
    """Motion + odometry part of H (eqs. 3, 16) in direct arithmetic (the sweep's fast path; equals the
    corresponding terms of :func:`energy_terms`)."""
    if prob.T == 0:
        return 0.0
    p0, p1 = poses[:-1], poses[1:]
    out = 0.0
    th = p0[:, 2]
    c, s = np.cos(th), np.sin(th)
    if W.use_motion:
        u, lat = prob.controls, prob.lat
        a0 = p0[:, 0] + prob.dt * u[:, 0] * c - prob.dt * lat * s - p1[:, 0]
        a1 = p0[:, 1] + prob.dt * u[:, 0] * s + prob.dt * lat * c - p1[:, 1]
        a2 = _wrap(th + prob.dt * u[:, 1] - p1[:, 2])
        out += W.R[0] * (a0 @ a0) + W.R[1] * (a1 @ a1) + W.R[2] * (a2 @ a2)
    if W.use_odometry:
        dx, dy = p1[:, 0] - p0[:, 0], p1[:, 1] - p0[:, 1]
        d = prob.odo_inc
        b0 = c * dx + s * dy - d[:, 0]
        b1 = -s * dx + c * dy - d[:, 1]
        b2 = _wrap(p1[:, 2] - th - d[:, 2])
        out += W.S[0] * (b0 @ b0) + W.S[1] * (b1 @ b1) + W.S[2] * (b2 @ b2)
    return float(out)


def observation_energy(points_xy, labels, landmarks_xy, Q) -> float:
    """``Σ_{c ≥ 0} ‖p_i − m_{c_i}‖²_Q`` for precomputed points ``h⁻¹(x_t, z_{t,i}) (N, 2)``."""
    ok = labels >= 0
    d = points_xy[ok] - landmarks_xy[labels[ok]]
    return float(Q[0] * np.sum(d[:, 0] ** 2) + Q[1] * np.sum(d[:, 1] ** 2))


# ------------------------------------------------------------------------------------------------------------
# per-step sufficient statistics of the observation potential
# ------------------------------------------------------------------------------------------------------------
def step_stats(prob: Problem, labels, landmarks_xy, W: Weights | None = None, obs_w=None) -> np.ndarray:
    """Sufficient statistics ``(14, T+1)`` of the observation part of the pose conditional.

    With ``e_i = p + R(θ) v_i − m_{c_i}`` (v_i = observation in the robot frame), the sum
    ``Σ_i e_iᵀ Q e_i`` over the observations at pose t depends on the data only through the rows
    ``n, Σv_x, Σv_y, Σm_x, Σm_y, Σv_x², Σv_xv_y, Σv_y², Σv_xm_x, Σv_xm_y, Σv_ym_x, Σv_ym_y, Σm_x², Σm_y²``.
    Observations with ``labels < 0`` are left out. With ``W`` the GPS fixes are added as weighted
    pseudo-observations (:func:`gps_step_stats`). With ``obs_w (N,)`` each observation's rows are scaled by its
    weight (the sum becomes ``Σ_i w_i e_iᵀ Q e_i``: the IRLS weights of a robust kernel).
    """
    labels = np.asarray(labels)
    ok = labels >= 0
    st = prob.step[ok]
    v = prob.v_body[ok]
    m = np.asarray(landmarks_xy, float)[labels[ok]]
    vx, vy, mx, my = v[:, 0], v[:, 1], m[:, 0], m[:, 1]
    K = prob.T + 1
    cols = [
        None,
        vx,
        vy,
        mx,
        my,
        vx * vx,
        vx * vy,
        vy * vy,
        vx * mx,
        vx * my,
        vy * mx,
        vy * my,
        mx * mx,
        my * my,
    ]
    out = gps_step_stats(prob, W) if W is not None else np.zeros((14, K))
    ow = None if obs_w is None else np.asarray(obs_w, float)[ok]
    for k, w in enumerate(cols):
        if ow is not None:
            w = ow if w is None else w * ow
        out[k] += np.bincount(st, weights=w, minlength=K)[:K]
    return out


# ------------------------------------------------------------------------------------------------------------
# 3-D conditional of one pose (eq. 14; eq. 11 with has_next = 0) — floats or arrays
# ------------------------------------------------------------------------------------------------------------
def _has_next(hn) -> bool:
    """False only for a Python float ``hn == 0`` (the last pose, the on-line init): its t+1 terms are
    ``0·(finite)`` and leave every sum as it is (up to the sign of a zero), so :func:`cond_cost` / :func:`cond_step` skip them.
    Arrays (the coding-scheme sweep) always take the full path."""
    return not isinstance(hn, float) or hn != 0.0


def cond_cost(x, y, th, ctx, st, Wf, dt, cos, sin):
    """Value of the terms of H that involve pose x_t = (x, y, th).

    ``ctx = (px, py, pth, gx, gy, gth, d0, d1, d2, hn, nx, ny, nth, v1, w1, e0, e1, e2, l1)``:
    previous pose, its motion prediction g(x_{t-1}, u_{t-1}), odometry increment of step t, ``hn`` = 1 if a next
    pose exists (0 drops every t+1 term, eq. 11), the next pose, the control u_t (twist ``[v1, w1]`` and lateral
    speed ``l1``, see :class:`Problem`) and the odometry increment of step t+1. ``st`` = the 14 sufficient statistics of :func:`step_stats` at t. ``Wf = Weights.flat``.
    """
    px, py, pth, gx, gy, gth, d0, d1, d2, hn, nx, ny, nth, v1, w1, e0, e1, e2, l1 = ctx
    r0, r1, r2, s0, s1, s2, q0, q1 = Wf
    n, V1x, V1y, M1x, M1y, Sxx, Sxy, Syy, Axx, Axy, Ayx, Ayy, Cmx, Cmy = st
    # motion t (eq. 3): g(x_{t-1}, u_{t-1}) − x_t
    a0 = gx - x
    a1 = gy - y
    a2 = _wrap(gth - th)
    cost = r0 * a0 * a0 + r1 * a1 * a1 + r2 * a2 * a2
    # odometry t (eq. 16): τ(θ_{t-1})(x_t − x_{t-1}) − d̃_t
    cp, sp = cos(pth), sin(pth)
    dx, dy = x - px, y - py
    b0 = cp * dx + sp * dy - d0
    b1 = -sp * dx + cp * dy - d1
    b2 = _wrap(th - pth - d2)
    cost = cost + s0 * b0 * b0 + s1 * b1 * b1 + s2 * b2 * b2
    c, s = cos(th), sin(th)
    if _has_next(hn):  # a last pose (float hn = 0) skips the t+1 terms: adding 0·(…) changes no value
        # motion t+1: g(x_t, u_t) − x_{t+1}
        f0 = x + dt * v1 * c - dt * l1 * s - nx
        f1 = y + dt * v1 * s + dt * l1 * c - ny
        f2 = _wrap(th + dt * w1 - nth)
        # odometry t+1: τ(θ_t)(x_{t+1} − x_t) − d̃_{t+1}
        ex, ey = nx - x, ny - y
        h0 = c * ex + s * ey - e0
        h1 = -s * ex + c * ey - e1
        h2 = _wrap(nth - th - e2)
        cost = cost + hn * (
            r0 * f0 * f0 + r1 * f1 * f1 + r2 * f2 * f2 + s0 * h0 * h0 + s1 * h1 * h1 + s2 * h2 * h2
        )
    # observations at t: Σ‖p + R(θ)v_i − m_i‖²_Q from the sufficient statistics
    RVx = c * V1x - s * V1y
    RVy = s * V1x + c * V1y
    Sxx_r = c * c * Sxx - 2.0 * c * s * Sxy + s * s * Syy
    Syy_r = s * s * Sxx + 2.0 * c * s * Sxy + c * c * Syy
    RxMx = c * Axx - s * Ayx
    RyMy = s * Axy + c * Ayy
    ex2 = n * x * x + Sxx_r + Cmx + 2.0 * x * RVx - 2.0 * x * M1x - 2.0 * RxMx
    ey2 = n * y * y + Syy_r + Cmy + 2.0 * y * RVy - 2.0 * y * M1y - 2.0 * RyMy
    return cost + q0 * ex2 + q1 * ey2


def cond_step(x, y, th, ctx, st, Wf, dt, cos, sin):
    """Gauss-Newton step ``δ = −(JᵀWJ)⁻¹ JᵀWe`` of the pose conditional at (x, y, th).

    Returns ``(δx, δy, δθ)`` (floats or arrays). Every Jacobian below is the analytic derivative of the
    corresponding residual in :func:`cond_cost` (tested against finite differences).
    """
    px, py, pth, gx, gy, gth, d0, d1, d2, hn, nx, ny, nth, v1, w1, e0, e1, e2, l1 = ctx
    r0, r1, r2, s0, s1, s2, q0, q1 = Wf
    n, V1x, V1y, M1x, M1y, Sxx, Sxy, Syy, Axx, Axy, Ayx, Ayy, _Cmx, _Cmy = st
    # motion t: J = −I
    a0 = gx - x
    a1 = gy - y
    a2 = _wrap(gth - th)
    H00 = r0
    H11 = r1
    H22 = r2
    H01 = 0.0
    H02 = 0.0
    H12 = 0.0
    g0 = -r0 * a0
    g1 = -r1 * a1
    g2 = -r2 * a2
    # odometry t: J = [[cp, sp, 0], [−sp, cp, 0], [0, 0, 1]]
    cp, sp = cos(pth), sin(pth)
    dx, dy = x - px, y - py
    b0 = cp * dx + sp * dy - d0
    b1 = -sp * dx + cp * dy - d1
    b2 = _wrap(th - pth - d2)
    H00 = H00 + s0 * cp * cp + s1 * sp * sp
    H01 = H01 + (s0 - s1) * cp * sp
    H11 = H11 + s0 * sp * sp + s1 * cp * cp
    H22 = H22 + s2
    g0 = g0 + cp * s0 * b0 - sp * s1 * b1
    g1 = g1 + sp * s0 * b0 + cp * s1 * b1
    g2 = g2 + s2 * b2
    c, s = cos(th), sin(th)
    if _has_next(hn):  # a last pose (float hn = 0) skips the t+1 terms (see cond_cost)
        # motion t+1: J = [[1, 0, −dt (v s + l c)], [0, 1, dt (v c − l s)], [0, 0, 1]]
        f0 = x + dt * v1 * c - dt * l1 * s - nx
        f1 = y + dt * v1 * s + dt * l1 * c - ny
        f2 = _wrap(th + dt * w1 - nth)
        j02 = -dt * v1 * s - dt * l1 * c
        j12 = dt * v1 * c - dt * l1 * s
        H00 = H00 + hn * r0
        H11 = H11 + hn * r1
        H02 = H02 + hn * r0 * j02
        H12 = H12 + hn * r1 * j12
        H22 = H22 + hn * (r0 * j02 * j02 + r1 * j12 * j12 + r2)
        g0 = g0 + hn * r0 * f0
        g1 = g1 + hn * r1 * f1
        g2 = g2 + hn * (r0 * j02 * f0 + r1 * j12 * f1 + r2 * f2)
        # odometry t+1: J = [[−c, −s, k02], [s, −c, k12], [0, 0, −1]]
        ex, ey = nx - x, ny - y
        h0 = c * ex + s * ey - e0
        h1 = -s * ex + c * ey - e1
        h2 = _wrap(nth - th - e2)
        k02 = -s * ex + c * ey
        k12 = -c * ex - s * ey
        H00 = H00 + hn * (s0 * c * c + s1 * s * s)
        H01 = H01 + hn * (s0 - s1) * c * s
        H11 = H11 + hn * (s0 * s * s + s1 * c * c)
        H02 = H02 + hn * (-c * s0 * k02 + s * s1 * k12)
        H12 = H12 + hn * (-s * s0 * k02 - c * s1 * k12)
        H22 = H22 + hn * (s0 * k02 * k02 + s1 * k12 * k12 + s2)
        g0 = g0 + hn * (-c * s0 * h0 + s * s1 * h1)
        g1 = g1 + hn * (-s * s0 * h0 - c * s1 * h1)
        g2 = g2 + hn * (k02 * s0 * h0 + k12 * s1 * h1 - s2 * h2)
    # observations: J_i = [[1, 0, −(Rv)_y], [0, 1, (Rv)_x]]
    RVx = c * V1x - s * V1y
    RVy = s * V1x + c * V1y
    Sxx_r = c * c * Sxx - 2.0 * c * s * Sxy + s * s * Syy
    Syy_r = s * s * Sxx + 2.0 * c * s * Sxy + c * c * Syy
    Sxy_r = c * s * (Sxx - Syy) + (c * c - s * s) * Sxy
    RxMy = c * Axy - s * Ayy
    RyMx = s * Axx + c * Ayx
    H00 = H00 + n * q0
    H11 = H11 + n * q1
    H02 = H02 - q0 * RVy
    H12 = H12 + q1 * RVx
    H22 = H22 + q0 * Syy_r + q1 * Sxx_r
    g0 = g0 + q0 * (n * x + RVx - M1x)
    g1 = g1 + q1 * (n * y + RVy - M1y)
    g2 = g2 - q0 * (x * RVy - RyMx + Sxy_r) + q1 * (y * RVx - RxMy + Sxy_r)
    # solve the symmetric 3×3 system (cofactors), tiny relative damping against singular conditionals
    mu = 1e-12 * (H00 + H11 + H22) + 1e-300
    H00 = H00 + mu
    H11 = H11 + mu
    H22 = H22 + mu
    C00 = H11 * H22 - H12 * H12
    C01 = H02 * H12 - H01 * H22
    C02 = H01 * H12 - H02 * H11
    C11 = H00 * H22 - H02 * H02
    C12 = H01 * H02 - H00 * H12
    C22 = H00 * H11 - H01 * H01
    det = H00 * C00 + H01 * C01 + H02 * C02
    inv = -1.0 / det
    return (
        inv * (C00 * g0 + C01 * g1 + C02 * g2),
        inv * (C01 * g0 + C11 * g1 + C12 * g2),
        inv * (C02 * g0 + C12 * g1 + C22 * g2),
    )


def cond_minimise_scalar(x, y, th, ctx, st, Wf, dt, iters: int, tol: float):
    """Conditional mode of one pose by ≤ ``iters`` Gauss-Newton steps with step halving (plain floats).

    Every accepted step lowers the conditional cost, hence the energy. Returns the new ``(x, y, th)``.
    """
    cos, sin = _cos, _sin
    f = cond_cost(x, y, th, ctx, st, Wf, dt, cos, sin)
    for _ in range(iters):
        dx, dy, dth = cond_step(x, y, th, ctx, st, Wf, dt, cos, sin)
        if not (math.isfinite(dx) and math.isfinite(dy) and math.isfinite(dth)):
            break
        alpha = 1.0
        accepted = False
        for _h in range(6):
            xn, yn, thn = x + alpha * dx, y + alpha * dy, _wrap(th + alpha * dth)
            fn = cond_cost(xn, yn, thn, ctx, st, Wf, dt, cos, sin)
            if fn <= f:
                accepted = True
                break
            if abs(dx) + abs(dy) + abs(dth) < 1e-6:  # failed tiny step: rounding noise, the mode is reached
                break
            alpha *= 0.5
        if not accepted:
            break
        x, y, th, f_old, f = xn, yn, thn, f, fn
        if alpha * (abs(dx) + abs(dy) + abs(dth)) < tol or f_old - f <= 1e-15 * (1.0 + f_old):
            break
    return x, y, th


def cond_minimise_batch(xs, ctx, st, Wf, dt, iters: int):
    """Vectorised :func:`cond_minimise_scalar` for poses that are conditionally independent.

    ``xs (K, 3)``; ``ctx`` / ``st`` are tuples of ``(K,)`` arrays. Backtracking is per pose (masked).
    """
    x, y, th = xs[:, 0].copy(), xs[:, 1].copy(), xs[:, 2].copy()
    cos, sin = np.cos, np.sin
    f = cond_cost(x, y, th, ctx, st, Wf, dt, cos, sin)
    for _ in range(iters):
        dx, dy, dth = cond_step(x, y, th, ctx, st, Wf, dt, cos, sin)
        # non-finite or negligible steps: that pose stays (its conditional mode is reached)
        done = ~(np.isfinite(dx) & np.isfinite(dy) & np.isfinite(dth))
        mag = np.abs(dx) + np.abs(dy) + np.abs(dth)
        done |= mag < 1e-9
        if done.all():
            break
        dx[done] = 0.0
        dy[done] = 0.0
        dth[done] = 0.0
        alpha = np.ones_like(x)
        xn, yn, thn, fn = x.copy(), y.copy(), th.copy(), f.copy()
        for _h in range(5):
            tx, ty, tth = x + alpha * dx, y + alpha * dy, _wrap(th + alpha * dth)
            ft = cond_cost(tx, ty, tth, ctx, st, Wf, dt, cos, sin)
            ok = (ft <= f) & ~done
            xn[ok], yn[ok], thn[ok], fn[ok] = tx[ok], ty[ok], tth[ok], ft[ok]
            done |= ok
            if _h == 0:  # a failed full step below 1e-6 is rounding noise of the cost: the mode is reached
                done |= mag < 1e-6
            if done.all():
                break
            alpha = np.where(done, alpha, 0.5 * alpha)
        x, y, th, f = xn, yn, thn, fn
    return np.stack([x, y, th], -1)


def pose_contexts(prob: Problem, poses, idx):
    """Contexts of :func:`cond_cost` for the poses ``idx (K,)`` (all ≥ 1) as a tuple of ``(K,)`` arrays."""
    T = prob.T
    idx = np.asarray(idx, np.int64)
    prev = poses[idx - 1]
    lat = prob.lat
    g = _motion(prev, prob.controls[idx - 1], prob.dt, lat[idx - 1])
    d = prob.odo_inc[idx - 1]
    hn = (idx < T).astype(float)
    jn = np.minimum(idx + 1, T)
    nxt = poses[jn]
    un = prob.controls[np.minimum(idx, T - 1)]
    en = prob.odo_inc[np.minimum(idx, T - 1)]
    return (
        prev[:, 0],
        prev[:, 1],
        prev[:, 2],
        g[:, 0],
        g[:, 1],
        g[:, 2],
        d[:, 0],
        d[:, 1],
        d[:, 2],
        hn,
        nxt[:, 0],
        nxt[:, 1],
        nxt[:, 2],
        un[:, 0],
        un[:, 1],
        en[:, 0],
        en[:, 1],
        en[:, 2],
        lat[np.minimum(idx, T - 1)],
    )


def _motion(x, u, dt, lat):
    """g(x, u) = p + dt·R(θ)[v, lat], θ + dt·ω without the heading wrap (residuals wrap themselves)."""
    c, s = np.cos(x[:, 2]), np.sin(x[:, 2])
    return np.stack(
        [
            x[:, 0] + dt * u[:, 0] * c - dt * lat * s,
            x[:, 1] + dt * u[:, 0] * s + dt * lat * c,
            x[:, 2] + dt * u[:, 1],
        ],
        -1,
    )


# ------------------------------------------------------------------------------------------------------------
# sweeps over the poses
# ------------------------------------------------------------------------------------------------------------
def sweep_poses_sequential(prob: Problem, W: Weights, poses, stats, iters: int = 3, tol: float = 1e-10):
    """Paper-exact visit x_1, x_2, …, x_T (eq. 14), each pose moved to its conditional mode in place.

    ``poses (T+1, 3)`` is modified in place; ``stats (14, T+1)`` from :func:`step_stats`. With numba installed
    (optional extra ``fast``) and at least :data:`JIT_MIN_POSES` poses the same loop runs compiled
    (:func:`compiled_kernels`); the poses are the same floats either way.
    """
    Wf = W.flat
    jit = compiled_kernels() if prob.T + 1 >= JIT_MIN_POSES else None
    if jit is not None:
        P = np.ascontiguousarray(poses, float)
        arr = functools.partial(np.ascontiguousarray, dtype=float)  # one compiled signature
        jit.sequential_loop(P, arr(prob.controls), arr(prob.lat), arr(prob.odo_inc), arr(stats.T), Wf,
                            float(prob.dt), int(iters), float(tol), int(prob.T))
        poses[:] = P
        return poses
    P = poses.tolist()
    sequential_loop(P, prob.controls.tolist(), prob.lat.tolist(), prob.odo_inc.tolist(), stats.T.tolist(), Wf,
                    prob.dt, iters, tol, prob.T)
    poses[:] = P
    return poses


def sequential_loop(P, U, LAT, D, ST, Wf, dt, iters, tol, T):
    """The loop of :func:`sweep_poses_sequential` over rows ``P[t] = [x, y, θ]`` (in place), controls ``U``,
    lateral speeds ``LAT``, odometry increments ``D`` and statistics ``ST[t]`` (14): nested lists in Python,
    arrays in its compiled copy (one source for both)."""
    for t in range(1, T + 1):
        px, py, pth = P[t - 1][0], P[t - 1][1], P[t - 1][2]
        v0, w0 = U[t - 1][0], U[t - 1][1]
        l0, cp, sp = LAT[t - 1], _cos(pth), _sin(pth)
        gx, gy, gth = px + dt * v0 * cp - dt * l0 * sp, py + dt * v0 * sp + dt * l0 * cp, pth + dt * w0
        d = D[t - 1]
        if t < T:
            nx, ny, nth = P[t + 1][0], P[t + 1][1], P[t + 1][2]
            v1, w1 = U[t][0], U[t][1]
            e = D[t]
            ctx = (px, py, pth, gx, gy, gth, d[0], d[1], d[2], 1.0, nx, ny, nth, v1, w1, e[0], e[1], e[2], LAT[t])
        else:
            ctx = (px, py, pth, gx, gy, gth, d[0], d[1], d[2], 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0)
        s = ST[t]
        st = (s[0], s[1], s[2], s[3], s[4], s[5], s[6], s[7], s[8], s[9], s[10], s[11], s[12], s[13])
        x, y, th = cond_minimise_scalar(P[t][0], P[t][1], P[t][2], ctx, st, Wf, dt, iters, tol)
        P[t][0], P[t][1], P[t][2] = x, y, th


def sweep_poses_parallel(prob: Problem, W: Weights, poses, stats, iters: int = 3):
    """Coding-scheme sweep: all odd poses at once, then all even poses (each colour class is conditionally
    independent given the map, the matchings and the other colour). In place."""
    T = prob.T
    for first in (1, 2):
        idx = np.arange(first, T + 1, 2)
        if idx.size == 0:
            continue
        ctx = pose_contexts(prob, poses, idx)
        st = tuple(stats[:, idx])
        poses[idx] = cond_minimise_batch(poses[idx], ctx, st, W.flat, prob.dt, iters)
    return poses


# ------------------------------------------------------------------------------------------------------------
# joint problem over all poses and the map (fixed matchings): whitened residuals and sparse Jacobian
# ------------------------------------------------------------------------------------------------------------
def joint_residuals(prob: Problem, W: Weights, poses, landmarks, labels, *, jacobian: bool = True, obs_w=None):
    """Whitened residual vector ``r`` (so that ``‖r‖² = H``) and its sparse Jacobian w.r.t.
    ``[x_1 … x_T (3T), m (2L)]`` (x_0 is fixed). With ``obs_w (N,)`` the rows of observation i are scaled by
    ``√w_i`` (an IRLS step of a robust kernel).

    Returns ``(r (M,), J (M, 3T+2L) csr or None)``.
    """
    T = prob.T
    L = landmarks.shape[0]
    n_var = 3 * T + 2 * L
    res, rows, cols, vals = [], [], [], []
    row0 = 0

    def add_block(r, sw, blocks):
        # r (K, k) residuals; sw (k,) sqrt-weights; blocks: list of (J (K, k, d), col_index (K, d))
        nonlocal row0
        K, k = r.shape
        sw = np.broadcast_to(sw, (K, k))  # (k,) per block or (K, k) per row
        res.append((r * sw).ravel())
        if jacobian:
            ridx = row0 + np.arange(K * k).reshape(K, k)
            for Jb, cidx in blocks:
                valid = cidx[:, 0] >= 0
                Jw = Jb[valid] * sw[valid][:, :, None]
                d = Jb.shape[2]
                rows.append(np.repeat(ridx[valid][:, :, None], d, axis=2).ravel())
                cols.append(np.repeat(cidx[valid][:, None, :], k, axis=1).ravel())
                vals.append(Jw.ravel())
        row0 += K * k

    t = np.arange(1, T + 1)
    pose_cols = lambda tt: np.where(tt[:, None] >= 1, 3 * (tt[:, None] - 1) + np.arange(3)[None, :], -1)
    if W.use_motion and T > 0:
        r = wrap_angle_last(prob.motion_prediction(poses[:-1]) - poses[1:])
        Ja, Jb = motion_jacobians(prob, poses)
        add_block(r, np.sqrt(W.R), [(Ja, pose_cols(t - 1)), (Jb, pose_cols(t))])
    if W.use_odometry and T > 0:
        r = wrap_angle_last(se2.between(poses[:-1], poses[1:]) - prob.odo_inc)
        Ja, Jb = potentials.odometry_residual_jacobians(poses[:-1], poses[1:])
        add_block(r, np.sqrt(W.S), [(Ja, pose_cols(t - 1)), (Jb, pose_cols(t))])
    ok = np.asarray(labels) >= 0
    if ok.any():
        st = prob.step[ok]
        lab = np.asarray(labels)[ok]
        r = potentials.observation_residual(poses[st], prob.z[ok], landmarks[lab])
        Jx, Jm = potentials.observation_residual_jacobians(poses[st], prob.z[ok])
        mcols = 3 * T + 2 * lab[:, None] + np.arange(2)[None, :]
        sq = np.sqrt(W.Q) if obs_w is None else np.sqrt(W.Q)[None, :] * np.sqrt(np.asarray(obs_w, float)[ok])[:, None]
        add_block(r, sq, [(Jx, pose_cols(st)), (Jm, mcols)])
    if W.K and prob.gps_step.size:
        g = prob.gps_step
        r = poses[g, :2] - prob.gps_xy
        Jg = np.zeros((len(g), 2, 3))
        Jg[:, 0, 0] = Jg[:, 1, 1] = 1.0
        add_block(r, np.sqrt(np.array([W.K, W.K])), [(Jg, pose_cols(g))])
    rvec = np.concatenate(res) if res else np.zeros(0)
    if not jacobian:
        return rvec, None
    J = sp.csr_matrix(
        (
            np.concatenate(vals) if vals else np.zeros(0),
            (
                np.concatenate(rows) if rows else np.zeros(0, int),
                np.concatenate(cols) if cols else np.zeros(0, int),
            ),
        ),
        shape=(row0, n_var),
    )
    return rvec, J


def motion_jacobians(prob: Problem, poses):
    """``(∂r/∂x_{t-1}, ∂r/∂x_t)``, each ``(T, 3, 3)``, of the motion residuals ``r_t = g(x_{t-1}, u_{t-1}) − x_t``
    of ``poses (T+1, 3)`` by the dataset's own model (DDMR, or the shared car model)."""
    if prob.car_controls is not None:  # ∂g/∂x of the shared car model, ∂r/∂x_t = −I
        Ja = ackermann_jacobians(poses[:-1], prob.car_controls, prob.dt, prob.vehicle)[0]
        return Ja, np.broadcast_to(-np.eye(3), Ja.shape).copy()
    Ja, Jb = potentials.motion_residual_jacobians(poses[:-1], prob.controls, poses[1:], prob.dt)
    if prob.lateral is not None:  # ∂/∂θ of dt·R(θ)[0, v_y]
        Ja[:, 0, 2] -= prob.dt * prob.lateral * np.cos(poses[:-1, 2])
        Ja[:, 1, 2] -= prob.dt * prob.lateral * np.sin(poses[:-1, 2])
    return Ja, Jb


def solve_normal_schur(J, r, n_pose: int, damping: float = 1e-9) -> np.ndarray:
    """Gauss-Newton step ``δ = −(JᵀJ)⁻¹Jᵀr`` by the Schur complement on the map.

    The pose block of JᵀJ is block-tridiagonal (motion/odometry chain + per-pose observation blocks), so it is
    factorised with a banded (natural-order) sparse LU; the reduced map system ``S = H_mm − H_mp H_pp⁻¹ H_pm``
    is dense ``(2L, 2L)``. A tiny relative diagonal keeps unobserved variables solvable.
    """
    H = (J.T @ J).tocsc()
    g = J.T @ r
    n = H.shape[0]
    diag = H.diagonal()
    H = (H + sp.diags(damping * (diag + (diag == 0)), format="csc")).tocsc()
    P = slice(0, n_pose)
    M = slice(n_pose, n)
    Hpp = H[P, P].tocsc()
    lu = spla.splu(Hpp, permc_spec="NATURAL")
    if n == n_pose:
        return -lu.solve(g)
    Hpm = H[P, M].toarray()
    Hmm = H[M, M].toarray()
    X = lu.solve(Hpm)  # H_pp⁻¹ H_pm
    y = lu.solve(g[P])  # H_pp⁻¹ g_p
    S = Hmm - Hpm.T @ X
    dm = np.linalg.solve(S, -(g[M] - Hpm.T @ y))
    dp = -(y + X @ dm)
    return np.concatenate([dp, dm])


def solve_normal_sparse(J, r, damping: float = 1e-9) -> np.ndarray:
    """Gauss-Newton step ``δ = −(JᵀJ)⁻¹Jᵀr`` by one sparse LU of the whole normal matrix with a fill-reducing
    minimum-degree ordering of ``H + Hᵀ`` (symmetric mode) — :func:`slamcli.solvers.nls.factorize_information`,
    the factorisation graph SLAM uses; a singular system raises ``numpy.linalg.LinAlgError``.

    Nothing dense of size poses × landmarks is ever formed (:func:`solve_normal_schur`'s ``H_pp⁻¹ H_pm`` is a
    dense ``3T × 2L`` block: 9.2 GB at 100k poses and ~5k landmarks). The ordering adapts to both shapes of the
    problem: few landmarks seen from many poses (the paper's laser worlds: the landmarks end up last, a small
    dense Schur complement) and many landmarks seen from few poses (city-scale worlds: fill stays local).
    The same tiny relative diagonal as the Schur variant keeps unobserved variables solvable.
    """
    H = (J.T @ J).tocsc()
    g = J.T @ r
    diag = H.diagonal()
    H = (H + sp.diags(damping * (diag + (diag == 0)), format="csc")).tocsc()
    return -factorize_information(H).solve(g)


def pack(poses, landmarks) -> np.ndarray:
    return np.concatenate([poses[1:].ravel(), landmarks.ravel()])


def unpack(prob: Problem, vec, L: int):
    T = prob.T
    poses = np.empty((T + 1, 3))
    poses[0] = prob.x0
    poses[1:] = vec[: 3 * T].reshape(T, 3)
    poses[1:, 2] = wrap_angle(poses[1:, 2])
    return poses, vec[3 * T :].reshape(L, 2).copy()


def joint_gn_step(prob: Problem, W: Weights, poses, landmarks, labels, *, max_halvings: int = 12):
    """One joint Gauss-Newton step over all poses and the map with fixed matchings, with backtracking.

    Returns ``(poses, landmarks, energy, accepted, error)``; when no step length lowers H the input is returned
    unchanged (so every accepted step is a strict decrease of the same energy ICM minimises). ``error`` is
    None, or one line saying why no step could be computed (a MemoryError or a singular system) — the caller
    reports it in the result, it is never swallowed.
    """
    L = landmarks.shape[0]
    r, J = joint_residuals(prob, W, poses, landmarks, labels)
    f0 = float(r @ r)
    try:
        delta = solve_normal_sparse(J, r)
    except MemoryError as exc:
        return poses, landmarks, f0, False, f"MemoryError in the joint step ({exc})"
    except (np.linalg.LinAlgError, RuntimeError, ValueError) as exc:
        return poses, landmarks, f0, False, f"{type(exc).__name__}: {str(exc).splitlines()[0] if str(exc) else ''}"
    if delta.size == 0 or not np.all(np.isfinite(delta)):
        return poses, landmarks, f0, False, (None if delta.size == 0 else "non-finite joint step")
    base = pack(poses, landmarks)
    alpha = 1.0
    for _ in range(max_halvings):
        p_new, m_new = unpack(prob, base + alpha * delta, L)
        f_new = energy(prob, W, p_new, m_new, labels)
        if f_new < f0:
            return p_new, m_new, f_new, True, None
        alpha *= 0.5
    return poses, landmarks, f0, False, None


def map_energy_fixed_assoc(
    prob: Problem, W: Weights, poses, landmarks, labels, *, max_iters: int = 100, rtol: float = 1e-13
):
    """MAP optimum of H over all poses and the map for fixed matchings, by joint Gauss-Newton from the given
    point. Returns ``(poses, landmarks, energy, iterations)``."""
    f = energy(prob, W, poses, landmarks, labels)
    for it in range(1, max_iters + 1):
        poses, landmarks, f_new, ok, _err = joint_gn_step(prob, W, poses, landmarks, labels)
        if not ok:
            return poses, landmarks, f, it
        done = f - f_new <= rtol * max(f, 1e-300)
        f = f_new
        if done:
            return poses, landmarks, f, it
    return poses, landmarks, f, max_iters


def laplace_covariances(prob: Problem, W: Weights, poses, landmarks, labels, *, chunk: int = 512):
    """Marginal covariances from the Laplace approximation ``Σ = (JᵀJ)⁻¹`` at the estimate (fixed matchings).

    The weight matrices are read as information matrices (Gibbs temperature 2, so P ∝ exp(−H/2) is the
    Gaussian with information JᵀJ). Returns ``pose_cov (T+1, 3, 3)`` (zero at the fixed x_0) and
    ``landmark_cov (L, 2, 2)``: the diagonal blocks of the inverse — marginals, not the conditional curvature
    ICM uses internally — by the one marginals path of slamcli,
    :func:`slamcli.solvers.nls.marginals.block_marginals` (``chunk`` columns of the inverse per batch when it
    solves for columns).

    Raises
    ------
    numpy.linalg.LinAlgError
        ``JᵀJ`` is not numerically positive definite (e.g. a landmark no kept sighting constrains); the
        message names the pose ``t`` (1..T) or landmark.
    """
    T, L = prob.T, landmarks.shape[0]
    _, J = joint_residuals(prob, W, poses, landmarks, labels)
    H = (J.T @ J).tocsc()
    pose_cols = np.arange(3 * T).reshape(T, 3)  # x_1..x_T; x_0 is held fixed
    lm_cols = 3 * T + np.arange(2 * L).reshape(L, 2)

    def locate(c: int) -> str:
        return f"pose {c // 3 + 1}" if c < 3 * T else f"landmark {(c - 3 * T) // 2}"

    pc, lm_cov = block_marginals(H, (pose_cols, lm_cols), names=("pose", "landmark"), chain=T, locate=locate,
                                 batch_size=chunk)
    pose_cov = np.zeros((T + 1, 3, 3))
    pose_cov[1:] = pc
    return pose_cov, lm_cov


# ------------------------------------------------------------------------------------------------------------
# compiled copies of the scalar kernels (optional extra ``fast``: numba)
# ------------------------------------------------------------------------------------------------------------
#: poses from which :func:`sweep_poses_sequential` and the on-line init run the compiled kernels: loading them
#: (numba's import and its on-disk cache) costs about as much as a few Python sweeps of this many poses
#: (benchmarks/results/design_notes.md); the results are the same floats either way
JIT_MIN_POSES = 1000
#: set to 1 to keep the pure-Python kernels even when numba is installed
NO_JIT_ENV = "SLAMCLI_NO_JIT"


@functools.cache
def _build_kernels():
    try:
        import numba
    except ImportError:
        return None
    jit = functools.partial(numba.njit, cache=True)
    env = dict(globals(), _wrap=jit(wrap_angle_fast), _has_next=jit(_has_next))

    def same_source(fn):  # the function's own code object, compiled against the jitted helpers
        f = types.FunctionType(fn.__code__, env, fn.__name__, fn.__defaults__)
        f.__qualname__ = fn.__qualname__
        return jit(f)

    env["cond_cost"] = same_source(cond_cost)
    env["cond_step"] = same_source(cond_step)
    env["cond_minimise_scalar"] = same_source(cond_minimise_scalar)
    k = types.SimpleNamespace(cond_minimise_scalar=env["cond_minimise_scalar"],
                              sequential_loop=same_source(sequential_loop))
    try:  # compile (or load from numba's cache) the one signature of each entry point now
        P = np.zeros((3, 3))
        k.sequential_loop(P, np.zeros((2, 2)), np.zeros(2), np.zeros((2, 3)), np.zeros((3, 14)), (1.0,) * 8, 0.1, 1,
                          0.0, 2)
        k.cond_minimise_scalar(0.0, 0.0, 0.0, (0.0,) * 19, (0.0,) * 14, (1.0,) * 8, 0.1, 1, 0.0)
    except Exception as exc:  # noqa: BLE001 - e.g. a stale numba cache; the Python kernels give the same floats
        warnings.warn(f"numba kernels unavailable, ICM runs its Python kernels ({type(exc).__name__}: {exc})",
                      RuntimeWarning, stacklevel=2)
        return None
    return k


def compiled_kernels():
    """numba-compiled :func:`cond_minimise_scalar` and :func:`sequential_loop` (same source, same IEEE
    arithmetic, no fast-math: tested equal to the Python kernels bit for bit), or None when numba is not
    installed or ``SLAMCLI_NO_JIT=1``. Compiled once per process; numba caches the machine code on disk."""
    if os.environ.get(NO_JIT_ENV, "") not in ("", "0"):
        return None
    return _build_kernels()
