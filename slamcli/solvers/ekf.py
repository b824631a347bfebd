# pylint: disable=invalid-name
"""EKF-SLAM: extended Kalman filter over the joint state ``[pose, landmarks]``.

The textbook predict → update cycle (Probabilistic Robotics ch. 10; paper 003; paper 002 §14.7 for unknown
correspondences), with filterpy's letters: ``Q`` process (motion) noise, ``R`` measurement noise, ``S`` the
innovation covariance.

* state ``x = [x_r (3,), m_1 (2,), ..., m_L (2,)]``, ``n = 3 + 2L``, covariance ``P (n, n)``, in preallocated
  zero-padded buffers updated in place (the state grows by two entries per new landmark);
* **predict** touches only the pose rows/columns (O(n)): the DDMR model driven by the controls with
  ``NoiseSpec.motion_std`` (``motion_input="controls"``) or the composition with the odometry increment with
  ``NoiseSpec.odometry_std`` (``motion_input="odometry"``);
* **update** with one range-bearing observation is O(n²): the rank-2 correction ``P −= V Vᵀ``, equal to the
  Joseph form for the gain ``K = P Hᵀ S⁻¹`` (:func:`update_inplace`); a step's observations in sequence;
* **association**: ``known`` uses ``observations.reported_id``; ``ml`` is the gated nearest neighbour in
  Mahalanobis distance (smallest ``d²``, so gate and choice use one statistic), a new landmark beyond a second
  χ² threshold, and an optional provisional list (paper 002 §14.1);
* optional GPS position fixes (linear update ``H = [I₂ 0]``) and **stabilising noise** (paper 001 §III):
  ``obs_std_scale``, ``motion_std_scale`` and ``stabilising_pose_std``.

The numerical core is module functions: in-place kernels (:func:`predict_inplace`, :func:`update_inplace`,
:func:`update_position_inplace`), pure twins that copy first (:func:`predict`, :func:`update`,
:func:`update_position`), :func:`landmark_init` and :func:`innovation_stats`; the class is a thin driver.
"""

from __future__ import annotations

import math
import time

import numpy as np

from slamcli.errors import SolverError
from slamcli.models.ackermann import ackermann_jacobians, ackermann_step
from slamcli.models.angles import wrap_angle, wrap_angle_fast
from slamcli.models.motion import odometry_increments
from slamcli.models.observation import (
    inverse_range_bearing,
    inverse_range_bearing_jacobians,
    mean_surface_offset,
    measurement_residual,
    range_bearing,
    range_bearing_jacobians,
)
from slamcli.models.se2 import rot2
from slamcli.params import check_allocation
from slamcli.solvers.base import BaseSolver
from slamcli.solvers.ekf_params import EkfParams
from slamcli.solvers.frontend import group_detections, inside_declared_size, resolve_motion_input
from slamcli.solvers.surface import declared_radius, require_radius
from slamcli.types import SlamInputs, SolverResult, Status


class _Candidate:
    """A provisional landmark (paper 002 §14.1): position, 2×2 covariance, sightings."""

    __slots__ = ("C", "first_frame", "hits", "m", "rows")

    def __init__(self, m, C, frame, rows):
        self.m = m
        self.C = C
        self.hits = 1
        self.first_frame = frame
        self.rows = list(rows)


class _GrowingState:
    """State ``x (n,)`` and covariance ``P (n, n)`` inside zero-padded, preallocated buffers.

    The in-place kernels (:func:`predict_inplace`, :func:`update_inplace`, ...) run on the padded pair
    ``xa (nₐ,)``, ``Pa (nₐ, nₐ)`` with ``nₐ ≥ n``: ``Pa`` is C-contiguous (numpy's in-place rank-k update on a
    strided ``[:n, :n]`` window of a larger square buffer is slower) and its
    rows/columns beyond ``n`` are exactly zero, which every kernel keeps exactly zero (their rows of
    ``P Hᵀ`` are 0), so the padding changes no number. ``x`` and ``P`` are the active ``[:n]`` views.

    Adding a landmark writes its two rows/columns into the padding (O(n)); only when the padding is used
    up is the block re-laid out into a fresh zeroed buffer with room for ``max(4, L/32)`` more landmarks
    (one O(n²) copy per L/32 additions: amortised O(n) per landmark, and at most ≈ 6 % extra work per
    update from the padding).
    """

    def __init__(self, x0, P0, cap_landmarks: int = 4):
        self.n = 3
        self._alloc(3 + 2 * cap_landmarks)
        self.x[:] = x0
        self.P[:] = P0

    def _alloc(self, na: int) -> None:
        """Move the active block into fresh zeroed buffers of size ``na ≥ n``."""
        n = self.n
        check_allocation("landmarks", (na - 3) // 2, 8.0 * na * na, "the EKF's joint covariance",
                         "the data make more landmarks than an EKF can hold; try -m graph or -m icm")
        xa, Pa = np.zeros(na), np.zeros((na, na))
        if hasattr(self, "xa"):
            xa[:n] = self.x
            Pa[:n, :n] = self.P
        self.xa, self.Pa = xa, Pa
        self._views()

    def _views(self) -> None:
        self.x = self.xa[: self.n]
        self.P = self.Pa[: self.n, : self.n]

    def append_landmark(self, m, P_mx, P_mm) -> int:
        """Add landmark ``m (2,)`` with cross-covariance ``P_mx (2, n)`` and ``P_mm (2, 2)``; return its index."""
        n, n2 = self.n, self.n + 2
        if n2 > self.xa.shape[0]:
            self._alloc(n2 + 2 * max(4, (n2 - 3) // 64))
        self.n = n2
        self._views()
        self.x[n:n2] = m
        self.P[n:n2, :n] = P_mx
        self.P[:n, n:n2] = P_mx.T
        self.P[n:n2, n:n2] = P_mm
        return (n - 3) // 2


class EkfSlam(BaseSolver):
    """EKF-SLAM with known or maximum-likelihood data association.

    Output (:class:`~slamcli.types.SolverResult`): ``poses_xyt (T+1, 3)`` filtered estimate of every step,
    ``landmarks_xy (L', 2)`` final map (rows in order of creation), ``assoc (N,)`` landmark row per
    observation (−1 = discarded / unconfirmed), ``pose_cov (T+1, 3, 3)`` filtered pose block at every step,
    ``landmark_cov (L', 2, 2)`` final landmark blocks, ``extra`` with the mean NIS and counters.
    A one-pass filter: ``init`` is ignored and ``rng`` is not used (the filter is deterministic).
    """

    name = "ekf"
    Params = EkfParams
    #: ackermann: the predict step uses slamcli.models.ackermann (controls = [v_e, α], noise motion_std)
    motion_models = ("ddmr", "ackermann")

    def solve(self, inputs: SlamInputs, *, init=None, rng: np.random.Generator, progress=None) -> SolverResult:
        t_start = time.perf_counter()
        p: EkfParams = self.params
        obs = inputs.observations
        T = inputs.n_poses - 1
        z_all = obs.z  # (N, 2)
        rho = declared_radius(inputs)  # the dataset's landmark radius per row, or None
        if p.surface:
            z_all[:, 0] += mean_surface_offset(require_radius(inputs, "ekf"))
        N = z_all.shape[0]
        sensor = np.asarray(obs.sensor)
        rid = np.asarray(obs.reported_id, np.int64)
        p, gate, new_thr = _resolve_association(p, rid, N)
        if p.motion_input == "auto":
            from dataclasses import replace

            p = replace(p, motion_input=resolve_motion_input(p.motion_input, inputs))
        obs_cov, Q_stab, motion_cov, drive = _noise_and_drive(inputs, p, T)
        gps_at, gps_cov = _gps_fixes(inputs, p)

        st = _GrowingState(np.asarray(inputs.x0, float), np.diag(np.square(np.asarray(p.init_pose_std, float))))
        poses = np.empty((T + 1, 3))
        pose_cov = np.empty((T + 1, 3, 3))
        assoc = np.full(N, -1, np.int64)
        id_to_lm: dict[int, int] = {}
        candidates: list[_Candidate] = []
        tally = _Tally()
        report_every = max(1, (T + 1) // 100)
        frame = -1  # sensor frames so far (steps that carry observation rows): the provisional window's clock

        for t in range(T + 1):
            # ---------------- predict (pose block only) ----------------
            if t > 0:
                _predict_pose(st, inputs, p.motion_input, drive[t - 1], motion_cov, Q_stab)

            # ---------------- GPS position fix (linear update) ----------------
            if t in gps_at:
                update_position_inplace(st.xa, st.Pa, gps_at[t], gps_cov)

            # ---------------- update with the rows of step t ----------------
            lo, hi = int(obs.offsets[t]), int(obs.offsets[t + 1])
            frame += hi > lo
            # Rows of landmarks not yet in the state (known: a new id; ml: no plausible state landmark) wait until
            # the step's re-observations are fused: they are appended to ``dets`` and visited after the first
            # pass, so h⁻¹ is linearised at the updated pose, not the predicted one (a far landmark initialised
            # from a pose with large heading noise is metres off the tangent line its linearised P_mx assumes;
            # benchmarks/results/design_notes.md). In the second pass a second row of a new id / ml match
            # updates the landmark the first one created.
            dets = group_detections(z_all, sensor, rid, lo, hi, st.x[:3], group=p.group_returns,
                                    association=p.association, group_dist=p.group_dist,
                                    range_offset=p.range_offset)
            _update_step(st, dets, frame, p, sensor, rid, obs_cov, gate, new_thr, assoc, id_to_lm, candidates, tally,
                         rho if p.size_gate else None)

            if p.provisional and candidates:
                tally.n_dropped += _drop_stale_candidates(candidates, frame, p.provisional_window)

            poses[t] = st.x[:3]
            P_rr = st.P[:3, :3]
            pose_cov[t] = 0.5 * (P_rr + P_rr.T)
            if progress is not None and (t % report_every == 0 or t == T):
                progress(t + 1, T + 1)

        L = (st.n - 3) // 2
        if not (np.all(np.isfinite(poses)) and np.all(np.isfinite(st.P))):
            status, message = Status.FAILED, "non-finite state or covariance (numerical breakdown)"
        else:
            status, message = Status.COMPLETED, f"filtered {T + 1} steps, {tally.n_upd} updates, {L} landmarks"
        landmarks, landmark_cov = _landmark_blocks(st)
        return self.make_result(
            status=status,
            poses_xyt=poses,
            landmarks_xy=landmarks,
            assoc=assoc,
            t_start=t_start,
            message=message,
            pose_cov=pose_cov,
            landmark_cov=landmark_cov,
            extra={
                "association": p.association,
                "motion_input": p.motion_input,
                "mean_nis": tally.nis_sum / tally.n_upd if tally.n_upd else None,
                "n_updates": tally.n_upd,
                "n_new_landmarks": tally.n_new,
                "n_discarded": tally.n_disc,
                "n_provisional_dropped": tally.n_dropped,
            },
        )


# ------------------------------------------------------------------------------------------------------
# helpers of the driver
# ------------------------------------------------------------------------------------------------------


class _Tally:
    """Running counters of :meth:`EkfSlam.solve` (``extra`` of the result): NIS sum and update/landmark counts."""

    __slots__ = ("n_disc", "n_dropped", "n_new", "n_upd", "nis_sum")

    def __init__(self):
        self.nis_sum, self.n_upd, self.n_new, self.n_disc, self.n_dropped = 0.0, 0, 0, 0, 0


def _resolve_association(p: EkfParams, rid, N: int) -> tuple[EkfParams, float, float]:
    """``p`` with ``association="auto"`` resolved, and the χ²(2) gate and new-landmark thresholds (inf unless ml)."""
    if p.association == "auto":
        from dataclasses import replace

        from slamcli.solvers.frontend import resolve_association

        p = replace(p, association=resolve_association(p.association, rid))
    if p.association == "known" and N > 0 and np.all(rid < 0):
        raise SolverError(
            "observations.reported_id: every row is -1; association=known needs sensor-reported ids "
            "(use --param association=ml)"
        )
    if p.association == "ml":
        gate, new_thr = _chi2_2dof_ppf(p.gate_prob), _chi2_2dof_ppf(p.new_landmark_prob)
    else:
        gate = new_thr = np.inf
    return p, gate, new_thr


def _noise_and_drive(inputs: SlamInputs, p: EkfParams, T: int):
    """``(obs_cov (2, 2), Q_stab (3, 3), motion_cov, drive)``: the filter's noise and the input of the predict.

    ``motion_input="controls"``: ``motion_cov`` is the actuation covariance and ``drive (T, 2)`` the controls;
    ``"odometry"``: ``motion_cov`` is the body-frame increment covariance and ``drive (T, 3)`` the increments.
    """
    noise = inputs.noise
    if not (noise.range_std * p.obs_std_scale > 0 and noise.bearing_std * p.obs_std_scale > 0):
        raise SolverError(
            f"noise: range_std={noise.range_std} and bearing_std={noise.bearing_std} must both be > 0 for the "
            "EKF (a noise-free sensor makes the innovation covariance S singular)"
        )
    obs_cov = np.diag([(p.obs_std_scale * noise.range_std) ** 2, (p.obs_std_scale * noise.bearing_std) ** 2])
    Q_stab = np.diag(np.square(np.asarray(p.stabilising_pose_std, float)))
    if p.motion_input == "controls":
        if inputs.controls.shape[0] != T:
            raise SolverError(f"controls: expected {T} rows, got {inputs.controls.shape[0]}")
        motion_cov = np.diag(np.square(p.motion_std_scale * np.asarray(noise.motion_std, float)))
        controls = np.asarray(inputs.controls, float)
        return obs_cov, Q_stab, motion_cov, controls
    odom_cov = np.diag(np.square(p.motion_std_scale * np.asarray(noise.odometry_std, float)))
    incr = odometry_increments(inputs.odometry_xyt)
    return obs_cov, Q_stab, odom_cov, incr


def _gps_fixes(inputs: SlamInputs, p: EkfParams):
    """``({step: xy (2,)}, gps_cov (2, 2) or None)`` of the GPS fixes the filter fuses (empty unless ``use_gps``)."""
    gps_at: dict[int, np.ndarray] = {}
    gps_cov = None
    if p.use_gps and len(inputs.gps_step):
        if not inputs.gps_std > 0:
            raise SolverError(f"gps_std={inputs.gps_std}: GPS fixes need a positive σ (or --param use_gps=false)")
        gps_at = {int(k): np.asarray(v, float) for k, v in zip(inputs.gps_step, inputs.gps_xy)}
        gps_cov = inputs.gps_std**2 * np.eye(2)
    return gps_at, gps_cov


def _predict_pose(st: _GrowingState, inputs: SlamInputs, motion_input: str, step_input, motion_cov, Q_stab) -> None:
    """Predict the pose block in place by one step's control ``u`` or odometry increment ``d`` (``step_input``)."""
    x_r = st.x[:3]
    if motion_input == "controls":
        # x_r⁻ = g(x_r, u),  F = ∂g/∂x,  Q = G_u M G_uᵀ  (M = motion_cov; Q: process noise in pose coordinates)
        u = step_input
        if inputs.motion_model == "ackermann":  # car model of the tracked point (G&N 2001)
            pose_new = ackermann_step(x_r, u, inputs.dt, inputs.vehicle)
            F, G_u = ackermann_jacobians(x_r, u, inputs.dt, inputs.vehicle)
        else:
            pose_new, F, G_u = _ddmr_predict(x_r, u, inputs.dt)
        Q = G_u @ motion_cov @ G_u.T
    else:
        # x_r⁻ = x_r ⊕ d,  F = ∂(a⊕b)/∂a,  Q = G Σ_d Gᵀ (Σ_d = odom_cov) with G = ∂(a⊕b)/∂b = blkdiag(R(θ), 1)
        pose_new, F, G = _odometry_predict(x_r, step_input)
        Q = G @ motion_cov @ G.T
    predict_inplace(st.xa, st.Pa, pose_new, F, Q + Q_stab)


def _update_step(st: _GrowingState, dets, frame: int, p: EkfParams, sensor, rid, obs_cov, gate, new_thr, assoc,
                 id_to_lm: dict[int, int], candidates: list[_Candidate], tally: _Tally, rho=None) -> None:
    """Associate and fuse the detections ``dets`` of one step, sensor frame ``frame`` (in place: state, ``assoc``,
    ids, candidates, tally).

    Detections of landmarks not yet in the state are appended to ``dets`` in the first pass (deferred) and
    handled in the second (see :meth:`EkfSlam.solve`). ``rho (N,)``: the declared landmark radius per row
    (``size_gate``), or None.
    """
    used: set[tuple[int, int]] = set()
    n_first = len(dets)
    for k_det, (z, g) in enumerate(dets):
        # z (2,): the measurement of one detection; g: its observation rows (several when grouped)
        i = int(g[0])
        if p.association == "known":
            key = int(rid[i])
            if key < 0:
                tally.n_disc += len(g)
                continue
            j = id_to_lm.get(key)
            if j is None and k_det < n_first:
                dets.append((z, g))  # deferred to the second pass
                continue
            if j is None:
                j = _add_landmark(st, z, obs_cov)
                id_to_lm[key] = j
                tally.n_new += 1
                assoc[g] = j
                continue
        else:
            j, d2 = _ml_best(st, z, obs_cov, exclude=[lm for (s, lm) in used if s == sensor[i]]
                             if p.exclusive_per_step else [])
            if (j < 0 or d2 > new_thr) and k_det < n_first:
                dets.append((z, g))  # deferred to the second pass
                continue
            if j < 0 or d2 > new_thr:
                if rho is not None and _inside_declared_size(st, z, 2.0 * float(rho[g].max())):
                    tally.n_disc += len(g)  # a post overlapping a state landmark: a cut view of that one
                    continue
                # no plausible state landmark: start a new one (or a provisional candidate)
                if p.provisional:  # ml only (this branch): known ids need no provisional list
                    j = _provisional_step(st, candidates, z, obs_cov, frame, g, gate, p, assoc)
                    if j >= 0:
                        tally.n_new += 1
                        used.add((int(sensor[i]), j))
                else:
                    j = _add_landmark(st, z, obs_cov)
                    tally.n_new += 1
                    assoc[g] = j
                    used.add((int(sensor[i]), j))
                continue
            if d2 > gate:
                tally.n_disc += len(g)  # ambiguous: neither clearly this landmark nor clearly a new one
                continue
            used.add((int(sensor[i]), j))
        y, S = update_inplace(st.xa, st.Pa, z, j, obs_cov)
        assoc[g] = j
        tally.nis_sum += float(y @ _inv2(S) @ y)  # NIS = yᵀ S⁻¹ y
        tally.n_upd += 1


def _drop_stale_candidates(candidates: list[_Candidate], frame: int, window: int) -> int:
    """Remove (in place) the candidates not confirmed within ``window`` sensor frames of their first sighting;
    return how many."""
    keep = []
    n_dropped = 0
    for c in candidates:
        if frame - c.first_frame >= window:
            n_dropped += 1
        else:
            keep.append(c)
    candidates[:] = keep
    return n_dropped


def _landmark_blocks(st: _GrowingState):
    """Final map ``(L, 2)`` and symmetrised landmark covariance blocks ``(L, 2, 2)`` of the state."""
    L = (st.n - 3) // 2
    P = st.P
    landmarks = st.x[3:].reshape(L, 2).copy()
    idx = 3 + 2 * np.arange(L)
    landmark_cov = np.empty((L, 2, 2))
    for a in range(2):
        for b in range(2):
            landmark_cov[:, a, b] = 0.5 * (P[idx + a, idx + b] + P[idx + b, idx + a])
    return landmarks, landmark_cov


def _chi2_2dof_ppf(q: float) -> float:
    """χ²(2) quantile in closed form: ``F(x) = 1 − exp(−x/2)``, so ``F⁻¹(q) = −2 ln(1 − q)`` (0.99 → 9.21);
    no ``scipy.stats`` import in the filter (its import cost: benchmarks/results/design_notes.md)."""
    return -2.0 * math.log1p(-q)


def _add_landmark(st: _GrowingState, z, R) -> int:
    m, P_mx, P_mm = landmark_init(st.x, st.P, z, R)
    return st.append_landmark(m, P_mx, P_mm)


def _inside_declared_size(st: _GrowingState, z, min_sep: float) -> bool:
    """Whether the point ``h⁻¹(x_r, z)`` lies closer than ``min_sep`` (m) to a state landmark's mean
    (:func:`slamcli.solvers.frontend.inside_declared_size`)."""
    L = (st.n - 3) // 2
    return bool(inside_declared_size(st.x[3:].reshape(L, 2), inverse_range_bearing(st.x[:3], z), min_sep))


def _ml_best(st: _GrowingState, z, R, exclude) -> tuple[int, float]:
    """Index and squared Mahalanobis distance of the most likely state landmark for ``z`` (−1, inf if none)."""
    L = (st.n - 3) // 2
    if L == 0:
        return -1, np.inf
    d2 = innovation_stats(st.x, st.P, z, R)
    if exclude:
        d2[np.asarray(exclude, np.int64)] = np.inf
    j = int(np.argmin(d2))
    return (j, float(d2[j])) if np.isfinite(d2[j]) else (-1, np.inf)


def _provisional_step(st, candidates, z, R, frame, rows, gate, p: EkfParams, assoc) -> int:
    """Match ``z`` against the provisional list; promote a candidate on its ``min_hits``-th sighting.

    Returns the new state landmark index if one was promoted, else −1 (the row stays unassociated until
    its candidate is confirmed; confirmed candidates label all their rows retroactively).
    """
    x_r, P_rr = st.x[:3], st.P[:3, :3]
    best, best_d2 = None, np.inf
    for c in candidates:
        # S = H_r P_rr H_rᵀ + H_m C H_mᵀ + R   (candidate treated as independent of the pose)
        H_r, H_m = range_bearing_jacobians(x_r, c.m)
        y = measurement_residual(z, range_bearing(x_r, c.m))
        S = H_r @ P_rr @ H_r.T + H_m @ c.C @ H_m.T + R
        d2 = float(y @ np.linalg.solve(S, y))
        if d2 < best_d2:
            best, best_d2 = c, d2
    if best is None or best_d2 > gate:
        M_x, M_z = inverse_range_bearing_jacobians(x_r, z)
        C = M_x @ P_rr @ M_x.T + M_z @ R @ M_z.T
        candidates.append(_Candidate(inverse_range_bearing(x_r, z), C, frame, rows))
        if p.provisional_min_hits > 1:
            return -1
        best = candidates[-1]
    else:
        # refine the candidate position with a 2-D Kalman update (pose uncertainty folded into R_eff)
        H_r, H_m = range_bearing_jacobians(x_r, best.m)
        y = measurement_residual(z, range_bearing(x_r, best.m))
        R_eff = H_r @ P_rr @ H_r.T + R
        S = H_m @ best.C @ H_m.T + R_eff
        K = np.linalg.solve(S, H_m @ best.C).T
        best.m = best.m + K @ y
        I_KH = np.eye(2) - K @ H_m
        best.C = I_KH @ best.C @ I_KH.T + K @ R_eff @ K.T
        best.hits += 1
        best.rows.extend(rows)
    if best.hits < p.provisional_min_hits:
        return -1
    # confirmed: initialise in the state from the current sighting, label every sighting of the candidate
    j = _add_landmark(st, z, R)
    assoc[np.asarray(best.rows, np.int64)] = j
    candidates.remove(best)
    return j


# ------------------------------------------------------------------------------------------------------
# pure-function core (shapes: n = 3 + 2L)
# ------------------------------------------------------------------------------------------------------


def compose_jacobians(a, b):
    """Jacobians of ``se2.compose(a, b)`` w.r.t. ``a`` and ``b``, each ``(3, 3)``.

    ``a ⊕ b = [a_x + c b_x − s b_y, a_y + s b_x + c b_y, a_θ + b_θ]`` with ``c, s = cos a_θ, sin a_θ``.
    """
    c, s = np.cos(a[2]), np.sin(a[2])
    J_a = np.eye(3)
    J_a[0, 2] = -s * b[0] - c * b[1]
    J_a[1, 2] = c * b[0] - s * b[1]
    J_b = np.eye(3)
    J_b[:2, :2] = rot2(a[2])
    return J_a, J_b


def predict(x, P, pose_pred, F, motion_cov):
    """EKF-SLAM prediction: only the pose moves (pure: returns new arrays; see :func:`predict_inplace`).

    ::

        x⁻ = [g(x_r, u), m]                       (g evaluated by the caller → ``pose_pred``)
        P⁻ = F̄ P F̄ᵀ + Q̄,   F̄ = blkdiag(F, I),  Q̄ = blkdiag(Q, 0)
           = [[F P_rr Fᵀ + Q,  F P_rm],
              [P_mr Fᵀ,        P_mm  ]]           (O(n), the map block is untouched)

    Parameters
    ----------
    x : ndarray (n,)         state mean.
    P : ndarray (n, n)       state covariance.
    pose_pred : ndarray (3,) predicted pose g(x_r, u).
    F : ndarray (3, 3)       motion Jacobian w.r.t. the pose.
    motion_cov : ndarray (3, 3)  process noise in pose coordinates (e.g. G_u M G_uᵀ).

    Returns
    -------
    x, P : ndarray (n,), ndarray (n, n)  new arrays.
    """
    Q = motion_cov  # Q: process noise in pose coordinates inside the kernel
    x = np.array(x, float, copy=True)
    P = np.array(P, float, copy=True)
    predict_inplace(x, P, pose_pred, F, Q)
    return x, P


def predict_inplace(x, P, pose_pred, F, motion_cov) -> None:
    """:func:`predict` written into ``x (n,)`` and ``P (n, n)`` (touches 3 rows and 3 columns: O(n))."""
    Q = motion_cov  # Q: process noise in pose coordinates inside the kernel
    x[:3] = pose_pred
    x[2] = _wrap(x[2])
    P[:3, :] = F @ P[:3, :]
    P[:, :3] = P[:, :3] @ F.T
    P[:3, :3] += Q


def update(x, P, z, j, obs_cov):
    """Range-bearing update of pose + landmark ``j``, O(n²) (pure: copies, then :func:`update_inplace`).

    Parameters
    ----------
    x : ndarray (n,);  P : ndarray (n, n);  z : ndarray (2,) [range, bearing];  j : int landmark index;
    obs_cov : ndarray (2, 2) measurement covariance.

    Returns
    -------
    x : ndarray (n,), P : ndarray (n, n) (new arrays), y : ndarray (2,) innovation, S : ndarray (2, 2).
    """
    R = obs_cov  # R: the measurement covariance inside the kernel
    x = np.array(x, float, copy=True)
    P = np.array(P, float, copy=True)
    y, S = update_inplace(x, P, z, j, R)
    return x, P, y, S


def update_inplace(x, P, z, j, obs_cov):
    """Range-bearing update of pose + landmark ``j`` written into ``x (n,)`` and ``P (n, n)``: O(n²).

    ::

        ẑ = h(x_r, m_j),   y = z ⊖ ẑ               (bearing wrapped)
        H = [H_r, 0 … 0, H_m, 0 … 0]  (2, n)     nonzero only in the pose and landmark-j columns
        U = P Hᵀ  (n, 2),   S = H U + R,   K = U S⁻¹   (closed-form 2×2 inverse)
        x = x + K y
        P = (I − KH) P (I − KH)ᵀ + K R Kᵀ          (Joseph form)
          = P − U S⁻¹ Uᵀ = P − V Vᵀ,   V = U L⁻ᵀ,  S = L Lᵀ     (for the gain K = U S⁻¹, P symmetric)

    The last line is one in-place BLAS ``dgemm`` (``beta = 1``, :func:`_rank2_downdate`): one read and one
    write of ``P``, no (n, n) temporary. It equals the Joseph form to round-off (``tests/solvers/test_ekf_inplace.py``);
    ``gemm`` leaves a round-off asymmetry, so the solver symmetrises the covariance blocks it reports.

    Parameters
    ----------
    x : ndarray (n,);  P : ndarray (n, n), C-contiguous for speed;  z : ndarray (2,) [range, bearing];
    j : int landmark index;  obs_cov : ndarray (2, 2) measurement covariance.

    Returns
    -------
    y : ndarray (2,) innovation, S : ndarray (2, 2) innovation covariance.
    """
    R = obs_cov  # R: the measurement covariance inside the kernel
    k = 3 + 2 * j
    y, Hs = _innovation_and_jacobian(x[0], x[1], x[2], x[k], x[k + 1], float(z[0]), float(z[1]))
    U = P[:, :3] @ Hs[:, :3].T  # (n, 2) = P Hᵀ, pose columns ...
    U += P[:, k : k + 2] @ Hs[:, 3:].T  # ... plus landmark-j columns
    S = Hs[:, :3] @ U[:3] + Hs[:, 3:] @ U[k : k + 2] + R  # (2, 2)
    K = U @ _inv2(S)  # (n, 2)
    x += K @ y
    x[2] = _wrap(x[2])
    _rank2_downdate(P, _sqrt_downdate_factor(U, S))
    return y, S


def _rank2_downdate(P, V) -> None:
    """``P −= V Vᵀ`` in place, one BLAS ``dgemm`` pass over ``P (n, n)`` with ``beta = 1`` (no (n, n) temporary).

    ``P`` C-contiguous is ``Pᵀ`` in Fortran order, which ``dgemm`` updates without a copy; ``V Vᵀ`` is
    symmetric, so updating ``Pᵀ`` by it is updating ``P``. Other layouts (a strided window) fall back to
    numpy's ``P −= V @ Vᵀ`` with its temporary.
    """
    if P.flags.c_contiguous:
        from scipy.linalg.blas import dgemm  # lazy: scipy.linalg is slow to import

        dgemm(-1.0, V, V, 1.0, P.T, trans_b=1, overwrite_c=1)
    else:
        P -= V @ V.T


def _sqrt_downdate_factor(U, S):
    """``V = U L⁻ᵀ (n, 2)`` with ``S = L Lᵀ`` (2×2 Cholesky in closed form), so that ``V Vᵀ = U S⁻¹ Uᵀ``.

    ::

        L = [[l₁₁, 0], [l₂₁, l₂₂]],  l₁₁ = √S₁₁,  l₂₁ = S₂₁ / l₁₁,  l₂₂ = √(S₂₂ − l₂₁²)
        V[:, 0] = U[:, 0] / l₁₁,  V[:, 1] = (U[:, 1] − l₂₁ V[:, 0]) / l₂₂
    """
    l11 = math.sqrt(S[0, 0])
    l21 = 0.5 * (S[0, 1] + S[1, 0]) / l11
    l22 = math.sqrt(S[1, 1] - l21 * l21)
    V = np.empty(U.shape, order="F")  # Fortran order: dgemm reads it without a copy
    V[:, 0] = U[:, 0] / l11
    V[:, 1] = (U[:, 1] - l21 * V[:, 0]) / l22
    return V


def _innovation_and_jacobian(px, py, th, mx, my, r, b):
    """Scalar twin of ``observation.range_bearing`` / ``range_bearing_jacobians`` / ``measurement_residual``
    for one pose-landmark pair (the filter's hot loop; ``tests/solvers/test_ekf.py`` checks it against the models).

    ::

        ẑ = [√q, wrap(atan2(dy, dx) − θ)],  q = dx² + dy²
        H_r = [[−dx/√q, −dy/√q, 0], [dy/q, −dx/q, −1]],   H_m = [[dx/√q, dy/√q], [−dy/q, dx/q]]

    Returns
    -------
    y : ndarray (2,)  innovation ``z ⊖ ẑ`` (bearing wrapped);  Hs : ndarray (2, 5)  ``[H_r | H_m]``.
    """
    dx, dy = mx - px, my - py
    q = dx * dx + dy * dy
    sq = math.sqrt(q)
    y = np.array([r - sq, _wrap(b - (math.atan2(dy, dx) - th))])
    a, c, e, f = dx / sq, dy / sq, dy / q, dx / q
    Hs = np.array([[-a, -c, 0.0, a, c], [e, -f, -1.0, -e, f]])
    return y, Hs


def _ddmr_predict(x_r, u, dt: float):
    """Scalar twin of ``motion.ddmr_step`` and ``motion.ddmr_jacobians`` for one pose (hot loop; tested
    against the models).

    ::

        g = [x + dt v cos θ, y + dt v sin θ, wrap(θ + dt ω)]
        F = ∂g/∂x = [[1, 0, −dt v sin θ], [0, 1, dt v cos θ], [0, 0, 1]]
        G_u = ∂g/∂u = [[dt cos θ, 0], [dt sin θ, 0], [0, dt]]

    Returns
    -------
    pose : ndarray (3,), F : ndarray (3, 3), G_u : ndarray (3, 2)
    """
    th = float(x_r[2])
    v, w = float(u[0]), float(u[1])
    c, s = math.cos(th), math.sin(th)
    pose = np.array([x_r[0] + dt * v * c, x_r[1] + dt * v * s, _wrap(th + dt * w)])
    F = np.array([[1.0, 0.0, -dt * v * s], [0.0, 1.0, dt * v * c], [0.0, 0.0, 1.0]])
    G_u = np.array([[dt * c, 0.0], [dt * s, 0.0], [0.0, dt]])
    return pose, F, G_u


def _odometry_predict(x_r, d):
    """Scalar twin of ``se2.compose(x_r, d)`` and :func:`compose_jacobians` for one pose and one odometry
    increment ``d = [d_x, d_y, d_θ]`` (hot loop; tested against them): ``(pose (3,), F = ∂(a⊕b)/∂a (3, 3),
    G = ∂(a⊕b)/∂b (3, 3))``, the heading wrapped."""
    th = float(x_r[2])
    dx, dy, dth = float(d[0]), float(d[1]), float(d[2])
    c, s = math.cos(th), math.sin(th)
    pose = np.array([x_r[0] + c * dx - s * dy, x_r[1] + s * dx + c * dy, _wrap(th + dth)])
    F = np.array([[1.0, 0.0, -s * dx - c * dy], [0.0, 1.0, c * dx - s * dy], [0.0, 0.0, 1.0]])
    G = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
    return pose, F, G


_wrap = wrap_angle_fast  # scalar heading wrap in the per-step prediction (no numpy scalar overhead)


def _inv2(S):
    """Inverse of a 2×2 matrix, ``adj(S) / det(S)``."""
    det = S[0, 0] * S[1, 1] - S[0, 1] * S[1, 0]
    return np.array([[S[1, 1], -S[0, 1]], [-S[1, 0], S[0, 0]]]) / det


def update_position(x, P, z_xy, obs_cov):
    """Linear position-fix update (GPS), O(n²) (pure: copies, then :func:`update_position_inplace`).

    Returns
    -------
    x, P : ndarray (n,), ndarray (n, n)  new arrays.
    """
    R = obs_cov  # R: the position-fix covariance inside the kernel
    x = np.array(x, float, copy=True)
    P = np.array(P, float, copy=True)
    update_position_inplace(x, P, z_xy, R)
    return x, P


def update_position_inplace(x, P, z_xy, obs_cov) -> None:
    """Linear position-fix update (GPS) written into ``x (n,)`` and ``P (n, n)``, O(n²).

    ::

        H = [I₂, 0 … 0]  (2, n),   y = z − p,   U = P Hᵀ = P[:, :2],   S = U[:2] + R,   K = U S⁻¹
        x = x + K y,   P = (I − KH) P (I − KH)ᵀ + K R Kᵀ = P − U S⁻¹ Uᵀ = P − V Vᵀ  (see :func:`update_inplace`)

    Parameters
    ----------
    x : ndarray (n,);  P : ndarray (n, n);  z_xy : ndarray (2,);  obs_cov : ndarray (2, 2) position-fix covariance
    """
    R = obs_cov  # R: the position-fix covariance inside the kernel
    y = np.asarray(z_xy, float) - x[:2]
    U = P[:, :2].copy()  # (n, 2)
    S = U[:2] + R
    x += U @ _inv2(S) @ y
    _rank2_downdate(P, _sqrt_downdate_factor(U, S))


def landmark_init(x, P, z, obs_cov):
    """Initialise a landmark from its first sighting (linearised inverse observation model).

    ::

        m = h⁻¹(x_r, z)
        P_mx = M_x P_{r,:}                 (2, n)   cross-covariance with the whole state
        P_mm = M_x P_rr M_xᵀ + M_z R M_zᵀ  (2, 2)

    Returns
    -------
    m : ndarray (2,), P_mx : ndarray (2, n), P_mm : ndarray (2, 2)
    """
    R = obs_cov  # R: the measurement covariance inside the kernel
    x = np.asarray(x, float)
    P = np.asarray(P, float)
    M_x, M_z = inverse_range_bearing_jacobians(x[:3], z)
    m = inverse_range_bearing(x[:3], z)
    P_mx = M_x @ P[:3, :]
    P_mm = M_x @ P[:3, :3] @ M_x.T + M_z @ R @ M_z.T
    return m, P_mx, 0.5 * (P_mm + P_mm.T)


def innovation_stats(x, P, z, obs_cov):
    """Squared Mahalanobis distance ``d²_k = y_kᵀ S_k⁻¹ y_k`` of ``z`` to every landmark k, vectorised.

    ::

        J_k = [H_r | H_m]  (2, 5),   P_k = [[P_rr, P_rk], [P_kr, P_kk]]  (5, 5)
        S_k = J_k P_k J_kᵀ + R
            = H_r P_rr H_rᵀ + H_r P_rk H_mᵀ + H_m P_kr H_rᵀ + H_m P_kk H_mᵀ + R

    Parameters
    ----------
    x : ndarray (n,);  P : ndarray (n, n);  z : ndarray (2,);  obs_cov : ndarray (2, 2)

    Returns
    -------
    d2 : ndarray (L,)
    """
    R = obs_cov  # R: the measurement covariance inside the kernel
    x = np.asarray(x, float)
    P = np.asarray(P, float)
    L = (x.shape[0] - 3) // 2
    m = x[3:].reshape(L, 2)
    dx = m[:, 0] - x[0]
    dy = m[:, 1] - x[1]
    q = dx * dx + dy * dy
    sq = np.sqrt(q)
    a, c, e, f = dx / sq, dy / sq, dy / q, dx / q
    J = np.zeros((L, 2, 5))  # [H_r | H_m], H_r = [[−a, −c, 0], [e, −f, −1]], H_m = −H_r[:, :2]
    J[:, 0, 0], J[:, 0, 1], J[:, 0, 3], J[:, 0, 4] = -a, -c, a, c
    J[:, 1, 0], J[:, 1, 1], J[:, 1, 2], J[:, 1, 3], J[:, 1, 4] = e, -f, -1.0, -e, f
    Pk = np.empty((L, 5, 5))
    Pk[:, :3, :3] = P[:3, :3]
    Pk[:, :3, 3:] = P[:3, 3:].reshape(3, L, 2).transpose(1, 0, 2)
    Pk[:, 3:, :3] = Pk[:, :3, 3:].transpose(0, 2, 1)
    diag = P[3:, 3:].reshape(L, 2, L, 2)
    ar = np.arange(L)
    Pk[:, 3:, 3:] = diag[ar, :, ar, :]
    S = J @ Pk @ J.transpose(0, 2, 1) + R
    y0 = z[0] - sq
    y1 = wrap_angle(z[1] - (np.arctan2(dy, dx) - x[2]))
    # 2×2 solve in closed form: S⁻¹ = adj(S)/det(S)
    det = S[:, 0, 0] * S[:, 1, 1] - S[:, 0, 1] * S[:, 1, 0]
    return (S[:, 1, 1] * y0**2 - (S[:, 0, 1] + S[:, 1, 0]) * y0 * y1 + S[:, 0, 0] * y1**2) / det
