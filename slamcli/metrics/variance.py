"""Variance-component estimation (VCE) as a metric: is a least-squares problem's noise model calibrated, group by
group? The estimator is :mod:`slamcli.solvers.nls.variance` (one implementation: the ``isam`` solver's
``noise="vce"`` option re-weights with it, so it lives in the solvers layer); this module names it among the
metrics."""

from slamcli.solvers.nls.variance import DENSE_LIMIT, VarianceComponents, variance_components

__all__ = ["DENSE_LIMIT", "VarianceComponents", "variance_components"]
