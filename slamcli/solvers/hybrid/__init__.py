"""Hybrid Bayesian/frequentist SLAM (paper 001): EKF on features + estimator E2 on an occupancy grid."""

from slamcli.solvers.hybrid.solver import HybridParams, HybridSlam

__all__ = ["HybridParams", "HybridSlam"]
