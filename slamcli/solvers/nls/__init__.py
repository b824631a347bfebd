"""A small sparse nonlinear least-squares engine (Gauss-Newton / Levenberg-Marquardt) for factor graphs.

The problem is a set of :class:`FactorBlock` s. A block holds ``F`` factors of one type; each factor has a
residual of size ``k`` and touches ``n`` columns of the flat state vector ``x (D,)``. A block evaluates all
of its factors at once (vectorised: ``r (F, k)``, ``J (F, k, n)``), and is whitened by a square-root
information ``L`` with ``LᵀL = Λ`` (``Λ = Σ⁻¹`` for a Gaussian noise model)::

    cost(x) = Σ_blocks Σ_f ρ(‖L r_f(x)‖)          ρ(s) = ½ s²  (or Huber, see below)

which is exactly GTSAM's ``NonlinearFactorGraph.error`` for Gaussian (and robust) noise models.

Normal equations (Gauss-Newton approximation of the Hessian; IRLS weights ``w_f`` for robust kernels)::

    H = Σ_f w_f J̃_fᵀ J̃_f ,   g = Σ_f w_f J̃_fᵀ r̃_f ,   J̃ = L J,  r̃ = L r
    (H + λ D) h = −g                                      (GN: λ = 0; LM: D = diag(H) or I)

``H``'s lower triangle is assembled in CSC order, its structure (the scatter position of every pair of a
factor's columns) computed once per problem; every iteration is one vectorised evaluation per block, the pair
products into buffers kept across iterations and one ``np.bincount`` scatter — no Python loop over factors
(:class:`Assembler`; the full symmetric matrix by a precomputed gather). LM's trial steps evaluate residuals
only (``FactorBlock.residual``). Linear systems (:func:`make_linear_solver`): CHOLMOD's supernodal
``LLᵀ`` (:mod:`~slamcli.solvers.nls.cholmod`) with its fill-reducing ordering
and symbolic analysis done once per problem and the numeric factorisation refilled in place; or SciPy's SuperLU in symmetric mode with the
minimum-degree ordering of the first factorisation reused; or the chain solver (:class:`_ChainSolver`,
banded Cholesky + dense border Schur complement). ``H`` is positive semi-definite in exact arithmetic, but
not always numerically: a landmark that sits (almost) on a pose has a bearing Jacobian ``∝ 1/r`` and puts
entries of 1e24 next to entries of 1e4 into ``H`` (seen on MRCLAM robot 5 with its misread barcodes), and
Cholesky then meets a non-positive pivot: the system then goes to SuperLU, LM damps that trial with
``D = diag(H)``, and Gauss-Newton falls back to a damped step whenever the undamped system cannot be
solved or its solution is not a descent direction (each noted in ``NlsResult.notes``).

Iterations are counted as GTSAM counts them: one iteration linearises once and ends with one accepted step;
the LM steps rejected on the way (λ raised, system solved again) belong to the same iteration. So
``iterations == len(cost_trace) − 1`` and ``NlsParams.max_iterations`` bounds the accepted steps.

LM follows GTSAM's ``LevenbergMarquardtOptimizer`` (defaults of GTSAM 4.3): ``D = I``, ``λ₀ = 1e-5``;
gain ratio (GTSAM's "model fidelity") ``ϱ = (F(x) − F(x ⊞ h)) / (L(0) − L(h))`` with
``L(0) − L(h) = −gᵀh − ½hᵀHh = ½ hᵀ(λ D h − g)``; a trial is accepted iff ``ϱ > 1e-3``; then ``λ ← λ/10``,
else ``λ ← 10 λ``; when λ would exceed 1e5 the optimiser gives up as converged. Marquardt's
``D = diag(H)`` and Nielsen's schedule (Madsen, Nielsen & Tingleff, *Methods for non-linear least squares
problems*, 2004, §3.2: ``λ ← λ · max(1/3, 1 − (2ϱ − 1)³)``, ``λ ← λν, ν ← 2ν``; Ceres's strategy) are
options. They were the former default and stalled on long real chains (Victoria Park): the
diagonal of a pose block is the chain's own stiffness there, so ``λ·diag(H)`` pins every pose and the soft
modes that bend the whole chain stay out of reach unless λ ≪ 1e-6. Powell's dogleg (``method="dogleg"``)
is GTSAM's ``DoglegOptimizer`` (:func:`_dogleg_iteration`). With ``NlsProblem.se2_poses`` the SE(2) poses
are stepped in GTSAM's Pose2 chart, ``x ⊕ Exp(ξ)`` (``NlsParams.pose_chart``).

Huber kernel (IRLS, per factor, on the whitened norm ``s = ‖r̃_f‖``, as GTSAM's ``mEstimator.Huber``)::

    ρ(s) = ½ s²           if s ≤ k          w(s) = 1
           k s − ½ k²     otherwise                k / s

Cauchy and Geman-McClure (GTSAM's ``mEstimator.Cauchy`` / ``GemanMcClure``) are in :func:`robust_kernel`.

Marginal covariances (Laplace approximation at the optimum, see ``EVALUATION-METHOD.md`` §A2) are blocks of
``H⁻¹``: for a pose chain + landmark border by :func:`marginals_chain_border` (banded Cholesky, Schur
complement, column batches — never a dense poses × landmarks block), otherwise by solving ``H X = E`` only
for the unit columns ``E`` of the requested variables, in batches, with one sparse factorisation
(:func:`marginal_covariances`) — never a dense inverse.
"""

from slamcli.solvers.nls.kernels import (  # noqa: F401
    kernel_cost,
    robust_kernel,
    whiten,
)
from slamcli.solvers.nls.linear import (  # noqa: F401
    FACTOR_NAMES,
    Assembler,
    ChainSolver,
    SuperLUFactor,
    cholmod_available,
    cholmod_spd_factor,
    factorize_lower,
    factorize_symmetric,
    make_linear_solver,
    solve_spd,
)
from slamcli.solvers.nls.marginals import (  # noqa: F401
    NotPositiveDefiniteError,
    block_marginals,
    check_covariance_blocks,
    factorize_information,
    is_block_tridiagonal,
    marginal_covariances,
    marginals_chain_border,
    result_marginals,
)
from slamcli.solvers.nls.optimize import (  # noqa: F401
    evaluate_cost,
    jacobian_matrix,
    residual_vector,
    solve,
    whitened_system,
)
from slamcli.solvers.nls.problem import (  # noqa: F401
    EvaluateFn,
    FactorBlock,
    NlsParams,
    NlsProblem,
    NlsResult,
    pose_offsets,
    retract,
)
