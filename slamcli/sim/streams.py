"""The simulator's named random streams: one ``np.random.Generator`` per (stream, seed).

Streams are independent and derived from ``(stream id, seed)`` with NumPy's recommended list seeding,
``np.random.default_rng([stream_id, seed])``, so changing e.g. the sensor noise level changes neither the
world nor the trajectory, and adding clutter does not change the noise on true returns. Every simulator
driver (:mod:`~slamcli.sim.simulate`, :mod:`~slamcli.sim.wallworld`, :mod:`~slamcli.sim.bounded`) draws from
here; the dispatcher in :mod:`~slamcli.sim.simulate` imports the drivers, never the reverse.
"""

from __future__ import annotations

import numpy as np

#: Stream ids for ``np.random.default_rng([stream_id, seed])``.
STREAMS = {"world": 0, "motion": 1, "odometry": 2, "sensor": 3, "clutter": 4, "gps": 5}


def stream(name: str, seed: int) -> np.random.Generator:
    """The generator of one named stream (``STREAMS``) for ``seed``."""
    return np.random.default_rng([STREAMS[name], int(seed)])
