"""Dataset files: HDF5 schema ``slamcli.dataset`` version 1 (full description in ``docs/schema.md``).

Layout (``T`` steps, ``T+1`` poses, ``N`` observations, ``L`` true landmarks, ``G`` GPS fixes)::

    /                      @schema @schema_version=1 @dt @seed @scenario @scenario_params_json @sensor_json
                           @robot_json @metadata_json @slamcli_version @created_utc @has_truth
    /inputs/               what a solver may see (SlamInputs)
        timestamps (T+1,)  x0 (3,)  controls (T,2)  odometry_xyt (T+1,3)  max_range ()
        observations/      step range_m bearing_rad sensor reported_id (N,)   offsets (T+2,)
                           [landmark_type (N,)] [diameter_m (N,)]
        noise/             motion_std (2,) odometry_std (3,) range_std () bearing_std ()
        noise_bounds/      (bounded-noise data) @odometry_model ... odometry_half_width (2,) range/bearing
        gps_step (G,) gps_xy (G,2) gps_std ()                     (only when G > 0)
        @motion_model (ddmr | ackermann, + vehicle/)  @motion_source (controls | odometry)
        sensor_offset_xy (2,)                                     (only when non-zero)
        constraints/       per-edge information (PoseConstraints): between_i between_j (B,) between_xyt
                           (B,3) between_info (B,3,3) [odometry_info (T,3,3)] [observation_info (N,2,2)]
        robots/, robot_observations/                              (multi-robot data, RobotTeam)
    /truth/                ground truth, read by metrics only (GroundTruth)
        poses_xyt (T+1,3)  landmarks_xy (L,2)  obs_landmark (N,)  (-1 = clutter)
        or @kind="position_reference" (a real recording's GPS): ref_time_s (G,) ref_xy (G,2)
"""

from __future__ import annotations

import hashlib
import os
from pathlib import Path
from typing import Any

import numpy as np

from slamcli.errors import SchemaError
from slamcli.io.schema import (
    DATASET_SCHEMA,
    MAX_POSES,
    SCHEMA_VERSION,
    Reader,
    attr_text,
    create_h5,
    open_for_read,
    to_json,
    utc_now,
    write_array,
)
from slamcli.numerics import MAX_INPUT_MAGNITUDE
from slamcli.types import (
    Dataset,
    GroundTruth,
    NoiseBounds,
    NoiseSpec,
    Observations,
    PoseConstraints,
    RobotTeam,
    SlamInputs,
)

#: metadata keys promoted to their own root attributes (dicts as ``<key>_json``, see
#: :func:`promoted_sections`); everything in ``Dataset.metadata`` also round-trips through ``@metadata_json``.
PROMOTED_KEYS = ("seed", "scenario", "scenario_params", "sensor", "robot")

_BEARING_TOL = 1e-9  # bearings must lie in [-pi, pi] up to rounding


def promoted_sections(meta: dict[str, Any]) -> dict[str, Any]:
    """``scenario_params``/``sensor``/``robot`` sections for the root attributes.

    Taken from the metadata keys of the same name, else from the resolved scenario configuration
    ``metadata["config"]`` (the simulator's nested dict: the whole config, its ``sensor`` and ``robot``).
    """
    config = meta.get("config") if isinstance(meta.get("config"), dict) else {}
    out = {}
    for key, fallback in (("scenario_params", config or None), ("sensor", config.get("sensor")),
                          ("robot", config.get("robot"))):
        value = meta.get(key, fallback)
        if value is not None:
            out[key] = value
    return out


# --------------------------------------------------------------------------------------------------------
# writing
# --------------------------------------------------------------------------------------------------------
def write_dataset(path: str | os.PathLike, dataset: Dataset) -> Path:
    """Write ``dataset`` to ``path`` atomically (temp file in the same directory + ``os.replace``).

    Arrays are stored in canonical dtypes (float64; int64 indices; int16 sensor ids) so a read gives
    bit-identical arrays. The file is validated by the reader before it is written (a dataset slamcli would
    refuse to read — a value beyond the input bounds, a NaN noise σ — is a one-line SchemaError, nothing
    written). Returns the final path.
    """
    import slamcli

    inp = dataset.inputs
    obs = inp.observations
    meta = dict(dataset.metadata or {})
    final = Path(path)
    try:
        metadata_json = to_json(meta)
    except (TypeError, ValueError) as exc:
        raise SchemaError(f"{final}: metadata: not JSON-serialisable ({exc})") from None
    with create_h5(final, check=_readable(final)) as f:
        a = f.attrs
        a["schema"] = DATASET_SCHEMA
        a["schema_version"] = SCHEMA_VERSION
        a["slamcli_version"] = slamcli.__version__
        a["created_utc"] = utc_now()
        a["dt"] = float(inp.dt)
        a["has_truth"] = dataset.truth is not None
        a["metadata_json"] = metadata_json
        if meta.get("seed") is not None:
            a["seed"] = int(meta["seed"])
        if meta.get("scenario") is not None:
            a["scenario"] = attr_text(meta["scenario"])
        for key, value in promoted_sections(meta).items():
            a[f"{key}_json"] = to_json(value)

        g = f.create_group("inputs")
        g.attrs["doc"] = "everything a solver may see (slamcli.types.SlamInputs)"
        write_array(g, "timestamps", np.asarray(inp.timestamps, np.float64), units="s", frame="-",
                    doc="time of each pose (T+1,)")
        write_array(g, "x0", np.asarray(inp.x0, np.float64), units="m,m,rad", frame="world",
                    doc="known start pose [x, y, theta] (3,)")
        write_array(g, "controls", np.asarray(inp.controls, np.float64).reshape(-1, 2),
                    units="m/s,rad/s", frame="body",
                    doc="commanded [v, omega] applied from pose t to t+1 (T,2)")
        write_array(g, "odometry_xyt", np.asarray(inp.odometry_xyt, np.float64).reshape(-1, 3),
                    units="m,m,rad", frame="odom",
                    doc="encoder dead-reckoning poses; only increments are trusted (T+1,3)")
        write_array(g, "max_range", np.float64(inp.max_range), units="m", frame="-",
                    doc="sensor max range (inf = unlimited)")

        go = g.create_group("observations")
        go.attrs["doc"] = "flat observation table in time order; rows of pose t are offsets[t]:offsets[t+1]"
        write_array(go, "step", np.asarray(obs.step, np.int64), units="-", frame="-",
                    doc="pose index t of each observation (N,)")
        write_array(go, "range_m", np.asarray(obs.range_m, np.float64), units="m", frame="sensor",
                    doc="measured range (N,)")
        write_array(go, "bearing_rad", np.asarray(obs.bearing_rad, np.float64), units="rad",
                    frame="body", doc="measured bearing, 0 = ahead, CCW positive, wrapped [-pi, pi) (N,)")
        write_array(go, "sensor", np.asarray(obs.sensor, np.int16), units="-", frame="-",
                    doc="index of the sensor that produced the row (N,)")
        write_array(go, "reported_id", np.asarray(obs.reported_id, np.int64), units="-", frame="-",
                    doc="landmark id reported by the sensor itself, -1 = none (N,)")
        write_array(go, "offsets", np.asarray(obs.offsets, np.int64), units="-", frame="-",
                    doc="CSR row offsets per pose (T+2,)")
        if inp.reported_id_source != "unknown":
            go["reported_id"].attrs["source"] = attr_text(inp.reported_id_source)

        if obs.landmark_type is not None:
            write_array(go, "landmark_type", np.asarray(obs.landmark_type, np.int64), units="-", frame="-",
                        doc="landmark type label reported by the sensor (not its identity) (N,)")
        if inp.noise_bounds is not None:
            _write_bounds(g, inp.noise_bounds)

        gn = g.create_group("noise")
        gn.attrs["doc"] = "noise standard deviations a solver may assume (slamcli.types.NoiseSpec)"
        n = inp.noise
        write_array(gn, "motion_std", np.asarray(n.motion_std, np.float64).reshape(2), units="m/s,rad/s",
                    frame="body", doc="[sigma_v, sigma_omega] actuation noise (2,)")
        write_array(gn, "odometry_std", np.asarray(n.odometry_std, np.float64).reshape(3),
                    units="m,m,rad", frame="body", doc="per-step odometry increment noise (3,)")
        write_array(gn, "range_std", np.float64(n.range_std), units="m", frame="sensor", doc="sigma_r")
        write_array(gn, "bearing_std", np.float64(n.bearing_std), units="rad", frame="sensor", doc="sigma_b")

        if len(inp.gps_step) > 0:
            write_array(g, "gps_step", np.asarray(inp.gps_step, np.int64), units="-", frame="-",
                        doc="pose index of each GPS fix (G,)")
            write_array(g, "gps_xy", np.asarray(inp.gps_xy, np.float64).reshape(-1, 2), units="m",
                        frame="world", doc="GPS position fixes (G,2)")
            write_array(g, "gps_std", np.float64(inp.gps_std), units="m", frame="world",
                        doc="sigma of one GPS fix")
        _write_motion_model(g, go, inp)

        if inp.constraints is not None:
            _write_constraints(g, inp.constraints)
        if inp.robots is not None:
            _write_robots(g, inp.robots)

        if dataset.truth is not None and dataset.truth.position_reference_only:
            _write_position_reference(f, dataset.truth)
        elif dataset.truth is not None:
            tr = dataset.truth
            gt = f.create_group("truth")
            gt.attrs["doc"] = "ground truth (slamcli.types.GroundTruth); never given to solvers"
            write_array(gt, "poses_xyt", np.asarray(tr.poses_xyt, np.float64).reshape(-1, 3),
                        units="m,m,rad", frame="world", doc="true poses (T+1,3)")
            write_array(gt, "landmarks_xy", np.asarray(tr.landmarks_xy, np.float64).reshape(-1, 2),
                        units="m", frame="world", doc="true landmark positions (L,2)")
            write_array(gt, "obs_landmark", np.asarray(tr.obs_landmark, np.int64), units="-", frame="-",
                        doc="true landmark index of each observation row, -1 = clutter (N,)")
            _write_truth_walls(gt, tr)
    return final


def _write_motion_model(g, go, inp: SlamInputs) -> None:
    """Motion-model tag, car geometry, sensor mount and per-observation object size."""
    g.attrs["motion_model"] = str(inp.motion_model)
    if inp.motion_source != "controls":  # written only when set, so older files read back unchanged
        g.attrs["motion_source"] = str(inp.motion_source)
    if inp.vehicle is not None:
        gv = g.create_group("vehicle")
        gv.attrs["doc"] = "car geometry of the ackermann motion model (slamcli.models.ackermann.AckermannParams)"
        write_array(gv, "wheelbase_m", np.float64(inp.vehicle.wheelbase_m), units="m", frame="body",
                    doc="L, rear axle to front axle")
        write_array(gv, "encoder_offset_m", np.float64(inp.vehicle.encoder_offset_m), units="m", frame="body",
                    doc="H, lateral offset of the rear-left speed encoder from the rear-axle centre")
    off = np.asarray(inp.sensor_offset_xy, np.float64).reshape(2)
    if off.any():
        write_array(g, "sensor_offset_xy", off, units="m", frame="body",
                    doc="sensor mount (a, b) in the body frame (2,)")
    if inp.observations.diameter_m is not None:
        write_array(go, "diameter_m", np.asarray(inp.observations.diameter_m, np.float64), units="m",
                    frame="-", doc="object size reported by the feature extractor, e.g. trunk diameter (N,)")


def _write_position_reference(f, tr: GroundTruth) -> None:
    gt = f.create_group("truth")
    gt.attrs["doc"] = "position-only reference (e.g. GPS): no true poses, landmarks or association"
    gt.attrs["kind"] = "position_reference"
    write_array(gt, "ref_time_s", np.asarray(tr.ref_time_s, np.float64).reshape(-1), units="s", frame="-",
                doc="time of each reference fix (G,)")
    write_array(gt, "ref_xy", np.asarray(tr.ref_xy, np.float64).reshape(-1, 2), units="m", frame="world",
                doc="reference positions (G,2)")
    if tr.ref_offset_xy is not None:
        write_array(gt, "ref_offset_xy", np.asarray(tr.ref_offset_xy, np.float64).reshape(2), units="m",
                    frame="body", doc="body-frame point the reference positions refer to (2,)")
    if tr.landmarks_xy is not None:
        write_array(gt, "landmarks_xy", np.asarray(tr.landmarks_xy, np.float64).reshape(-1, 2), units="m",
                    frame="world", doc="surveyed landmark positions in the reference frame (L,2); no association")


def _read_motion_model(r: Reader, inputs: SlamInputs) -> SlamInputs:
    import dataclasses

    from slamcli.models.ackermann import MOTION_MODELS, AckermannParams

    model = r.attr("inputs", "motion_model", str, default="ddmr")
    if model not in MOTION_MODELS:
        raise r.fail("inputs/@motion_model", f"unknown motion model {model!r} (known: {', '.join(MOTION_MODELS)})")
    source = r.attr("inputs", "motion_source", str, default="controls")
    if source not in MOTION_SOURCES:
        raise r.fail("inputs/@motion_source", f"must be one of {MOTION_SOURCES}, got {source!r}")
    vehicle = None
    if r.has("inputs/vehicle"):
        L = float(r.array("inputs/vehicle/wheelbase_m", dtype="f", shape=()))
        H = float(r.array("inputs/vehicle/encoder_offset_m", dtype="f", shape=()))
        if not L > 0:
            raise r.fail("inputs/vehicle/wheelbase_m", f"must be > 0, got {L}")
        vehicle = AckermannParams(wheelbase_m=L, encoder_offset_m=H)
    if model == "ackermann" and vehicle is None:
        raise r.fail("inputs/vehicle", "missing group (required by motion_model='ackermann')")
    off = np.zeros(2)
    if r.has("inputs/sensor_offset_xy"):
        off = r.array("inputs/sensor_offset_xy", dtype="f", shape=(2,))
    obs = inputs.observations
    if r.has("inputs/observations/diameter_m"):
        diam = r.array("inputs/observations/diameter_m", dtype="f", shape=(None,))
        r.expect_len("inputs/observations/diameter_m", diam, len(obs), "number of observations")
        obs = dataclasses.replace(obs, diameter_m=diam)
    return dataclasses.replace(inputs, motion_model=model, vehicle=vehicle, sensor_offset_xy=off,
                               observations=obs, motion_source=source)


OBSERVATION_MODELS = ("range_bearing", "xy")
REPORTED_ID_SOURCES = ("sensor", "file", "unknown")
#: values of ``inputs@motion_source`` (SlamInputs.motion_source)
MOTION_SOURCES = ("controls", "odometry")


def _write_constraints(g, c: PoseConstraints) -> None:
    """``/inputs/constraints``: pose-pose constraints and per-edge information matrices (all optional)."""
    gc = g.create_group("constraints")
    gc.attrs["doc"] = ("per-edge constraints with their own information matrices (slamcli.types.PoseConstraints): "
                       "pose-pose between-factors (loop closures, any two poses) and per-edge information")
    ij = np.asarray(c.between_ij, np.int64).reshape(-1, 2)
    write_array(gc, "between_i", ij[:, 0].copy(), units="-", frame="-", doc="first pose index i (B,)")
    write_array(gc, "between_j", ij[:, 1].copy(), units="-", frame="-", doc="second pose index j (B,)")
    write_array(gc, "between_xyt", np.asarray(c.between_xyt, np.float64).reshape(-1, 3), units="m,m,rad",
                frame="body", doc="measured pose of j in the body frame of i [dx, dy, dtheta] (B,3)")
    write_array(gc, "between_info", np.asarray(c.between_info, np.float64).reshape(-1, 3, 3), units="1/m2,1/m2,1/rad2",
                frame="body", doc="information (inverse covariance) of the SE(2) log error of each constraint (B,3,3)")
    if c.odometry_info is not None:
        write_array(gc, "odometry_info", np.asarray(c.odometry_info, np.float64).reshape(-1, 3, 3),
                    units="1/m2,1/m2,1/rad2", frame="body",
                    doc="information of each odometry increment t -> t+1 (T,3,3)")
    if c.observation_info is not None:
        write_array(gc, "observation_info", np.asarray(c.observation_info, np.float64).reshape(-1, 2, 2),
                    units="per model", frame="body",
                    doc="information of each observation row in the model named by @model (N,2,2)")
        gc["observation_info"].attrs["model"] = str(c.observation_model)


def _read_info(r: Reader, name: str, arr: np.ndarray) -> None:
    """Every matrix of ``arr (n, k, k)`` must be symmetric positive definite."""
    if not arr.shape[0]:
        return
    asym = np.abs(arr - np.swapaxes(arr, 1, 2)).max(axis=(1, 2)) > 1e-9 * np.maximum(1.0, np.abs(arr).max(axis=(1, 2)))
    if asym.any():
        raise r.fail(name, f"matrix {int(np.argmax(asym))} is not symmetric")
    low = np.linalg.eigvalsh(arr)[:, 0]
    if (low <= 0).any():
        k = int(np.argmax(low <= 0))
        raise r.fail(name, f"matrix {k} is not positive definite (smallest eigenvalue {low[k]:.3g})")


def _read_constraints(r: Reader, n_poses: int, n_obs: int) -> PoseConstraints | None:
    g = "inputs/constraints"
    if not r.has(g):
        return None
    r.group(g)
    bi = r.array(f"{g}/between_i", dtype="i", shape=(None,)).astype(np.int64, copy=False)
    B = bi.shape[0]
    bj = r.array(f"{g}/between_j", dtype="i", shape=(None,)).astype(np.int64, copy=False)
    r.expect_len(f"{g}/between_j", bj, B, f"len({g}/between_i)")
    xyt = r.array(f"{g}/between_xyt", dtype="f", shape=(None, 3))
    r.expect_len(f"{g}/between_xyt", xyt, B, f"len({g}/between_i)")
    info = r.array(f"{g}/between_info", dtype="f", shape=(None, 3, 3))
    r.expect_len(f"{g}/between_info", info, B, f"len({g}/between_i)")
    _check_index_range(r, f"{g}/between_i", bi, 0, n_poses - 1)
    _check_index_range(r, f"{g}/between_j", bj, 0, n_poses - 1)
    if B and (bi == bj).any():
        raise r.fail(f"{g}/between_j", f"constraint {int(np.argmax(bi == bj))} links a pose to itself")
    _read_info(r, f"{g}/between_info", info)
    odo_info = None
    if r.has(f"{g}/odometry_info"):
        odo_info = r.array(f"{g}/odometry_info", dtype="f", shape=(None, 3, 3))
        r.expect_len(f"{g}/odometry_info", odo_info, n_poses - 1, "T = len(timestamps) - 1")
        _read_info(r, f"{g}/odometry_info", odo_info)
    obs_info, model = None, "range_bearing"
    if r.has(f"{g}/observation_info"):
        obs_info = r.array(f"{g}/observation_info", dtype="f", shape=(None, 2, 2))
        r.expect_len(f"{g}/observation_info", obs_info, n_obs, "number of observations")
        _read_info(r, f"{g}/observation_info", obs_info)
        model = r.f[f"{g}/observation_info"].attrs.get("model", "")
        model = model.decode() if isinstance(model, bytes) else str(model)
        if model not in OBSERVATION_MODELS:
            raise r.fail(f"{g}/observation_info", f"@model must be one of {OBSERVATION_MODELS}, got {model!r}")
    return PoseConstraints(between_ij=np.stack([bi, bj], axis=1), between_xyt=xyt, between_info=info,
                           odometry_info=odo_info, observation_info=obs_info, observation_model=model)
def _write_robots(g, team: RobotTeam) -> None:
    """``/inputs/robots`` and ``/inputs/robot_observations`` (multi-robot datasets)."""
    gr = g.create_group("robots")
    gr.attrs["doc"] = ("multi-robot layout (slamcli.types.RobotTeam): poses of all robots stacked robot-major on "
                       "one common time grid; the odometry chain never crosses from one robot to the next")
    write_array(gr, "pose_robot", np.asarray(team.pose_robot, np.int64), units="-", frame="-",
                doc="robot index 0..R-1 of each stacked pose (P,)")
    write_array(gr, "robot_number", np.asarray(team.robot_number, np.int64), units="-", frame="-",
                doc="the dataset's own robot numbers (R,)")
    write_array(gr, "x0_xyt", np.asarray(team.x0_xyt, np.float64).reshape(-1, 3), units="m,m,rad", frame="world",
                doc="known start pose of each robot (R,3)")
    go = g.create_group("robot_observations")
    go.attrs["doc"] = "range-bearing readings of one robot by another, between two stacked poses of the same step"
    write_array(go, "observer_pose", np.asarray(team.observer_pose, np.int64), units="-", frame="-",
                doc="stacked pose index of the observing robot (K,)")
    write_array(go, "observed_pose", np.asarray(team.observed_pose, np.int64), units="-", frame="-",
                doc="stacked pose index of the observed robot at the same step (K,)")
    write_array(go, "range_m", np.asarray(team.range_m, np.float64), units="m", frame="sensor",
                doc="measured range to the observed robot (K,)")
    write_array(go, "bearing_rad", np.asarray(team.bearing_rad, np.float64), units="rad", frame="body",
                doc="measured bearing in the observer's frame, wrapped [-pi, pi) (K,)")


def _read_robots(r: Reader, n_poses: int) -> RobotTeam | None:
    """The optional multi-robot groups; None for single-robot files (every file written before them)."""
    g = "inputs/robots"
    if not r.has(g):
        return None
    r.group(g)
    pr = r.array(f"{g}/pose_robot", dtype="i", shape=(None,)).astype(np.int64, copy=False)
    r.expect_len(f"{g}/pose_robot", pr, n_poses, "T+1 = len(timestamps)")
    num = r.array(f"{g}/robot_number", dtype="i", shape=(None,)).astype(np.int64, copy=False)
    R = num.shape[0]
    if R < 1:
        raise r.fail(f"{g}/robot_number", "needs at least one robot")
    x0 = r.array(f"{g}/x0_xyt", dtype="f", shape=(None, 3))
    r.expect_len(f"{g}/x0_xyt", x0, R, f"len({g}/robot_number)")
    _check_index_range(r, f"{g}/pose_robot", pr, 0, R - 1)
    if n_poses > 1 and (np.diff(pr) < 0).any():
        raise r.fail(f"{g}/pose_robot", f"not non-decreasing at index {int(np.argmax(np.diff(pr) < 0)) + 1} "
                                        "(poses are stacked robot-major)")
    if np.unique(pr).size != R:
        raise r.fail(f"{g}/pose_robot", f"some of the {R} robots own no pose")
    go = "inputs/robot_observations"
    r.group(go)
    oi = r.array(f"{go}/observer_pose", dtype="i", shape=(None,)).astype(np.int64, copy=False)
    K = oi.shape[0]
    oj = r.array(f"{go}/observed_pose", dtype="i", shape=(None,)).astype(np.int64, copy=False)
    r.expect_len(f"{go}/observed_pose", oj, K, f"len({go}/observer_pose)")
    rng = r.array(f"{go}/range_m", dtype="f", shape=(None,))
    r.expect_len(f"{go}/range_m", rng, K, f"len({go}/observer_pose)")
    brg = r.array(f"{go}/bearing_rad", dtype="f", shape=(None,))
    r.expect_len(f"{go}/bearing_rad", brg, K, f"len({go}/observer_pose)")
    _check_index_range(r, f"{go}/observer_pose", oi, 0, n_poses - 1)
    _check_index_range(r, f"{go}/observed_pose", oj, 0, n_poses - 1)
    if K and (pr[oi] == pr[oj]).any():
        raise r.fail(f"{go}/observed_pose", f"reading {int(np.argmax(pr[oi] == pr[oj]))} links a robot to itself")
    if K and (rng < 0).any():
        raise r.fail(f"{go}/range_m", f"range must be >= 0, got {float(rng[np.argmax(rng < 0)]):g}")
    return RobotTeam(pose_robot=pr, robot_number=num, x0_xyt=x0, observer_pose=oi, observed_pose=oj,
                     range_m=rng, bearing_rad=brg)


def _write_bounds(g, nb: NoiseBounds) -> None:
    gb = g.create_group("noise_bounds")
    gb.attrs["doc"] = "guaranteed error half-widths (slamcli.types.NoiseBounds): |error| <= bound"
    gb.attrs["odometry_model"] = str(nb.odometry_model)
    write_array(gb, "odometry_half_width", np.asarray(nb.odometry_half_width, np.float64).reshape(2),
                units="m,rad", frame="body", doc="[h_d, h_alpha] of the turn_move odometry (2,)")
    write_array(gb, "range_half_width", np.float64(nb.range_half_width), units="m", frame="sensor", doc="h_r")
    write_array(gb, "bearing_half_width", np.float64(nb.bearing_half_width), units="rad", frame="sensor",
                doc="h_b")
    gb.attrs["closest_only"] = bool(nb.closest_only)
    gb.attrs["min_range"] = float(nb.min_range)
    gb.attrs["min_separation"] = float(nb.min_separation)


def _read_bounds(r: Reader) -> NoiseBounds | None:
    if not r.has("inputs/noise_bounds"):
        return None
    g = "inputs/noise_bounds"
    r.group(g)
    model = r.attr(g, "odometry_model", str)
    if model != "turn_move":
        raise r.fail(f"{g}/@odometry_model", f"unknown odometry model {model!r} (known: turn_move)")
    odo = r.array(f"{g}/odometry_half_width", dtype="f", shape=(2,))
    hr = float(r.array(f"{g}/range_half_width", dtype="f", shape=()))
    hb = float(r.array(f"{g}/bearing_half_width", dtype="f", shape=()))
    for name, v in (("odometry_half_width", odo), ("range_half_width", hr), ("bearing_half_width", hb)):
        if (np.asarray(v) < 0).any():
            raise r.fail(f"{g}/{name}", f"half-widths must be >= 0, got {v}")
    # sensor / map declarations (optional; files written before they existed declare nothing)
    closest = bool(r.attr(g, "closest_only", bool, default=False))
    min_range = float(r.attr(g, "min_range", float, default=0.0))
    min_sep = float(r.attr(g, "min_separation", float, default=0.0))
    for name, v in (("@min_range", min_range), ("@min_separation", min_sep)):
        if not (v >= 0 and np.isfinite(v)):
            raise r.fail(f"{g}/{name}", f"must be a finite number >= 0, got {v}")
    return NoiseBounds(odometry_model=model, odometry_half_width=odo, range_half_width=hr,
                       bearing_half_width=hb, closest_only=closest, min_range=min_range, min_separation=min_sep)


# --------------------------------------------------------------------------------------------------------
# reading
# --------------------------------------------------------------------------------------------------------
def read_dataset(path: str | os.PathLike, *, with_truth: bool = True) -> Dataset:
    """Read and fully validate a dataset file.

    Parameters
    ----------
    path : dataset file (schema ``slamcli.dataset`` v1).
    with_truth : when False, ``/truth`` is not read and ``Dataset.truth`` is None.

    Raises
    ------
    SchemaError
        one line ``<file>: <group/field>: <problem>`` for any missing/corrupt/inconsistent content.
    """
    with open_for_read(path) as r:
        return _read_dataset(r, with_truth)


def _read_dataset(r: Reader, with_truth: bool = True) -> Dataset:
    r.check_schema(DATASET_SCHEMA)
    dt = r.finite_attr("/", "dt", positive=True)
    metadata = r.json_attr("/", "metadata_json", default={})
    if not isinstance(metadata, dict):
        raise r.fail("@metadata_json", f"expected a JSON object, got {type(metadata).__name__}")
    has_truth = r.attr("/", "has_truth", bool, default=r.has("truth"))
    check_declared_shapes(r, with_truth=with_truth and has_truth)
    inputs = _read_motion_model(r, _read_inputs(r, dt))
    truth = None
    if with_truth and has_truth:
        truth = _read_truth(r, inputs)
    return Dataset(inputs=inputs, truth=truth, metadata=metadata)


def _readable(final: Path):
    """The ``create_h5`` check of :func:`write_dataset`: the finished file must pass :func:`read_dataset`'s
    validation (what slamcli writes, slamcli reads), else a one-line SchemaError naming ``final`` and the
    field, and nothing is written."""

    def check(f) -> None:
        try:
            _read_dataset(Reader(f, final))
        except SchemaError as exc:
            what = str(exc).removeprefix(f"{final}: ")
            raise SchemaError(f"{final}: not written, slamcli could not read it back: {what}") from None

    return check


def check_declared_shapes(r: Reader, *, with_truth: bool = True) -> None:
    """Check the *declared* array shapes against each other and :data:`MAX_POSES` before any array is read.

    A forged header (say ``timestamps`` claiming 10⁹ rows in a 100 kB file) is refused here with one line,
    instead of being materialised in memory by the first read. Missing arrays are left to the full reader.
    """
    ts = r.declared_shape("inputs/timestamps")
    if ts is None or len(ts) != 1:
        return
    n_poses = ts[0]
    if n_poses > MAX_POSES:
        raise r.fail("inputs/timestamps", f"declares {n_poses} poses, above the limit of {MAX_POSES}")
    g = "inputs/observations"
    step = r.declared_shape(f"{g}/step")
    expect: list[tuple[str, int, str]] = [
        ("inputs/controls", n_poses - 1, "T = len(timestamps) - 1"),
        ("inputs/odometry_xyt", n_poses, "T+1 = len(timestamps)"),
        (f"{g}/offsets", n_poses + 1, "T+2 = len(timestamps) + 1"),
    ]
    if step is not None and len(step) == 1:
        expect += [(f"{g}/{n}", step[0], f"len({g}/step)") for n in ("range_m", "bearing_rad", "sensor",
                                                                     "reported_id")]
        if with_truth:
            expect.append(("truth/obs_landmark", step[0], "number of observations"))
    if with_truth:
        expect.append(("truth/poses_xyt", n_poses, "T+1 = len(inputs/timestamps)"))
    gps = r.declared_shape("inputs/gps_step")
    if gps is not None and len(gps) == 1:
        expect.append(("inputs/gps_xy", gps[0], "len(gps_step)"))
    gc = "inputs/constraints"
    bi = r.declared_shape(f"{gc}/between_i")
    if bi is not None and len(bi) == 1:
        expect += [(f"{gc}/{n}", bi[0], f"len({gc}/between_i)") for n in ("between_j", "between_xyt", "between_info")]
    expect.append((f"{gc}/odometry_info", n_poses - 1, "T = len(timestamps) - 1"))
    expect.append(("inputs/robots/pose_robot", n_poses, "T+1 = len(timestamps)"))
    if step is not None and len(step) == 1:
        expect.append((f"{gc}/observation_info", step[0], "number of observations"))
    for name, n, what in expect:
        shp = r.declared_shape(name)
        if shp is not None and len(shp) >= 1 and shp[0] != n:
            raise r.fail(name, f"declared length {shp[0]} does not match {what} ({n})")




def check_magnitude(r: Reader, name: str, a: np.ndarray) -> None:
    """Refuse values of magnitude above :data:`MAX_INPUT_MAGNITUDE` (one line naming the field and index)."""
    big = np.abs(a) > MAX_INPUT_MAGNITUDE
    if big.any():
        idx = np.unravel_index(int(np.argmax(big)), a.shape)
        raise r.fail(name, f"value {a[idx]:g} at index {tuple(int(i) for i in idx)} is beyond ±{MAX_INPUT_MAGNITUDE:g} "
                           "(not a physical pose or control)")


def _read_inputs(r: Reader, dt: float) -> SlamInputs:
    r.group("inputs")
    ts = r.array("inputs/timestamps", dtype="f", shape=(None,))
    n_poses = ts.shape[0]
    if n_poses < 1:
        raise r.fail("inputs/timestamps", "needs at least one pose (T+1 >= 1)")
    robots = _read_robots(r, n_poses)
    # multi-robot: the time grid repeats per robot; strictly increasing within each robot
    same = np.ones(max(n_poses - 1, 0), bool) if robots is None else robots.pose_robot[:-1] == robots.pose_robot[1:]
    if n_poses > 1 and not (np.diff(ts)[same] > 0).all():
        k = int(np.argmax(~(np.diff(ts) > 0) & same))
        raise r.fail("inputs/timestamps", f"not strictly increasing at index {k + 1}")
    T = n_poses - 1
    x0 = r.array("inputs/x0", dtype="f", shape=(3,))
    controls = r.array("inputs/controls", dtype="f", shape=(None, 2))
    r.expect_len("inputs/controls", controls, T, "T = len(timestamps) - 1")
    odo = r.array("inputs/odometry_xyt", dtype="f", shape=(None, 3))
    r.expect_len("inputs/odometry_xyt", odo, n_poses, "T+1 = len(timestamps)")
    for name, a in (("inputs/x0", x0), ("inputs/controls", controls), ("inputs/odometry_xyt", odo)):
        check_magnitude(r, name, a)
    max_range = float(r.array("inputs/max_range", dtype="f", shape=(), finite=False))
    if np.isnan(max_range) or not max_range > 0:
        raise r.fail("inputs/max_range", f"must be > 0 (inf allowed), got {max_range}")

    observations = _read_observations(r, n_poses)

    r.group("inputs/noise")
    motion_std = r.array("inputs/noise/motion_std", dtype="f", shape=(2,))
    odometry_std = r.array("inputs/noise/odometry_std", dtype="f", shape=(3,))
    range_std = float(r.array("inputs/noise/range_std", dtype="f", shape=()))
    bearing_std = float(r.array("inputs/noise/bearing_std", dtype="f", shape=()))
    for name, v in (("motion_std", motion_std), ("odometry_std", odometry_std), ("range_std", range_std),
                    ("bearing_std", bearing_std)):
        if (np.asarray(v) < 0).any():
            raise r.fail(f"inputs/noise/{name}", f"standard deviations must be >= 0, got {v}")
    noise = NoiseSpec(motion_std=motion_std, odometry_std=odometry_std, range_std=range_std,
                      bearing_std=bearing_std)

    gps_names = [n for n in ("gps_step", "gps_xy", "gps_std") if r.has(f"inputs/{n}")]
    gps_step = np.zeros(0, dtype=np.int64)
    gps_xy = np.zeros((0, 2))
    gps_std = 0.0
    if gps_names:
        for n in ("gps_step", "gps_xy", "gps_std"):
            if n not in gps_names:
                raise r.fail(f"inputs/{n}", f"missing dataset (required together with {', '.join(gps_names)})")
        gps_step = r.array("inputs/gps_step", dtype="i", shape=(None,)).astype(np.int64, copy=False)
        gps_xy = r.array("inputs/gps_xy", dtype="f", shape=(None, 2))
        r.expect_len("inputs/gps_xy", gps_xy, gps_step.shape[0], "len(gps_step)")
        gps_std = float(r.array("inputs/gps_std", dtype="f", shape=()))
        if gps_std < 0:
            raise r.fail("inputs/gps_std", f"must be >= 0, got {gps_std}")
        _check_index_range(r, "inputs/gps_step", gps_step, 0, T)

    return SlamInputs(
        dt=dt,
        timestamps=ts,
        x0=x0,
        controls=controls,
        odometry_xyt=odo,
        observations=observations,
        noise=noise,
        max_range=max_range,
        gps_step=gps_step,
        gps_xy=gps_xy,
        gps_std=gps_std,
        constraints=_read_constraints(r, n_poses, len(observations)),
        reported_id_source=_reported_id_source(r),
        noise_bounds=_read_bounds(r),
        robots=robots,
    )


def _reported_id_source(r: Reader) -> str:
    """``@source`` of ``inputs/observations/reported_id`` (``sensor`` / ``file``), ``unknown`` when absent."""
    v = r.f["inputs/observations/reported_id"].attrs.get("source", "unknown")
    v = v.decode() if isinstance(v, bytes) else str(v)
    if v not in REPORTED_ID_SOURCES:
        raise r.fail("inputs/observations/reported_id@source", f"must be one of {REPORTED_ID_SOURCES}, got {v!r}")
    return v


def _check_index_range(r: Reader, name: str, idx: np.ndarray, lo: int, hi: int) -> None:
    """All entries of ``idx`` must lie in ``[lo, hi]``."""
    if idx.size:
        bad = np.flatnonzero((idx < lo) | (idx > hi))
        if bad.size:
            k = int(bad[0])
            raise r.fail(name, f"value {int(idx[k])} at row {k} out of range [{lo}, {hi}]")


def _read_observations(r: Reader, n_poses: int) -> Observations:
    g = "inputs/observations"
    r.group(g)
    step = r.array(f"{g}/step", dtype="i", shape=(None,)).astype(np.int64, copy=False)
    N = step.shape[0]
    range_m = r.array(f"{g}/range_m", dtype="f", shape=(None,))
    bearing = r.array(f"{g}/bearing_rad", dtype="f", shape=(None,))
    sensor = r.array(f"{g}/sensor", dtype="i", shape=(None,))
    if sensor.size and int(sensor.max()) > np.iinfo(np.int16).max:
        k = int(np.argmax(sensor > np.iinfo(np.int16).max))
        raise r.fail(f"{g}/sensor", f"sensor index {int(sensor[k])} at row {k} above {np.iinfo(np.int16).max}")
    if sensor.size and int(sensor.min()) < 0:
        k = int(np.argmax(sensor < 0))
        raise r.fail(f"{g}/sensor", f"negative sensor index {int(sensor[k])} at row {k}")
    sensor = sensor.astype(np.int16, copy=False)
    reported = r.array(f"{g}/reported_id", dtype="i", shape=(None,)).astype(np.int64, copy=False)
    offsets = r.array(f"{g}/offsets", dtype="i", shape=(None,)).astype(np.int64, copy=False)
    for name, arr in (("range_m", range_m), ("bearing_rad", bearing), ("sensor", sensor),
                      ("reported_id", reported)):
        r.expect_len(f"{g}/{name}", arr, N, f"len({g}/step)")
    r.expect_len(f"{g}/offsets", offsets, n_poses + 1, "T+2 = len(timestamps) + 1")
    if N and (range_m < 0).any():
        k = int(np.argmax(range_m < 0))
        raise r.fail(f"{g}/range_m", f"negative range {range_m[k]} at row {k}")
    if N and (np.abs(bearing) > np.pi + _BEARING_TOL).any():
        k = int(np.argmax(np.abs(bearing) > np.pi + _BEARING_TOL))
        raise r.fail(f"{g}/bearing_rad", f"bearing {bearing[k]} at row {k} outside [-pi, pi] (radians?)")
    if N and (sensor < 0).any():
        k = int(np.argmax(sensor < 0))
        raise r.fail(f"{g}/sensor", f"negative sensor index {int(sensor[k])} at row {k}")
    if N and (reported < -1).any():
        k = int(np.argmax(reported < -1))
        raise r.fail(f"{g}/reported_id", f"value {int(reported[k])} at row {k} below -1")
    _check_index_range(r, f"{g}/step", step, 0, n_poses - 1)
    if offsets[0] != 0:
        raise r.fail(f"{g}/offsets", f"must start at 0, got {int(offsets[0])}")
    d = np.diff(offsets)
    if (d < 0).any():
        k = int(np.argmax(d < 0))
        raise r.fail(f"{g}/offsets", f"not monotone: offsets[{k + 1}]={int(offsets[k + 1])} < "
                                     f"offsets[{k}]={int(offsets[k])}")
    if offsets[-1] != N:
        raise r.fail(f"{g}/offsets", f"last offset {int(offsets[-1])} != number of observations {N}")
    expected = Observations.offsets_from_steps(step, n_poses)
    if not np.array_equal(expected, offsets):
        k = int(np.argmax(expected != offsets))
        raise r.fail(f"{g}/offsets", f"do not match the step column (first mismatch at pose {max(k - 1, 0)}; "
                                     "steps must be sorted and counted per pose)")
    landmark_type = None
    if r.has(f"{g}/landmark_type"):
        landmark_type = r.array(f"{g}/landmark_type", dtype="i", shape=(None,)).astype(np.int64, copy=False)
        r.expect_len(f"{g}/landmark_type", landmark_type, N, f"len({g}/step)")
        if N and (landmark_type < -1).any():
            k = int(np.argmax(landmark_type < -1))
            raise r.fail(f"{g}/landmark_type", f"value {int(landmark_type[k])} at row {k} below -1")
    return Observations(step=step, range_m=range_m, bearing_rad=bearing, sensor=sensor, reported_id=reported,
                        offsets=offsets, landmark_type=landmark_type)


def _read_truth(r: Reader, inputs: SlamInputs) -> GroundTruth:
    r.group("truth")
    if r.attr("truth", "kind", str, default="full") == "position_reference":
        ref_t = r.array("truth/ref_time_s", dtype="f", shape=(None,))
        ref_xy = r.array("truth/ref_xy", dtype="f", shape=(None, 2))
        r.expect_len("truth/ref_xy", ref_xy, ref_t.shape[0], "len(truth/ref_time_s)")
        if ref_t.shape[0] > 1 and not (np.diff(ref_t) > 0).all():
            raise r.fail("truth/ref_time_s", "not strictly increasing")
        lms = r.array("truth/landmarks_xy", dtype="f", shape=(None, 2)) if r.has("truth/landmarks_xy") else None
        ref_off = r.array("truth/ref_offset_xy", dtype="f", shape=(2,)) if r.has("truth/ref_offset_xy") else None
        return GroundTruth(poses_xyt=None, landmarks_xy=lms, obs_landmark=None, ref_time_s=ref_t, ref_xy=ref_xy,
                           ref_offset_xy=ref_off)
    poses = r.array("truth/poses_xyt", dtype="f", shape=(None, 3))
    r.expect_len("truth/poses_xyt", poses, inputs.n_poses, "T+1 = len(inputs/timestamps)")
    lms = r.array("truth/landmarks_xy", dtype="f", shape=(None, 2))
    obs_lm = r.array("truth/obs_landmark", dtype="i", shape=(None,)).astype(np.int64, copy=False)
    r.expect_len("truth/obs_landmark", obs_lm, len(inputs.observations), "number of observations")
    _check_index_range(r, "truth/obs_landmark", obs_lm, -1, lms.shape[0] - 1)
    occupancy, walls_xyxy, lap_end = _read_truth_walls(r)
    return GroundTruth(poses_xyt=poses, landmarks_xy=lms, obs_landmark=obs_lm, occupancy=occupancy,
                       walls_xyxy=walls_xyxy, lap_end_step=lap_end)


def _write_truth_walls(gt, tr: GroundTruth) -> None:
    """Optional wall-world truth (paper 001): ``occupancy/`` grid group, ``walls_xyxy``, ``lap_end_step``."""
    from slamcli.io.grid import write_grid

    if tr.occupancy is not None:
        write_grid(gt, "occupancy", tr.occupancy)
    if tr.walls_xyxy is not None:
        write_array(gt, "walls_xyxy", np.asarray(tr.walls_xyxy, np.float64).reshape(-1, 4), units="m",
                    frame="world", doc="wall segments [x1, y1, x2, y2] (W,4)")
    if tr.lap_end_step is not None:
        write_array(gt, "lap_end_step", np.asarray(tr.lap_end_step, np.int64), units="-", frame="-",
                    doc="step at which each lap of the route ended (K,)")


def _read_truth_walls(r: Reader):
    from slamcli.io.grid import read_grid

    occ = read_grid(r, "truth/occupancy") if r.has("truth/occupancy") else None
    walls = r.array("truth/walls_xyxy", dtype="f", shape=(None, 4)) if r.has("truth/walls_xyxy") else None
    laps = (r.array("truth/lap_end_step", dtype="i", shape=(None,)).astype(np.int64, copy=False)
            if r.has("truth/lap_end_step") else None)
    return occ, walls, laps


def read_header(path: str | os.PathLike) -> dict[str, Any]:
    """Root attributes of a slamcli dataset or result file (schema name/version checked loosely).

    Returns a dict of plain Python values (JSON attributes decoded); used by ``slamcli info``.
    """
    import json

    with open_for_read(path) as r:
        out: dict[str, Any] = {}
        for key in r.f.attrs:
            v = r.f.attrs[key]
            if isinstance(v, bytes):
                v = v.decode("utf-8", "replace")
            if isinstance(v, np.generic):
                v = v.item()
            if key.endswith("_json") and isinstance(v, str):
                try:
                    v = json.loads(v)
                except json.JSONDecodeError:
                    raise r.fail(f"@{key}", "invalid JSON") from None
            out[key] = v
    return out


# --------------------------------------------------------------------------------------------------------
# content hash
# --------------------------------------------------------------------------------------------------------
def _feed(h: hashlib._Hash, name: str, arr: Any, dtype: Any) -> None:
    a = np.ascontiguousarray(np.asarray(arr, dtype=dtype))
    a = a.astype(a.dtype.newbyteorder("<"), copy=False)
    h.update(f"{name}|{a.dtype.str}|{a.shape}|".encode())
    h.update(a.tobytes())


def dataset_hash(dataset: Dataset) -> str:
    """``sha256:<hex>`` over the canonical input and truth arrays and key metadata (not file bytes).

    Two files with the same content (e.g. the same simulation written twice, or a dataset before and after a
    write/read round-trip) get the same hash; changing any input value, the truth, ``dt``, the noise spec,
    ``max_range``, the GPS fixes, or metadata ``seed``/``scenario`` changes it. Creation time and
    version attributes are deliberately left out.
    """
    inp = dataset.inputs
    obs = inp.observations
    h = hashlib.sha256()
    h.update(f"{DATASET_SCHEMA}/v{SCHEMA_VERSION}|".encode())
    _feed(h, "dt", inp.dt, np.float64)
    _feed(h, "timestamps", inp.timestamps, np.float64)
    _feed(h, "x0", inp.x0, np.float64)
    _feed(h, "controls", np.asarray(inp.controls, np.float64).reshape(-1, 2), np.float64)
    _feed(h, "odometry_xyt", np.asarray(inp.odometry_xyt, np.float64).reshape(-1, 3), np.float64)
    _feed(h, "max_range", inp.max_range, np.float64)
    _feed(h, "obs.step", obs.step, np.int64)
    _feed(h, "obs.range_m", obs.range_m, np.float64)
    _feed(h, "obs.bearing_rad", obs.bearing_rad, np.float64)
    _feed(h, "obs.sensor", obs.sensor, np.int16)
    _feed(h, "obs.reported_id", obs.reported_id, np.int64)
    _feed(h, "obs.offsets", obs.offsets, np.int64)
    n = inp.noise
    _feed(h, "noise.motion_std", n.motion_std, np.float64)
    _feed(h, "noise.odometry_std", n.odometry_std, np.float64)
    _feed(h, "noise.range_std", n.range_std, np.float64)
    _feed(h, "noise.bearing_std", n.bearing_std, np.float64)
    _feed(h, "gps_step", inp.gps_step, np.int64)
    _feed(h, "gps_xy", np.asarray(inp.gps_xy, np.float64).reshape(-1, 2), np.float64)
    _feed(h, "gps_std", inp.gps_std if len(inp.gps_step) else 0.0, np.float64)
    if inp.reported_id_source != "unknown":  # fed only when set, so older hashes are unchanged
        h.update(f"reported_id_source|{inp.reported_id_source}|".encode())
    if inp.motion_source != "controls":  # likewise
        h.update(f"motion_source|{inp.motion_source}|".encode())
    c = inp.constraints
    if c is not None:  # fed only when present, so the hash of a dataset without constraints is unchanged
        _feed(h, "constraints.between_ij", np.asarray(c.between_ij, np.int64).reshape(-1, 2), np.int64)
        _feed(h, "constraints.between_xyt", np.asarray(c.between_xyt, np.float64).reshape(-1, 3), np.float64)
        _feed(h, "constraints.between_info", np.asarray(c.between_info, np.float64).reshape(-1, 3, 3), np.float64)
        if c.odometry_info is not None:
            _feed(h, "constraints.odometry_info", c.odometry_info, np.float64)
        if c.observation_info is not None:
            _feed(h, "constraints.observation_info", c.observation_info, np.float64)
            h.update(f"constraints.observation_model|{c.observation_model}|".encode())
    if obs.landmark_type is not None:  # fed only when present: hashes of older datasets are unchanged
        _feed(h, "obs.landmark_type", obs.landmark_type, np.int64)
    if inp.noise_bounds is not None:
        nb = inp.noise_bounds
        h.update(f"noise_bounds|{nb.odometry_model}|".encode())
        _feed(h, "noise_bounds.values", np.r_[np.asarray(nb.odometry_half_width, float).reshape(2),
                                              nb.range_half_width, nb.bearing_half_width], np.float64)
        if nb.closest_only or nb.min_range or nb.min_separation:  # declarations hashed only when made
            _feed(h, "noise_bounds.declared", np.array([float(nb.closest_only), nb.min_range, nb.min_separation]),
                  np.float64)
    # issue-14 fields are hashed only when not at their defaults, so hashes of older datasets are unchanged
    if inp.motion_model != "ddmr" or inp.vehicle is not None:
        h.update(f"motion_model|{inp.motion_model}|{inp.vehicle!r}|".encode())
    if np.asarray(inp.sensor_offset_xy).any():
        _feed(h, "sensor_offset_xy", inp.sensor_offset_xy, np.float64)
    if obs.diameter_m is not None:
        _feed(h, "obs.diameter_m", obs.diameter_m, np.float64)
    if inp.robots is not None:  # multi-robot (fed only when present: single-robot hashes are unchanged)
        tm = inp.robots
        _feed(h, "robots.pose_robot", tm.pose_robot, np.int64)
        _feed(h, "robots.robot_number", tm.robot_number, np.int64)
        _feed(h, "robots.x0_xyt", np.asarray(tm.x0_xyt, np.float64).reshape(-1, 3), np.float64)
        _feed(h, "robots.obs_ij", np.stack([np.asarray(tm.observer_pose, np.int64),
                                            np.asarray(tm.observed_pose, np.int64)], -1), np.int64)
        _feed(h, "robots.obs_z", tm.z, np.float64)
    if dataset.truth is not None and dataset.truth.position_reference_only:
        _feed(h, "truth.ref_time_s", dataset.truth.ref_time_s, np.float64)
        _feed(h, "truth.ref_xy", np.asarray(dataset.truth.ref_xy, np.float64).reshape(-1, 2), np.float64)
        if dataset.truth.ref_offset_xy is not None:
            _feed(h, "truth.ref_offset_xy", dataset.truth.ref_offset_xy, np.float64)
        if dataset.truth.landmarks_xy is not None:
            _feed(h, "truth.landmarks_xy", np.asarray(dataset.truth.landmarks_xy, np.float64).reshape(-1, 2),
                  np.float64)
    elif dataset.truth is not None:
        t = dataset.truth
        _feed(h, "truth.poses_xyt", np.asarray(t.poses_xyt, np.float64).reshape(-1, 3), np.float64)
        _feed(h, "truth.landmarks_xy", np.asarray(t.landmarks_xy, np.float64).reshape(-1, 2), np.float64)
        _feed(h, "truth.obs_landmark", t.obs_landmark, np.int64)
    else:
        h.update(b"no-truth|")
    meta = dataset.metadata or {}
    h.update(to_json({k: meta.get(k) for k in ("seed", "scenario")}).encode())
    return "sha256:" + h.hexdigest()
