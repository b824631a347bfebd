"""Parameters of ``--method isam`` (:class:`IsamParams`)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

from slamcli.params import param


@dataclass(frozen=True)
class IsamParams:
    """Parameters of :class:`~slamcli.solvers.isam.solver.IsamSlam`.

    Each field's documentation is its ``metadata["doc"]`` (``slamcli solvers NAME`` shows it).
    """

    association: Literal["auto", "reported", "nn"] = param("auto",
        "`reported` = sensor identities; `nn` = per-step χ²-gated nearest neighbour against the current "
        "estimate (the smoother's joint covariance of the current pose and each landmark); `auto` = "
        "reported when any row carries an id, else nn.")
    gate_prob: float = param(0.999, "χ² gate probability of the per-step association (default 0.999, "
                                    "`graph`'s).")
    segment_dist: float = param(0.5, "Returns of one pose closer than this (m) and adjacent in bearing "
                                     "are one detection "
                                     "(:func:`slamcli.solvers.frontend.segment_returns`; default 0.5, "
                                     "`graph`'s `nn_segment_dist`).")
    lag_s: float = param(3.0, "Length of the smoothing window, s of data time (default 3): older keyframe "
                              "poses, and the landmarks no window pose sees, are marginalised into the "
                              "window's Schur-complement prior.")
    relin_threshold: float = param(0.1, "A variable is relinearised (its factors' Jacobians recomputed) "
                                        "when its step since its linearisation point exceeds this in any "
                                        "component (m or rad; default 0.1, GTSAM "
                                        "`ISAM2Params.relinearizeThreshold`).")
    iterations: int = param(1, "Gauss-Newton steps of the window per update (default 1, as one "
                               "`ISAM2.update`).")
    reactivate: bool = param(True, "A re-observed marginalised landmark re-enters the window at once, "
                                   "with its frozen marginal as a prior (default True; approximate until "
                                   "the next batch step rebuilds the prior from the factors); False = its "
                                   "sightings wait in the store for the next batch step.")
    batch_every_s: float = param(20.0, "A re-observed marginalised landmark (a loop closure) makes the "
                                       "next update a batch step once at least this many seconds of data "
                                       "passed since the previous one (default 20; 0 = at every loop "
                                       "closure): LM over the whole keyframe graph from the current "
                                       "estimate, then the window prior is rebuilt.")
    batch_iterations: int = param(10, "LM budget of a periodic batch step (default 10).")
    end_batch: bool = param(True, "End the run with a batch step over the keyframe graph even when no "
                                  "loop closure is pending (default True): the window only moves the "
                                  "poses of the last `lag_s` seconds, so the poses marginalised before "
                                  "the last batch step keep the estimate they had when they left the "
                                  "window.")
    final_batch: bool = param(False, "After the last update, run `graph`'s batch LM on the full graph "
                                     "(every pose, same factors and association) from the smoother's "
                                     "estimate (default False). With it the result is `graph`'s optimum.")
    noise: Literal["dataset", "vce"] = param("dataset", "Noise model of the result. `dataset` (default): "
                                                        "the dataset's NoiseSpec σ throughout. `vce`: "
                                                        "after the on-line pass (association and "
                                                        "smoothing with the dataset's σ, unchanged), the "
                                                        "σ of odometry x / lateral / heading, range and "
                                                        "bearing are re-estimated from the smoother's own "
                                                        "residuals by iterated variance-component "
                                                        "estimation "
                                                        "(:mod:`slamcli.solvers.graph.variance`: batch LM "
                                                        "over every pose on the smoother's association, "
                                                        "σ_g ← σ_g·√r_g, re-solve) and the result is the "
                                                        "batch optimum under those σ (implies "
                                                        "`final_batch`; needs `robust` to resolve to "
                                                        "`none`). No GPS and no ground truth enter.")
    vce_tol: float = param(0.05, "`noise=vce`: stop when every variance factor is within this of 1 "
                                 "(default 0.05).")
    vce_max_rounds: int = param(10, "`noise=vce`: at most this many re-weighted batch solves (default 10; "
                                    "1 = one round). Iterating is the default by the rule fixed before "
                                    "measuring (`benchmarks/bench_isam.py`): one round leaves a variance "
                                    "factor 0.47 from 1 on Victoria Park; 4 re-weightings reach 5 % at "
                                    "25.7× real time.")
    robust: Literal["auto", "none", "cauchy", "huber"] = param("auto",
        "Kernel on the sightings (as `graph`'s `robust`; `auto` = `graph`'s choice for the association: "
        "cauchy for ids reported by a real sensor, else none).")
    cauchy_k: float = param(2.3849, "Kernel scales (`graph`'s defaults).")
    huber_k: float = param(1.345, "Kernel scales (`graph`'s defaults).")

    def __post_init__(self) -> None:
        if not 0.0 < self.gate_prob < 1.0:
            raise ValueError("gate_prob must be in (0, 1)")
        if self.segment_dist < 0:
            raise ValueError("segment_dist must be ≥ 0 m")
        if not self.lag_s > 0:
            raise ValueError("lag_s must be > 0 s")
        if not self.relin_threshold >= 0:
            raise ValueError("relin_threshold must be ≥ 0")
        if self.iterations < 1 or self.batch_iterations < 1:
            raise ValueError("iterations and batch_iterations must be ≥ 1")
        if self.batch_every_s < 0:
            raise ValueError("batch_every_s must be ≥ 0 s")
        if self.noise not in ("dataset", "vce"):
            raise ValueError(f"noise must be dataset or vce, got {self.noise!r}")
        if not 0.0 < self.vce_tol < 1.0:
            raise ValueError("vce_tol must be in (0, 1)")
        if self.vce_max_rounds < 1:
            raise ValueError("vce_max_rounds must be ≥ 1")
        if self.cauchy_k <= 0 or self.huber_k <= 0:
            raise ValueError("cauchy_k and huber_k must be > 0")


Params = IsamParams
