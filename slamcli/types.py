"""Typed containers that flow between the simulator, the solvers, the metrics and the ``io`` package.

The split is deliberate: :class:`SlamInputs` is everything a solver may see (controls, odometry,
observations, sensor specs and the known start pose); :class:`GroundTruth` is produced only by the
simulator (or a real dataset's reference system) and read only by metrics. Solvers never receive it.

Shapes are in the names and docstrings: ``poses_xyt (T+1, 3)``, ``landmarks_xy (L, 2)``, ``*_cov (..., k, k)``.
Observations are a flat table in time order with CSR offsets: the observations taken at pose ``t`` are rows
``offsets[t]:offsets[t+1]``; ``offsets`` has length ``T+2`` (one entry per pose plus the end).
"""

from __future__ import annotations

import dataclasses
import enum
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np

#: Progress of a long computation: ``progress(done, total)`` — called by the simulators, the solvers and the
#: api workflows (e.g. ``(0, T)`` at the start, every few thousand steps, ``(T, T)`` at the end).
ProgressFn = Callable[[int, int], None]
#: One-line status messages (``log("fig5: 12 runs")``): the reproduce driver and its sections.
LogFn = Callable[[str], None]


@dataclass(frozen=True)
class NoiseSpec:
    """Noise levels a solver may assume (sensor data sheets / calibration), all standard deviations.

    Attributes
    ----------
    motion_std : ndarray (2,)     [σ_v m/s, σ_ω rad/s] of the actuation noise on the commanded controls.
    odometry_std : ndarray (3,)   [σ_x m, σ_y m, σ_θ rad] per-step noise of the body-frame odometry increment.
    range_std : float             σ_r of range measurements, m.
    bearing_std : float           σ_b of bearing measurements, rad.
    """

    motion_std: np.ndarray
    odometry_std: np.ndarray
    range_std: float
    bearing_std: float

    @property
    def obs_cov(self) -> np.ndarray:
        """Measurement covariance ``(2, 2)`` of one range-bearing observation."""
        return np.diag([self.range_std**2, self.bearing_std**2])


@dataclass(frozen=True)
class Observations:
    """Flat observation table, time-ordered, with CSR offsets per pose.

    Attributes
    ----------
    step : ndarray (N,) int64          index t of the pose at which each observation was taken.
    range_m : ndarray (N,) float64     measured range, m (≥ 0).
    bearing_rad : ndarray (N,) float64 measured bearing, rad, wrapped to [-pi, pi), 0 = straight ahead.
    sensor : ndarray (N,) int16        index of the sensor that produced the row (0 = first sensor).
    reported_id : ndarray (N,) int64   landmark identity reported *by the sensor* (e.g. MRCLAM barcodes,
                                       simulator option ``report_ids``); -1 when the sensor reports none.
                                       This is a measurement a solver may use, not ground truth.
    offsets : ndarray (T+2,) int64     rows of pose t are ``offsets[t]:offsets[t+1]``.
    diameter_m : ndarray (N,) | None   optional size of the observed object reported by the feature
                                       extractor (Victoria Park: trunk diameter), m; None = not reported.
    landmark_type : ndarray (N,) int64 | None  landmark *type* label reported by the sensor (e.g. 0 = door,
                                       1 = corridor) without the identity; None when the sensor reports none.
    """

    step: np.ndarray
    range_m: np.ndarray
    bearing_rad: np.ndarray
    sensor: np.ndarray
    reported_id: np.ndarray
    offsets: np.ndarray
    diameter_m: np.ndarray | None = None
    landmark_type: np.ndarray | None = None

    def __len__(self) -> int:
        return int(self.range_m.shape[0])

    @property
    def z(self) -> np.ndarray:
        """Measurements ``(N, 2)`` as ``[range, bearing]``."""
        return np.stack([self.range_m, self.bearing_rad], axis=-1)

    def at(self, t: int) -> slice:
        """Row slice of the observations taken at pose ``t``."""
        return slice(int(self.offsets[t]), int(self.offsets[t + 1]))

    @staticmethod
    def from_rows(
        step,
        z,
        n_poses: int,
        *,
        reported_id=None,
        sensor=None,
    ) -> Observations:
        """Build the table from time-ordered rows.

        Parameters
        ----------
        step : array (N,)            pose index of each row (non-decreasing).
        z : array (N, 2)             ``[range, bearing]``; bearings are wrapped here with the one wrap helper.
        n_poses : int                T+1 (sets the length of ``offsets``).
        reported_id : array (N,)     sensor-reported ids; default all -1 (the sensor reports none).
        sensor : array (N,)          sensor index; default all 0.
        """
        from slamcli.models.angles import wrap_angle

        step = np.asarray(step, np.int64).reshape(-1)
        z = np.asarray(z, float).reshape(-1, 2)
        n = step.shape[0]
        return Observations(
            step=step,
            range_m=z[:, 0].copy(),
            bearing_rad=np.asarray(wrap_angle(z[:, 1]), float).reshape(-1),
            sensor=np.zeros(n, np.int16) if sensor is None else np.asarray(sensor, np.int16).copy(),
            reported_id=(
                np.full(n, -1, np.int64) if reported_id is None else np.asarray(reported_id, np.int64).copy()
            ),
            offsets=Observations.offsets_from_steps(step, n_poses),
        )

    @staticmethod
    def offsets_from_steps(step: np.ndarray, n_poses: int) -> np.ndarray:
        """CSR offsets ``(n_poses+1,)`` for a sorted step column."""
        counts = np.bincount(np.asarray(step, dtype=np.int64), minlength=n_poses)
        return np.concatenate([[0], np.cumsum(counts)]).astype(np.int64)


@dataclass(frozen=True)
class PoseConstraints:
    """Per-edge constraints with their own information matrices (``/inputs/constraints`` in the schema).

    Pose graphs (g2o ``EDGE_SE2`` loop closures), lossless graph imports and, later, multi-robot encounters
    carry one information matrix per edge instead of one σ per quantity. Every field is optional (None or
    zero rows when absent).

    Attributes
    ----------
    between_ij : ndarray (B, 2) int64       pose indices ``(i, j)`` of each pose-pose constraint (any two poses;
                                            the odometry chain ``t → t+1`` is *not* repeated here).
    between_xyt : ndarray (B, 3)            measured pose of ``j`` in ``i``'s body frame ``[dx, dy, dθ]``
                                            (g2o / GTSAM ``BetweenFactorPose2``: ``e = Log(d⁻¹ ⊕ x_i⁻¹ ⊕ x_j)``).
    between_info : ndarray (B, 3, 3)        information ``Λ = Σ⁻¹`` of ``e`` (symmetric positive definite).
    odometry_info : ndarray (T, 3, 3) | None  information of each odometry increment (replaces
                                            ``NoiseSpec.odometry_std`` for the graph solver).
    observation_info : ndarray (N, 2, 2) | None  information of each observation row, in the model named by
                                            ``observation_model``.
    observation_model : "range_bearing" | "xy"  ``range_bearing``: residual ``[r̂ − r, b̂ − b]``; ``xy``: the
                                            Cartesian offset ``z = [r cos b, r sin b]`` in the body frame,
                                            residual ``R(θ)ᵀ(m − p) − z`` (g2o ``EDGE_SE2_XY``).
    """

    between_ij: np.ndarray = field(default_factory=lambda: np.zeros((0, 2), dtype=np.int64))
    between_xyt: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))
    between_info: np.ndarray = field(default_factory=lambda: np.zeros((0, 3, 3)))
    odometry_info: np.ndarray | None = None
    observation_info: np.ndarray | None = None
    observation_model: str = "range_bearing"

    @property
    def n_between(self) -> int:
        return int(np.asarray(self.between_ij).reshape(-1, 2).shape[0])


@dataclass(frozen=True)
class NoiseBounds:
    """Guaranteed error bounds (set-membership data): every error lies in ``[-h, +h]`` of its half-width ``h``.

    The simulator's bounded-noise option draws errors uniformly within these bounds and records them here,
    so a set-membership solver reads the bounds, never the truth.

    Attributes
    ----------
    odometry_model : str               ``"turn_move"``: pose t → t+1 is a turn in place by ``α`` followed by a
                                       straight move of length ``d`` along the new heading; the odometry
                                       increment of ``odometry_xyt`` encodes the measured ``(d̃, α̃)``.
    odometry_half_width : ndarray (2,) ``[h_d m, h_α rad]``: ``|d − d̃| ≤ h_d``, ``|α − α̃| ≤ h_α``.
    range_half_width : float           ``|r − r̃| ≤ h_r``, m.
    bearing_half_width : float         ``|b − b̃| ≤ h_b``, rad.
    closest_only : bool                the sensor (360° field of view) reports exactly the closest landmark of
                                       any type whose range is in ``[min_range, SlamInputs.max_range]``, or
                                       nothing when there is none (paper 004 §6) — negative information a
                                       set-membership solver may use; False = not declared.
    min_range : float                  the sensor's minimum range, m (closer landmarks are invisible).
    min_separation : float             declared map prior, m: distinct landmarks are at least this far apart
                                       (0 = nothing declared). Not a sensor fact; a wrong declaration can
                                       refute the truth like a too-small error bound.
    """

    odometry_model: str
    odometry_half_width: np.ndarray
    range_half_width: float
    bearing_half_width: float
    closest_only: bool = False
    min_range: float = 0.0
    min_separation: float = 0.0


@dataclass(frozen=True)
class RobotTeam:
    """Multi-robot layout of a dataset (``/inputs/robots`` and ``/inputs/robot_observations`` in the schema).

    The poses of all ``R`` robots are stacked robot-major into one pose array: robot ``r`` owns the
    contiguous poses ``first_pose[r] .. first_pose[r+1]−1``, all on one common time grid (the same
    ``timestamps`` block repeats per robot). Observation rows, controls and odometry refer to that stacked
    index; the odometry chain never links the last pose of one robot to the first of the next (the control
    row between them is zero and unused). Landmarks are shared by all robots.

    Attributes
    ----------
    pose_robot : ndarray (P,) int64      robot index ``0..R-1`` of each stacked pose (non-decreasing).
    robot_number : ndarray (R,) int64    the dataset's own robot numbers (MRCLAM: 1..5).
    x0_xyt : ndarray (R, 3)              known start pose of each robot, world frame (one common frame).
    observer_pose : ndarray (K,) int64   stacked pose index of the robot that took each inter-robot reading ...
    observed_pose : ndarray (K,) int64   ... and of the robot it saw, at the same time step.
    range_m : ndarray (K,)               measured range to the observed robot's body origin, m.
    bearing_rad : ndarray (K,)           measured bearing in the observer's body frame, rad, wrapped.
    """

    pose_robot: np.ndarray
    robot_number: np.ndarray
    x0_xyt: np.ndarray
    observer_pose: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=np.int64))
    observed_pose: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=np.int64))
    range_m: np.ndarray = field(default_factory=lambda: np.zeros(0))
    bearing_rad: np.ndarray = field(default_factory=lambda: np.zeros(0))

    @property
    def n_robots(self) -> int:
        return int(np.asarray(self.robot_number).shape[0])

    @property
    def first_pose(self) -> np.ndarray:
        """``(R+1,)`` CSR offsets: robot r owns stacked poses ``first_pose[r]:first_pose[r+1]``."""
        counts = np.bincount(np.asarray(self.pose_robot, np.int64), minlength=self.n_robots)
        return np.concatenate([[0], np.cumsum(counts)]).astype(np.int64)

    @property
    def chain_pairs(self) -> np.ndarray:
        """``(E,)`` indices ``i`` of the odometry edges ``i → i+1`` that stay within one robot."""
        pr = np.asarray(self.pose_robot, np.int64)
        return np.flatnonzero(pr[:-1] == pr[1:]).astype(np.int64)

    @property
    def z(self) -> np.ndarray:
        """Inter-robot measurements ``(K, 2)`` as ``[range, bearing]``."""
        return np.stack([np.asarray(self.range_m, float), np.asarray(self.bearing_rad, float)], axis=-1)


@dataclass(frozen=True)
class SlamInputs:
    """Everything a solver may use.

    Attributes
    ----------
    dt : float                       sampling period, s.
    timestamps : ndarray (T+1,)      time of each pose, s.
    x0 : ndarray (3,)                known start pose (paper 000 §3; it fixes the gauge).
    controls : ndarray (T, 2)        commanded [v, ω] applied from pose t to pose t+1.
    odometry_xyt : ndarray (T+1, 3)  encoder dead-reckoning poses (their increments are the odometry data).
    observations : Observations;  noise : NoiseSpec
    max_range : float                sensor max range, m (inf when unlimited).
    gps_step, gps_xy : ndarray (G,) int64, (G, 2)   optional GPS fixes: pose index and position, m.
    gps_std : float                  σ of a GPS fix, m.
    motion_model : str               "ddmr" (controls = [v, ω]) or "ackermann" (controls = [v_e, α], encoder speed
                                     and steering, ``noise.motion_std`` = [σ_v m/s, σ_α rad]; slamcli.models.ackermann).
    vehicle : AckermannParams | None car geometry, required with motion_model="ackermann".
    sensor_offset_xy : ndarray (2,)  sensor mount (a, b) in the body frame, m (zeros = at the body origin).
    constraints : PoseConstraints | None  per-edge information and pose-pose (loop-closure) constraints.
    reported_id_source : str         origin of ``observations.reported_id``: ``"sensor"`` (may misread),
                                     ``"file"`` (a graph file's association) or ``"unknown"`` (default).
    noise_bounds : NoiseBounds | None  guaranteed error bounds (bounded-noise datasets only).
    robots : RobotTeam | None        multi-robot layout (stacked poses, inter-robot readings); None = one robot.
    motion_source : str              ``"controls"`` (default; commanded controls, odometry a separate log) or
                                     ``"odometry"`` (measured SE(2) increments, ``controls`` derived from them);
                                     solvers' ``motion_input="auto"`` follows it.
    """

    dt: float
    timestamps: np.ndarray
    x0: np.ndarray
    controls: np.ndarray
    odometry_xyt: np.ndarray
    observations: Observations
    noise: NoiseSpec
    max_range: float = float("inf")
    gps_step: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=np.int64))
    gps_xy: np.ndarray = field(default_factory=lambda: np.zeros((0, 2)))
    gps_std: float = 0.0
    motion_model: str = "ddmr"
    vehicle: Any = None
    sensor_offset_xy: np.ndarray = field(default_factory=lambda: np.zeros(2))
    constraints: PoseConstraints | None = None
    reported_id_source: str = "unknown"
    noise_bounds: NoiseBounds | None = None
    robots: RobotTeam | None = None
    motion_source: str = "controls"

    @property
    def n_poses(self) -> int:
        """T+1."""
        return int(self.odometry_xyt.shape[0])


def robot_slice(inputs: SlamInputs, robot: int) -> tuple[int, int, np.ndarray]:
    """Where robot index ``robot`` sits in a multi-robot problem: its stacked poses ``a:b`` and its observation
    rows ``(N_r,)``. ``ValueError`` for a single-robot problem or an index out of range."""
    team = inputs.robots
    if team is None:
        raise ValueError("a multi-robot dataset is needed (inputs.robots is None)")
    if not 0 <= robot < team.n_robots:
        raise ValueError(f"robot index {robot} out of range 0..{team.n_robots - 1}")
    fp = team.first_pose
    a, b = int(fp[robot]), int(fp[robot + 1])
    obs = inputs.observations
    return a, b, np.arange(int(obs.offsets[a]), int(obs.offsets[b]))


def solo_inputs(inputs: SlamInputs, robot: int) -> SlamInputs:
    """Robot index ``robot`` (0-based, into ``inputs.robots.robot_number``) of a multi-robot problem, alone: its
    poses' timestamps, controls, odometry and landmark observations, its start pose as ``x0``, no robots group.
    Solvers use it for per-robot work (it never touches ground truth); :func:`slamcli.datasets.team.solo_dataset`
    adds that robot's slice of the truth."""
    a, b, rows = robot_slice(inputs, robot)
    obs = inputs.observations
    solo_obs = Observations.from_rows(obs.step[rows] - a, obs.z[rows], b - a, reported_id=obs.reported_id[rows],
                                      sensor=obs.sensor[rows])
    return dataclasses.replace(
        inputs,
        timestamps=np.asarray(inputs.timestamps)[a:b].copy(),
        x0=np.asarray(inputs.robots.x0_xyt[robot], float).copy(),
        controls=np.asarray(inputs.controls)[a : b - 1].copy(),
        odometry_xyt=np.asarray(inputs.odometry_xyt)[a:b].copy(),
        observations=solo_obs,
        robots=None,
    )


@dataclass(frozen=True)
class OccupancyGrid:
    """A 2-D occupancy grid (paper 001): cell ``(row, col)`` covers
    ``[x0 + col·res, x0 + (col+1)·res) × [y0 + row·res, y0 + (row+1)·res)``.

    Attributes
    ----------
    origin_xy : ndarray (2,)                lower-left corner of cell (0, 0), m (world).
    resolution : float                      cell side, m.
    prob : ndarray (H, W) float32           occupancy probability of every cell (truth: 0/1).
    observed : ndarray (H, W) int32 | None  how many steps updated each cell (0 = never observed).
    snapshot_step : ndarray (K,) int64 | None   steps after which ``snapshots`` were taken ...
    snapshots : ndarray (K, H, W) float32 | None ... the probabilities at those steps.
    """

    origin_xy: np.ndarray
    resolution: float
    prob: np.ndarray
    observed: np.ndarray | None = None
    snapshot_step: np.ndarray | None = None
    snapshots: np.ndarray | None = None

    @property
    def shape(self) -> tuple[int, int]:
        return (int(self.prob.shape[0]), int(self.prob.shape[1]))


@dataclass(frozen=True)
class GroundTruth:
    """What really happened; produced by the simulator, read only by metrics.

    Attributes
    ----------
    poses_xyt : ndarray (T+1, 3)       true poses.
    landmarks_xy : ndarray (L, 2)      true landmark positions.
    obs_landmark : ndarray (N,) int64  true landmark index of each observation row; -1 for clutter.
    occupancy : OccupancyGrid | None   wall worlds: the true grid (walls rasterised, prob 0/1).
    walls_xyxy : ndarray (W, 4) | None wall worlds: wall segments ``[x1, y1, x2, y2]``, m.
    lap_end_step : ndarray (K,) int64 | None  wall worlds: step at which each lap of the route ended.
    ref_time_s : ndarray (G,) | None   position-only reference (a real recording's GPS): fix times, s ...
    ref_xy : ndarray (G, 2) | None     ... and positions, m. When ``poses_xyt`` is None the truth is a
                                       position reference only: no true poses, landmarks or association.
    ref_offset_xy : ndarray (2,) | None  body-frame point the reference positions refer to (e.g. the GPS
                                       antenna); None = the body origin.
    """

    poses_xyt: np.ndarray | None
    landmarks_xy: np.ndarray | None
    obs_landmark: np.ndarray | None
    occupancy: OccupancyGrid | None = None
    walls_xyxy: np.ndarray | None = None
    lap_end_step: np.ndarray | None = None
    ref_time_s: np.ndarray | None = None
    ref_xy: np.ndarray | None = None
    ref_offset_xy: np.ndarray | None = None

    @property
    def position_reference_only(self) -> bool:
        """True when only a time-stamped position reference (e.g. GPS) is known."""
        return self.poses_xyt is None


@dataclass(frozen=True)
class Dataset:
    """A simulated (or imported) run: solver inputs, ground truth and self-describing metadata."""

    inputs: SlamInputs
    truth: GroundTruth | None
    metadata: dict[str, Any]


class Status(str, enum.Enum):
    """How a solve ended."""

    CONVERGED = "converged"  # an iterative solver met its tolerance
    MAX_ITERATIONS = "max_iterations"  # stopped on the iteration budget
    COMPLETED = "completed"  # a filter/one-pass solver processed every step
    FAILED = "failed"  # no usable estimate; message says why
    TRUNCATED = "truncated"  # a set-membership solver hit its hypothesis cap: the set may miss solutions


@dataclass(frozen=True)
class IterationTrace:
    """Per-iteration record of an iterative solver (index 0 = the initialisation).

    Attributes
    ----------
    objective : ndarray (K,)          energy / cost after each iteration.
    map_change : ndarray (K,)         mean norm of landmark displacement from the previous iteration, m
                                      (NaN-free; 0 for iteration 0).
    time_s : ndarray (K,)             wall time of each iteration, s.
    landmarks_xy : ndarray (M, 2)     landmark estimates of all iterations, flattened ...
    landmark_offsets : ndarray (K+1,) ... iteration k owns rows ``landmark_offsets[k]:landmark_offsets[k+1]``.
    poses_xyt : ndarray (P, T+1, 3) | None   optional pose estimates of P <= K recorded iterations (a solver
                                      may record only some iterations to bound memory: P·(T+1)·3 floats).
    pose_iterations : ndarray (P,) int64 | None  the iteration of each ``poses_xyt`` row, strictly increasing
                                      in [0, K-1]; None together with ``poses_xyt`` = every iteration
                                      (``arange(K)``, then P = K).
    """

    objective: np.ndarray
    map_change: np.ndarray
    time_s: np.ndarray
    landmarks_xy: np.ndarray
    landmark_offsets: np.ndarray
    poses_xyt: np.ndarray | None = None
    pose_iterations: np.ndarray | None = None

    def __len__(self) -> int:
        return int(self.objective.shape[0])

    def landmarks_at(self, k: int) -> np.ndarray:
        """Landmark estimates ``(L_k, 2)`` after iteration ``k``."""
        return self.landmarks_xy[self.landmark_offsets[k] : self.landmark_offsets[k + 1]]

    def poses_at(self, k: int) -> np.ndarray | None:
        """Pose estimates ``(T+1, 3)`` after iteration ``k``, or None when iteration ``k`` was not recorded."""
        if self.poses_xyt is None:
            return None
        k = int(k) % len(self) if k < 0 else int(k)
        if self.pose_iterations is None:
            return self.poses_xyt[k] if k < self.poses_xyt.shape[0] else None
        i = int(np.searchsorted(self.pose_iterations, k))
        if i < len(self.pose_iterations) and int(self.pose_iterations[i]) == k:
            return self.poses_xyt[i]
        return None

    @staticmethod
    def from_lists(objective, map_change, time_s, landmarks_per_iter, poses_per_iter=None,
                   pose_iterations=None) -> IterationTrace:
        """Build a trace from per-iteration Python lists (landmarks: list of ``(L_k, 2)`` arrays).

        ``poses_per_iter`` (optional): list of ``(T+1, 3)`` arrays, one per iteration in ``pose_iterations``
        (default: one per iteration, ``0..K-1``).
        """
        counts = [len(m) for m in landmarks_per_iter]
        offsets = np.concatenate([[0], np.cumsum(counts)]).astype(np.int64)
        lm = (
            np.concatenate([np.asarray(m, float).reshape(-1, 2) for m in landmarks_per_iter])
            if landmarks_per_iter
            else np.zeros((0, 2))
        )
        return IterationTrace(
            objective=np.asarray(objective, float),
            map_change=np.asarray(map_change, float),
            time_s=np.asarray(time_s, float),
            landmarks_xy=lm,
            landmark_offsets=offsets,
            poses_xyt=(np.stack([np.asarray(x, float).reshape(-1, 3) for x in poses_per_iter])
                       if poses_per_iter is not None and len(poses_per_iter) else None),
            pose_iterations=(np.asarray(pose_iterations, np.int64)
                             if pose_iterations is not None and poses_per_iter is not None
                             and len(poses_per_iter) else None),
        )


@dataclass(frozen=True)
class SolverResult:
    """What a solver returns; written by ``slamcli.io`` as a result file (schema ``slamcli.result`` v1).

    Attributes
    ----------
    solver : str                       registered name, e.g. ``"ekf"``.
    solver_version : str               version of the distribution that provides the solver.
    params : dict                      the full resolved parameter set (``dataclasses.asdict`` of Params).
    status : Status
    message : str
    poses_xyt : ndarray (T+1, 3)       estimated poses.
    landmarks_xy : ndarray (L', 2)     estimated landmarks (L' may differ from the truth).
    assoc : ndarray (N,) int64         label (row of landmarks_xy) given to every observation; -1 = none.
    pose_cov : ndarray (T+1, 3, 3) | None     marginal pose covariances, world frame [x, y, θ].
    landmark_cov : ndarray (L', 2, 2) | None  marginal landmark covariances.
    trace : IterationTrace | None
    wall_time_s : float
    dataset_hash : str                 content hash of the input dataset (filled in by the caller).
    hypotheses : BoxHypotheses | None  set-membership solvers: every surviving hypothesis with its boxes.
    extra : dict                       small JSON-serialisable, deterministic solver-specific values (no timings).
    timings : dict[str, float]         solver-specific wall-clock measurements (unit in the key, e.g. ICM
                                       ``init_s``); with ``wall_time_s`` and ``trace.time_s`` the only
                                       non-deterministic numbers of a result (docs/schema.md "Timings").
    grids : dict[str, OccupancyGrid]   occupancy maps by name (``hybrid``: "frequentist", "logodds"),
                                       written as the optional ``/grids`` group.
    """

    solver: str
    solver_version: str
    params: dict[str, Any]
    status: Status
    message: str
    poses_xyt: np.ndarray
    landmarks_xy: np.ndarray
    assoc: np.ndarray
    pose_cov: np.ndarray | None = None
    landmark_cov: np.ndarray | None = None
    trace: IterationTrace | None = None
    wall_time_s: float = 0.0
    dataset_hash: str = ""
    extra: dict[str, Any] = field(default_factory=dict)
    timings: dict[str, float] = field(default_factory=dict)
    hypotheses: BoxHypotheses | None = None
    grids: dict[str, OccupancyGrid] = field(default_factory=dict)


@dataclass(frozen=True)
class BoxHypotheses:
    """Every surviving hypothesis (kinematic graph) of a set-membership solver, H of them.

    Landmark rows of hypothesis h are ``0 .. n_landmarks[h]-1``; rows beyond are NaN padding (-1 for types).

    Attributes
    ----------
    assoc : ndarray (H, N) int64              landmark row of each observation under hypothesis h.
    pose_lo, pose_hi : ndarray (H, T+1, 3)    lower/upper bounds of [x, y, θ]; θ is *unwrapped* (a box may
                                              extend beyond [-π, π)).
    landmark_lo, landmark_hi : ndarray (H, Lmax, 2)   lower/upper bounds of landmark [x, y].
    n_landmarks : ndarray (H,) int64
    landmark_type : ndarray (H, Lmax) int64   type label of each landmark (-1 = none/padding).
    """

    assoc: np.ndarray
    pose_lo: np.ndarray
    pose_hi: np.ndarray
    landmark_lo: np.ndarray
    landmark_hi: np.ndarray
    n_landmarks: np.ndarray
    landmark_type: np.ndarray

    def __len__(self) -> int:
        return int(self.assoc.shape[0])
