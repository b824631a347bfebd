"""ICM-SLAM (paper 000): the solver (:mod:`.solver`), its Gibbs energy and conditional modes (:mod:`.energy`)
and the map node — matchings, eq. (17), label fusion, the ς filter (:mod:`.map_step`)."""

from slamcli.solvers.lazy import lazy_exports

_EXPORTS = {
    "online_init": "slamcli.solvers.icm.common",
    "reported_labels": "slamcli.solvers.icm.common",
    "IcmParams": "slamcli.solvers.icm.params",
    "IcmSlam": "slamcli.solvers.icm.solver",
}
__getattr__, __dir__ = lazy_exports(__name__, _EXPORTS)
__all__ = ["IcmParams", "IcmSlam", "online_init", "reported_labels"]
