"""``--method hybrid``: :class:`HybridParams`, importable without numpy (``slamcli solvers hybrid`` reads it)."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Literal

from slamcli.params import param


@dataclass(frozen=True)
class HybridParams:
    """Parameters of :class:`HybridSlam`.

    Each field's documentation is its ``metadata["doc"]`` (``slamcli solvers NAME`` shows it).
    """

    resolution: float = param(0.5, "grid cell side, m (> 0).")
    grid_offset: float = param(0.5, "grid lines at `(k + grid_offset)·resolution` (0.5 = the simulator's "
                                    "grid).")
    grid_margin: float = param(2.0, "grid = bounding box of the EKF trajectory ± (max range + margin), m.")
    max_cells: int = param(50_000_000, "refuse larger grids (one-line error before the mapping starts).")
    prior: float = param(0.5, "initial occupancy probability P_i(0).")
    a: float = param(0.5, "learning rate γ = a·n^(−α) (paper: α < 1).")
    alpha: float = param(0.6, "learning rate γ = a·n^(−α) (paper: α < 1).")
    step_clock: Literal["cell", "global"] = param("cell", "n = the cell's own update count, or the global "
                                                          "step t.")
    samples: Literal["sigma", "random"] = param("sigma", "pose samples of the belief: 7 sigma points (κ = "
                                                         "`kappa`) or `n_samples` random draws (rng).")
    n_samples: int = param(10, 'random draws per step (`samples = "random"`).')
    kappa: float = param(1.0, "sigma-point spread κ.")
    outlier_prob: float = param(0.02, "ε of the scan likelihood floor.")
    min_traversal: float = param(0.1, "a crossed cell counts as observed empty only if the beam runs ≥ "
                                      "this far in it, as a fraction of the resolution ...")
    free_margin: float = param(3.0, "... and leaves it at least this far (m) before the reading: a beam "
                                    "grazing a wall at angle φ runs 0.5·res/sin φ through the wall's row "
                                    "of cells before it meets the wall line (3 m covers φ ≥ 4.8° at 0.5 m "
                                    "cells).")
    conditional_a: bool = param(True, "observation matrices conditional on the cell being observed (see "
                                      "`models.occupancy.observation_probs`); false = eqs. (33)-(34) "
                                      "verbatim.")
    max_cell_dist: float = param(40.0, "B_i of eq. (51): update only cells within this distance of the "
                                       "belief mean (paper: 40 m).")
    bearing_in_range: bool = param(True, "fold the bearing σ into the range σ of the sensor model (r·σ_θ).")
    stabilising_scale: float = param(3.0, "EKF stabilising noise: factor on σ_r, σ_θ. The paper uses ≈10; "
                                          "our EKF is already conservative at 3 (pose NEES well below 3), "
                                          "and with 10 the sigma points spread so wide that the scan "
                                          "likelihood often prefers an off-mean sample (measured on "
                                          "hybrid-map1 with 1 m cells, 90 beams and free_margin 1.5 m: "
                                          "final per-cell error 0.196 with 10, 0.029 with 3) — hence the "
                                          "default 3 (the reproduce section lists it among the deviations "
                                          "and runs 10 beside it).")
    motion_std_scale: float = param(1.0, "EKF factor on the process noise.")
    feature_sensor: int = param(0, "sensor indices of the feature rows and the scan rows.")
    scan_sensor: int = param(1, "sensor indices of the feature rows and the scan rows.")
    association: Literal["auto", "known", "ml"] = param("auto",
        "EKF data association of the feature rows: the reported ids (paper 001 assumes identified "
        "features), maximum likelihood, or `auto` = known when the feature rows carry ids, else ml.")
    baseline: bool = param(True, "also build the log-odds (eq. 24) grid from the belief mean.")
    logodds_clamp: float = param(20.0, "|log-odds| bound of the baseline.")
    n_snapshots: int = param(12, "grid snapshots at evenly spaced steps (the last one = the final map).")
    weight_floor: float = param(1e-9, "pose samples whose normalised weight p(z|s)b(s) is below this are "
                                      "left out of the E2 sums (they change c_i and A_i by less than "
                                      "S·floor; with the laser most steps keep one or two of the seven "
                                      "sigma points); 0 keeps all.")
    thin_wall_likelihood: bool = param(True, "(`frequentist.scan_log_likelihood` with `free_margin`): "
                                             "cells within `free_margin` before a reading do not block "
                                             "the beam, and a wall cell stops it with probability ∝ its "
                                             "crossing length. False = the forward model of eqs. "
                                             "(32)-(34) as is, which (measured on hybrid-map1 under a "
                                             "near-exact map) prefers sigma points 0.2-0.4 m off the true "
                                             "pose and smears the map.")
    weighted_clock: bool = param(True, "with the cell clock: n advances by min(1, W_i), the weight of the "
                                       "samples that observe the cell (false: by 1 per update, however "
                                       "small W_i).")
    mapping: bool = param(True, "False: the Bayesian part alone (the EKF on the feature rows, no grids), e.g. "
                                "for a NEES Monte-Carlo of the filter.")
    map_poses: Literal["belief", "mean", "odometry"] = param(
        "belief", "what the frequentist part maps from: the belief's samples (`samples`), its mean alone (one "
                  "pose per step, weight 1), or the dataset's odometry poses (mapping with given poses; the EKF "
                  "is then not run and the result has no covariance or landmarks).")
    snapshot_steps: tuple[int, ...] = param((), "grid snapshots after these steps (e.g. a route's lap ends) "
                                                "instead of `n_snapshots` evenly spaced ones; empty = evenly "
                                                "spaced.")

    def __post_init__(self) -> None:
        if not (math.isfinite(self.resolution) and self.resolution > 0):
            raise ValueError(f"resolution must be a finite number > 0, got {self.resolution}")
        if not 0.0 <= self.grid_offset < 1.0:
            raise ValueError(f"grid_offset must be in [0, 1), got {self.grid_offset}")
        if self.max_cells < 1 or self.grid_margin < 0:
            raise ValueError("max_cells must be >= 1 and grid_margin >= 0")
        if not 0.0 < self.prior < 1.0:
            raise ValueError(f"prior must be in (0, 1), got {self.prior}")
        if not (self.a > 0 and 0.0 <= self.alpha <= 1.0):
            raise ValueError(f"need a > 0 and alpha in [0, 1], got a={self.a}, alpha={self.alpha}")
        if self.n_samples < 1 or self.kappa <= 0:
            raise ValueError("n_samples must be >= 1 and kappa > 0")
        if not 0.0 < self.outlier_prob < 1.0:
            raise ValueError(f"outlier_prob must be in (0, 1), got {self.outlier_prob}")
        if self.min_traversal < 0 or self.max_cell_dist <= 0 or self.free_margin < 0:
            raise ValueError("min_traversal and free_margin must be >= 0 and max_cell_dist > 0")
        if self.stabilising_scale <= 0 or self.motion_std_scale <= 0:
            raise ValueError("stabilising_scale and motion_std_scale must be > 0")
        if not 0.0 <= self.weight_floor < 1e-3:
            raise ValueError(f"weight_floor must be in [0, 1e-3), got {self.weight_floor}")
        if self.n_snapshots < 1 or self.logodds_clamp <= 0:
            raise ValueError("n_snapshots must be >= 1 and logodds_clamp > 0")
        if any(k < 0 for k in self.snapshot_steps):
            raise ValueError(f"snapshot_steps must be >= 0, got {list(self.snapshot_steps)}")


Params = HybridParams
