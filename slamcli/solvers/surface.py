"""The landmark radius a dataset declares, for surface-aware observation models (beyond paper 000).

A dataset declares the size of what its sensor hits per return in ``observations.diameter_m`` (the simulator's
laser scenarios with ``sensor.report_size``; Victoria Park's trunk detector). ρ_i = diameter_m / 2. The
surface model itself is in :mod:`slamcli.models.observation`; ICM's per-return use in
:mod:`slamcli.solvers.icm.surface`. Solvers that fuse a laser's several returns on one post into one mean
(graph's ``group_returns``) use the mean offset π/4 · ρ: the mean of √(ρ² − s²) over a lateral offset s uniform
on [−ρ, ρ].
"""

from __future__ import annotations

import dataclasses

import numpy as np

from slamcli.errors import ConfigError
from slamcli.models.observation import mean_surface_offset


def declared_radius(inputs) -> np.ndarray | None:
    """ρ_i ``(N,)`` from the dataset's declared object size (``observations.diameter_m / 2``; non-finite or
    non-positive sizes read as 0), or None when the dataset declares none."""
    d = getattr(inputs.observations, "diameter_m", None)
    if d is None:
        return None
    rho = 0.5 * np.asarray(d, float).reshape(-1)
    return np.where(np.isfinite(rho) & (rho > 0), rho, 0.0)


def require_radius(inputs, solver: str) -> np.ndarray:
    """:func:`declared_radius`, or the one-line refusal of ``-p surface=true`` on a dataset that declares none."""
    rho = declared_radius(inputs)
    if rho is None:
        raise ConfigError(f"{solver}: surface=true needs the landmark radius the dataset declares "
                          "(inputs/observations/diameter_m), this dataset declares none")
    return rho


def mean_offset_inputs(inputs, solver: str):
    """``inputs`` with every range lengthened by π/4 · ρ_i (the declared radius; refusal when none)."""
    rho = require_radius(inputs, solver)
    obs = inputs.observations
    obs = dataclasses.replace(obs, range_m=np.asarray(obs.range_m, float) + mean_surface_offset(rho))
    return dataclasses.replace(inputs, observations=obs)
