"""Batch graph SLAM (``--method graph``): all poses ``x_0..x_T`` and landmarks ``m_0..m_{L-1}`` at once.

Factors (``model="gtsam"``, default) are GTSAM's, so the optimum is checked against
``gtsam.LevenbergMarquardtOptimizer`` (``tests/solvers/test_graph_gtsam.py``)::

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

from slamcli.solvers.lazy import lazy_exports

_EXPORTS = {
    "GraphProblem": "slamcli.solvers.graph.build",
    "build_gtsam_problem": "slamcli.solvers.graph.build",
    "landmark_joint_covariance": "slamcli.solvers.graph.build",
    "laplace_marginals": "slamcli.solvers.graph.build",
    "located": "slamcli.solvers.graph.build",
    "pack_state": "slamcli.solvers.graph.build",
    "Certificate": "slamcli.solvers.graph.certify",
    "certify_pose_graph": "slamcli.solvers.graph.certify",
    "bearing_range_error": "slamcli.solvers.graph.factors",
    "between_error": "slamcli.solvers.graph.factors",
    "group_returns": "slamcli.solvers.graph.factors",
    "landmark_offset_error": "slamcli.solvers.graph.factors",
    "log_jacobian": "slamcli.solvers.graph.factors",
    "prior_error": "slamcli.solvers.graph.factors",
    "robot_range_bearing_error": "slamcli.solvers.graph.factors",
    "sqrt_info_batch": "slamcli.solvers.graph.factors",
    "sqrt_info_from_cov": "slamcli.solvers.graph.factors",
    "sqrt_of_weight": "slamcli.solvers.graph.factors",
    "chordal_poses": "slamcli.solvers.graph.init",
    "incremental_initial_poses": "slamcli.solvers.graph.init",
    "initial_poses": "slamcli.solvers.graph.init",
    "nearest_neighbour_association": "slamcli.solvers.graph.init",
    "odometry_initial_poses": "slamcli.solvers.graph.init",
    "pose_graph_edges": "slamcli.solvers.graph.init",
    "robust_initial_poses": "slamcli.solvers.graph.init",
    "spanning_tree_poses": "slamcli.solvers.graph.init",
    "merge_candidates": "slamcli.solvers.graph.merge",
    "build_paper_problem": "slamcli.solvers.graph.paper",
    "default_paper_weights": "slamcli.solvers.graph.paper",
    "optimize_paper_energy": "slamcli.solvers.graph.paper",
    "paper_energy": "slamcli.solvers.graph.paper",
    "GraphParams": "slamcli.solvers.graph.params",
    "resolve_robust": "slamcli.solvers.graph.params",
    "GraphSlam": "slamcli.solvers.graph.solver",
    "chi2_outlier_counts": "slamcli.solvers.graph.solver",
    "NOISE_GROUPS": "slamcli.solvers.graph.variance",
    "NoiseCalibration": "slamcli.solvers.graph.variance",
    "calibrate_noise": "slamcli.solvers.graph.variance",
    "noise_row_groups": "slamcli.solvers.graph.variance",
    "noise_sigmas": "slamcli.solvers.graph.variance",
    "noise_with_sigmas": "slamcli.solvers.graph.variance",
}
__getattr__, __dir__ = lazy_exports(__name__, _EXPORTS)
