"""Pure evaluation metrics (numpy in, numbers / DataFrames out; no file I/O, no CLI libraries).

* :mod:`~slamcli.metrics.landmarks`   paper nearest-neighbour error, assignment + OSPA/GOSPA
* :mod:`~slamcli.metrics.trajectory`  ATE (unaligned / SE(2)-aligned), RPE, Umeyama alignment
* :mod:`~slamcli.metrics.consistency` NEES, Monte-Carlo average NEES and χ² band
* :mod:`~slamcli.metrics.summary`     everything ``slamcli evaluate`` reports for one result
* :mod:`~slamcli.metrics.variance`    variance-component estimation: is a noise model calibrated, group by group
                                      (re-exports :mod:`slamcli.solvers.nls.variance`, which ``isam -p noise=vce`` uses)
"""

from slamcli.metrics.consistency import average_nees, chi2_band, landmark_nees, nees, pose_nees
from slamcli.metrics.landmarks import (
    assign_landmarks,
    honest_landmark_error,
    map_change,
    nearest_true_errors,
    paper_error_per_iteration,
    paper_landmark_error,
    paper_landmark_error_near_path,
)
from slamcli.metrics.trajectory import ate, ate_errors, rpe, rpe_errors, umeyama_se2

__all__ = [
    "assign_landmarks", "ate", "ate_errors", "average_nees", "chi2_band", "honest_landmark_error",
    "landmark_nees", "map_change", "nearest_true_errors", "nees", "paper_error_per_iteration",
    "paper_landmark_error", "paper_landmark_error_near_path", "pose_nees", "rpe", "rpe_errors", "umeyama_se2",
]
