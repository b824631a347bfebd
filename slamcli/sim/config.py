"""Simulator configuration: frozen nested dataclasses with documented defaults and units.

A :class:`ScenarioConfig` fully determines a simulated run together with the integer ``seed``. Named scenarios
(``slamcli.sim.scenarios``) are factories returning a ``ScenarioConfig``; users change any leaf with dotted
overrides (``sensor.max_range=10``, ``robot.actuation_std=0.05,0.02``, ``n_steps=2000``), validated by
:func:`apply_overrides` with one-line :class:`~slamcli.errors.ConfigError` messages.

Units: metres, seconds, radians — except ``sensor.fov_deg`` (degrees, as on a data sheet). Every standard
deviation ``*_std`` is a 1-σ value of zero-mean Gaussian noise.
"""

from __future__ import annotations

import dataclasses
import math
import typing
from dataclasses import dataclass, field
from typing import Any, Literal

from slamcli.errors import ConfigError
from slamcli.numerics import MAX_INPUT_MAGNITUDE
from slamcli.params import convert, known_text, param


def _check(cond: bool, message: str) -> None:
    if not cond:
        raise ConfigError(message)


#: Size limits, checked before anything is simulated (a typo such as ``n_steps=1000000000000`` must not try
#: to allocate terabytes): steps per run, landmarks of a world, laser beams, ellipse points / path waypoints.
MAX_STEPS = 1_000_000
MAX_LANDMARKS = 100_000
MAX_BEAMS = 10_000
MAX_WAYPOINTS = 1_000_000
MAX_CLUTTER_RATE = 1_000.0


def _check_finite(obj: Any) -> None:
    """Every float field (and every entry of a float tuple) of a config dataclass must be finite and within
    ±:data:`~slamcli.numerics.MAX_INPUT_MAGNITUDE` (``dt=1e300`` overflowed deep inside the simulation)."""
    for f in dataclasses.fields(obj):
        v = getattr(obj, f.name)
        vals = v if isinstance(v, tuple) else (v,)
        for x in vals:
            if isinstance(x, float) and not (math.isfinite(x) and abs(x) <= MAX_INPUT_MAGNITUDE):
                what = "must be finite" if not math.isfinite(x) else f"must be within ±{MAX_INPUT_MAGNITUDE:g}"
                raise ConfigError(f"{type(obj).__name__.removesuffix('Config').lower()}.{f.name}: {what}, got {x}")


@dataclass(frozen=True)
class WorldConfig:
    """Landmark layout (drawn from the *world* random stream).

    Each field's documentation is its ``metadata["doc"]``.
    """

    layout: Literal["rows", "random", "octagon", "none"] = param("rows",
        "`rows`: `n_rows` rows at `y = row_y0 + k·row_spacing`, landmarks every `col_spacing` m from "
        "`x_min` to `x_max` (paper 000, Fig. 4/5 setting). `random`: `n_landmarks` uniform in the box "
        "`[x_min, x_max] × [y_min, y_max]`, at least `min_separation` apart and `path_clearance` from the "
        "waypoint polyline. `octagon`: 8 points on a regular octagon of circumradius `octagon_radius` "
        "centred at the origin plus its centre (paper 000 §6). `none`: only `extra_landmarks`.")
    x_min: float = param(5.0, "box of the layout, m.")
    x_max: float = param(45.0, "box of the layout, m.")
    y_min: float = param(5.0, "box of the layout, m.")
    y_max: float = param(35.0, "box of the layout, m.")
    n_rows: int = param(7, "rows of the `rows` layout.")
    row_y0: float = param(5.0, "y of the first row and spacing between rows, m.")
    row_spacing: float = param(5.0, "y of the first row and spacing between rows, m.")
    col_spacing: float = param(5.0, "spacing along a row, m.")
    n_landmarks: int = param(12, "count for the `random` layout.")
    min_separation: float = param(2.0, "minimum landmark-landmark distance (`random`), m.")
    path_clearance: float = param(1.0, "minimum landmark-path distance (`random`), m.")
    jitter: float = param(0.0, "σ of a Gaussian perturbation added to every generated position, m.")
    octagon_radius: float = param(7.12, "circumradius of the octagon, m (paper 000 §6: 7.12 m).")
    extra_landmarks: tuple[float, ...] = param((), "additional fixed points `x1,y1,x2,y2,...` (m), "
                                                   "appended last.")
    landmark_radius: float = param(0.15, "radius of the disc a laser beam hits (cone, pole, person), m.")
    seed: int = param(-1, "seed of the world stream (landmarks and path jitter); −1 = the run's seed. Fix "
                          "it for Monte-Carlo runs over one map (NEES averages).")

    def __post_init__(self) -> None:
        _check(self.x_max > self.x_min and self.y_max > self.y_min, "world: need x_min < x_max and y_min < y_max")
        _check(self.n_rows >= 0 and self.n_landmarks >= 0, "world: n_rows and n_landmarks must be >= 0")
        _check(self.row_spacing > 0 and self.col_spacing > 0, "world: row_spacing and col_spacing must be > 0")
        _check(self.jitter >= 0 and self.min_separation >= 0 and self.path_clearance >= 0,
               "world: jitter, min_separation and path_clearance must be >= 0")
        _check(self.octagon_radius > 0, "world.octagon_radius must be > 0")
        _check(len(self.extra_landmarks) % 2 == 0, "world.extra_landmarks must be x,y pairs (even length)")
        _check(self.landmark_radius > 0, "world.landmark_radius must be > 0")
        _check(self.seed >= -1, "world.seed must be >= 0 (or -1 = the run's seed)")
        _check_finite(self)
        _check(self.n_landmarks <= MAX_LANDMARKS and self.n_rows <= MAX_LANDMARKS,
               f"world: n_landmarks and n_rows must be <= {MAX_LANDMARKS} (the limit of landmarks)")
        n_rows_layout = self.n_rows * (math.floor((self.x_max - self.x_min) / self.col_spacing) + 1)
        _check(self.layout != "rows" or n_rows_layout <= MAX_LANDMARKS,
               f"world: the rows layout would place {n_rows_layout} landmarks, above the limit of {MAX_LANDMARKS} "
               "(check col_spacing and n_rows)")
        _check(len(self.extra_landmarks) // 2 <= MAX_LANDMARKS,
               f"world.extra_landmarks: more than {MAX_LANDMARKS} points")


@dataclass(frozen=True)
class PathConfig:
    """Waypoints the robot's tracking controller follows.

    Each field's documentation is its ``metadata["doc"]``.
    """

    kind: Literal["rect", "serpentine", "ellipse", "explicit"] = param("rect",
        "`rect`: the corners of `[x_min, x_max] × [y_min, y_max]` counter-clockwise from `(x_min, "
        "y_min)`. `serpentine`: lanes at the y values `lanes` driven alternately left→right and "
        "right→left between `x_min` and `x_max` (a lawn-mower path among rows of landmarks). `ellipse`: "
        "`n_points` points on the ellipse inscribed in the box, counter-clockwise. `explicit`: "
        "`waypoints`.")
    x_min: float = param(0.0, "box of the path, m.")
    x_max: float = param(10.0, "box of the path, m.")
    y_min: float = param(0.0, "box of the path, m.")
    y_max: float = param(10.0, "box of the path, m.")
    lanes: tuple[float, ...] = param((), "lane y values for `serpentine`, m.")
    n_points: int = param(16, "points on the ellipse.")
    spacing: float = param(0.0, "straight edges are subdivided into waypoints about this far apart (m; 0 "
                                "= corners only); with `jitter` this makes the path irregular.")
    jitter: float = param(0.0, "σ of a Gaussian perturbation of every waypoint (world stream), m.")
    waypoints: tuple[float, ...] = param((), "`x1,y1,x2,y2,...` for `explicit`, m.")
    cyclic: bool = param(True, "start over at the first waypoint after the last one (else stop).")

    def __post_init__(self) -> None:
        _check(self.x_max > self.x_min and self.y_max > self.y_min, "path: need x_min < x_max and y_min < y_max")
        _check(self.spacing >= 0 and self.jitter >= 0, "path: spacing and jitter must be >= 0")
        _check(self.n_points >= 3, "path.n_points must be >= 3")
        _check(len(self.waypoints) % 2 == 0, "path.waypoints must be x,y pairs (even length)")
        if self.kind == "explicit":
            _check(len(self.waypoints) >= 4, "path.waypoints: kind=explicit needs at least 2 points")
        if self.kind == "serpentine":
            _check(len(self.lanes) >= 1, "path.lanes: kind=serpentine needs at least one lane")
        _check_finite(self)
        _check(self.n_points <= MAX_WAYPOINTS, f"path.n_points must be <= {MAX_WAYPOINTS}")
        if self.spacing > 0:  # edges are subdivided: bound the waypoint count before it is built
            span = 2.0 * (self.x_max - self.x_min + self.y_max - self.y_min) * (len(self.lanes) + 1)
            span += sum(abs(a - b) for a, b in zip(self.waypoints[2:], self.waypoints[:-2]))
            _check(span / self.spacing <= MAX_WAYPOINTS,
                   f"path.spacing: {self.spacing} m would make about {span / self.spacing:.3g} waypoints, above "
                   f"the limit of {MAX_WAYPOINTS}")


@dataclass(frozen=True)
class RobotConfig:
    """Differential-drive robot (paper 000 §4) and its waypoint-tracking controller.

    The controller computes the *commanded* control ``u_t = [v_t, ω_t]`` from the true pose::

        e_t = wrap(atan2(w_y − y_t, w_x − x_t) − θ_t),   ω_t = clip(k_heading · e_t, ±w_max),
        v_t = v_max · max(0, cos e_t)

    and switches to the next waypoint within ``waypoint_tol``. The robot executes
    ``u_t + n_t, n_t ~ N(0, diag(actuation_std²))`` through ``g(x, u)`` (``models.motion.ddmr_step``).
    With acceleration limits (``accel_max`` / ``decel_max`` > 0, a MobileSim/Stage robot base) the executed
    velocity moves towards ``u_t + n_t`` by at most ``accel·dt`` per step when speeding up and ``decel·dt``
    when slowing down, from rest at t = 0, so the executed motion lags the command the solvers see.

    Each field's documentation is its ``metadata["doc"]``.
    """

    start: tuple[float, ...] = param((), "`x, y, θ` of the start pose (m, m, rad); empty = first "
                                         "waypoint, facing the second one.")
    v_max: float = param(0.5, "cruise speed, m/s.")
    w_max: float = param(0.8, "maximum turn rate, rad/s.")
    k_heading: float = param(1.5, "heading gain, 1/s.")
    waypoint_tol: float = param(0.5, "waypoint switching radius, m.")
    actuation_std: tuple[float, float] = param((0.02, 0.02),
        "actuation noise on the commanded controls (m/s, rad/s).")
    accel_max: tuple[float, float] = param((0.0, 0.0), "acceleration limits of the executed velocities "
                                                       "(m/s², rad/s²); 0 = none.")
    decel_max: tuple[float, float] = param((0.0, 0.0), "deceleration limits (m/s², rad/s²); 0 = none.")

    def __post_init__(self) -> None:
        _check(len(self.start) in (0, 3), "robot.start must be empty or x,y,theta")
        _check(self.v_max > 0 and self.w_max > 0 and self.k_heading > 0, "robot: v_max, w_max, k_heading must be > 0")
        _check(self.waypoint_tol > 0, "robot.waypoint_tol must be > 0")
        _check(all(s >= 0 for s in self.actuation_std), "robot.actuation_std must be >= 0")
        _check(len(self.accel_max) == 2 and all(a >= 0 for a in self.accel_max), "robot.accel_max: two values >= 0")
        _check(len(self.decel_max) == 2 and all(a >= 0 for a in self.decel_max), "robot.decel_max: two values >= 0")
        _check_finite(self)


@dataclass(frozen=True)
class OdometryConfig:
    """Wheel-encoder odometry: noisy, optionally biased body-frame increments of the true motion (eq. 16).

    ``d̃_t = [(1+scale_bias) d_x, (1+scale_bias) d_y, (1+turn_bias) d_θ] + n_t,  n_t ~ N(0, diag(std²))``,
    chained from the true start pose.

    Each field's documentation is its ``metadata["doc"]``.
    """

    std: tuple[float, float, float] = param((0.002, 0.002, 0.002),
        "per-step noise of the increment (m, m, rad).")
    scale_bias: float = param(0.0, "relative wheel-distance scale error (0.01 = odometry reads 1 % long).")
    turn_bias: float = param(0.0, "relative heading-increment scale error.")

    def __post_init__(self) -> None:
        _check(all(s >= 0 for s in self.std), "odometry.std must be >= 0")
        _check(self.scale_bias > -1 and self.turn_bias > -1, "odometry: biases must be > -1")
        _check_finite(self)


@dataclass(frozen=True)
class SensorConfig:
    """Range-bearing sensor (sensor index 0).

    ``kind = "point"``: every landmark inside ``[min_range, max_range]`` and the field of view gives one
    observation ``[r + n_r, wrap(b + n_b)]`` of its centre (range clipped to [0, max_range]) with probability
    ``detection_prob``. ``kind = "laser"``: ``n_beams`` beams over ``fov_deg``, each returning the nearest
    intersection with the landmark discs (``world.landmark_radius``) or missing with probability
    ``1 − detection_prob``; bearing = beam angle + noise. Preprocessing as in paper 000 §5: ``drop_max_range``
    removes beams without a hit (else reported at ``max_range``, truth id −1); ``drop_isolated`` removes a return
    without a neighbouring return within ``isolation_gap`` m in range.

    Each field's documentation is its ``metadata["doc"]``.
    """

    kind: Literal["point", "laser"] = "point"
    max_range: float = param(8.0, "m.")
    min_range: float = param(0.1, "m.")
    fov_deg: float = param(180.0, "field of view centred straight ahead, degrees (360 = all round).")
    range_std: float = param(0.05, "m.")
    bearing_std: float = param(0.01, "rad.")
    detection_prob: float = param(1.0, "probability that a visible landmark (point) / a hitting beam "
                                       "(laser) is reported.")
    report_ids: bool = param(False, "the sensor reports the landmark identity (`Observations.reported_id`).")
    period_steps: int = param(1, "scan every this many poses (pose 0 is scanned).")
    n_beams: int = param(181, "laser beams.")
    drop_max_range: bool = param(True, "laser preprocessing.")
    drop_isolated: bool = param(True, "laser preprocessing.")
    isolation_gap: float = param(0.5, "laser: neighbouring-return range difference still called "
                                      '"similar", m.')
    report_size: bool = param(False, "laser: declare the size of what the beams hit — every return "
                                     "carries `observations.diameter_m = 2 · world.landmark_radius` "
                                     "(clutter too), the radius a surface-aware model reads (`-p "
                                     "surface=true`); off = no size declared.")

    def __post_init__(self) -> None:
        _check(self.max_range > 0 and math.isfinite(self.max_range), "sensor.max_range must be a finite number > 0")
        _check(0 <= self.min_range < self.max_range, "sensor.min_range must be in [0, max_range)")
        _check(0 < self.fov_deg <= 360, "sensor.fov_deg must be in (0, 360]")
        _check(self.range_std >= 0 and self.bearing_std >= 0, "sensor: range_std and bearing_std must be >= 0")
        _check(0 <= self.detection_prob <= 1, "sensor.detection_prob must be in [0, 1]")
        _check(self.period_steps >= 1, "sensor.period_steps must be >= 1")
        _check(self.n_beams >= 2, "sensor.n_beams must be >= 2")
        _check(self.isolation_gap >= 0, "sensor.isolation_gap must be >= 0")
        _check_finite(self)
        _check(self.n_beams <= MAX_BEAMS, f"sensor.n_beams must be <= {MAX_BEAMS}")

    @property
    def fov_rad(self) -> float:
        return math.radians(self.fov_deg)


@dataclass(frozen=True)
class ClutterConfig:
    """False returns (truth id −1), drawn from the *clutter* stream.

    Each field's documentation is its ``metadata["doc"]``.
    """

    rate: float = param(0.0, "mean number of false returns per scan (Poisson), uniform in range "
                             "`[min_range, max_range]` and bearing over the field of view. For the laser "
                             "they replace the reading of a random beam when nearer than its true return, "
                             "so `drop_isolated` removes most of them (paper 000 §5).")

    def __post_init__(self) -> None:
        _check(self.rate >= 0, "clutter.rate must be >= 0")
        _check(self.rate <= MAX_CLUTTER_RATE, f"clutter.rate must be <= {MAX_CLUTTER_RATE:g} false returns per scan")


@dataclass(frozen=True)
class GpsConfig:
    """Optional position fixes ``p_t + n, n ~ N(0, std² I)`` every ``period_steps`` poses (off by default).

    Each field's documentation is its ``metadata["doc"]``.
    """

    enabled: bool = False
    period_steps: int = 10
    std: float = param(1.0, "m.")

    def __post_init__(self) -> None:
        _check(self.period_steps >= 1, "gps.period_steps must be >= 1")
        _check(self.std >= 0, "gps.std must be >= 0")
        _check_finite(self)


@dataclass(frozen=True)
class BoundedConfig:
    """Bounded-error "turn and move" runs for set-membership SLAM (paper 004 §6; off by default).

    When ``enabled`` the robot turns in place towards each next waypoint of ``path`` and drives straight to it,
    one pose per waypoint. Every error is *uniform* within its ± bound, and the bounds are written into the
    dataset (``inputs/noise_bounds``). Odometry reports ``d̃ = d + u_d``, ``α̃ = α + u_α``; the point sensor
    reports ``r + u_r``, ``b + u_b`` and each landmark's type label, never its identity.

    Each field's documentation is its ``metadata["doc"]``.
    """

    enabled: bool = param(False, "use the turn-and-move robot with bounded noise.")
    odometry_d: float = param(0.25, "half-width of the distance error, m (paper 004: 0.25).")
    odometry_turn_deg: float = param(5.0, "half-width of the turn error, degrees (paper 004: 5).")
    range: float = param(0.025, "half-width of the range error, m (paper 004: 10× smaller, 0.025).")
    bearing_deg: float = param(0.5, "half-width of the bearing error, degrees (0.5).")
    closest_only: bool = param(True, "the sensor reports only the closest visible landmark (paper 004 §6).")
    landmark_types: tuple[int, ...] = param((), "type label per landmark in world order (e.g. 0 = door, 1 "
                                                "= corridor); empty = all type 0.")
    declared_scale: float = param(1.0, "the bounds written into the dataset are `declared_scale ×` the "
                                       "true ones (< 1 = a deliberately wrong, too small declaration, for "
                                       "tests).")
    exact_readings: bool = param(False, "every error is zero while the bounds are still declared — paper "
                                        "004 §6 simulated exact readings (its Table 1 l1 box is centred "
                                        "on the truth).")
    declared_separation: float = param(0.0, "map prior declared in the dataset "
                                            "(`NoiseBounds.min_separation`), m: distinct landmarks are at "
                                            "least this far apart; 0 = none declared. The simulator does "
                                            "not enforce it (a wrong declaration is a test case).")
    loop_closure_error: float = param(0.0, "0 = off; else the room's loop-closure sightings (first-seen "
                                           "landmark after pose 0) get errors of exactly this many declared "
                                           "half-widths in range and bearing, signs from `default_rng(seed)` "
                                           "(paper 004's wrong-bound test).")

    def __post_init__(self) -> None:
        _check(min(self.odometry_d, self.odometry_turn_deg, self.range, self.bearing_deg) >= 0,
               "bounded: every half-width must be >= 0")
        _check(all(t >= 0 for t in self.landmark_types), "bounded.landmark_types must be >= 0")
        _check(self.declared_scale > 0, "bounded.declared_scale must be > 0")
        _check(self.declared_separation >= 0, "bounded.declared_separation must be >= 0")
        _check(self.loop_closure_error >= 0, "bounded.loop_closure_error must be >= 0")


@dataclass(frozen=True)
class WallsConfig:
    """Wall world and ray-casting scan of paper 001 §III (off unless ``layout`` is set; see ``sim.walls``).

    With ``layout = "ladder"`` an outer ``width × height`` rectangle holds ``block_rows × block_cols`` blocks
    separated by corridors of width ``corridor``; the robot follows the corridor centre lines; the sensor gives
    range-bearing observations of the features with their identity (sensor 0) and a ray-cast scan of
    ``sensor.n_beams`` beams against the walls (sensor 1, max-range readings kept).

    Each field's documentation is its ``metadata["doc"]``.
    """

    layout: Literal["none", "ladder"] = "none"
    width: float = param(100.0, "outer rectangle, m.")
    height: float = param(100.0, "outer rectangle, m.")
    block_rows: int = 1
    block_cols: int = 1
    corridor: float = param(10.0, "corridor width, m.")
    features: Literal["corners", "corners+mid", "posts"] = param("corners+mid",
        "corners of every wall rectangle; plus the mid-point of every wall segment and, on the outer "
        "walls, the point opposite the mid-point of every corridor stretch between crossings "
        "(`walls.corridor_wall_midpoints`); or point landmarks (posts a quarter corridor width off the "
        "centre lines, `post_spacing` apart; Map 3 variant).")
    post_spacing: float = param(20.0, "m.")
    resolution: float = param(0.5, "cell side of the true occupancy grid, m.")
    grid_margin: float = param(2.0, "grid extends this far beyond the walls, m.")
    laps: int = param(3, "laps of the route; > 0 sets the run length (`n_steps` is then ignored: the run "
                         "ends when the robot is back at the start for the `laps`-th time).")
    max_cells: int = param(50_000_000, "refuse grids with more cells (memory guard).")
    wrong_id_prob: float = param(0.0, "probability that a feature row reports the id of another feature "
                                      "(drawn uniformly among the others) instead of its own — a "
                                      "data-association fault; the truth keeps the row's real feature. "
                                      "Clutter (`clutter.rate`) adds false feature rows with id −1.")

    def __post_init__(self) -> None:
        _check(0.0 <= self.wrong_id_prob <= 1.0, "walls.wrong_id_prob must be in [0, 1]")
        _check(self.width > 0 and self.height > 0 and self.corridor > 0, "walls: width, height, corridor must be > 0")
        _check(self.block_rows >= 1 and self.block_cols >= 1, "walls: block_rows and block_cols must be >= 1")
        _check(self.width - (self.block_cols + 1) * self.corridor > 0
               and self.height - (self.block_rows + 1) * self.corridor > 0,
               "walls: corridors leave no room for the blocks (corridor too wide for width/height)")
        _check(math.isfinite(self.resolution) and self.resolution > 0, "walls.resolution must be a finite number > 0")
        _check(self.grid_margin >= 0 and self.post_spacing > 0, "walls: grid_margin >= 0 and post_spacing > 0")
        _check(self.laps >= 0, "walls.laps must be >= 0")
        if self.layout != "none":
            cells = math.ceil((self.width + 2 * self.grid_margin) / self.resolution + 2) * math.ceil(
                (self.height + 2 * self.grid_margin) / self.resolution + 2)
            _check(cells <= self.max_cells, f"walls.resolution={self.resolution}: the grid would have {cells} "
                   f"cells, more than walls.max_cells={self.max_cells} (too large for memory)")


@dataclass(frozen=True)
class ScenarioConfig:
    """Everything that defines a simulated run (with the seed).

    Each field's documentation is its ``metadata["doc"]``.
    """

    name: str = param("custom", "scenario name (for metadata).")
    dt: float = param(0.1, "sampling period Δt, s (paper 000: 0.1 s).")
    n_steps: int = param(500, "number of controls T; the run has T+1 poses and lasts `T·dt` s.")
    world: WorldConfig = field(default_factory=WorldConfig)
    path: PathConfig = field(default_factory=PathConfig)
    robot: RobotConfig = field(default_factory=RobotConfig)
    odometry: OdometryConfig = field(default_factory=OdometryConfig)
    sensor: SensorConfig = field(default_factory=SensorConfig)
    clutter: ClutterConfig = field(default_factory=ClutterConfig)
    gps: GpsConfig = field(default_factory=GpsConfig)
    walls: WallsConfig = field(default_factory=WallsConfig)
    bounded: BoundedConfig = field(default_factory=BoundedConfig)

    def __post_init__(self) -> None:
        _check(self.dt > 0 and math.isfinite(self.dt), "dt must be a finite number > 0")
        _check_finite(self)
        _check(self.n_steps >= 1, "n_steps must be >= 1")
        _check(self.n_steps <= MAX_STEPS, f"n_steps must be <= {MAX_STEPS} (got {self.n_steps}; the limit of one run)")

    @property
    def duration_s(self) -> float:
        return self.n_steps * self.dt


_SECTIONS = ("world", "path", "robot", "odometry", "sensor", "clutter", "gps", "walls", "bounded")


def known_keys(cfg: ScenarioConfig | None = None) -> list[str]:
    """All dotted override keys, e.g. ``["dt", "n_steps", "world.layout", ...]``."""
    cfg = cfg or ScenarioConfig()
    keys = [f.name for f in dataclasses.fields(cfg) if f.name not in _SECTIONS and f.name != "name"]
    for sec in _SECTIONS:
        keys += [f"{sec}.{f.name}" for f in dataclasses.fields(getattr(cfg, sec))]
    return keys


def apply_overrides(cfg: ScenarioConfig, overrides: dict[str, Any] | None, *, where: str = "--set") -> ScenarioConfig:
    """Return ``cfg`` with dotted-key overrides applied (values may be strings, as from the command line).

    Raises
    ------
    ConfigError
        One line: unknown key (listing the known keys), a value of the wrong type, or an invalid value.
    """
    if not overrides:
        return cfg
    top: dict[str, Any] = {}
    per_section: dict[str, dict[str, Any]] = {}
    for key, value in overrides.items():
        key = str(key).strip()
        sec, _, leaf = key.rpartition(".")
        if sec:
            if sec not in _SECTIONS or leaf not in {f.name for f in dataclasses.fields(getattr(cfg, sec))}:
                raise ConfigError(f"{where}: unknown key {key!r}{known_text(key, known_keys(cfg))}")
            hints = typing.get_type_hints(type(getattr(cfg, sec)))
            per_section.setdefault(sec, {})[leaf] = convert(value, hints[leaf], f"{where} {key}")
        else:
            if leaf not in ("dt", "n_steps"):
                raise ConfigError(f"{where}: unknown key {key!r}{known_text(key, known_keys(cfg))}")
            hints = typing.get_type_hints(ScenarioConfig)
            top[leaf] = convert(value, hints[leaf], f"{where} {key}")
    try:
        changes: dict[str, Any] = dict(top)
        for sec, vals in per_section.items():
            changes[sec] = dataclasses.replace(getattr(cfg, sec), **vals)
        return dataclasses.replace(cfg, **changes)
    except ConfigError as exc:
        raise ConfigError(f"{where}: {exc}") from None
    except (TypeError, ValueError) as exc:
        raise ConfigError(f"{where}: {exc}") from None


def config_to_dict(cfg: ScenarioConfig) -> dict[str, Any]:
    """JSON-serialisable nested dict of the resolved configuration (tuples become lists)."""

    def conv(v: Any) -> Any:
        if isinstance(v, dict):
            return {k: conv(x) for k, x in v.items()}
        if isinstance(v, (list, tuple)):
            return [conv(x) for x in v]
        return v

    return conv(dataclasses.asdict(cfg))


def config_from_dict(d: dict[str, Any]) -> ScenarioConfig:
    """Inverse of :func:`config_to_dict` (e.g. to re-simulate from a dataset's metadata)."""
    flat: dict[str, Any] = {}
    for k, v in d.items():
        if k in _SECTIONS and isinstance(v, dict):
            flat.update({f"{k}.{kk}": vv for kk, vv in v.items()})
        elif k != "name":
            flat[k] = v
    return dataclasses.replace(apply_overrides(ScenarioConfig(), flat, where="config"), name=str(d.get("name", "custom")))
