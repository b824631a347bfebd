"""Per-robot trajectory metrics of a multi-robot result (:class:`slamcli.types.RobotTeam`).

The stacked poses of a team are cut per robot: ATE (unaligned, and SE(2)-aligned per robot) and the
dead-reckoning ATE of each robot, and the RPE over pairs that stay within one robot — a pair from the last pose
of one robot to the first of the next compares two different robots and is never formed. The overall
(joint) ATE over all stacked poses is the ordinary ``ate_rmse_m``; its aligned variant uses ONE SE(2)
alignment for all robots (they share one world frame).
"""

from __future__ import annotations

import numpy as np

from slamcli.metrics import trajectory


def per_robot_trajectory_metrics(est_xyt, true_xyt, first_pose, robot_number, odometry_xyt=None,
                                 rpe_delta: float = 1.0, rpe_unit: str = "steps") -> dict:
    """Scalars ``robot<N>_ate_rmse_m``, ``robot<N>_aligned_ate_rmse_m``, ``robot<N>_heading_rmse_rad``,
    ``robot<N>_odometry_ate_rmse_m`` (with ``odometry_xyt``) for every robot, ``robots`` (the numbers) and the
    pooled within-robot RPE ``rpe_trans_rmse_m``, ``rpe_trans_mean_m``, ``rpe_rot_rmse_rad``,
    ``rpe_rot_mean_rad``, ``rpe_pairs``.

    Parameters
    ----------
    est_xyt, true_xyt : ndarray (P, 3)  stacked poses;  first_pose : ndarray (R+1,) CSR offsets per robot;
    robot_number : ndarray (R,);  odometry_xyt : ndarray (P, 3) | None
    """
    est, true = np.asarray(est_xyt, float), np.asarray(true_xyt, float)
    out: dict = {"robots": [int(n) for n in robot_number]}
    et_all, er_all = [], []
    for r, n in enumerate(robot_number):
        a, b = int(first_pose[r]), int(first_pose[r + 1])
        u = trajectory.ate(est[a:b], true[a:b])
        out[f"robot{int(n)}_ate_rmse_m"] = u["ate_rmse_m"]
        out[f"robot{int(n)}_heading_rmse_rad"] = u["heading_rmse_rad"]
        out[f"robot{int(n)}_aligned_ate_rmse_m"] = trajectory.ate(est[a:b], true[a:b], align=True)["ate_rmse_m"]
        if odometry_xyt is not None:
            out[f"robot{int(n)}_odometry_ate_rmse_m"] = trajectory.ate(np.asarray(odometry_xyt)[a:b],
                                                                       true[a:b])["ate_rmse_m"]
        _, _, et, er = trajectory.rpe_errors(est[a:b], true[a:b], rpe_delta, rpe_unit)
        et_all.append(et)
        er_all.append(er)
    et, er = np.concatenate(et_all), np.concatenate(er_all)
    if et.size:
        out.update(rpe_trans_rmse_m=float(np.sqrt(np.mean(et**2))), rpe_trans_mean_m=float(np.mean(et)),
                   rpe_rot_rmse_rad=float(np.sqrt(np.mean(er**2))), rpe_rot_mean_rad=float(np.mean(er)),
                   rpe_pairs=int(et.size))
    return out

