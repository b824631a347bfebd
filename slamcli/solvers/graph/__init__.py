"""Batch graph SLAM (``--method graph``): all poses ``x_0..x_T`` and landmarks ``m_0..m_{L-1}`` at once.

Factors (``model="gtsam"``, default) are GTSAM's, so the optimum is checked against
``gtsam.LevenbergMarquardtOptimizer`` (``tests/test_graph_gtsam.py``)::

    prior      e = Log(p⁻¹ ⊕ x_0)                               PriorFactorPose2,     Σ = diag(prior_std²)
    odometry   e = Log(d_t⁻¹ ⊕ (x_{t-1}⁻¹ ⊕ x_t))                BetweenFactorPose2,   Σ = diag(odometry_std²)
    motion     same with d_t = [v dt, 0, ω dt] (DDMR, optional)   Σ = diag((σ_v dt)², σ_lat², (σ_ω dt)²)
    bearing-   e = [‖m − p‖ − r,  wrap(∠(m − p) − θ − b)]        BearingRangeFactor2D, Σ = NoiseSpec.obs_cov
    range
    GPS        e = p_t − z_gps (optional)                         Σ = gps_std² I

with ``Log`` the SE(2) logarithm; the cost is GTSAM's ``½ Σ eᵀ Σ⁻¹ e``. ``model="paper"`` minimises the
ICM-SLAM Gibbs energy of paper 000 (eqs. 3-5, 16) with the correspondences fixed and ``x_0`` known::

    E = Σ_t ‖g(x_{t-1}, u_{t-1}) − x_t‖²_R + Σ_t ‖τ(θ_{t-1})(x_t − x_{t-1}) − d_t‖²_S
        + Σ_{t,i} ‖h⁻¹(x_t, z_{t,i}) − m_{c_{t,i}}‖²_Q ,      ‖a‖²_W = aᵀ W a

(:func:`optimize_paper_energy`, which ICM uses to compare its energy with the optimum). The state is
optimised in world coordinates ``[x, y, θ]``, so the Laplace marginals are world-frame (GTSAM's body-frame
Pose2 marginals equal ``J Σ_b Jᵀ``, ``J = blkdiag(R(θ), 1)``). The optimiser is :mod:`slamcli.solvers.nls`.
"""

from slamcli.solvers.graph.build import (  # noqa: F401
    GraphProblem,
    build_gtsam_problem,
    landmark_joint_covariance,
    laplace_marginals,
    located,
    pack_state,
)
from slamcli.solvers.graph.certify import Certificate, certify_pose_graph  # noqa: F401
from slamcli.solvers.graph.factors import (  # noqa: F401
    bearing_range_error,
    between_error,
    group_returns,
    landmark_offset_error,
    log_jacobian,
    prior_error,
    robot_range_bearing_error,
    sqrt_info_batch,
    sqrt_info_from_cov,
    sqrt_of_weight,
)
from slamcli.solvers.graph.init import (  # noqa: F401
    chordal_poses,
    incremental_initial_poses,
    initial_poses,
    nearest_neighbour_association,
    odometry_initial_poses,
    pose_graph_edges,
    robust_initial_poses,
    spanning_tree_poses,
)
from slamcli.solvers.graph.merge import (  # noqa: F401
    merge_candidates,
)
from slamcli.solvers.graph.paper import (  # noqa: F401
    build_paper_problem,
    default_paper_weights,
    optimize_paper_energy,
    paper_energy,
)
from slamcli.solvers.graph.params import (  # noqa: F401
    GraphParams,
    resolve_robust,
)
from slamcli.solvers.graph.solver import (  # noqa: F401
    GraphSlam,
    chi2_outlier_counts,
)
from slamcli.solvers.graph.variance import (  # noqa: F401
    NOISE_GROUPS,
    NoiseCalibration,
    calibrate_noise,
    noise_row_groups,
    noise_sigmas,
    noise_with_sigmas,
)
