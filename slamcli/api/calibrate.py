"""Noise of a recording estimated from the recording itself (used to set the importers' default noise).

A workflow, so it sits in ``api`` (it runs the EKF through :func:`slamcli.api.solve.solve_dataset`); the
importers in :mod:`slamcli.datasets` only quote the numbers it found.

Observation noise: scan-to-scan residuals
----------------------------------------
Two consecutive scans at poses ``s_1``, ``s_2`` (sensor frame) see mostly the same landmarks. Dead reckoning
over the short gap (≈ 0.2 s) gives the relative pose ``Δ = s_1⁻¹ ⊕ s_2`` from the odometry; a detection
``z_1`` of scan 1 predicts ``ẑ = h(Δ⁻¹ ⊕ h⁻¹(0, z_1))`` in scan 2. Detections are paired by mutual nearest
neighbour (Cartesian, within ``gate_m``) and the innovation ``ν = z_2 − ẑ`` has covariance
``R(z_1) + R(z_2) + J Σ_Δ Jᵀ ≈ 2R`` when the odometry error over the gap is small against the sensor noise
(the part it adds makes the estimate an upper bound). Robust scale: ``σ = 1.4826 · MAD(ν) / √2`` per
component (mismatched pairs and the odd outlier do not inflate it).

Control noise: EKF innovation calibration
-----------------------------------------
With R fixed as above, the control noise ``σ_u = k · σ_u⁰`` is the one scale for which the EKF's mean
normalised innovation squared (NIS) over a prefix of the run equals its expectation d = 2 (a χ²₂ variable):
:func:`nis_for_motion_scale` runs the EKF for one ``k``; the importers' docstrings state the k found and the
NIS it gives.
"""

from __future__ import annotations

import numpy as np

from slamcli.models import se2
from slamcli.models.angles import wrap_angle
from slamcli.models.observation import inverse_range_bearing, range_bearing
from slamcli.types import SlamInputs


def scan_pair_residuals(inputs: SlamInputs, *, gate_m: float = 1.0, max_gap_s: float = 0.5) -> np.ndarray:
    """Innovations ``ν = z_2 − ẑ (K, 2)`` ([range, bearing]) of mutually nearest detections in consecutive scans.

    ``inputs`` must be in the sensor frame (``slamcli.solvers.sensor_frame.to_sensor_frame``): its odometry is
    the dead-reckoned sensor pose. Scans further apart than ``max_gap_s`` are not paired.
    """
    obs = inputs.observations
    odo = np.asarray(inputs.odometry_xyt, float)
    ts = np.asarray(inputs.timestamps, float)
    z = np.column_stack([obs.range_m, obs.bearing_rad])
    off = np.asarray(obs.offsets)
    scans = np.flatnonzero(np.diff(off[: len(odo) + 1]) > 0)
    out = []
    for k1, k2 in zip(scans[:-1], scans[1:]):
        if ts[k2] - ts[k1] > max_gap_s:
            continue
        z1, z2 = z[off[k1]:off[k1 + 1]], z[off[k2]:off[k2 + 1]]
        d = se2.between(odo[k1], odo[k2])
        # z_1's points in the scan-2 frame: Δ⁻¹ ⊕ h⁻¹(0, z_1)
        pts = inverse_range_bearing(np.broadcast_to(se2.inverse(d), (len(z1), 3)), z1)
        q2 = inverse_range_bearing(np.zeros((len(z2), 3)), z2)
        dist = np.linalg.norm(pts[:, None, :] - q2[None, :, :], axis=-1)
        i2 = np.argmin(dist, axis=1)
        i1 = np.argmin(dist, axis=0)
        mutual = (i1[i2] == np.arange(len(z1))) & (dist[np.arange(len(z1)), i2] <= gate_m)
        if not mutual.any():
            continue
        zh = range_bearing(np.zeros((int(mutual.sum()), 3)), pts[mutual])
        nu = z2[i2[mutual]] - zh
        nu[:, 1] = wrap_angle(nu[:, 1])
        out.append(nu)
    return np.concatenate(out) if out else np.zeros((0, 2))


def robust_std(residuals: np.ndarray) -> np.ndarray:
    """``1.4826 · MAD`` per column (the standard deviation of a Gaussian, robust to a minority of outliers)."""
    r = np.asarray(residuals, float)
    med = np.median(r, axis=0)
    return 1.4826 * np.median(np.abs(r - med), axis=0)


def observation_noise(inputs: SlamInputs, **kw) -> tuple[float, float, int]:
    """``(σ_r, σ_b, pairs)`` from :func:`scan_pair_residuals` (see the module docstring)."""
    nu = scan_pair_residuals(inputs, **kw)
    if len(nu) < 10:
        raise ValueError(f"only {len(nu)} scan-to-scan pairs: too few to estimate the observation noise")
    s = robust_std(nu) / np.sqrt(2.0)
    return float(s[0]), float(s[1]), int(len(nu))


def nis_for_motion_scale(inputs: SlamInputs, scale: float, **ekf_params) -> tuple[float, int]:
    """Mean NIS and update count of the EKF (``association=ml`` unless given) with ``motion_std_scale = scale``."""
    from slamcli.api.solve import solve_dataset

    # the EKF's earlier defaults, spelled out: a calibration must not move with the solver's defaults
    params = {"association": "ml", "provisional": False, "group_returns": False, "new_landmark_prob": 0.9999,
              **ekf_params, "motion_std_scale": float(scale)}
    res = solve_dataset(inputs, "ekf", params)
    m = res.extra.get("mean_nis")
    return (float("nan") if m is None else float(m)), int(res.extra.get("n_updates", 0))
