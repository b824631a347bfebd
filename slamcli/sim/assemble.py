"""What the three simulator drivers (:mod:`~slamcli.sim.simulate`, :mod:`~slamcli.sim.wallworld`,
:mod:`~slamcli.sim.bounded`) assemble alike: the solver-visible :class:`~slamcli.types.SlamInputs` of a
simulated run and the dataset metadata (scenario, seeds, resolved configuration, stream table)."""

from __future__ import annotations

from typing import Any

import numpy as np

import slamcli
from slamcli.sim.config import ScenarioConfig, config_to_dict
from slamcli.sim.streams import STREAMS
from slamcli.types import NoiseSpec, Observations, SlamInputs


def simulated_inputs(cfg: ScenarioConfig, n_steps: int, poses_xyt: np.ndarray, controls: np.ndarray,
                     odometry_xyt: np.ndarray, observations: Observations, noise: NoiseSpec,
                     **optional: Any) -> SlamInputs:
    """``SlamInputs`` on the grid ``t_k = k·dt`` (k = 0..n_steps) with the true start pose ``poses_xyt[0]`` as
    the known ``x0`` and the sensor's max range; ``optional`` are further SlamInputs fields (GPS, noise
    bounds). Shapes: poses_xyt (T+1, 3), controls (T, 2), odometry_xyt (T+1, 3)."""
    return SlamInputs(
        dt=float(cfg.dt),
        timestamps=np.arange(n_steps + 1) * float(cfg.dt),
        x0=poses_xyt[0].copy(),
        controls=controls,
        odometry_xyt=odometry_xyt,
        observations=observations,
        noise=noise,
        max_range=float(cfg.sensor.max_range),
        **optional,
    )


def simulated_metadata(cfg: ScenarioConfig, *, seed: int, world_seed: int, n_steps: int, sensor_kind: str,
                       generator: str = "slamcli.sim", config: ScenarioConfig | None = None,
                       with_streams: bool = True, **extra: Any) -> dict[str, Any]:
    """The metadata of a simulated dataset (JSON-serialisable). ``config``: the configuration to record when
    it differs from ``cfg`` (wall worlds record the ``n_steps`` their laps took); ``with_streams``: record
    :data:`~slamcli.sim.streams.STREAMS` (wall-world files never did, and stay as they were); ``extra``:
    driver-specific keys."""
    metadata: dict[str, Any] = {
        "generator": generator,
        "slamcli_version": slamcli.__version__,
        "scenario": cfg.name,
        "seed": int(seed),
        "world_seed": int(world_seed),
        "dt": float(cfg.dt),
        "n_steps": int(n_steps),
        "sensor_kind": sensor_kind,
        "config": config_to_dict(cfg if config is None else config),
    }
    if with_streams:
        metadata["streams"] = dict(STREAMS)
    metadata.update(extra)
    return metadata
