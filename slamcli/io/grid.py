"""Occupancy grids in slamcli HDF5 files (an optional group; schema version unchanged — files without it read
as before, readers that do not know it ignore it).

Layout of one grid group (``/truth/occupancy`` in datasets, ``/grids/<name>`` in results)::

    @resolution (m)   origin_xy (2,)   prob (H,W) float32   [observed (H,W) int32]
    [snapshot_step (K,) int64   snapshots (K,H,W) float32]      (one gzip chunk per snapshot)

Also the optional dataset fields ``/truth/walls_xyxy (W,4)`` and ``/truth/lap_end_step (K,)``.
"""

from __future__ import annotations

import h5py
import numpy as np

from slamcli.io.schema import GZIP_LEVEL, Reader, write_array
from slamcli.types import OccupancyGrid


def _write_image(g: h5py.Group, name: str, data: np.ndarray, doc: str, units: str) -> None:
    data = np.ascontiguousarray(data)
    kwargs = {}
    if data.size:
        chunk = (1,) * (data.ndim - 2) + tuple(min(s, 512) for s in data.shape[-2:])
        kwargs = {"chunks": chunk, "compression": "gzip", "compression_opts": GZIP_LEVEL, "shuffle": True,
                  "fletcher32": True}
    ds = g.create_dataset(name, data=data, **kwargs)
    ds.attrs["units"] = units
    ds.attrs["frame"] = "grid (row = y, col = x)"
    ds.attrs["doc"] = doc


def write_grid(parent: h5py.Group, name: str, grid: OccupancyGrid) -> None:
    """Write ``grid`` as the group ``parent/name``."""
    g = parent.create_group(name)
    g.attrs["doc"] = "occupancy grid; cell (row, col) covers [x0+col*res, ...) x [y0+row*res, ...)"
    g.attrs["resolution"] = float(grid.resolution)
    write_array(g, "origin_xy", np.asarray(grid.origin_xy, np.float64).reshape(2), units="m", frame="world",
                doc="lower-left corner of cell (0, 0) (2,)")
    _write_image(g, "prob", np.asarray(grid.prob, np.float32), "occupancy probability (H,W)", "-")
    if grid.observed is not None:
        _write_image(g, "observed", np.asarray(grid.observed, np.int32), "steps that updated each cell (H,W)", "-")
    if grid.snapshots is not None:
        write_array(g, "snapshot_step", np.asarray(grid.snapshot_step, np.int64), units="-", frame="-",
                    doc="step after which each snapshot was taken (K,)")
        _write_image(g, "snapshots", np.asarray(grid.snapshots, np.float32), "probabilities at snapshot_step (K,H,W)",
                     "-")


def read_grid(r: Reader, path: str) -> OccupancyGrid:
    """Read and validate the grid group at ``path``; one-line SchemaError otherwise."""
    r.group(path)
    res = r.finite_attr(path, "resolution", positive=True)
    origin = r.array(f"{path}/origin_xy", dtype="f", shape=(2,))
    prob = r.array(f"{path}/prob", dtype="f", shape=(None, None)).astype(np.float32, copy=False)
    if prob.size and ((prob < 0).any() or (prob > 1).any()):
        raise r.fail(f"{path}/prob", "probabilities must lie in [0, 1]")
    H, W = prob.shape
    observed = None
    if r.has(f"{path}/observed"):
        observed = r.array(f"{path}/observed", dtype="i", shape=(H, W)).astype(np.int32, copy=False)
    steps = snaps = None
    if r.has(f"{path}/snapshots"):
        steps = r.array(f"{path}/snapshot_step", dtype="i", shape=(None,)).astype(np.int64, copy=False)
        snaps = r.array(f"{path}/snapshots", dtype="f", shape=(len(steps), H, W)).astype(np.float32, copy=False)
        if len(steps) > 1 and (np.diff(steps) <= 0).any():
            raise r.fail(f"{path}/snapshot_step", "must increase strictly")
    return OccupancyGrid(origin_xy=origin, resolution=res, prob=prob, observed=observed, snapshot_step=steps,
                         snapshots=snaps)
