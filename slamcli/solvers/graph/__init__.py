"""Batch graph SLAM (``--method graph``): all poses ``x_0..x_T`` and landmarks ``m_0..m_{L-1}`` at once.

Factors (``model="gtsam"``, default) are defined exactly as GTSAM's, so the optimum can be checked against
``gtsam.LevenbergMarquardtOptimizer`` (``tests/test_graph_gtsam.py``)::

    prior      e = Log(p⁻¹ ⊕ x_0)                               PriorFactorPose2,     Σ = diag(prior_std²)
    odometry   e = Log(d_t⁻¹ ⊕ (x_{t-1}⁻¹ ⊕ x_t))                BetweenFactorPose2,   Σ = diag(odometry_std²)
               d_t = between(x̃_{t-1}, x̃_t) (paper 000 eq. 16)
    motion     same with d_t = [v dt, 0, ω dt] (DDMR, optional)   Σ = diag((σ_v dt)², σ_lat², (σ_ω dt)²)
    bearing-   e = [‖m − p‖ − r,  wrap(∠(m − p) − θ − b)]        BearingRangeFactor2D, Σ = NoiseSpec.obs_cov
    range                                                          (GTSAM orders it [bearing, range])
    GPS        e = p_t − z_gps (optional)                         Σ = gps_std² I

with ``Log`` the SE(2) logarithm (tangent ``[v_x, v_y, ω]``). The cost is GTSAM's ``graph.error``:
``½ Σ eᵀ Σ⁻¹ e``.

``model="paper"`` minimises the ICM-SLAM Gibbs energy of paper 000, eqs. (3)-(5) with (16), with the
correspondences held fixed and ``x_0`` fixed at the known start pose (§3)::

    E = Σ_t ‖g(x_{t-1}, u_{t-1}) − x_t‖²_R + Σ_t ‖τ(θ_{t-1})(x_t − x_{t-1}) − d_t‖²_S
        + Σ_{t,i} ‖h⁻¹(x_t, z_{t,i}) − m_{c_{t,i}}‖²_Q ,      ‖a‖²_W = aᵀ W a

(residuals from :mod:`slamcli.models.potentials`; a zero weight matrix drops its potential). See
:func:`optimize_paper_energy` — the entry point the ICM solver uses to compare its final energy with the
optimum of the same energy.

The state is optimised in world coordinates ``[x, y, θ]`` (additive update, θ wrapped) with Jacobians in
the same coordinates, so the Laplace marginals (``EVALUATION-METHOD.md`` §A2) are directly world-frame —
GTSAM's body-frame Pose2 marginals equal ``J Σ_b Jᵀ`` with ``J = blkdiag(R(θ), 1)`` of ours. The optimiser
is :mod:`slamcli.solvers.nls` (sparse GN / LM, optional Huber kernel on the observation factors).
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
