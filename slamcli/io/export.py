"""Trajectory and graph files of the wider SLAM ecosystem: TUM, KITTI, g2o, GTSAM text and a tidy CSV.

Writers (all atomic: temporary name in the destination directory, then ``os.replace``):

* **TUM** ``timestamp x y z qx qy qz qw`` (what ``evo`` reads): ``[x, y, θ]`` lifted to ``t = (x, y, 0)``,
  ``q = (0, 0, sin(θ/2), cos(θ/2))``.
* **KITTI** 12 numbers per pose, the rows of ``[Rz(θ) | (x, y, 0)]`` (world frame, z up; no time stamps).
* **g2o** ``VERTEX_SE2`` (poses ``0..T``), ``VERTEX_XY`` (landmarks ``T+1+l``), ``EDGE_SE2`` (odometry chain,
  then every between factor) and ``EDGE_SE2_XY`` (sightings; an unassociated one becomes a landmark of its own,
  placed where seen, so it adds nothing to the cost). GTSAM's ``readG2o`` skips ``EDGE_SE2_XY`` (warned).
* **GTSAM** the same vertices and edges with each sighting as ``BR i l bearing range σ_b σ_r``
  (``gtsam.readG2o(path, False)`` reads it all); exact for range-bearing data with one σ each, otherwise the
  diagonal of ``Σ_rb`` (a dropped correlation is warned about).
* **CSV** ``kind, index, t_s, x_m, y_m, theta_rad`` (+ covariance columns), ``kind`` = pose / landmark.

The g2o file is the factor graph ``slamcli.solvers.graph`` optimises (its prior on pose 0 aside), so a result
read back has the solver's cost: per-edge information of a lossless import is written as is (a
``range_bearing`` row's through the propagation below); with one σ per quantity the odometry information is
``diag(1/odometry_std²)`` and a sighting's ``Λ = (J diag(σ_r², σ_b²) Jᵀ)⁻¹``,
``J = [[cos b, −r sin b], [sin b, r cos b]]`` (first order for the landmark edges).

Readers :func:`read_tum` and :func:`read_kitti` return planar poses (yaw of the rotation); every error is a
one-line :class:`~slamcli.errors.SchemaError` naming the file and line.
"""

from __future__ import annotations

import math
import os
from pathlib import Path

import numpy as np

from slamcli.errors import SchemaError
from slamcli.io.atomic import atomic_path
from slamcli.models.angles import wrap_angle

FORMATS = ("tum", "kitti", "g2o", "gtsam", "csv")
#: |correlation| of a sighting's (bearing, range) covariance above which the GTSAM export warns that its
#: diagonal BR noise drops it
BR_CORRELATION_TOL = 1e-6


def _g(v: float) -> str:
    """Shortest text that round-trips a float exactly (``repr``)."""
    return repr(float(v))


def _write_lines(path: str | os.PathLike, lines) -> Path:
    final = Path(path)
    with atomic_path(final) as tmp, open(tmp, "w", encoding="utf-8") as fh:
        for line in lines:
            fh.write(line)
            fh.write("\n")
    return final


# -- planar pose <-> SE(3) ------------------------------------------------------------------------------


def yaw_to_quaternion(theta) -> np.ndarray:
    """``(..., 4)`` quaternions ``[qx, qy, qz, qw]`` of a rotation ``θ`` about z."""
    th = np.asarray(theta, float)
    z = np.zeros_like(th)
    return np.stack([z, z, np.sin(th / 2), np.cos(th / 2)], -1)


def quaternion_to_yaw(q_xyzw) -> np.ndarray:
    """Yaw (rotation about z, ZYX Euler convention) of quaternions ``(..., 4)`` ``[qx, qy, qz, qw]``:
    ``ψ = atan2(2(qw qz + qx qy), 1 − 2(qy² + qz²))``, wrapped to ``[-π, π)``."""
    q = np.asarray(q_xyzw, float)
    qx, qy, qz, qw = q[..., 0], q[..., 1], q[..., 2], q[..., 3]
    return wrap_angle(np.arctan2(2 * (qw * qz + qx * qy), 1 - 2 * (qy**2 + qz**2)))


def poses_to_matrices(poses_xyt) -> np.ndarray:
    """``(n, 3, 4)`` KITTI rows ``[Rz(θ) | (x, y, 0)]``."""
    p = np.asarray(poses_xyt, float).reshape(-1, 3)
    c, s = np.cos(p[:, 2]), np.sin(p[:, 2])
    M = np.zeros((len(p), 3, 4))
    M[:, 0, 0], M[:, 0, 1], M[:, 1, 0], M[:, 1, 1] = c, -s, s, c
    M[:, 2, 2] = 1.0
    M[:, 0, 3], M[:, 1, 3] = p[:, 0], p[:, 1]
    return M


# -- writers ------------------------------------------------------------------------------------------------


def write_tum(path, timestamps_s, poses_xyt) -> Path:
    """TUM trajectory file: ``timestamp x y z qx qy qz qw`` (T+1 lines)."""
    t = np.asarray(timestamps_s, float).reshape(-1)
    p = np.asarray(poses_xyt, float).reshape(-1, 3)
    if len(t) != len(p):
        raise ValueError(f"{len(t)} timestamps for {len(p)} poses")
    q = yaw_to_quaternion(p[:, 2])
    return _write_lines(path, (
        " ".join(_g(v) for v in (t[i], p[i, 0], p[i, 1], 0.0, *q[i])) for i in range(len(p))
    ))


def write_kitti(path, poses_xyt) -> Path:
    """KITTI pose file: 12 numbers per line (3×4 ``[R | t]`` row-major)."""
    M = poses_to_matrices(poses_xyt).reshape(-1, 12)
    return _write_lines(path, (" ".join(_g(v) for v in row) for row in M))


def odometry_information(odometry_std) -> np.ndarray:
    """``(3, 3)`` information ``diag(1/σ²)`` of an odometry increment ``[dx, dy, dθ]``."""
    return np.diag(1.0 / np.square(np.asarray(odometry_std, float)))


def rb_to_xy_information(range_m, bearing_rad, cov_rb) -> np.ndarray:
    """``(N, 2, 2)`` first-order Cartesian information ``(J Σ_rb Jᵀ)⁻¹`` of range-bearing observations.

    ``cov_rb`` is one ``(2, 2)`` covariance over ``(r, b)`` for all rows or one per row ``(N, 2, 2)``;
    ``J = ∂(r cos b, r sin b)/∂(r, b)`` (module docstring).
    """
    r = np.asarray(range_m, float).reshape(-1)
    b = np.asarray(bearing_rad, float).reshape(-1)
    c, s = np.cos(b), np.sin(b)
    J = np.stack([np.stack([c, -r * s], -1), np.stack([s, r * c], -1)], -2)  # (N,2,2)
    cov = J @ np.asarray(cov_rb, float) @ np.swapaxes(J, -1, -2)
    return np.linalg.inv(cov)


def observation_xy_information(range_m, bearing_rad, range_std: float, bearing_std: float) -> np.ndarray:
    """``(N, 2, 2)`` first-order Cartesian information of range-bearing observations with one σ each."""
    return rb_to_xy_information(range_m, bearing_rad, np.diag([range_std**2, bearing_std**2]))


def _graph_parts(poses_xyt, odometry_xyt, odometry_std, obs_step, obs_range_m, obs_bearing_rad, obs_landmark,
                 range_std: float, bearing_std: float, constraints, use_edge_info: bool, n_landmarks: int) -> dict:
    """The factor graph ``graph`` optimises, as arrays shared by the g2o and GTSAM writers.

    Returns ``edges_ij (E, 2)``, ``edges_xyt (E, 3)``, ``edges_info (E, 3, 3)`` (odometry chain first, then
    the constraints' between-factors) and for every one of the N sightings ``step``, ``landmark (N,)``,
    ``r, b (N,)``, ``info_xy (N, 2, 2)`` (Cartesian, body frame) and ``cov_rb (N, 2, 2)`` over (r, b). A
    sighting attached to no landmark (``obs_landmark < 0``) gets a landmark of its own, rows ``L, L+1, …``
    after the ``L`` landmarks, placed where it was seen (``poses[step] ⊕ (r cos b, r sin b)``, body frame),
    so its factor adds nothing to the cost there: ``extra_landmarks_xy (U, 2)``, ``n_unassociated = U``.
    """
    from slamcli.models import se2

    poses = np.asarray(poses_xyt, float).reshape(-1, 3)
    odo = np.asarray(odometry_xyt, float).reshape(-1, 3)
    n = len(poses)
    if len(odo) != n:
        raise ValueError(f"{len(odo)} odometry poses for {n} poses")
    c = constraints
    d = se2.between(odo[:-1], odo[1:])
    if c is not None and use_edge_info and c.odometry_info is not None:
        I_odo = np.asarray(c.odometry_info, float).reshape(-1, 3, 3)
        if len(I_odo) != n - 1:
            raise ValueError(f"{len(I_odo)} odometry information matrices for {n - 1} increments")
    else:
        I_odo = np.broadcast_to(odometry_information(odometry_std), (n - 1, 3, 3))
    ij = np.column_stack([np.arange(n - 1), np.arange(1, n)]).astype(np.int64)
    if c is not None and c.n_between:
        ij = np.concatenate([ij, np.asarray(c.between_ij, np.int64).reshape(-1, 2)])
        d = np.concatenate([d, np.asarray(c.between_xyt, float).reshape(-1, 3)])
        I_odo = np.concatenate([I_odo, np.asarray(c.between_info, float).reshape(-1, 3, 3)])
    lab = np.asarray(obs_landmark, np.int64).reshape(-1).copy()
    keep = np.arange(len(lab))
    r = np.asarray(obs_range_m, float).reshape(-1)
    b = np.asarray(obs_bearing_rad, float).reshape(-1)
    step = np.asarray(obs_step, np.int64).reshape(-1)
    alone = np.flatnonzero(lab < 0)
    lab[alone] = n_landmarks + np.arange(alone.size)
    seen_at = se2.compose(poses[step[alone]], np.column_stack([r[alone] * np.cos(b[alone]),
                                                                  r[alone] * np.sin(b[alone]), np.zeros(alone.size)]))
    cs, sn = np.cos(b), np.sin(b)
    J = np.stack([np.stack([cs, -r * sn], -1), np.stack([sn, r * cs], -1)], -2)  # ∂(x, y)/∂(r, b), (M,2,2)
    obs_info = c.observation_info if (c is not None and use_edge_info) else None
    if obs_info is None:
        cov_rb = np.broadcast_to(np.diag([range_std**2, bearing_std**2]), (len(keep), 2, 2))
        I_xy = rb_to_xy_information(r, b, cov_rb)
    elif c.observation_model == "xy":  # already over the body-frame offset: exact for g2o
        I_xy = np.asarray(obs_info, float).reshape(-1, 2, 2)[keep]
        Jinv = np.linalg.inv(J)
        cov_rb = Jinv @ np.linalg.inv(I_xy) @ np.swapaxes(Jinv, -1, -2)  # Σ_rb = J⁻¹ Σ_xy J⁻ᵀ
    else:  # per-row information over (r, b): first order for g2o, as for the σ's
        cov_rb = np.linalg.inv(np.asarray(obs_info, float)[keep])
        I_xy = rb_to_xy_information(r, b, cov_rb)
    return {"n": n, "edges_ij": ij, "edges_xyt": d, "edges_info": I_odo, "step": step, "landmark": lab,
            "r": r, "b": b, "info_xy": I_xy, "cov_rb": np.asarray(cov_rb),
            "extra_landmarks_xy": seen_at[:, :2].reshape(-1, 2), "n_unassociated": int(alone.size)}


def _vertex_and_se2_lines(poses, lms, parts: dict, landmark_id0: int):
    """``VERTEX_SE2`` / ``VERTEX_XY`` / ``EDGE_SE2`` lines (no comment line: GTSAM stops at one it does not
    understand); landmark l (the ``lms`` rows, then each unassociated sighting's own) gets vertex id
    ``landmark_id0 + l``."""
    iu3 = np.triu_indices(3)
    for i, (x, y, th) in enumerate(poses):
        yield f"VERTEX_SE2 {i} {_g(x)} {_g(y)} {_g(th)}"
    for l, (x, y) in enumerate(np.concatenate([lms, parts["extra_landmarks_xy"]])):
        yield f"VERTEX_XY {landmark_id0 + l} {_g(x)} {_g(y)}"
    for (i, j), m, info in zip(parts["edges_ij"], parts["edges_xyt"], parts["edges_info"]):
        yield f"EDGE_SE2 {int(i)} {int(j)} {_g(m[0])} {_g(m[1])} {_g(m[2])} " + " ".join(_g(v) for v in info[iu3])


def write_g2o(path, poses_xyt, landmarks_xy, odometry_xyt, odometry_std, obs_step, obs_range_m,
              obs_bearing_rad, obs_landmark, range_std: float, bearing_std: float, *,
              constraints=None, use_edge_info: bool = True) -> Path:
    """g2o factor graph (see module docstring): odometry chain, loop closures, landmark sightings.

    Parameters
    ----------
    poses_xyt : (T+1, 3)          vertex estimates (ids 0..T).
    landmarks_xy : (L, 2)         landmark vertex estimates (ids T+1+l).
    odometry_xyt : (T+1, 3)       dead-reckoning poses; edge t→t+1 measures ``between(odo_t, odo_{t+1})``.
    odometry_std : (3,)           σ of one odometry increment (used when there is no per-edge information).
    obs_step, obs_range_m, obs_bearing_rad : (N,)   observation rows.
    obs_landmark : (N,)           row of ``landmarks_xy`` each observation is attached to; -1 = none: the
                                  sighting is written with a landmark of its own (ids after the others).
    range_std, bearing_std        σ of one observation (used when there is no per-edge information).
    constraints : PoseConstraints | None   the dataset's per-edge constraints: its between-factors are
                                  written as ``EDGE_SE2 i j`` after the odometry chain, always with their own
                                  information (as the graph solver uses them).
    use_edge_info : bool          with ``constraints``, write its ``odometry_info`` (T, 3, 3) and
                                  ``observation_info`` (N, 2, 2) instead of the σ's (the graph solver's
                                  ``edge_info``).
    """
    poses = np.asarray(poses_xyt, float).reshape(-1, 3)
    lms = np.asarray(landmarks_xy, float).reshape(-1, 2)
    g = _graph_parts(poses, odometry_xyt, odometry_std, obs_step, obs_range_m, obs_bearing_rad, obs_landmark,
                     range_std, bearing_std, constraints, use_edge_info, len(lms))
    n = g["n"]
    xy = np.column_stack([g["r"] * np.cos(g["b"]), g["r"] * np.sin(g["b"])])

    def lines():
        yield from _vertex_and_se2_lines(poses, lms, g, n)
        for k in range(len(xy)):
            I = g["info_xy"][k]
            yield (f"EDGE_SE2_XY {int(g['step'][k])} {n + int(g['landmark'][k])} {_g(xy[k, 0])} {_g(xy[k, 1])} "
                   f"{_g(I[0, 0])} {_g(I[0, 1])} {_g(I[1, 1])}")

    return _write_lines(path, lines())


def write_gtsam(path, poses_xyt, landmarks_xy, odometry_xyt, odometry_std, obs_step, obs_range_m,
                obs_bearing_rad, obs_landmark, range_std: float, bearing_std: float, *,
                constraints=None, use_edge_info: bool = True) -> tuple[Path, int]:
    """GTSAM 2-D text file (module docstring): what :func:`write_g2o` writes, with each sighting as a
    ``BR i l bearing range σ_b σ_r`` line that ``gtsam.readG2o`` turns into a
    ``BearingRangeFactor2D(i, L(T+1+l))``; landmark vertices are ``VERTEX_XY T+1+l`` (key ``L(T+1+l)``).

    Parameters are those of :func:`write_g2o`. Returns the path and the number of sightings whose
    (bearing, range) correlation exceeds :data:`BR_CORRELATION_TOL` (dropped by the diagonal BR noise).
    """
    poses = np.asarray(poses_xyt, float).reshape(-1, 3)
    lms = np.asarray(landmarks_xy, float).reshape(-1, 2)
    g = _graph_parts(poses, odometry_xyt, odometry_std, obs_step, obs_range_m, obs_bearing_rad, obs_landmark,
                     range_std, bearing_std, constraints, use_edge_info, len(lms))
    n = g["n"]
    cov = g["cov_rb"]
    sd_r, sd_b = np.sqrt(cov[:, 0, 0]), np.sqrt(cov[:, 1, 1])
    n_correlated = int(np.count_nonzero(np.abs(cov[:, 0, 1]) > BR_CORRELATION_TOL * sd_r * sd_b))

    def lines():
        yield from _vertex_and_se2_lines(poses, lms, g, n)
        for k in range(len(sd_r)):
            yield (f"BR {int(g['step'][k])} {n + int(g['landmark'][k])} {_g(g['b'][k])} {_g(g['r'][k])} "
                   f"{_g(sd_b[k])} {_g(sd_r[k])}")

    return _write_lines(path, lines()), n_correlated


_COV3 = ("cov_xx", "cov_xy", "cov_xt", "cov_yy", "cov_yt", "cov_tt")
_COV2 = ("cov_xx", "cov_xy", "cov_yy")


def trajectory_frame(timestamps_s, poses_xyt, landmarks_xy=None, pose_cov=None, landmark_cov=None):
    """Tidy DataFrame: one row per pose (``kind="pose"``) and per landmark (``kind="landmark"``)."""
    import pandas as pd

    p = np.asarray(poses_xyt, float).reshape(-1, 3)
    rows = {"kind": ["pose"] * len(p), "index": np.arange(len(p)), "t_s": np.asarray(timestamps_s, float),
            "x_m": p[:, 0], "y_m": p[:, 1], "theta_rad": p[:, 2]}
    df = pd.DataFrame(rows)
    if pose_cov is not None:
        C = np.asarray(pose_cov, float).reshape(-1, 3, 3)
        for name, (i, j) in zip(_COV3, zip(*np.triu_indices(3))):
            df[name] = C[:, i, j]
    if landmarks_xy is not None and len(landmarks_xy):
        m = np.asarray(landmarks_xy, float).reshape(-1, 2)
        lm = pd.DataFrame({"kind": "landmark", "index": np.arange(len(m)), "t_s": np.nan, "x_m": m[:, 0],
                           "y_m": m[:, 1], "theta_rad": np.nan})
        if landmark_cov is not None:
            C = np.asarray(landmark_cov, float).reshape(-1, 2, 2)
            lm["cov_xx"], lm["cov_xy"], lm["cov_yy"] = C[:, 0, 0], C[:, 0, 1], C[:, 1, 1]
        df = pd.concat([df, lm], ignore_index=True)
    return df


def write_csv(path, timestamps_s, poses_xyt, landmarks_xy=None, pose_cov=None, landmark_cov=None) -> Path:
    """Tidy CSV (see :func:`trajectory_frame`), full float precision."""
    df = trajectory_frame(timestamps_s, poses_xyt, landmarks_xy, pose_cov, landmark_cov)
    final = Path(path)
    with atomic_path(final) as tmp:
        df.to_csv(tmp, index=False, float_format="%.17g")
    return final


# -- readers ------------------------------------------------------------------------------------------------


def _numeric_rows(path, n_fields: tuple[int, ...], what: str) -> np.ndarray:
    p = Path(path)
    if not p.is_file():
        raise SchemaError(f"{p}: file not found")
    rows = []
    with open(p, encoding="utf-8", errors="replace") as fh:
        for lineno, line in enumerate(fh, 1):
            s = line.replace(",", " ").strip()
            if not s or s.startswith("#"):
                continue
            parts = s.split()
            if len(parts) not in n_fields:
                raise SchemaError(f"{p}:{lineno}: {what} needs {' or '.join(map(str, n_fields))} numbers per "
                                  f"line, got {len(parts)}")
            try:
                vals = [float(v) for v in parts]
            except ValueError:
                raise SchemaError(f"{p}:{lineno}: non-numeric value in {s[:60]!r}") from None
            if not all(math.isfinite(v) for v in vals):
                raise SchemaError(f"{p}:{lineno}: non-finite value")
            rows.append(vals)
    if not rows:
        raise SchemaError(f"{p}: no {what} rows")
    return np.asarray(rows, float)


def read_tum(path) -> tuple[np.ndarray, np.ndarray]:
    """Read a TUM file → ``(timestamps_s (n,), poses_xyt (n, 3))`` sorted by time (strictly increasing)."""
    a = _numeric_rows(path, (8,), "TUM (timestamp x y z qx qy qz qw)")
    t = a[:, 0]
    order = np.argsort(t, kind="stable")
    t, a = t[order], a[order]
    if np.any(np.diff(t) <= 0):
        k = int(np.flatnonzero(np.diff(t) <= 0)[0])
        raise SchemaError(f"{path}: duplicate timestamp {float(t[k])!r}")
    norms = np.linalg.norm(a[:, 4:8], axis=1)
    if np.any(norms < 1e-9):
        raise SchemaError(f"{path}: zero quaternion at timestamp {float(t[int(np.argmin(norms))])!r}")
    yaw = quaternion_to_yaw(a[:, 4:8] / norms[:, None])
    return t, np.column_stack([a[:, 1], a[:, 2], yaw])


def read_kitti(path) -> np.ndarray:
    """Read a KITTI pose file → ``poses_xyt (n, 3)``: ``x = t_x``, ``y = t_y``, ``θ = atan2(R₁₀, R₀₀)``."""
    a = _numeric_rows(path, (12,), "KITTI (3x4 pose matrix)").reshape(-1, 3, 4)
    return np.column_stack([a[:, 0, 3], a[:, 1, 3], wrap_angle(np.arctan2(a[:, 1, 0], a[:, 0, 0]))])


def read_times(path) -> np.ndarray:
    """A KITTI ``times.txt``: one timestamp (s) per line."""
    return _numeric_rows(path, (1,), "times (one timestamp per line)")[:, 0]
