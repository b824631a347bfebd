"""Importers that turn public real-world recordings into slamcli datasets (schema v1).

Each importer reads the recording's own text files and returns a :class:`~slamcli.types.Dataset`; write it
with :func:`slamcli.io.write_dataset` (``slamcli import <format> ...`` does both). After that, every solver,
``evaluate`` and ``plot`` command works on the real data exactly as on simulated data.

* :mod:`slamcli.datasets.mrclam`: UTIAS Multi-Robot Cooperative Localization and Mapping (MRCLAM) datasets
  (Leung et al., IJRR 2011): one robot's velocity log, barcode range-bearing measurements and motion-capture
  ground truth.
* :mod:`slamcli.datasets.g2o`: landmark pose-graph files (g2o ``EDGE_SE2``/``EDGE_SE2_XY``, GTSAM
  ``ODOMETRY``/``LANDMARK``), e.g. the DLR graph and GTSAM's Victoria Park: solver inputs only, no ground truth.

Every problem with the input files (missing file, malformed row, no overlap in time) raises
:class:`DatasetImportError` (a :class:`~slamcli.errors.SlamcliError`) with one line naming the file.
"""

from __future__ import annotations

from slamcli.errors import SlamcliError


class DatasetImportError(SlamcliError):
    """A recording that cannot be imported: missing file, malformed row, empty or non-overlapping time."""


__all__ = ["DatasetImportError"]
