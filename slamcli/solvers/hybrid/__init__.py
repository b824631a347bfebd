"""Hybrid Bayesian/frequentist SLAM (paper 001): EKF on features + estimator E2 on an occupancy grid."""

from slamcli.solvers.lazy import lazy_exports

_EXPORTS = {
    "HybridParams": "slamcli.solvers.hybrid.params",
    "HybridSlam": "slamcli.solvers.hybrid.solver",
}
__getattr__, __dir__ = lazy_exports(__name__, _EXPORTS)
__all__ = ["HybridParams", "HybridSlam"]
