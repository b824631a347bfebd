"""A small sparse nonlinear least-squares engine (Gauss-Newton / Levenberg-Marquardt) for factor graphs.

The problem is a set of :class:`FactorBlock` s of ``F`` factors each (residual ``r (F, k)``, Jacobian
``J (F, k, n)`` over ``n`` columns of the state ``x (D,)``), whitened by ``L`` with ``LᵀL = Λ``::

    cost(x) = Σ_blocks Σ_f ρ(‖L r_f(x)‖)          ρ(s) = ½ s²  (or a robust kernel, :func:`robust_kernel`)
    H = Σ_f w_f J̃_fᵀ J̃_f ,   g = Σ_f w_f J̃_fᵀ r̃_f ,   (H + λ D) h = −g     (GN: λ = 0)

which is GTSAM's ``NonlinearFactorGraph.error`` (Gaussian and robust noise models, Huber / Cauchy /
Geman-McClure by IRLS weights ``w_f``). ``H`` is assembled by :class:`Assembler` (structure once per problem,
one vectorised pass per block, no Python loop over factors) and solved by :func:`make_linear_solver`: CHOLMOD
(:mod:`~slamcli.solvers.nls.cholmod`), SciPy's SuperLU, or the chain solver (banded Cholesky + dense border).
A numerically indefinite ``H`` (a landmark almost on a pose) goes to SuperLU, LM damps that trial and
Gauss-Newton falls back to a damped step; each is noted in ``NlsResult.notes``.

Iterations are counted as GTSAM counts them (one linearisation, one accepted step; rejected LM trials belong
to it): ``iterations == len(cost_trace) − 1``. LM follows GTSAM 4.3's ``LevenbergMarquardtOptimizer``:
``D = I``, ``λ₀ = 1e-5``, accept iff ``ϱ = (F(x) − F(x ⊞ h)) / (½ hᵀ(λ D h − g)) > 1e-3``, then ``λ/10``, else
``10 λ``, converged when λ would exceed 1e5. Marquardt's ``D = diag(H)`` with Nielsen's schedule is an option
(it stalls on long real chains: ``λ·diag(H)`` pins every pose); ``method="dogleg"`` is GTSAM's
``DoglegOptimizer``. ``NlsProblem.se2_poses`` steps poses in GTSAM's Pose2 chart, ``x ⊕ Exp(ξ)``.

Marginal covariances (Laplace approximation at the optimum) are blocks of ``H⁻¹``, never a dense inverse:
:func:`marginals_chain_border` for a pose chain + landmark border, else :func:`marginal_covariances` (one
sparse factorisation, unit columns of the requested variables in batches).
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
    Workspace,
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
