"""Trajectory accuracy: ATE (absolute trajectory error) and RPE (relative pose error) for SE(2) paths.

Definitions follow Sturm et al. (TUM RGB-D benchmark), specialised to the plane (EVALUATION-METHOD.md §A3):

* ATE: ``F_i = Q_i⁻¹ S P_i`` with ``Q`` the truth, ``P`` the estimate and ``S`` either the identity
  (**unaligned**, the primary number: slamcli solvers know the start pose, so the gauge is fixed) or the
  least-squares rigid SE(2) alignment (Umeyama/Kabsch, no scale) of the estimated onto the true positions.
  ``ATE_RMSE = sqrt( (1/n) Σ ‖trans(F_i)‖² )``; heading errors are wrapped with :func:`angle_diff`.
* RPE over pairs ``(i, j)`` separated by ``delta`` steps or by ``delta`` metres travelled along the true
  path: ``E_ij = (Q_i⁻¹ Q_j)⁻¹ (P_i⁻¹ P_j)``; translational error ``‖trans(E_ij)‖``, rotational ``|θ(E_ij)|``.

Pure functions; arrays ``(T+1, 3)`` are ``[x, y, θ]`` in the world frame.
"""

from __future__ import annotations

import numpy as np

from slamcli.models import se2
from slamcli.models.angles import angle_diff, wrap_angle


def _as_poses(a, name: str) -> np.ndarray:
    a = np.asarray(a, dtype=float)
    if a.ndim != 2 or a.shape[1] != 3:
        raise ValueError(f"{name} must have shape (T+1, 3), got {a.shape}")
    return a


def _check_same(est, true):
    if est.shape != true.shape:
        raise ValueError(f"estimated poses {est.shape} and true poses {true.shape} differ in length")


def umeyama_se2(src_xy, dst_xy):
    """Least-squares rotation + translation (no scale) taking ``src`` onto ``dst`` (Umeyama 1991, s = 1).

    Minimises ``Σ_i ‖dst_i − (R src_i + t)‖²``. With centroids ``μ_s, μ_d`` and the cross-covariance
    ``C = (1/n) Σ (dst_i − μ_d)(src_i − μ_s)ᵀ = U D Vᵀ``:
    ``R = U diag(1, det(U Vᵀ)) Vᵀ`` (the sign fix keeps a proper rotation), ``t = μ_d − R μ_s``.

    Parameters
    ----------
    src_xy, dst_xy : ndarray (n, 2), n ≥ 2 corresponding points.

    Returns
    -------
    R : ndarray (2, 2), t : ndarray (2,)
    """
    src = np.asarray(src_xy, float)
    dst = np.asarray(dst_xy, float)
    if src.shape != dst.shape or src.ndim != 2 or src.shape[1] != 2:
        raise ValueError(f"alignment needs two (n, 2) arrays of equal shape, got {src.shape} and {dst.shape}")
    if len(src) < 2:
        raise ValueError("SE(2) alignment needs at least 2 point pairs")
    mu_s = src.mean(axis=0)
    mu_d = dst.mean(axis=0)
    C = (dst - mu_d).T @ (src - mu_s) / len(src)
    U, _, Vt = np.linalg.svd(C)
    S = np.diag([1.0, np.sign(np.linalg.det(U @ Vt)) or 1.0])
    R = U @ S @ Vt
    t = mu_d - R @ mu_s
    return R, t


def apply_se2(poses_xyt, R, t) -> np.ndarray:
    """Left-multiply poses ``(n, 3)`` by the rigid transform ``(R, t)``: ``S P_i``."""
    p = _as_poses(poses_xyt, "poses_xyt")
    out = np.empty_like(p)
    out[:, :2] = p[:, :2] @ np.asarray(R).T + t
    out[:, 2] = wrap_angle(p[:, 2] + np.arctan2(R[1, 0], R[0, 0]))
    return out


def ate_errors(est_xyt, true_xyt, align: bool = False):
    """Per-pose absolute errors.

    Returns
    -------
    trans_err_m : ndarray (T+1,)     ``‖p̂_i − p_i‖`` (after the optional alignment).
    heading_err_rad : ndarray (T+1,) ``wrap(θ̂_i − θ_i)``, signed.
    """
    est = _as_poses(est_xyt, "est_xyt")
    true = _as_poses(true_xyt, "true_xyt")
    _check_same(est, true)
    if align:
        R, t = umeyama_se2(est[:, :2], true[:, :2])
        est = apply_se2(est, R, t)
    return np.linalg.norm(est[:, :2] - true[:, :2], axis=1), angle_diff(est[:, 2], true[:, 2])


def ate(est_xyt, true_xyt, align: bool = False) -> dict:
    """ATE summary: ``ate_rmse_m, ate_mean_m, ate_median_m, ate_max_m, heading_rmse_rad, heading_max_rad``."""
    e, h = ate_errors(est_xyt, true_xyt, align)
    return {
        "ate_rmse_m": float(np.sqrt(np.mean(e**2))),
        "ate_mean_m": float(np.mean(e)),
        "ate_median_m": float(np.median(e)),
        "ate_max_m": float(np.max(e)),
        "heading_rmse_rad": float(np.sqrt(np.mean(h**2))),
        "heading_max_rad": float(np.max(np.abs(h))),
    }


def rpe_pairs(true_xyt, delta: float, unit: str = "steps"):
    """Index pairs ``(i, j)`` for the RPE.

    ``unit="steps"``: ``j = i + delta`` (integer delta ≥ 1).
    ``unit="m"``: ``j`` is the first pose whose distance travelled along the *true* path since ``i`` is
    ≥ ``delta`` metres; poses with no such ``j`` are skipped.
    """
    true = _as_poses(true_xyt, "true_xyt")
    n = len(true)
    if unit == "steps":
        d = int(delta)
        if d < 1 or d != delta:
            raise ValueError(f"RPE step delta must be an integer ≥ 1, got {delta}")
        i = np.arange(max(n - d, 0))
        return i, i + d
    if unit == "m":
        if not delta > 0:
            raise ValueError(f"RPE distance delta must be > 0, got {delta}")
        cum = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(true[:, :2], axis=0), axis=1))])
        j = np.searchsorted(cum, cum + delta, side="left")
        i = np.arange(n)
        ok = j < n
        return i[ok], j[ok]
    raise ValueError(f"RPE unit must be 'steps' or 'm', got {unit!r}")


def rpe_errors(est_xyt, true_xyt, delta: float = 1, unit: str = "steps"):
    """Per-pair relative errors ``E_ij = (Q_i⁻¹ Q_j)⁻¹ (P_i⁻¹ P_j)``.

    Returns
    -------
    i, j : ndarray (K,) int
    trans_err_m : ndarray (K,)   ``‖trans(E_ij)‖``.
    rot_err_rad : ndarray (K,)   ``|wrap(θ(E_ij))|``.
    """
    est = _as_poses(est_xyt, "est_xyt")
    true = _as_poses(true_xyt, "true_xyt")
    _check_same(est, true)
    i, j = rpe_pairs(true, delta, unit)
    E = se2.between(se2.between(true[i], true[j]), se2.between(est[i], est[j]))
    return i, j, np.linalg.norm(E[:, :2], axis=1), np.abs(wrap_angle(E[:, 2]))


def rpe(est_xyt, true_xyt, delta: float = 1, unit: str = "steps") -> dict:
    """RPE summary: ``rpe_trans_rmse_m, rpe_trans_mean_m, rpe_rot_rmse_rad, rpe_rot_mean_rad, rpe_pairs``
    (NaN when the path is too short for a single pair)."""
    _, _, et, er = rpe_errors(est_xyt, true_xyt, delta, unit)
    if et.size == 0:
        nan = float("nan")
        return {"rpe_trans_rmse_m": nan, "rpe_trans_mean_m": nan, "rpe_rot_rmse_rad": nan,
                "rpe_rot_mean_rad": nan, "rpe_pairs": 0}
    return {
        "rpe_trans_rmse_m": float(np.sqrt(np.mean(et**2))),
        "rpe_trans_mean_m": float(np.mean(et)),
        "rpe_rot_rmse_rad": float(np.sqrt(np.mean(er**2))),
        "rpe_rot_mean_rad": float(np.mean(er)),
        "rpe_pairs": int(et.size),
    }
