"""Landmark pose-graph files (g2o ``EDGE_SE2``/``EDGE_SE2_XY`` and GTSAM ``ODOMETRY``/``LANDMARK``) → slamcli.

Two public benchmarks are distributed this way: the DLR-Spatial-Cognition landmark graph (``dlr.g2o``) and
GTSAM's ``victoria_park.txt``. A graph file carries the *measurements* of a run, with no time and usually no
ground truth, so the import gives solver inputs only (``has_truth = false``): every solver runs on it;
``evaluate`` needs ground truth and says so.

Lines understood (anything else is an error naming the line; ``#`` comments and blank lines are skipped):

===========================================  ===================================================================
``VERTEX_SE2 id x y θ`` / ``VERTEX2``        initial pose guess; only the first pose's is used (as ``x0``)
``VERTEX_XY id x y``                         initial landmark guess (not used: solvers initialise themselves)
``EDGE_SE2 i j dx dy dθ I11 I12 I13 I22      odometry increment, pose i's frame; 3×3 *information*,
I23 I33``                                    upper triangle row by row (g2o order)
``ODOMETRY i j dx dy dθ C11 C12 C13 C22      the same with a 3×3 *covariance* (GTSAM's "COV" layout, the one
C23 C33``                                    its loader detects for victoria_park.txt)
``EDGE_SE2_XY i l dx dy I11 I12 I22``        landmark l seen from pose i at (dx, dy) in pose i's frame;
                                             2×2 information
``LANDMARK i l dx dy C11 C12 C22``           the same with a 2×2 covariance (GTSAM)
===========================================  ===================================================================

Conversion
----------
* **Pose order** – the odometry edges must form one chain ``p_0 → p_1 → … → p_T`` (each pose at most one
  outgoing and one incoming edge, no loop-closure edges); pose ``p_k`` becomes step ``k``.
* **Body axes** – slamcli's body frame has x forward (bearing 0 straight ahead). Some files drive along
  another axis (``dlr.g2o`` along −y). With ``forward = "auto"`` the axis with the largest summed odometry
  translation (with its sign) is taken as forward; the body frame is rotated by φ (0, ±π/2, π) so that it
  points forward: increments become ``(R(−φ)·[dx, dy], dθ)``, landmark offsets ``R(−φ)·[dx, dy]``, poses
  ``θ + φ`` (an SE(2) change of body frame, exact).
* **Odometry** – ``odometry_xyt`` chains the converted increments from ``x0`` (the first pose's vertex,
  converted, or the origin); ``controls = [d_x/dt, d_θ/dt]`` per step (the DDMR model has no lateral
  velocity, so d_y is only in the odometry). ``dt`` is nominal (default 1 s): a graph carries no time.
* **Observations** – ``range = ‖[dx, dy]‖``, ``bearing = atan2(dy, dx)`` in the converted body frame;
  ``reported_id`` = landmark index (landmark ids in ascending order), because the file's data association
  is part of the data. Rows keep the file order within a step.
* **Noise** – schema v1 keeps one σ per quantity, so the per-edge matrices are summarised by their median:
  ``odometry_std`` = median √diag of the increment covariances (converted axes), ``motion_std`` =
  ``[σ_x, σ_θ]/dt``, range/bearing σ = median of the first-order polar propagation
  ``J P Jᵀ, J = [[x/r, y/r], [−y/r², x/r²]]`` of each landmark covariance P. The spread is in the metadata.
  (GTSAM's own loader reads a ``LANDMARK`` covariance ``c·I`` differently: σ_r = √c, σ_b = √(c/10), i.e.
  "the covariance describes the uncertainty at 10 m"; for victoria_park.txt that is 0.63 m and 0.2 rad, against
  our 0.63 m and a median 0.05 rad. Pass ``range_std``/``bearing_std`` to choose other values.)
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Literal

import numpy as np

from slamcli.datasets import DatasetImportError
from slamcli.models.angles import wrap_angle
from slamcli.models.motion import chain_increments
from slamcli.types import Dataset, NoiseSpec, Observations, SlamInputs

#: number of numeric fields after the tag, per supported tag
_FIELDS = {
    "VERTEX_SE2": 4,
    "VERTEX2": 4,
    "VERTEX_XY": 3,
    "EDGE_SE2": 11,
    "ODOMETRY": 11,
    "EDGE_SE2_XY": 7,
    "LANDMARK": 7,
}
_FORWARD_ANGLE = {"x": 0.0, "y": math.pi / 2, "-x": math.pi, "-y": -math.pi / 2}


def _sym3(v) -> np.ndarray:
    """Upper triangle ``[a11 a12 a13 a22 a23 a33]`` → symmetric 3×3."""
    a11, a12, a13, a22, a23, a33 = v
    return np.array([[a11, a12, a13], [a12, a22, a23], [a13, a23, a33]], float)


def _sym2(v) -> np.ndarray:
    a11, a12, a22 = v
    return np.array([[a11, a12], [a12, a22]], float)


def _rot(phi: float) -> np.ndarray:
    c, s = math.cos(phi), math.sin(phi)
    return np.array([[c, -s], [s, c]])


def read_graph(path: str | Path) -> dict:
    """Parse a graph file into plain lists (ids as ints, matrices as covariances in the file's axes).

    Returns
    -------
    dict with ``vertices`` {id: (x, y, θ)}, ``odometry`` [(i, j, d (3,), cov (3,3), line)],
    ``landmark_obs`` [(i, l, xy (2,), cov (2,2), line)], ``n_landmark_vertices``.

    Raises
    ------
    DatasetImportError  missing file, unknown tag, wrong field count, non-numeric/non-finite value, non-integer
        id, or a matrix that is not positive definite (names the line).
    """
    path = Path(path)
    if not path.is_file():
        raise DatasetImportError(f"{path}: file not found")
    vertices: dict[int, tuple[float, float, float]] = {}
    odometry: list = []
    landmark_obs: list = []
    n_lm_vertices = 0
    with open(path, encoding="utf-8", errors="replace") as fh:
        for lineno, line in enumerate(fh, 1):
            s = line.strip()
            if not s or s.startswith("#"):
                continue
            tag, *parts = s.split()
            n = _FIELDS.get(tag)
            where = f"{path}:{lineno}"
            if n is None:
                raise DatasetImportError(
                    f"{where}: unsupported tag {tag!r} (supported: {', '.join(_FIELDS)})"
                )
            if len(parts) != n:
                raise DatasetImportError(f"{where}: {tag} needs {n} numbers, got {len(parts)}")
            try:
                vals = [float(p) for p in parts]
            except ValueError:
                bad = next(p for p in parts if not _is_float(p))
                raise DatasetImportError(f"{where}: not a number: {bad!r}") from None
            if not all(math.isfinite(v) for v in vals):
                raise DatasetImportError(f"{where}: non-finite value")
            n_ids = 1 if tag.startswith("VERTEX") else 2
            if any(v != int(v) or v < 0 for v in vals[:n_ids]):
                raise DatasetImportError(f"{where}: ids must be non-negative integers")
            ids = [int(v) for v in vals[:n_ids]]
            if tag in ("VERTEX_SE2", "VERTEX2"):
                vertices[ids[0]] = tuple(vals[1:4])
            elif tag == "VERTEX_XY":
                n_lm_vertices += 1
            elif tag in ("EDGE_SE2", "ODOMETRY"):
                m = _sym3(vals[5:11])
                cov = _invert_pd(m, where) if tag == "EDGE_SE2" else _check_pd(m, where)
                odometry.append((ids[0], ids[1], np.array(vals[2:5]), cov, lineno))
            else:  # EDGE_SE2_XY / LANDMARK
                m = _sym2(vals[4:7])
                cov = _invert_pd(m, where) if tag == "EDGE_SE2_XY" else _check_pd(m, where)
                landmark_obs.append((ids[0], ids[1], np.array(vals[2:4]), cov, lineno))
    return {
        "vertices": vertices,
        "odometry": odometry,
        "landmark_obs": landmark_obs,
        "n_landmark_vertices": n_lm_vertices,
    }


def _is_float(p: str) -> bool:
    try:
        float(p)
    except ValueError:
        return False
    return True


def _check_pd(m: np.ndarray, where: str) -> np.ndarray:
    if np.any(np.linalg.eigvalsh(m) <= 0):
        raise DatasetImportError(f"{where}: matrix is not positive definite")
    return m


def _invert_pd(m: np.ndarray, where: str) -> np.ndarray:
    return np.linalg.inv(_check_pd(m, where))


def _chain(odometry: list, path: Path) -> list:
    """Order the odometry edges into one chain; returns the edges in order."""
    by_src: dict[int, tuple] = {}
    dst_seen: set[int] = set()
    for e in odometry:
        i, j, *_, line = e
        if i in by_src:
            raise DatasetImportError(
                f"{path}:{line}: pose {i} has a second odometry edge (to {j}); only one "
                "odometry chain is supported, no loop-closure edges"
            )
        if j in dst_seen:
            raise DatasetImportError(f"{path}:{line}: pose {j} is reached by a second odometry edge")
        by_src[i] = e
        dst_seen.add(j)
    starts = [i for i in by_src if i not in dst_seen]
    if len(starts) != 1:
        raise DatasetImportError(
            f"{path}: the odometry edges do not form one chain ({len(starts)} start poses)"
        )
    chain, cur = [], starts[0]
    while cur in by_src:
        e = by_src[cur]
        chain.append(e)
        cur = e[1]
    if len(chain) != len(odometry):
        raise DatasetImportError(
            f"{path}: the odometry edges do not form one chain (a cycle or a second piece)"
        )
    return chain


def import_graph(
    path: str | Path,
    *,
    dt: float = 1.0,
    forward: Literal["auto", "x", "y", "-x", "-y"] = "auto",
    range_std: float | None = None,
    bearing_std: float | None = None,
) -> Dataset:
    """Import a landmark pose-graph file as a slamcli :class:`Dataset` without ground truth.

    Parameters
    ----------
    path : the ``.g2o`` / GTSAM text file.
    dt : nominal sampling period, s (> 0); controls are increments / dt.
    forward : which axis of the file's body frame points forward (see the module docstring).
    range_std, bearing_std : σ to store instead of the medians of the propagated landmark covariances.

    Raises
    ------
    DatasetImportError  see :func:`read_graph`; also no odometry edges, edges that are not one chain,
        a landmark observation from a pose that is not on the chain, bad ``dt``/``forward``.
    """
    path = Path(path)
    if not (math.isfinite(dt) and dt > 0):
        raise DatasetImportError(f"--dt: must be a finite number > 0, got {dt}")
    if forward != "auto" and forward not in _FORWARD_ANGLE:
        raise DatasetImportError(f"--forward: must be auto, x, y, -x or -y, got {forward!r}")
    for name, v in (("--range-std", range_std), ("--bearing-std", bearing_std)):
        if v is not None and not (math.isfinite(v) and v >= 0):
            raise DatasetImportError(f"{name}: must be a finite number >= 0, got {v}")
    g = read_graph(path)
    if not g["odometry"]:
        raise DatasetImportError(f"{path}: no odometry edges (EDGE_SE2 or ODOMETRY)")
    chain = _chain(g["odometry"], path)
    pose_ids = [chain[0][0]] + [e[1] for e in chain]
    step_of = {pid: k for k, pid in enumerate(pose_ids)}
    T = len(chain)

    d_file = np.array([e[2] for e in chain])  # (T, 3) in the file's body axes
    if forward == "auto":
        total = d_file[:, :2].sum(axis=0)
        ax = int(np.argmax(np.abs(total)))
        forward = ("" if total[ax] >= 0 else "-") + "xy"[ax]
    phi = _FORWARD_ANGLE[forward]
    R = _rot(-phi)  # file body → slamcli body
    R3 = np.eye(3)
    R3[:2, :2] = R

    inc = np.column_stack([d_file[:, :2] @ R.T, d_file[:, 2]])
    cov_inc = np.array([R3 @ e[3] @ R3.T for e in chain])
    v0 = g["vertices"].get(pose_ids[0])
    x0 = np.array([v0[0], v0[1], wrap_angle(v0[2] + phi)]) if v0 is not None else np.zeros(3)
    odometry_xyt = chain_increments(x0, inc)
    odometry_xyt[:, 2] = wrap_angle(odometry_xyt[:, 2])
    controls = np.column_stack([inc[:, 0], inc[:, 2]]) / dt

    # --- landmark observations --------------------------------------------------------------------------------
    obs_rows = g["landmark_obs"]
    for i, _l, _xy, _c, line in obs_rows:
        if i not in step_of:
            raise DatasetImportError(
                f"{path}:{line}: landmark observation from pose {i}, which is not on the odometry chain"
            )
    lm_ids = sorted({r[1] for r in obs_rows})
    lm_index = {lid: k for k, lid in enumerate(lm_ids)}
    if obs_rows:
        step = np.array([step_of[r[0]] for r in obs_rows], np.int64)
        xy = np.array([r[2] for r in obs_rows]) @ R.T
        cov = np.einsum("ij,njk,lk->nil", R, np.array([r[3] for r in obs_rows]), R)
        rid = np.array([lm_index[r[1]] for r in obs_rows], np.int64)
        order = np.argsort(step, kind="stable")
        step, xy, cov, rid = step[order], xy[order], cov[order], rid[order]
        rng = np.hypot(xy[:, 0], xy[:, 1])
        if np.any(rng == 0):
            raise DatasetImportError(f"{path}: a landmark observation at zero distance has no bearing")
        brg = wrap_angle(np.arctan2(xy[:, 1], xy[:, 0]))
        # polar propagation J P Jᵀ, J = [[x/r, y/r], [−y/r², x/r²]]
        J = np.stack(
            [
                np.column_stack([xy[:, 0] / rng, xy[:, 1] / rng]),
                np.column_stack([-xy[:, 1] / rng**2, xy[:, 0] / rng**2]),
            ],
            axis=1,
        )
        P = np.einsum("nij,njk,nlk->nil", J, cov, J)
        sr, sb = np.sqrt(P[:, 0, 0]), np.sqrt(P[:, 1, 1])
    else:
        step = rid = np.zeros(0, np.int64)
        rng = brg = sr = sb = np.zeros(0)
    obs = Observations.from_rows(step, np.column_stack([rng, brg]), T + 1, reported_id=rid)

    s_inc = np.sqrt(np.diagonal(cov_inc, axis1=1, axis2=2))  # (T, 3)
    odo_std = np.median(s_inc, axis=0)
    noise = NoiseSpec(
        motion_std=np.array([odo_std[0], odo_std[2]]) / dt,
        odometry_std=odo_std,
        range_std=float(range_std) if range_std is not None else float(np.median(sr)) if len(sr) else 0.0,
        bearing_std=float(bearing_std)
        if bearing_std is not None
        else float(np.median(sb))
        if len(sb)
        else 0.0,
    )
    inputs = SlamInputs(
        dt=float(dt),
        timestamps=dt * np.arange(T + 1),
        x0=x0,
        controls=controls,
        odometry_xyt=odometry_xyt,
        observations=obs,
        noise=noise,
    )

    def spread(a):
        return [float(np.min(a)), float(np.median(a)), float(np.max(a))] if len(a) else []

    metadata = {
        "scenario": f"graph:{path.name}",
        "source_file": str(path.resolve()),
        "importer": "slamcli.datasets.g2o",
        "scenario_params": {"dt": float(dt), "forward": forward, "format": "g2o/gtsam landmark graph"},
        "sensor": {"type": "landmark offsets from a graph file", "reports_ids": True},
        "forward_axis": forward,
        "n_poses": T + 1,
        "n_landmarks": len(lm_ids),
        "landmark_ids": [int(x) for x in lm_ids],
        "pose_ids_first_last": [int(pose_ids[0]), int(pose_ids[-1])],
        "noise_spread_min_median_max": {
            "odometry_std_x": spread(s_inc[:, 0]),
            "odometry_std_y": spread(s_inc[:, 1]),
            "odometry_std_theta": spread(s_inc[:, 2]),
            "range_std": spread(sr),
            "bearing_std": spread(sb),
        },
        "ground_truth": "none (a graph file holds measurements only)",
    }
    return Dataset(inputs=inputs, truth=None, metadata=metadata)
