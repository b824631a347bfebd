"""``--method odometry``: :class:`OdometryParams`, importable without numpy (``slamcli solvers odometry`` reads it)."""

from __future__ import annotations

from dataclasses import dataclass

from slamcli.params import param


@dataclass(frozen=True)
class OdometryParams:
    """Parameters of :class:`OdometrySolver`.

    Each field's documentation is its ``metadata["doc"]`` (``slamcli solvers NAME`` shows it).
    """

    use_reported_ids: bool = param(True, "Label rows by their sensor-reported id when they have one "
                                         "(`reported_id ≥ 0`).")
    nn_threshold: float = param(1.0, "Greedy nearest-neighbour gate in metres (landmark space) for rows "
                                     "without a reported id.")
    min_support: int = param(1, "Minimum number of rows a label needs to be kept as a landmark (2 or more "
                                "drops single-shot clutter).")

    def __post_init__(self) -> None:
        if not self.nn_threshold > 0:
            raise ValueError(f"nn_threshold must be > 0, got {self.nn_threshold}")
        if self.min_support < 1:
            raise ValueError(f"min_support must be >= 1, got {self.min_support}")


Params = OdometryParams
