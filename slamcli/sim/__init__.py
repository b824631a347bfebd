"""Simulator: named scenarios → :class:`~slamcli.types.Dataset` (solver inputs + ground truth + metadata).

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
from slamcli.sim.simulate import STREAMS, noise_spec, simulate, simulate_scenario

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
