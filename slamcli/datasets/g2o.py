"""Pose-graph and landmark-graph files (g2o, GTSAM text, TORO) → slamcli, losslessly.

For the public graph benchmarks (DLR, GTSAM's ``victoria_park.txt``, Intel, MIT, CSAIL, M3500, City10000,
KITTI 00). A graph file carries measurements only (no time, usually no truth): ``has_truth = false``.

Lines understood (anything else is an error naming the line; ``#`` comments and blank lines skipped), each tag
read as the tool that defined it, or every tag as one tool with ``convention = "g2o" | "toro" | "gtsam" |
"isam"`` (:mod:`slamcli.datasets.graph_conventions`): ``VERTEX_SE2``/``VERTEX2`` (only the first pose's guess
is used, as ``x0``), ``VERTEX_XY`` (ignored), ``EDGE_SE2`` (3×3 information, g2o order), ``EDGE2`` (TORO
order), ``ODOMETRY`` (3×3 covariance), ``EDGE_SE2_XY``/``LANDMARK2`` (2×2 information), ``LANDMARK`` (2×2
covariance), ``BR i l b r σ_b σ_r`` (bearing-range) and ``EQUIV a b`` (b merged into the smaller id).

* **Poses**: ids in ascending order become steps; the first edge p_k → p_{k+1} (or its exact inverse) is step
  k's odometry; missing steps are completed from the initial estimate with near-zero information and each
  further component gets one prior (:func:`_chain`, reported in ``metadata["import_note"]``).
* **Loop closures**: every other pose-pose edge becomes a between factor of ``inputs.constraints``.
* **Body axes**: ``forward = "auto"`` rotates the body frame by φ ∈ {0, ±π/2, π} onto the axis of largest
  summed translation; measurements and information matrices are rotated with it (every cost unchanged).
* **Odometry / controls**: chained from ``x0``; ``controls = [d_x/dt, d_θ/dt]`` with a nominal ``dt``;
  ``motion_source = "odometry"``.
* **Observations**: range and bearing of ``[dx, dy]``; ``reported_id`` = landmark index.
* **Noise**: every edge keeps its information matrix (``odometry_info``, ``observation_info`` in the file's
  model, ``xy`` or ``range_bearing``; a file mixing both is refused); ``NoiseSpec`` holds their medians for
  solvers with one σ per quantity (GTSAM reads ``LANDMARK`` σ differently: benchmarks/results/design_notes.md).
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Literal

import numpy as np

from slamcli.datasets import DatasetImportError
from slamcli.datasets.graph_conventions import (
    CONVENTIONS,
    ConventionError,
    gtsam_landmark_sigmas,
    pose_matrix,
    separate_landmark_ids,
    xy_matrix,
)
from slamcli.models import se2
from slamcli.models.angles import wrap_angle
from slamcli.models.motion import chain_increments
from slamcli.types import Dataset, NoiseSpec, Observations, PoseConstraints, SlamInputs

#: number of numeric fields after the tag, per supported tag
_FIELDS = {
    "VERTEX_SE2": 4,
    "VERTEX2": 4,
    "VERTEX_XY": 3,
    "EDGE_SE2": 11,
    "EDGE2": 11,
    "ODOMETRY": 11,
    "EDGE_SE2_XY": 7,
    "LANDMARK2": 7,
    "LANDMARK": 7,
    "BR": 6,
    "EQUIV": 2,
}
_POSE_EDGES = ("EDGE_SE2", "EDGE2", "ODOMETRY")
_SIGHTINGS = ("EDGE_SE2_XY", "LANDMARK2", "LANDMARK", "BR")
_FORWARD_ANGLE = {"x": 0.0, "y": math.pi / 2, "-x": math.pi, "-y": -math.pi / 2}


def _rot(phi: float) -> np.ndarray:
    c, s = math.cos(phi), math.sin(phi)
    return np.array([[c, -s], [s, c]])


def _records(path: Path) -> list[tuple[int, str, list[float], list[int]]]:
    """Every non-comment line as ``(line number, tag, numbers, ids)``, checked for tag, field count,
    numbers and ids (one-line DatasetImportError naming file:line)."""
    out = []
    with open(path, encoding="utf-8", errors="replace") as fh:
        for lineno, line in enumerate(fh, 1):
            s = line.strip()
            if not s or s.startswith("#"):
                continue
            tag, *parts = s.split()
            n = _FIELDS.get(tag)
            where = f"{path}:{lineno}"
            if n is None:
                raise DatasetImportError(f"{where}: unsupported tag {tag!r} (supported: {', '.join(_FIELDS)})")
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
            out.append((lineno, tag, vals, _ids(parts[:n_ids], vals[:n_ids], where)))
    return out


def read_graph(path: str | Path, convention: str = "auto") -> dict:
    """Parse a graph file into plain lists (ids as ints, matrices in the file's axes) under ``convention``
    (:mod:`slamcli.datasets.graph_conventions`: the order and meaning of each edge's numbers, landmark id
    spaces). ``EQUIV a b`` merges pose b into pose a (the smaller id is kept; every edge and sighting of the
    other is moved to it).

    Returns
    -------
    dict with ``vertices`` {id: (x, y, θ)}, ``pose_edges`` [(i, j, d (3,), cov (3,3), info (3,3), line)],
    ``sightings`` [(i, l, z (2,), cov (2,2), info (2,2), line, model)] with ``model`` ``"xy"`` (z = offset
    (dx, dy), matrices over (x, y)) or ``"range_bearing"`` (z = (range, bearing), matrices over (r, b)),
    ``n_landmark_vertices``; ``convention``, ``readings`` {tag: how its numbers were read},
    ``separate_landmark_ids``, ``merged`` [(kept, merged, line)] (EQUIV); and the short forms ``odometry``
    [(i, j, d, cov, line)] (all pose-pose edges) and ``landmark_obs`` [(i, l, z, cov, line)].

    Raises
    ------
    DatasetImportError  missing file, unknown convention or tag, wrong field count, non-numeric/non-finite
        value, non-integer id or one ≥ 2^63, a duplicate vertex id, an edge to a vertex the file does not
        declare (when it declares vertices of that kind; for poses more than the start pose's), a landmark id
        equal to a pose id in a convention with one id space, a matrix the convention cannot read (the
        message names the reading and the conventions that read it), a BR σ ≤ 0, an EQUIV of a non-pose
        (each names file:line).
    """
    path = Path(path)
    if convention not in CONVENTIONS:
        raise DatasetImportError(f"--convention: must be one of {', '.join(CONVENTIONS)}, got {convention!r}")
    if not path.is_file():
        raise DatasetImportError(f"{path}: file not found")
    records = _records(path)
    separate = separate_landmark_ids(convention, {r[1] for r in records if r[1] in _SIGHTINGS})
    g = {"vertices": {}, "pose_edges": [], "sightings": [], "readings": {}, "lm_vertices": set(), "equiv": []}
    vertex_line: dict[tuple[str, int], tuple[int, str]] = {}  # (id space, id) → (line, tag) of its VERTEX_*
    for lineno, tag, vals, ids in records:
        where = f"{path}:{lineno}"
        if tag.startswith("VERTEX"):
            space = "landmark" if separate and tag == "VERTEX_XY" else "pose"
            first, first_tag = vertex_line.setdefault((space, ids[0]), (lineno, tag))
            if first != lineno:
                mixed = "VERTEX_XY" in (tag, first_tag) and tag != first_tag  # a landmark and a pose
                raise DatasetImportError(f"{where}: duplicate vertex id {ids[0]} (first declared at line {first})"
                                         + (_ID_SPACE_HINT.format(convention) if mixed else ""))
        try:
            _read_record(g, tag, vals, ids, lineno, convention)
        except ValueError as e:  # ConventionError included: it names the reading and the alternatives
            raise DatasetImportError(f"{where}: {e}") from None
    merged = _merge_equivalent(path, g)
    _check_references(path, g["vertices"], g["lm_vertices"], g["pose_edges"], g["sightings"], separate, convention)
    edges, obs = g["pose_edges"], g["sightings"]
    return {
        "vertices": g["vertices"],
        "pose_edges": edges,
        "sightings": obs,
        "odometry": [(e[0], e[1], e[2], e[3], e[5]) for e in edges],
        "landmark_obs": [(o[0], o[1], o[2], o[3], o[5]) for o in obs],
        "n_landmark_vertices": len(g["lm_vertices"]),
        "convention": convention,
        "readings": {t: sorted(r) for t, r in g["readings"].items()},
        "separate_landmark_ids": separate,
        "merged": merged,
        "within_merged_costs": g.get("within_merged", []),
    }


_ID_SPACE_HINT = (" (convention {0}: poses and landmarks share one id space; --convention gtsam or isam read "
                  "landmark ids in their own space)")


def _read_record(g: dict, tag: str, vals: list[float], ids: list[int], lineno: int, convention: str) -> None:
    """Add one parsed line to ``g`` (see :func:`read_graph`); ValueError/ConventionError on a bad line."""
    if tag in ("VERTEX_SE2", "VERTEX2"):
        g["vertices"][ids[0]] = tuple(vals[1:4])
    elif tag == "VERTEX_XY":
        g["lm_vertices"].add(ids[0])
    elif tag == "EQUIV":
        g["equiv"].append((ids[0], ids[1], lineno))
    elif tag in _POSE_EDGES:
        if ids[0] == ids[1]:
            raise ValueError(f"edge from pose {ids[0]} to itself")
        cov, info, how = pose_matrix(tag, vals[5:11], convention)
        g["readings"].setdefault(tag, set()).add(how)
        g["pose_edges"].append((ids[0], ids[1], np.array(vals[2:5]), cov, info, lineno))
    elif tag == "BR" or (tag == "LANDMARK" and convention == "gtsam"):
        if tag == "BR":
            b, r, sb, sr = vals[2:6]
            if not (sb > 0 and sr > 0):
                raise ValueError("BR needs σ_bearing > 0 and σ_range > 0")
            g["readings"].setdefault(tag, set()).add("bearing-range σ's")
        else:  # GTSAM's load2D: the offset as bearing and range, the covariance as its 10 m σ's
            b, r = math.atan2(vals[3], vals[2]), math.hypot(vals[2], vals[3])
            sb, sr = gtsam_landmark_sigmas(vals[4:7])
            g["readings"].setdefault(tag, set()).add("bearing-range, σ_r = √c, σ_b = √(c/10) (GTSAM load2D)")
        if not r > 0:
            raise ValueError(f"{tag} range must be > 0, got {r}")
        cov = np.diag([sr * sr, sb * sb])
        with np.errstate(divide="ignore", over="ignore"):
            if not np.all(np.isfinite(1.0 / np.diag(cov))) or not np.all(np.isfinite(cov)):
                raise ValueError(f"{tag} σ's ({sr:g}, {sb:g}) give a covariance that is not positive definite with a finite inverse")
        g["sightings"].append((ids[0], ids[1], np.array([r, b]), cov, np.linalg.inv(cov), lineno, "range_bearing"))
    else:  # EDGE_SE2_XY / LANDMARK2 / LANDMARK
        if convention == "gtsam":
            raise ConventionError(f"{tag} is not read by GTSAM's load2D (convention gtsam, which skips it); "
                                  "pass --convention g2o or auto")
        cov, info, how = xy_matrix(tag, vals[4:7], convention)
        g["readings"].setdefault(tag, set()).add(how)
        g["sightings"].append((ids[0], ids[1], np.array(vals[2:4]), cov, info, lineno, "xy"))


def _merge_equivalent(path: Path, g: dict) -> list[tuple[int, int, int]]:
    """Apply the file's ``EQUIV a b`` lines to ``g`` in place: every pose of an equivalence class becomes its
    smallest id (edges, sightings, vertices). An edge between two poses of one class becomes a constant
    ``½ log(d⁻¹)ᵀ Λ log(d⁻¹)`` of the cost: it is dropped and its constant listed in ``g["within_merged"]``.
    Returns ``[(kept, merged, line)]``."""
    if not g["equiv"]:
        return []
    pose_ids = set(g["vertices"]) | {e[0] for e in g["pose_edges"]} | {e[1] for e in g["pose_edges"]}
    parent: dict[int, int] = {}

    def root(v: int) -> int:
        while parent.get(v, v) != v:
            v = parent[v]
        return v

    for a, b, line in g["equiv"]:
        for v in (a, b):
            if v not in pose_ids:
                raise DatasetImportError(f"{path}:{line}: EQUIV {a} {b}: {v} is not a pose id of the file")
        ra, rb = root(a), root(b)
        parent[max(ra, rb)] = min(ra, rb)
    rep = {v: root(v) for v in parent}
    merged = [(root(a), v, line) for a, b, line in g["equiv"] for v in (a, b) if root(v) != v]
    edges, within = [], []
    for i, j, d, cov, info, line in g["pose_edges"]:
        i2, j2 = rep.get(i, i), rep.get(j, j)
        if i2 == j2:  # its error log(d⁻¹) no longer depends on any estimate: a constant of the cost
            e = se2.log(se2.inverse(d))
            within.append(0.5 * float(e @ info @ e))
        else:
            edges.append((i2, j2, d, cov, info, line))
    g["pose_edges"] = edges
    g["within_merged"] = within
    g["sightings"] = [(rep.get(o[0], o[0]), *o[1:]) for o in g["sightings"]]
    g["vertices"] = {v: p for v, p in g["vertices"].items() if rep.get(v, v) == v}
    return sorted(set(merged))


#: ids are stored as signed 64-bit integers (HDF5, numpy int64)
MAX_ID = 2**63 - 1


def _ids(texts: list[str], vals: list[float], where: str) -> list[int]:
    """Exact non-negative integer ids of a line (parsed from the text, not through a float)."""
    out = []
    for s, v in zip(texts, vals):
        try:
            i = int(s)
        except ValueError:
            if v != int(v):
                raise DatasetImportError(f"{where}: ids must be non-negative integers") from None
            i = int(v)
        if i < 0:
            raise DatasetImportError(f"{where}: ids must be non-negative integers")
        if i > MAX_ID:
            raise DatasetImportError(f"{where}: id {s} ≥ 2^63 does not fit a 64-bit signed integer")
        out.append(i)
    return out


def _check_references(path: Path, vertices: dict, lm_vertices: set, pose_edges: list, sightings: list,
                      separate: bool, convention: str) -> None:
    """Refuse an edge to an undeclared vertex (when the file declares vertices of that kind — for poses, more
    than one: a single VERTEX_SE2 only gives the start pose) and, with one id space, a landmark id that is
    also a pose id, naming file:line of the first offending edge."""
    if len(vertices) > 1:
        for e in pose_edges:
            for v in (e[0], e[1]):
                if v not in vertices:
                    raise DatasetImportError(f"{path}:{e[5]}: edge to unknown pose vertex {v} (no VERTEX_SE2 {v})")
        for o in sightings:
            if o[0] not in vertices:
                raise DatasetImportError(f"{path}:{o[5]}: sighting from unknown pose vertex {o[0]}")
    if lm_vertices:
        for o in sightings:
            if o[1] not in lm_vertices:
                raise DatasetImportError(f"{path}:{o[5]}: sighting of unknown landmark vertex {o[1]} (no VERTEX_XY)")
    if separate:
        return
    pose_ids = set(vertices) | {e[0] for e in pose_edges} | {e[1] for e in pose_edges}
    for o in sightings:
        if o[1] in pose_ids:
            raise DatasetImportError(f"{path}:{o[5]}: landmark id {o[1]} is also a pose id"
                                     + _ID_SPACE_HINT.format(convention))
    clash = sorted(lm_vertices & pose_ids)
    if clash:
        raise DatasetImportError(f"{path}: landmark vertex id {clash[0]} is also a pose id"
                                 + _ID_SPACE_HINT.format(convention))


def _is_float(p: str) -> bool:
    try:
        float(p)
    except ValueError:
        return False
    return True


#: information of an odometry step the file has no edge for, relative to the median information of the file's
#: edges: such a step only completes the chain t → t+1 that slamcli's datasets carry; at ε its pull on the
#: optimum is ½ ε ‖e‖² (e = how far the optimum moves that relative pose from its initial estimate)
VIRTUAL_INFO_REL = 1e-9


def _chain(pose_edges: list, pose_ids: list[int], vertices: dict) -> tuple[list, list, dict]:
    """The odometry step ``p_k → p_{k+1}`` of every step and all other edges, for any pose graph.

    A step is the first edge (file order) from ``p_k`` to ``p_{k+1}``, else the first from ``p_{k+1}`` to
    ``p_k``, reversed (:func:`_oriented`, exact). Where the file has neither (a graph
    merged from several runs, a trajectory that restarts), the step is *virtual*: its measurement is the
    relative pose of the initial estimate (the file's vertices, or a breadth-first spanning tree of the edges
    from the first pose of each connected component) and its information ``VIRTUAL_INFO_REL`` × the median
    edge information — except the first step into each further connected component, which is that
    component's one prior: the median information, relative to poses already anchored. A prior that links
    otherwise disconnected components is satisfied exactly at the optimum (nothing else constrains the
    relative placement), so it fixes the gauge without moving any estimate.

    Returns
    -------
    chain : list of ``(i, j, d (3,), cov (3,3), info (3,3), line)``, ``line = None`` for a virtual step;
    others : the remaining edges;  layout : metadata (components, virtual steps, init source, one-line note).
    """
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components

    step_of = {pid: k for k, pid in enumerate(pose_ids)}
    n = len(pose_ids)
    first: dict[tuple[int, int], tuple[int, bool]] = {}  # (i, j) → (edge, stored as j → i)
    for m, e in enumerate(pose_edges):
        first.setdefault((e[0], e[1]), (m, False))
    for m, e in enumerate(pose_edges):
        first.setdefault((e[1], e[0]), (m, True))
    ij = np.array([[step_of[e[0]], step_of[e[1]]] for e in pose_edges], np.int64).reshape(-1, 2)
    _, comp = connected_components(coo_matrix((np.ones(len(ij)), (ij[:, 0], ij[:, 1])), shape=(n, n)), directed=False)
    missing = [k for k, (a, b) in enumerate(zip(pose_ids[:-1], pose_ids[1:])) if (a, b) not in first]
    layout = {"components": int(comp.max(initial=0) + 1), "virtual_odometry_steps": len(missing)}
    if not missing:
        idx = [first[(a, b)] for a, b in zip(pose_ids[:-1], pose_ids[1:])]
        used = {m for m, _ in idx}
        return ([_oriented(pose_edges[m], rev) for m, rev in idx],
                [e for m, e in enumerate(pose_edges) if m not in used], layout)
    from_vertices = all(pid in vertices for pid in pose_ids)
    init = (np.array([vertices[pid] for pid in pose_ids], float) if from_vertices
            else _spanning_tree_estimate(n, ij, np.array([e[2] for e in pose_edges]).reshape(-1, 3), comp))
    med = np.median(np.array([e[4] for e in pose_edges]), axis=0)
    med = 0.5 * (med + med.T) if np.all(np.linalg.eigvalsh(0.5 * (med + med.T)) > 0) else np.eye(3)
    seen = {int(comp[0])}
    chain, used, priors = [], set(), []
    for k, (a, b) in enumerate(zip(pose_ids[:-1], pose_ids[1:])):
        if (a, b) in first:
            m, rev = first[(a, b)]
            chain.append(_oriented(pose_edges[m], rev))
            used.add(m)
            continue
        new_component = int(comp[k + 1]) not in seen
        seen.add(int(comp[k + 1]))
        info = med if new_component else VIRTUAL_INFO_REL * med
        if new_component:
            priors.append(b)
        chain.append((a, b, se2.between(init[k], init[k + 1]), np.linalg.inv(info), info, None))
    source = "the file's vertices" if from_vertices else "a spanning tree of the edges"
    layout.update(init_source=source, component_priors=[int(b) for b in priors])
    layout["import_note"] = (
        f"{len(missing)} consecutive pose id pair(s) without an edge: chain completed from {source}"
        + (f"; {layout['components']} disconnected components, one prior per component (on poses "
           f"{', '.join(map(str, priors[:5]))}{', …' if len(priors) > 5 else ''})" if priors else "")
    )
    return chain, [e for m, e in enumerate(pose_edges) if m not in used], layout


def _oriented(edge: tuple, reverse: bool) -> tuple:
    """The edge ``(i, j, d, Σ, Λ, line)`` itself, or with ``reverse`` the same factor stored as ``j → i``:
    measurement ``d⁻¹``; its error is ``e' = −Ad_d e`` (``log(d g⁻¹ d⁻¹) = −Ad_d log(g)``), so
    ``Σ' = Ad_d Σ Ad_dᵀ`` and ``Λ' = Ad_d⁻ᵀ Λ Ad_d⁻¹`` keep its cost exactly."""
    if not reverse:
        return edge
    i, j, d, cov, info, line = edge
    A = se2.adjoint(d)
    A_inv = np.linalg.inv(A)
    return j, i, se2.inverse(d), A @ cov @ A.T, A_inv.T @ info @ A_inv, line


def _spanning_tree_estimate(n: int, ij: np.ndarray, d: np.ndarray, comp: np.ndarray) -> np.ndarray:
    """Poses ``(n, 3)`` composed along a breadth-first spanning tree of the edges ``ij (E, 2)`` with
    measurements ``d (E, 3)`` (``x_j = x_i ⊕ d``), from the origin at the first pose of each component."""
    adj: list[list[tuple[int, int, bool]]] = [[] for _ in range(n)]
    for e, (i, j) in enumerate(ij.tolist()):
        adj[i].append((j, e, True))
        adj[j].append((i, e, False))
    poses = np.zeros((n, 3))
    done = np.zeros(n, bool)
    for root in range(n):
        if done[root]:
            continue
        done[root] = True
        queue = [root]
        while queue:
            u = queue.pop(0)
            for v, e, forward in adj[u]:
                if done[v]:
                    continue
                step = d[e] if forward else se2.inverse(d[e])
                poses[v] = se2.compose(poses[u], step)
                done[v] = True
                queue.append(v)
    return poses


def import_graph(
    path: str | Path,
    *,
    dt: float = 1.0,
    forward: Literal["auto", "x", "y", "-x", "-y"] = "auto",
    range_std: float | None = None,
    bearing_std: float | None = None,
    max_poses: int | None = None,
    convention: str = "auto",
) -> Dataset:
    """Import a pose-graph or landmark-graph file as a slamcli :class:`Dataset` without ground truth.

    Parameters
    ----------
    path : the ``.g2o`` / GTSAM / TORO text file.
    dt : nominal sampling period, s (> 0); controls are increments / dt.
    forward : which axis of the file's body frame points forward (see the module docstring).
    range_std, bearing_std : σ to store in the NoiseSpec instead of the medians of the sightings.
    max_poses : keep only the first N poses (ascending ids) and the edges/sightings among them (≥ 2).
    convention : how the file's numbers are read: auto (per tag), g2o, toro, gtsam or isam
        (:mod:`slamcli.datasets.graph_conventions`).

    Raises
    ------
    DatasetImportError  see :func:`read_graph`; also no pose-pose edges, a broken odometry chain, a landmark
        observation from a pose that is not on the chain, xy and BR sightings mixed, bad arguments.
    """
    path = Path(path)
    _check_arguments(dt, forward, range_std, bearing_std, max_poses)
    g = read_graph(path, convention)
    edges = g["pose_edges"]
    if not edges:
        raise DatasetImportError(f"{path}: no odometry edges (EDGE_SE2, EDGE2 or ODOMETRY)")
    pose_ids = sorted({e[0] for e in edges} | {e[1] for e in edges} | set(g["vertices"]))
    n_poses_file = len(pose_ids)
    if max_poses is not None and max_poses < len(pose_ids):
        pose_ids = pose_ids[:max_poses]
        keep = set(pose_ids)
        edges = [e for e in edges if e[0] in keep and e[1] in keep]
    step_of = {pid: k for k, pid in enumerate(pose_ids)}
    chain, others, layout = _chain(edges, pose_ids, g["vertices"])
    T = len(chain)
    real = np.array([e[5] is not None for e in chain], bool)  # steps with an edge of the file

    d_file = np.array([e[2] for e in chain])  # (T, 3) in the file's body axes
    if forward == "auto":
        total = d_file[real, :2].sum(axis=0)
        ax = int(np.argmax(np.abs(total)))
        forward = ("" if total[ax] >= 0 else "-") + "xy"[ax]
    phi = _FORWARD_ANGLE[forward]
    R = _rot(-phi)  # file body → slamcli body
    R3 = np.eye(3)
    R3[:2, :2] = R

    def to_body(d):  # (n, 3) relative poses in file axes → slamcli body axes
        d = np.asarray(d, float).reshape(-1, 3)
        return np.column_stack([d[:, :2] @ R.T, d[:, 2]])

    def info_to_body(m):  # (n, 3, 3): Λ' = R₃ Λ R₃ᵀ
        return np.einsum("ij,njk,lk->nil", R3, np.asarray(m, float).reshape(-1, 3, 3), R3)

    inc = to_body(d_file)
    cov_inc = info_to_body([e[3] for e in chain])
    info_inc = info_to_body([e[4] for e in chain])
    v0 = g["vertices"].get(pose_ids[0])
    x0 = np.array([v0[0], v0[1], wrap_angle(v0[2] + phi)]) if v0 is not None else np.zeros(3)
    odometry_xyt = chain_increments(x0, inc)
    odometry_xyt[:, 2] = wrap_angle(odometry_xyt[:, 2])
    controls = np.column_stack([inc[:, 0], inc[:, 2]]) / dt

    # --- loop closures / other pose-pose edges ----------------------------------------------------------------
    between_ij = np.array([[step_of[e[0]], step_of[e[1]]] for e in others], np.int64).reshape(-1, 2)
    between_xyt = to_body([e[2] for e in others])
    between_info = info_to_body([e[4] for e in others])

    obs_rows = g["sightings"]
    if max_poses is not None:
        obs_rows = [r for r in obs_rows if r[0] in step_of]
    obs, info, sr, sb, obs_model, lm_ids = _sightings(path, obs_rows, step_of, R, T)

    s_inc = np.sqrt(np.diagonal(cov_inc, axis1=1, axis2=2))[real]  # (T', 3), the file's own steps
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
    constraints = PoseConstraints(
        between_ij=between_ij,
        between_xyt=between_xyt,
        between_info=between_info,
        odometry_info=info_inc,
        observation_info=info,
        observation_model=obs_model,
    )
    inputs = SlamInputs(
        dt=float(dt),
        timestamps=dt * np.arange(T + 1),
        x0=x0,
        controls=controls,
        odometry_xyt=odometry_xyt,
        observations=obs,
        noise=noise,
        constraints=constraints,
        reported_id_source="file",
        motion_source="odometry",  # the file's odometry edges; controls drop their sideways part
    )

    metadata = _metadata(path, dt, forward, max_poses, obs_model, T, n_poses_file, lm_ids, between_ij, pose_ids,
                         s_inc, sr, sb)
    metadata.update(layout)
    metadata.update(convention=convention, convention_readings=g["readings"],
                    landmark_id_space="own id space" if g["separate_landmark_ids"] else "shared with pose ids",
                    equiv_merged=[[int(a), int(b)] for a, b, _ in g["merged"]],
                    equiv_dropped_edges=len(g["within_merged_costs"]),
                    equiv_dropped_cost=float(sum(g["within_merged_costs"])))
    return Dataset(inputs=inputs, truth=None, metadata=metadata)


def _check_arguments(dt, forward, range_std, bearing_std, max_poses) -> None:
    """Refuse bad importer arguments (one line naming the option)."""
    if not (math.isfinite(dt) and dt > 0):
        raise DatasetImportError(f"--dt: must be a finite number > 0, got {dt}")
    if forward != "auto" and forward not in _FORWARD_ANGLE:
        raise DatasetImportError(f"--forward: must be auto, x, y, -x or -y, got {forward!r}")
    for name, v in (("--range-std", range_std), ("--bearing-std", bearing_std)):
        if v is not None and not (math.isfinite(v) and v >= 0):
            raise DatasetImportError(f"{name}: must be a finite number >= 0, got {v}")
    if max_poses is not None and max_poses < 2:
        raise DatasetImportError(f"--max-poses: must be >= 2, got {max_poses}")


def _sightings(path: Path, obs_rows: list, step_of: dict, R: np.ndarray, T: int):
    """The graph's landmark sightings as slamcli observations (range, bearing in the slamcli body frame).

    Returns
    -------
    obs : Observations over ``T+1`` steps (reported ids = landmark rows);  info : (N, 2, 2) information of
    each sighting (over x, y or range, bearing, see ``obs_model``);  sr, sb : (N,) range and bearing σ;
    obs_model : "xy" | "br";  lm_ids : sorted landmark ids of the file.
    """
    for i, _l, _z, _c, _m, line, _k in obs_rows:
        if i not in step_of:
            raise DatasetImportError(
                f"{path}:{line}: landmark observation from pose {i}, which is not on the odometry chain"
            )
    models = sorted({r[6] for r in obs_rows})
    if len(models) > 1:
        raise DatasetImportError(
            f"{path}: the file mixes Cartesian (EDGE_SE2_XY/LANDMARK) and bearing-range (BR) sightings; "
            "one sighting model per file is supported"
        )
    obs_model = models[0] if models else "xy"
    lm_ids = sorted({r[1] for r in obs_rows})
    lm_index = {lid: k for k, lid in enumerate(lm_ids)}
    if obs_rows:
        step = np.array([step_of[r[0]] for r in obs_rows], np.int64)
        z_file = np.array([r[2] for r in obs_rows])
        if obs_model == "xy":
            xy = z_file @ R.T
        else:  # (range, bearing) → offset, rotated with the body frame; range unchanged, bearing − φ
            xy = (z_file[:, 0:1] * np.column_stack([np.cos(z_file[:, 1]), np.sin(z_file[:, 1])])) @ R.T
        cov = np.array([r[3] for r in obs_rows])
        info = np.array([r[4] for r in obs_rows])
        if obs_model == "xy":  # matrices over (x, y) rotate with the frame; over (r, b) they do not
            cov = np.einsum("ij,njk,lk->nil", R, cov, R)
            info = np.einsum("ij,njk,lk->nil", R, info, R)
        rid = np.array([lm_index[r[1]] for r in obs_rows], np.int64)
        order = np.argsort(step, kind="stable")
        step, xy, cov, info, rid = step[order], xy[order], cov[order], info[order], rid[order]
        rng = np.hypot(xy[:, 0], xy[:, 1])
        if np.any(rng == 0):
            raise DatasetImportError(f"{path}: a landmark observation at zero distance has no bearing")
        brg = wrap_angle(np.arctan2(xy[:, 1], xy[:, 0]))
        if obs_model == "xy":
            # polar propagation J P Jᵀ, J = [[x/r, y/r], [−y/r², x/r²]]
            J = np.stack(
                [
                    np.column_stack([xy[:, 0] / rng, xy[:, 1] / rng]),
                    np.column_stack([-xy[:, 1] / rng**2, xy[:, 0] / rng**2]),
                ],
                axis=1,
            )
            P = np.einsum("nij,njk,nlk->nil", J, cov, J)
        else:
            P = cov
        sr, sb = np.sqrt(P[:, 0, 0]), np.sqrt(P[:, 1, 1])
    else:
        step = rid = np.zeros(0, np.int64)
        rng = brg = sr = sb = np.zeros(0)
        info = np.zeros((0, 2, 2))
    obs = Observations.from_rows(step, np.column_stack([rng, brg]), T + 1, reported_id=rid)
    return obs, info, sr, sb, obs_model, lm_ids


def _metadata(path, dt, forward, max_poses, obs_model, T, n_poses_file, lm_ids, between_ij, pose_ids, s_inc, sr, sb):
    """The dataset's metadata dict (provenance, counts, spread of the per-edge σ's)."""

    def spread(a):
        return [float(np.min(a)), float(np.median(a)), float(np.max(a))] if len(a) else []

    return {
        "scenario": f"graph:{path.name}",
        "source_file": str(path.resolve()),
        "importer": "slamcli.datasets.g2o",
        "scenario_params": {
            "dt": float(dt),
            "forward": forward,
            "format": "g2o/gtsam/toro graph",
            "max_poses": max_poses,
        },
        "sensor": {"type": "landmark sightings from a graph file", "reports_ids": True, "model": obs_model},
        "forward_axis": forward,
        "n_poses": T + 1,
        "n_poses_in_file": n_poses_file,
        "n_landmarks": len(lm_ids),
        "n_loop_closures": int(between_ij.shape[0]),
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
