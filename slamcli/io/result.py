"""Result files: HDF5 schema ``slamcli.result`` version 1 (full description in ``docs/schema.md``).

Layout (``T+1`` poses, ``L'`` estimated landmarks, ``N`` observations, ``K`` trace iterations)::

    /            @schema="slamcli.result" @schema_version=1 @solver @solver_version @status @message
                 @wall_time_s @params_json @dataset_hash @dataset_path @extra_json @timings_json
                 @slamcli_version @created_utc
    poses_xyt (T+1,3)   landmarks_xy (L',2)   assoc (N,)   [pose_cov (T+1,3,3)]  [landmark_cov (L',2,2)]
    /trace/      (iterative solvers only) objective (K,) map_change (K,) time_s (K,)
                 landmarks_xy (M,2) landmark_offsets (K+1,)
                 [poses_xyt (P,T+1,3) pose_iterations (P,)]  (optional; one chunk per recorded iteration)
    /hypotheses/ (set-membership solvers only, H surviving hypotheses, Lmax landmarks at most)
                 assoc (H,N) pose_lo pose_hi (H,T+1,3) landmark_lo landmark_hi (H,Lmax,2; NaN padding)
                 n_landmarks (H,) landmark_type (H,Lmax; -1 padding)
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from slamcli.errors import SchemaError
from slamcli.io.schema import (
    COMPRESSION,
    MAX_POSES,
    RESULT_SCHEMA,
    SCHEMA_VERSION,
    Reader,
    attr_text,
    create_h5,
    open_for_read,
    to_json,
    utc_now,
    write_array,
)
from slamcli.types import BoxHypotheses, IterationTrace, SolverResult, Status


def write_result(path: str | os.PathLike, result: SolverResult) -> Path:
    """Write ``result`` atomically (temp file in the same directory + ``os.replace``); returns the path.

    ``result.extra["dataset_path"]``, when present, is also written as the root attribute ``dataset_path``.
    """
    import slamcli

    final = Path(path)
    try:
        params_json = to_json(result.params)
        extra_json = to_json(result.extra)
        timings_json = to_json({str(k): float(v) for k, v in (result.timings or {}).items()})
    except (TypeError, ValueError) as exc:
        raise SchemaError(f"{final}: params/extra: not JSON-serialisable ({exc})") from None
    status = Status(result.status)
    with create_h5(final) as f:
        a = f.attrs
        a["schema"] = RESULT_SCHEMA
        a["schema_version"] = SCHEMA_VERSION
        a["slamcli_version"] = slamcli.__version__
        a["created_utc"] = utc_now()
        a["solver"] = attr_text(result.solver)
        a["solver_version"] = attr_text(result.solver_version)
        a["status"] = status.value
        a["message"] = attr_text(result.message)
        a["wall_time_s"] = float(result.wall_time_s)
        a["params_json"] = params_json
        a["dataset_hash"] = str(result.dataset_hash)
        a["dataset_path"] = attr_text(result.extra.get("dataset_path", ""))
        a["extra_json"] = extra_json
        a["timings_json"] = timings_json
        write_array(f, "poses_xyt", np.asarray(result.poses_xyt, np.float64).reshape(-1, 3),
                    units="m,m,rad", frame="world", doc="estimated poses (T+1,3)")
        write_array(f, "landmarks_xy", np.asarray(result.landmarks_xy, np.float64).reshape(-1, 2),
                    units="m", frame="world", doc="estimated landmarks (L',2)")
        write_array(f, "assoc", np.asarray(result.assoc, np.int64), units="-", frame="-",
                    doc="row of landmarks_xy given to each observation, -1 = none (N,)")
        if result.pose_cov is not None:
            write_array(f, "pose_cov", np.asarray(result.pose_cov, np.float64).reshape(-1, 3, 3),
                        units="m^2,rad^2 (block)", frame="world",
                        doc="marginal pose covariances over [x, y, theta] (T+1,3,3)")
        if result.landmark_cov is not None:
            write_array(f, "landmark_cov", np.asarray(result.landmark_cov, np.float64).reshape(-1, 2, 2),
                        units="m^2", frame="world", doc="marginal landmark covariances (L',2,2)")
        if result.trace is not None:
            tr = result.trace
            g = f.create_group("trace")
            g.attrs["doc"] = "per-iteration record; iteration 0 = initialisation"
            write_array(g, "objective", np.asarray(tr.objective, np.float64), units="-", frame="-",
                        doc="objective / energy after each iteration (K,)")
            write_array(g, "map_change", np.asarray(tr.map_change, np.float64), units="m", frame="world",
                        doc="mean landmark displacement from the previous iteration (K,)")
            write_array(g, "time_s", np.asarray(tr.time_s, np.float64), units="s", frame="-",
                        doc="wall time of each iteration (K,)")
            write_array(g, "landmarks_xy", np.asarray(tr.landmarks_xy, np.float64).reshape(-1, 2),
                        units="m", frame="world", doc="landmarks of all iterations, flattened (M,2)")
            write_array(g, "landmark_offsets", np.asarray(tr.landmark_offsets, np.int64), units="-",
                        frame="-", doc="iteration k owns rows offsets[k]:offsets[k+1] (K+1,)")
            if tr.poses_xyt is not None:
                _write_trace_poses(g, tr)
        if result.grids:  # optional occupancy maps (paper 001 hybrid solver), see slamcli/io/grid.py
            from slamcli.io.grid import write_grid

            gg = f.create_group("grids")
            for name, grid in result.grids.items():
                write_grid(gg, name, grid)
        if result.hypotheses is not None:
            _write_hypotheses(f, result.hypotheses)
    return final


def _write_hypotheses(f, hb: BoxHypotheses) -> None:
    g = f.create_group("hypotheses")
    g.attrs["doc"] = "every surviving hypothesis (kinematic graph) with its association and boxes"
    write_array(g, "assoc", np.asarray(hb.assoc, np.int64), units="-", frame="-",
                doc="landmark row of each observation under hypothesis h (H,N)")
    for name, doc in (("pose_lo", "lower"), ("pose_hi", "upper")):
        write_array(g, name, np.asarray(getattr(hb, name), np.float64), units="m,m,rad", frame="world",
                    doc=f"{doc} bounds of [x, y, theta] per hypothesis; theta unwrapped (H,T+1,3)")
    for name, doc in (("landmark_lo", "lower"), ("landmark_hi", "upper")):
        write_array(g, name, np.asarray(getattr(hb, name), np.float64), units="m", frame="world",
                    doc=f"{doc} bounds of landmark [x, y]; NaN beyond n_landmarks[h] (H,Lmax,2)")
    write_array(g, "n_landmarks", np.asarray(hb.n_landmarks, np.int64), units="-", frame="-",
                doc="landmarks of each hypothesis (H,)")
    write_array(g, "landmark_type", np.asarray(hb.landmark_type, np.int64), units="-", frame="-",
                doc="type label of each landmark, -1 = padding (H,Lmax)")


def _read_hypotheses(r: Reader, n_poses: int, n_obs: int) -> BoxHypotheses:
    g = "hypotheses"
    r.group(g)
    assoc = r.array(f"{g}/assoc", dtype="i", shape=(None, n_obs)).astype(np.int64, copy=False)
    H = assoc.shape[0]
    lo = r.array(f"{g}/pose_lo", dtype="f", shape=(H, n_poses, 3))
    hi = r.array(f"{g}/pose_hi", dtype="f", shape=(H, n_poses, 3))
    llo = r.array(f"{g}/landmark_lo", dtype="f", shape=(H, None, 2), finite=False)
    lhi = r.array(f"{g}/landmark_hi", dtype="f", shape=(H, llo.shape[1], 2), finite=False)
    n_lm = r.array(f"{g}/n_landmarks", dtype="i", shape=(H,)).astype(np.int64, copy=False)
    types = r.array(f"{g}/landmark_type", dtype="i", shape=(H, llo.shape[1])).astype(np.int64, copy=False)
    if (lo > hi).any():
        raise r.fail(f"{g}/pose_lo", "a lower bound exceeds its upper bound (pose_hi)")
    if n_lm.size and (n_lm.min() < 0 or n_lm.max() > llo.shape[1]):
        raise r.fail(f"{g}/n_landmarks", f"values must lie in [0, {llo.shape[1]}]")
    for h in range(H):
        L = int(n_lm[h])
        if not (np.isfinite(llo[h, :L]).all() and np.isfinite(lhi[h, :L]).all()):
            raise r.fail(f"{g}/landmark_lo", f"non-finite bound of hypothesis {h} within n_landmarks")
        if (llo[h, :L] > lhi[h, :L]).any():
            raise r.fail(f"{g}/landmark_lo", f"a lower bound exceeds its upper bound (hypothesis {h})")
        if assoc.size and ((assoc[h] < -1) | (assoc[h] >= L)).any():
            raise r.fail(f"{g}/assoc", f"hypothesis {h}: label out of range [-1, {L - 1}]")
    return BoxHypotheses(assoc=assoc, pose_lo=lo, pose_hi=hi, landmark_lo=llo, landmark_hi=lhi, n_landmarks=n_lm,
                         landmark_type=types)


def _write_trace_poses(g, tr: IterationTrace) -> None:
    """``trace/poses_xyt`` (P, T+1, 3), one gzip+shuffle chunk per recorded iteration, + ``pose_iterations``."""
    poses = np.ascontiguousarray(np.asarray(tr.poses_xyt, np.float64))
    if poses.ndim != 3 or poses.shape[2] != 3:
        raise SchemaError(f"trace.poses_xyt: expected shape (P, T+1, 3), got {poses.shape}")
    iters = (np.arange(poses.shape[0], dtype=np.int64) if tr.pose_iterations is None
             else np.asarray(tr.pose_iterations, np.int64))
    kwargs = {}
    if poses.size:  # chunk = one iteration's (T+1, 3) block: reading one snapshot decompresses only it
        kwargs = {"chunks": (1,) + poses.shape[1:], **COMPRESSION}
    ds = g.create_dataset("poses_xyt", data=poses, **kwargs)
    ds.attrs["units"] = "m,m,rad"
    ds.attrs["frame"] = "world"
    ds.attrs["doc"] = "pose estimates of the recorded iterations (P,T+1,3)"
    write_array(g, "pose_iterations", iters, units="-", frame="-",
                doc="iteration of each poses_xyt row, strictly increasing in [0, K-1] (P,)")


def read_result(path: str | os.PathLike) -> SolverResult:
    """Read and validate a result file; one-line :class:`SchemaError` naming the file and field otherwise.

    Estimates must be finite unless ``status == "failed"`` (a failed solver may leave NaN placeholders).
    """
    with open_for_read(path) as r:
        r.check_schema(RESULT_SCHEMA)
        status_text = r.attr("/", "status", str)
        try:
            status = Status(status_text)
        except ValueError:
            known = ", ".join(s.value for s in Status)
            raise r.fail("@status", f"unknown status {status_text!r} (known: {known})") from None
        finite = status is not Status.FAILED
        solver = r.attr("/", "solver", str)
        solver_version = r.attr("/", "solver_version", str)
        message = r.attr("/", "message", str)
        wall = r.finite_attr("/", "wall_time_s")
        if wall < 0:
            raise r.fail("@wall_time_s", f"must be >= 0, got {wall}")
        params = r.json_attr("/", "params_json")
        if not isinstance(params, dict):
            raise r.fail("@params_json", f"expected a JSON object, got {type(params).__name__}")
        extra = r.json_attr("/", "extra_json", default={})
        if not isinstance(extra, dict):
            raise r.fail("@extra_json", f"expected a JSON object, got {type(extra).__name__}")
        timings = r.json_attr("/", "timings_json", default={})
        if not isinstance(timings, dict) or not all(
                isinstance(v, (int, float)) and not isinstance(v, bool) for v in timings.values()):
            raise r.fail("@timings_json", "expected a JSON object of numbers")
        dataset_hash = r.attr("/", "dataset_hash", str)
        check_declared_result_shapes(r)

        poses = r.array("poses_xyt", dtype="f", shape=(None, 3), finite=finite)
        lms = r.array("landmarks_xy", dtype="f", shape=(None, 2), finite=finite)
        assoc = r.array("assoc", dtype="i", shape=(None,)).astype(np.int64, copy=False)
        L = lms.shape[0]
        if assoc.size:
            bad = np.flatnonzero((assoc < -1) | (assoc >= L))
            if bad.size:
                k = int(bad[0])
                raise r.fail("assoc", f"label {int(assoc[k])} at row {k} out of range [-1, {L - 1}]")
        pose_cov = None
        if r.has("pose_cov"):
            pose_cov = r.array("pose_cov", dtype="f", shape=(None, 3, 3), finite=finite)
            r.expect_len("pose_cov", pose_cov, poses.shape[0], "len(poses_xyt)")
        landmark_cov = None
        if r.has("landmark_cov"):
            landmark_cov = r.array("landmark_cov", dtype="f", shape=(None, 2, 2), finite=finite)
            r.expect_len("landmark_cov", landmark_cov, L, "len(landmarks_xy)")
        trace = _read_trace(r, finite) if r.has("trace") else None
        grids = {}
        if r.has("grids"):
            from slamcli.io.grid import read_grid

            grids = {name: read_grid(r, f"grids/{name}") for name in r.group("grids")}
        hypotheses = _read_hypotheses(r, poses.shape[0], assoc.shape[0]) if r.has("hypotheses") else None
    return SolverResult(
        solver=solver,
        solver_version=solver_version,
        params=params,
        status=status,
        message=message,
        poses_xyt=poses,
        landmarks_xy=lms,
        assoc=assoc,
        pose_cov=pose_cov,
        landmark_cov=landmark_cov,
        trace=trace,
        wall_time_s=wall,
        dataset_hash=dataset_hash,
        extra=extra,
        grids=grids,
        timings={str(k): float(v) for k, v in timings.items()},
        hypotheses=hypotheses,
    )


def check_declared_result_shapes(r: Reader) -> None:
    """Declared shapes against each other and :data:`MAX_POSES`, before any array of a result is read."""
    poses = r.declared_shape("poses_xyt")
    lms = r.declared_shape("landmarks_xy")
    if poses is not None and len(poses) >= 1 and poses[0] > MAX_POSES:
        raise r.fail("poses_xyt", f"declares {poses[0]} poses, above the limit of {MAX_POSES}")
    expect = []
    if poses is not None and len(poses) >= 1:
        expect.append(("pose_cov", poses[0], "len(poses_xyt)"))
    if lms is not None and len(lms) >= 1:
        expect.append(("landmark_cov", lms[0], "len(landmarks_xy)"))
    obj = r.declared_shape("trace/objective")
    if obj is not None and len(obj) == 1:
        expect += [("trace/map_change", obj[0], "len(trace/objective)"), ("trace/time_s", obj[0], "len(trace/objective)"),
                   ("trace/landmark_offsets", obj[0] + 1, "len(trace/objective) + 1")]
    tp = r.declared_shape("trace/poses_xyt")
    if tp is not None and len(tp) >= 1:
        expect.append(("trace/pose_iterations", tp[0], "len(trace/poses_xyt)"))
    for name, n, what in expect:
        shp = r.declared_shape(name)
        if shp is not None and len(shp) >= 1 and shp[0] != n:
            raise r.fail(name, f"declared length {shp[0]} does not match {what} ({n})")


def _read_trace(r: Reader, finite: bool = True) -> IterationTrace:
    r.group("trace")
    obj = r.array("trace/objective", dtype="f", shape=(None,), finite=False)
    K = obj.shape[0]
    if np.isnan(obj).any():
        raise r.fail("trace/objective", f"NaN at iteration {int(np.argmax(np.isnan(obj)))}")
    change = r.array("trace/map_change", dtype="f", shape=(None,))
    r.expect_len("trace/map_change", change, K, "len(trace/objective)")
    time_s = r.array("trace/time_s", dtype="f", shape=(None,))
    r.expect_len("trace/time_s", time_s, K, "len(trace/objective)")
    lms = r.array("trace/landmarks_xy", dtype="f", shape=(None, 2))
    offs = r.array("trace/landmark_offsets", dtype="i", shape=(None,)).astype(np.int64, copy=False)
    r.expect_len("trace/landmark_offsets", offs, K + 1, "len(trace/objective) + 1")
    if offs[0] != 0 or (np.diff(offs) < 0).any() or offs[-1] != lms.shape[0]:
        raise r.fail("trace/landmark_offsets", f"must rise monotonically from 0 to {lms.shape[0]}, got "
                                               f"[{int(offs[0])} .. {int(offs[-1])}]")
    poses = iters = None
    if r.has("trace/poses_xyt"):
        poses = r.array("trace/poses_xyt", dtype="f", shape=(None, None, 3), finite=finite)
        iters = r.array("trace/pose_iterations", dtype="i", shape=(None,)).astype(np.int64, copy=False)
        r.expect_len("trace/pose_iterations", iters, poses.shape[0], "len(trace/poses_xyt)")
        if iters.size and (iters[0] < 0 or iters[-1] >= K or (np.diff(iters) <= 0).any()):
            raise r.fail("trace/pose_iterations", f"must rise strictly within [0, {K - 1}], got "
                                                  f"[{int(iters[0])} .. {int(iters[-1])}]")
        if r.has("poses_xyt") and poses.shape[1] != r.f["poses_xyt"].shape[0]:
            raise r.fail("trace/poses_xyt", f"expected shape (*, {r.f['poses_xyt'].shape[0]}, 3) "
                                            f"(T+1 = len(poses_xyt)), got {poses.shape}")
    return IterationTrace(objective=obj, map_change=change, time_s=time_s, landmarks_xy=lms,
                          landmark_offsets=offs, poses_xyt=poses, pose_iterations=iters)
