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
