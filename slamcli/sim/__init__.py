"""Simulator: named scenarios → :class:`~slamcli.types.Dataset` (solver inputs + ground truth + metadata).

Pipeline of :func:`simulate` (``slamcli/sim/simulate.py``), each stage with its own random stream
``np.random.default_rng([stream_id, seed])`` (ids in :data:`STREAMS`):

1. world (``world.py``): waypoints (optionally jittered) and landmarks (rows / random / octagon + extras);
2. motion (``robot.py``): a waypoint-tracking controller gives the commanded controls ``u_t`` (what solvers
   see); the robot executes ``u_t`` + actuation noise through the DDMR model ``g(x, u)`` (paper 000 §4);
3. odometry (``robot.py``): noisy, optionally biased eq.-16 increments of the true motion, chained from x0;
4. sensor + clutter (``sensors.py``): point range-bearing sensor, or a multi-beam laser hitting landmark
   discs with the paper's preprocessing (drop max-range / isolated returns), plus Poisson clutter;
5. gps (optional).

Scenarios (``scenarios.py``): ``loop`` (tests), ``paper-sim1``, ``paper-sim2``, ``octagon``; configuration
dataclasses and dotted overrides in ``config.py``.

>>> from slamcli.sim import resolve_scenario, simulate
>>> ds = simulate(resolve_scenario("loop", {"sensor.range_std": 0.1}), seed=3)
"""

from slamcli.sim.config import (
    ClutterConfig,
    GpsConfig,
    OdometryConfig,
    PathConfig,
    RobotConfig,
    ScenarioConfig,
    SensorConfig,
    WorldConfig,
    apply_overrides,
    config_from_dict,
    config_to_dict,
    known_keys,
)
from slamcli.sim.scenarios import SCENARIOS, list_scenarios, resolve_scenario
from slamcli.sim.simulate import noise_spec, simulate, simulate_scenario
from slamcli.sim.streams import STREAMS

__all__ = [
    "SCENARIOS",
    "STREAMS",
    "ClutterConfig",
    "GpsConfig",
    "OdometryConfig",
    "PathConfig",
    "RobotConfig",
    "ScenarioConfig",
    "SensorConfig",
    "WorldConfig",
    "apply_overrides",
    "config_from_dict",
    "config_to_dict",
    "known_keys",
    "list_scenarios",
    "noise_spec",
    "resolve_scenario",
    "simulate",
    "simulate_scenario",
]
