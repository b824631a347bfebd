"""ICM-SLAM (paper 000): the solver (:mod:`.solver`), its Gibbs energy and conditional modes (:mod:`.energy`)
and the map node — matchings, eq. (17), label fusion, the ς filter (:mod:`.map_step`)."""

from slamcli.solvers.icm.common import online_init, reported_labels
from slamcli.solvers.icm.solver import IcmParams, IcmSlam

__all__ = ["IcmParams", "IcmSlam", "online_init", "reported_labels"]
