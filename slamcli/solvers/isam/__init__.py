"""Incremental smoothing for on-line SLAM (``--method isam``): fixed-lag window + Schur-complement prior,
partial relinearisation, per-update association, periodic batch steps, optional final batch LM.

(Design choice and its measurements: see the end of this docstring.)
"""

from slamcli.solvers.isam.params import IsamParams  # noqa: F401
from slamcli.solvers.isam.smoother import IncrementalSmoother  # noqa: F401
from slamcli.solvers.isam.solver import IsamSlam, per_step_slope  # noqa: F401
