"""Named scenarios. Each factory returns a :class:`ScenarioConfig`; ``resolve_scenario`` applies overrides.

How they approximate paper 000 (MobileSim with a Pioneer P3-DX and its SICK laser; outdoors a Pioneer 3-AT):

* ``loop`` — not from the paper: a small, fast world for tests (12 random landmarks in 20 m × 14 m, one
  rectangular lap plus a bit, 500 steps, point sensor of 8 m range over 180°).
* ``paper-sim1`` — Simulations 1 (Figs. 4-5): ≈50 m × 40 m with 7 rows of 9 jittered landmarks 5 m apart, an
  irregular lawn-mower path along three lanes (jittered waypoints every 5 m), Δt = 0.1 s, a 181-beam laser
  over 180° at full range (≈30 m, the simulated SICK LMS-200). Landmarks are 0.25 m-radius posts (assumed;
  chosen by measurement: benchmarks/results/design_notes.md), so a post gives several returns on adjacent
  beams and far posts are coarsely resolved (the poor initial maps of Fig. 5(a)); returns lie on the post
  surface (``range_offset`` re-centres them). Small odometry noise, max-range and isolated returns dropped,
  0.2 clutter returns per scan; 3250 steps cover the ≈155 m path at 0.5 m/s.
* ``paper-sim2`` — Simulation 2 (Fig. 7): ``paper-sim1`` with a 10 m laser.
* ``octagon`` — the outdoor experiment of §6 (Figs. 8-9): 8 cones on an octagon of radius 7.12 m, one at its
  centre and two static people (positions assumed), circled on a jittered ≈10.5 m path for 1830 steps of 0.1 s
  with a 30 m outdoor laser, noisier skid-steer odometry with a small turn bias and more clutter.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Any

import numpy as np

from slamcli.errors import ConfigError
from slamcli.sim.config import (
    BoundedConfig,
    ClutterConfig,
    OdometryConfig,
    PathConfig,
    RobotConfig,
    ScenarioConfig,
    SensorConfig,
    WorldConfig,
    apply_overrides,
)


def _loop() -> ScenarioConfig:
    return ScenarioConfig(
        name="loop",
        dt=0.1,
        n_steps=500,
        world=WorldConfig(
            layout="random", x_min=0.0, x_max=20.0, y_min=0.0, y_max=14.0, n_landmarks=12,
            min_separation=2.0, path_clearance=1.0,
        ),
        path=PathConfig(kind="rect", x_min=3.0, x_max=17.0, y_min=3.0, y_max=11.0, cyclic=True),
        robot=RobotConfig(v_max=1.0, w_max=1.0, k_heading=2.0, waypoint_tol=0.5, actuation_std=(0.05, 0.02)),
        odometry=OdometryConfig(std=(0.005, 0.005, 0.002)),
        sensor=SensorConfig(kind="point", max_range=8.0, min_range=0.1, fov_deg=180.0, range_std=0.05,
                            bearing_std=0.01, detection_prob=0.95),
        clutter=ClutterConfig(rate=0.0),
    )


def _paper_sim(max_range: float, name: str) -> ScenarioConfig:
    return ScenarioConfig(
        name=name,
        dt=0.1,
        n_steps=3250,
        world=WorldConfig(
            layout="rows", x_min=5.0, x_max=45.0, n_rows=7, row_y0=5.0, row_spacing=5.0, col_spacing=5.0,
            jitter=0.3, landmark_radius=0.25,
        ),
        path=PathConfig(
            kind="serpentine", x_min=2.5, x_max=47.5, y_min=0.0, y_max=40.0, lanes=(7.5, 17.5, 27.5),
            spacing=5.0, jitter=0.5, cyclic=False,
        ),
        robot=RobotConfig(v_max=0.5, w_max=0.6, k_heading=1.5, waypoint_tol=0.5, actuation_std=(0.02, 0.02)),
        odometry=OdometryConfig(std=(0.001, 0.001, 0.0005)),
        sensor=SensorConfig(kind="laser", max_range=max_range, min_range=0.1, fov_deg=180.0, n_beams=181,
                            range_std=0.01, bearing_std=0.0, detection_prob=1.0, drop_max_range=True,
                            drop_isolated=True, isolation_gap=0.5, report_size=True),
        clutter=ClutterConfig(rate=0.2),
    )


def _paper_sim_mobilesim() -> ScenarioConfig:
    """``paper-sim1-mobilesim``: ``paper-sim1`` with the robot base, laser and odometry of MobileSim's Pioneer
    P3-DX model as documented by its model files (sources: benchmarks/results/design_notes.md).

    Mapped onto the simulator: executed velocities ramp with ``accel_max = (0.3, 1.74)`` and ``decel_max =
    (0.6, 1.74)`` (the solvers see the commanded velocities; the motion lags them); no actuation noise beyond a
    1 mm/s, 1 mrad/s floor (keeps every motion covariance positive); odometry with the documented constant error
    at its bound, ``scale_bias = turn_bias = 0.0075``, plus ``paper-sim1``'s small white noise; laser range
    σ = 0.005/√3 m and bearing σ = 0.0007/√3 rad (the documented uniform errors), 32 m range. The world, path,
    cruise speed and clutter stay those of ``paper-sim1``.
    """
    base = _paper_sim(32.0, "paper-sim1-mobilesim")
    return apply_overrides(base, {
        "robot.accel_max": [0.3, 1.74], "robot.decel_max": [0.6, 1.74], "robot.actuation_std": [0.001, 0.001],
        "odometry.scale_bias": 0.0075, "odometry.turn_bias": 0.0075,
        "sensor.range_std": 0.005 / 3**0.5, "sensor.bearing_std": 0.0007 / 3**0.5,
    })


def _octagon() -> ScenarioConfig:
    return ScenarioConfig(
        name="octagon",
        dt=0.1,
        n_steps=1830,
        world=WorldConfig(layout="octagon", octagon_radius=7.12, extra_landmarks=(-11.0, 13.0, 9.0, 15.5),
                          landmark_radius=0.15),
        path=PathConfig(kind="ellipse", x_min=-10.5, x_max=10.5, y_min=-10.5, y_max=10.5, n_points=16,
                        jitter=0.4, cyclic=True),
        robot=RobotConfig(v_max=0.5, w_max=0.6, k_heading=1.5, waypoint_tol=0.5, actuation_std=(0.03, 0.03)),
        odometry=OdometryConfig(std=(0.003, 0.003, 0.003), turn_bias=0.01),
        sensor=SensorConfig(kind="laser", max_range=30.0, min_range=0.1, fov_deg=180.0, n_beams=181,
                            range_std=0.02, bearing_std=0.0, detection_prob=0.98, report_size=True),
        clutter=ClutterConfig(rate=1.0),
    )


def _hybrid(name: str, sensor: str, width: float, height: float, rows: int, cols: int, corridor: float,
            features: str = "corners+mid") -> ScenarioConfig:
    """Paper 001 §III: DDMR with wheel radius R = 0.25 m and width L = 0.5 m (eqs. 29-31) at a mean wheel
    speed of 5 rad/s (v = 1.25 m/s), Δt = 0.5 s, wheel-encoder noise σ_u = 0.5 rad/s per wheel, i.e.
    σ_v = R σ_u/√2 = 0.088 m/s and σ_ω = √2 R σ_u / L = 0.354 rad/s (independent); a 40 m sensor, either the
    noisy 2-D sensor (σ_r = 0.2 m, σ_θ = 0.6°) or the laser (σ_r = 0.01 m, σ_θ = 0.05°), 180 beams all round
    (the paper gives no beam count); 3 laps (``walls.laps``)."""
    import math

    from slamcli.sim.config import WallsConfig

    r_std, b_deg = (0.2, 0.6) if sensor == "noisy" else (0.01, 0.05)
    R, L, s_u = 0.25, 0.5, 0.5
    return ScenarioConfig(
        name=name,
        dt=0.5,
        n_steps=1,
        world=WorldConfig(layout="none"),
        robot=RobotConfig(v_max=5.0 * R, w_max=0.6, k_heading=1.0, waypoint_tol=1.0,
                          actuation_std=(R * s_u / math.sqrt(2), math.sqrt(2) * R * s_u / L)),
        odometry=OdometryConfig(std=(0.044, 0.005, 0.177)),
        sensor=SensorConfig(kind="laser", max_range=40.0, min_range=0.1, fov_deg=360.0, n_beams=180,
                            range_std=r_std, bearing_std=math.radians(b_deg), detection_prob=1.0,
                            report_ids=True, drop_max_range=False, drop_isolated=False),
        clutter=ClutterConfig(rate=0.0),
        walls=WallsConfig(layout="ladder", width=width, height=height, block_rows=rows, block_cols=cols,
                          corridor=corridor, features=features),  # type: ignore[arg-type]
    )


_MAPS = {  # paper 001 §III: (width, height, block rows, block cols, corridor width)
    1: (100.0, 100.0, 1, 1, 10.0),  # one cyclic corridor of side 100 m
    2: (100.0, 40.0, 1, 4, 8.0),  # 100 m x 40 m hallway, 4 cyclic corridors
    3: (220.0, 40.0, 1, 10, 8.0),  # 220 m x 40 m, 10 cycles
    4: (1000.0, 200.0, 2, 10, 10.0),  # ~1 km x 200 m, 20 cycles (city blocks)
}


#: paper 004's leg length: its Table 1 r2 box is centred √60 m from r1
PAPER004_LEG = math.sqrt(60.0)


def _cuik_room(name: str = "cuik-room", leg: float | None = None, porta: bool = False) -> ScenarioConfig:
    """Paper 004 §6: a 30 m square room, doors (type 0) at (15, 0) and (15, 30), corridors (type 1) at
    (30, 15) and (0, 15); 8 turn-and-move legs of 7.65 m around an octagon of radius 10 m centred at
    (15, 15), turning +45° (paper: −45°, its θ runs clockwise) per leg and closing the loop at pose 9 (our
    pose 8). Start r1 = (15, 5, 1.963495) in the paper's heading convention (Table 1). Declares a landmark
    separation of 5 m (a map prior the paper does not state; ``bounded.declared_separation=0`` drops it).

    ``leg``: legs of this length instead (octagon radius ``leg / (2 sin 22.5°)``, centred above the start so
    r1 stays (15, 5)); ``porta``: Porta's setting (paper 004 §1, §6) — the sensor reports every landmark
    within 40 m with its identity, instead of the closest one within 12 m with its type only."""
    from slamcli.sim.bounded import heading_from_paper004

    radius = 10.0 if leg is None else leg / (2.0 * math.sin(math.pi / 8))
    a = np.deg2rad(-90.0 + 45.0 * np.arange(8))
    wp = np.column_stack([15.0 + radius * np.cos(a), 5.0 + radius + radius * np.sin(a)]).round(12)
    return ScenarioConfig(
        name=name, dt=1.0, n_steps=8,
        world=WorldConfig(layout="none", extra_landmarks=(15.0, 0.0, 30.0, 15.0, 15.0, 30.0, 0.0, 15.0)),
        path=PathConfig(kind="explicit", waypoints=tuple(wp.ravel().tolist()), cyclic=True),
        robot=RobotConfig(start=(15.0, 5.0, float(heading_from_paper004(1.9634954)))),
        sensor=SensorConfig(kind="point", max_range=40.0 if porta else 12.0, min_range=0.1, fov_deg=360.0,
                            report_ids=porta),
        bounded=BoundedConfig(enabled=True, odometry_d=0.25, odometry_turn_deg=5.0, range=0.025,
                              bearing_deg=0.5, closest_only=not porta, landmark_types=(0, 1, 0, 1),
                              declared_separation=5.0),  # map prior (true minimum 21.2 m); 0 = the paper's
    )


def _cuik_corridors() -> ScenarioConfig:
    """Beyond paper 004: a 40 m × 20 m block of corridors driven 1.5 times around (45 legs of 4 m) with
    14 doors (type 0) and corridor junctions (type 1) 2 m off the path; closest-landmark sensor of 6 m."""
    corners = np.array([[0.0, 0.0], [40.0, 0.0], [40.0, 20.0], [0.0, 20.0]])
    lms = [(4.0, -2.0), (12.0, 2.0), (20.0, -2.0), (28.0, 2.0), (36.0, -2.0), (42.0, 6.0), (38.0, 14.0),
           (34.0, 22.0), (26.0, 18.0), (18.0, 22.0), (10.0, 18.0), (2.0, 22.0), (-2.0, 14.0), (2.0, 6.0)]
    types = (0, 1, 0, 0, 1, 0, 1, 0, 0, 1, 0, 0, 1, 0)
    return ScenarioConfig(
        name="cuik-corridors", dt=1.0, n_steps=45,
        world=WorldConfig(layout="none", extra_landmarks=tuple(np.ravel(lms).tolist())),
        path=PathConfig(kind="explicit", waypoints=tuple(_subdivide_closed(corners, 4.0).ravel().tolist()),
                        cyclic=True),
        robot=RobotConfig(start=(0.0, 0.0, 0.0)),
        sensor=SensorConfig(kind="point", max_range=6.0, min_range=0.1, fov_deg=360.0),
        bounded=BoundedConfig(enabled=True, odometry_d=0.1, odometry_turn_deg=2.0, range=0.025,
                              bearing_deg=0.5, closest_only=True, landmark_types=types,
                              declared_separation=4.0),  # map prior (true minimum 8.25 m)
    )


def _subdivide_closed(corners_xy: np.ndarray, spacing: float) -> np.ndarray:
    pts = []
    for a, b in zip(corners_xy, np.roll(corners_xy, -1, axis=0)):
        n = max(1, round(float(np.hypot(*(b - a))) / spacing))
        pts += [a + (b - a) * k / n for k in range(n)]
    return np.asarray(pts)


SCENARIOS: dict[str, tuple[Callable[[], ScenarioConfig], str]] = {
    "loop": (_loop, "small fast world for tests: 12 random landmarks, rectangular loop, point sensor, 500 steps"),
    "paper-sim1": (lambda: _paper_sim(30.0, "paper-sim1"),
                   "paper 000 Sim. 1: 50×40 m, 7 rows of landmarks, irregular path, 30 m 181-beam laser"),
    "paper-sim2": (lambda: _paper_sim(10.0, "paper-sim2"), "paper 000 Sim. 2: as paper-sim1 with a 10 m laser"),
    "octagon": (_octagon, "paper 000 §6: 8 cones on a 7.12 m octagon + centre cone + 2 people, 183 s, laser"),
    **{f"hybrid-map{k}{suffix}": ((lambda k=k, s=sens, sf=suffix: _hybrid(f"hybrid-map{k}{sf}", s, *_MAPS[k])),
                                  f"paper 001 Map {k} ({'x'.join(str(int(v)) for v in _MAPS[k][:2])} m, "
                                  f"{_MAPS[k][2] * _MAPS[k][3]} cycles), {sens} sensor, walls + features, 3 laps")
       for k in (1, 2, 3, 4) for suffix, sens in (("", "laser"), ("-noisy", "noisy")) if not (k == 4 and sens == "noisy")},
    "hybrid-map3-posts": (lambda: _hybrid("hybrid-map3-posts", "laser", *_MAPS[3], features="posts"),
                          "paper 001 Map 3 with point landmarks (posts) instead of corners, laser"),
    "cuik-room": (_cuik_room, "paper 004 §6: 30 m room, 2 doors + 2 corridors, 8 turn-and-move legs, bounded noise"),
    "cuik-room-porta": (lambda: _cuik_room("cuik-room-porta", porta=True),
                        "cuik-room in Porta's setting (paper 004 §1): every landmark within 40 m, with its id"),
    "cuik-room-paper-legs": (lambda: _cuik_room("cuik-room-paper-legs", leg=PAPER004_LEG),
                             "cuik-room with paper 004's leg length √60 = 7.746 m (ours 7.654 m)"),
    "cuik-corridors": (_cuik_corridors, "paper 004 beyond: 40×20 m corridors, 14 typed landmarks, 45 legs, bounded"),
    "paper-sim1-mobilesim": (_paper_sim_mobilesim, "paper-sim1 with MobileSim's documented Pioneer P3-DX "
                             "acceleration limits, odometry error and SICK LMS-200 noise"),
}


def list_scenarios() -> list[tuple[str, str]]:
    """``[(name, one-line description)]``."""
    return [(k, v[1]) for k, v in SCENARIOS.items()]


def resolve_scenario(name: str, overrides: dict[str, Any] | None = None) -> ScenarioConfig:
    """The named scenario with dotted-key ``overrides`` applied (e.g. ``{"sensor.max_range": 10}``).

    Raises
    ------
    ConfigError
        Unknown scenario (listing the names) or a bad override.
    """
    if name not in SCENARIOS:
        raise ConfigError(f"--scenario: unknown scenario {name!r}; known: {', '.join(SCENARIOS)}")
    return apply_overrides(SCENARIOS[name][0](), overrides)
