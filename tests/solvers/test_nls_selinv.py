"""Selected inverse (Takahashi recurrence on the sparse factor, ``slamcli.solvers.nls.selinv``) against dense
``inv(H)``, against the SciPy marginals path it replaced, and on held-fixed / uncoupled variables."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse as sp
from conftest import DATA

from slamcli.solvers import graph, nls
from slamcli.solvers.nls import marginals, selinv

pytestmark = pytest.mark.skipif(not nls.cholmod_available(), reason="needs CHOLMOD (cvxopt)")


def _random_spd(n: int, density: float, seed: int) -> sp.csc_matrix:
    """Sparse SPD ``A Aᵀ + δ I`` with a random pattern (fill-in under any ordering)."""
    rng = np.random.default_rng(seed)
    A = sp.random(n, n, density=density, random_state=rng, data_rvs=rng.standard_normal)
    return sp.csc_matrix(A @ A.T + 0.1 * sp.eye(n))


def _block_spd(n_blocks: int, k: int, seed: int) -> sp.csc_matrix:
    """Block-sparse SPD (``k × k`` variables, a chain plus random long-range couplings) — SLAM-like."""
    rng = np.random.default_rng(seed)
    n = n_blocks * k
    pairs = [(i, i + 1) for i in range(n_blocks - 1)]
    pairs += [tuple(sorted(rng.choice(n_blocks, 2, replace=False))) for _ in range(n_blocks)]
    J = []
    for a, b in pairs:  # one "factor" per pair: a k-row residual on the two blocks
        Jf = np.zeros((k, n))
        Jf[:, a * k : (a + 1) * k] = rng.standard_normal((k, k))
        Jf[:, b * k : (b + 1) * k] = rng.standard_normal((k, k))
        J.append(sp.csr_matrix(Jf))
    J.append(sp.csr_matrix(np.eye(k, n)))  # prior on block 0
    Jm = sp.vstack(J)
    return sp.csc_matrix(Jm.T @ Jm)


@pytest.mark.parametrize(
    "H",
    [_random_spd(40, 0.06, 0), _random_spd(120, 0.02, 1), _random_spd(200, 0.01, 2), _block_spd(60, 3, 3),
     _block_spd(90, 2, 4)],
    ids=["n40", "n120", "n200", "blocks3", "blocks2"],
)
@pytest.mark.slow
def test_selected_inverse_equals_dense_inverse_on_the_pattern(H):
    Hinv = np.linalg.inv(H.toarray())
    scale = np.abs(Hinv).max()
    S = selinv.SelectedInverse.from_matrix(H)
    F = selinv.factor_ldl(H)
    assert np.array_equal(S.perm, F.perm)
    # H⁻¹ on the whole pattern of the factor L (read off CHOLMOD's L and mapped to the original order, not
    # through the supernodes' own row sets): every entry the Takahashi recurrence defines
    Lc = sp.coo_matrix(F.L)
    got = S.entries(F.perm[Lc.row], F.perm[Lc.col])
    assert np.abs(got - Hinv[F.perm[Lc.row], F.perm[Lc.col]]).max() <= 1e-10 * scale
    # and the original-order lookup returns H⁻¹ on the whole pattern of H
    C = sp.coo_matrix(H)
    got = S.entries(C.row, C.col)
    assert np.abs(got - Hinv[C.row, C.col]).max() <= 1e-10 * scale
    # the factorisation behind it: P H Pᵀ = L D Lᵀ
    LD = (F.L @ sp.diags(F.d) @ F.L.T).toarray()
    assert np.abs(LD - H.toarray()[np.ix_(F.perm, F.perm)]).max() <= 1e-12 * np.abs(H).max()


@pytest.mark.parametrize("overhead, ratio", [(0.0, 1.01), (1e18, 1.25), (4e4, 2.0)])
@pytest.mark.slow
def test_any_bucketing_gives_the_dense_inverse(monkeypatch, overhead, ratio):
    """Supernodes of one level batched one size class per bucket (no merging), all in one bucket padded to
    the largest (merge always) and the default cost model: every stored entry equals the dense inverse's."""
    monkeypatch.setattr(selinv, "BUCKET_OVERHEAD", overhead)
    monkeypatch.setattr(selinv, "CLASS_RATIO", ratio)
    H = _block_spd(150, 3, 5)
    S = selinv.SelectedInverse.from_matrix(H)
    Hinv = np.linalg.inv(H.toarray())
    C = sp.coo_matrix(H)
    assert np.abs(S.entries(C.row, C.col) - Hinv[C.row, C.col]).max() <= 1e-10 * np.abs(Hinv).max()
    idx = np.arange(450).reshape(150, 3)
    (blk,) = selinv.inverse_blocks(H, [idx])
    ref = Hinv.reshape(150, 3, 150, 3)[np.arange(150), :, np.arange(150), :]
    assert np.abs(blk - ref).max() <= 1e-10 * np.abs(Hinv).max()


@pytest.mark.parametrize("max_width, max_zeros", [(0, 0.5), (6, 0.0), (12, 0.5), (48, 1.0)])
@pytest.mark.slow
def test_any_relaxed_supernodes_give_the_dense_inverse(monkeypatch, max_width, max_zeros):
    """Fundamental supernodes only (width 0), merges without any explicit zero, the default and merges
    along whole chains (widths ≤ 48, any zeros): the selected inverse equals the dense inverse on the
    pattern and in the marginal blocks, on a random sparse SPD matrix and a SLAM-like block matrix."""
    monkeypatch.setattr(selinv, "AMALGAMATE_MAX_WIDTH", max_width)
    monkeypatch.setattr(selinv, "AMALGAMATE_MAX_ZEROS", max_zeros)
    for H, k in [(_random_spd(200, 0.01, 2), 1), (_block_spd(150, 3, 5), 3)]:
        S = selinv.SelectedInverse.from_matrix(H)
        Hinv = np.linalg.inv(H.toarray())
        C = sp.coo_matrix(H)
        assert np.abs(S.entries(C.row, C.col) - Hinv[C.row, C.col]).max() <= 1e-10 * np.abs(Hinv).max()
        B = H.shape[0] // k
        (blk,) = selinv.inverse_blocks(H, [np.arange(B * k).reshape(B, k)])
        ref = Hinv.reshape(B, k, B, k)[np.arange(B), :, np.arange(B), :]
        assert np.abs(blk - ref).max() <= 1e-10 * np.abs(Hinv).max()
    if max_width == 48:  # the chains did merge: fewer supernodes than the fundamental ones
        monkeypatch.setattr(selinv, "AMALGAMATE_MAX_WIDTH", 0)
        assert len(S.sn_first) < len(selinv.SelectedInverse.from_matrix(H).sn_first)


@pytest.mark.parametrize("width, trtri_from", [(1, 128), (3, 128), (12, 128), (12, 5), (30, 128)])
def test_unit_lower_inverse_equals_numpy_inverse(monkeypatch, width, trtri_from):
    """Batched forward substitution and the blocked inverse (``trtri_from`` ≤ width, or 7 blocks of 30) against
    ``np.linalg.inv`` on random unit lower triangular blocks."""
    monkeypatch.setattr(selinv, "TRTRI_MIN_WIDTH", trtri_from)
    rng = np.random.default_rng(width)
    L = np.tril(rng.standard_normal((7, width, width)), -1) + np.eye(width)
    ref = np.linalg.inv(L)
    assert np.abs(selinv._unit_lower_inverse(L) - ref).max() <= 1e-12 * np.abs(ref).max()


@pytest.mark.parametrize("n_blocks, width", [(1, 33), (3, 40), (1, 90), (2, 288)])
def test_blocked_unit_lower_inverse_equals_extended_precision_substitution(n_blocks, width):
    """The recursive block inverse (one split at 33 and 40, two at 90, four at 288) against forward
    substitution in extended precision (``np.longdouble``), on unit lower triangular blocks with entries
    N(0, 1/w) (conditioned as factors of SPD matrices are; N(0, 1) entries make 40 × 40 inverses of 1e6 whose
    float64 rounding alone exceeds 1e-12 of them)."""
    rng = np.random.default_rng(width)
    L = np.tril(rng.standard_normal((n_blocks, width, width)) / np.sqrt(width), -1) + np.eye(width)
    Le = L.astype(np.longdouble)
    ref = np.zeros_like(Le)
    ref[:, np.arange(width), np.arange(width)] = 1
    for i in range(1, width):
        ref[:, i, :i] = -np.einsum("bk,bkj->bj", Le[:, i, :i], ref[:, :i, :i])
    got = selinv._unit_lower_inverse_blocked(L)
    assert np.abs(got - ref).max() <= 1e-12 * np.abs(ref).max()
    assert not np.triu(got, 1).any()


def test_inverse_blocks_adds_the_pattern_of_a_block_off_the_factor():
    """A held-fixed variable's 2×2 block is off the pattern of ``H``'s factor: :func:`selinv.inverse_blocks`
    factors again with the blocks' pattern added and returns the dense inverse's blocks."""
    H = sp.csc_matrix(sp.block_diag([_block_spd(10, 2, 5), sp.diags([2.0, 4.0])]))
    idx = np.array([[20, 21], [0, 1], [4, 5]])
    (got,) = selinv.inverse_blocks(H, [idx])
    Hinv = np.linalg.inv(H.toarray())
    np.testing.assert_allclose(got, Hinv[idx[:, :, None], idx[:, None, :]], rtol=1e-12, atol=1e-15)


def test_pose_graph_excerpt_marginals_reuse_the_lm_analysis(monkeypatch):
    """``graph`` on the intel excerpt (300 poses, loop closures): its marginals — from the LM's lower
    triangle at the estimate in the body chart, factored with the LM's CHOLMOD analysis, the pose blocks
    rotated to the world chart afterwards — equal the blocks of the dense inverse of the full world-chart
    ``H``, and the marginals of that full ``H`` with a fresh analysis give the same blocks."""

    from slamcli.datasets.g2o import import_graph
    from slamcli.solvers.graph import solver

    inp = import_graph(DATA / "intel_excerpt.g2o").inputs
    seen = {}
    inner = solver.laplace_marginals

    def grab(gp, lm_res):
        seen.update(gp=gp, lm_res=lm_res)
        return inner(gp, lm_res)

    monkeypatch.setattr(solver, "laplace_marginals", grab)
    res = graph.GraphSlam(graph.GraphParams()).solve(inp, rng=np.random.default_rng(0))
    gp, lm_res = seen["gp"], seen["lm_res"]
    assert lm_res.information_chart == "body"
    assert marginals._lower_at_estimate(lm_res, [gp.pose_cols()]) is not None  # the lower-triangle path ran
    H = lm_res.information  # full, world chart: the reference
    ip = gp.pose_cols()
    Hinv = np.linalg.inv(H.toarray())
    ref = Hinv[ip[:, :, None], ip[:, None, :]]
    assert res.pose_cov.shape == ref.shape
    assert np.abs(res.pose_cov - ref).max() <= 1e-10 * np.abs(ref).max()
    fresh, _ = graph.laplace_marginals(gp, H)
    assert np.abs(fresh - ref).max() <= 1e-10 * np.abs(ref).max()


def test_recurrence_on_a_hand_made_factor_without_cholmod_ordering():
    """The recurrence alone, on an ``L D Lᵀ`` from a dense Cholesky in natural order (banded + arrow
    pattern, chordal): independent of CHOLMOD's ordering and of :func:`selinv.factor_ldl`."""
    rng = np.random.default_rng(7)
    n, bw = 30, 2
    A = np.zeros((n, n))
    for i in range(n):
        for j in range(max(0, i - bw), i + 1):
            A[i, j] = A[j, i] = rng.standard_normal()
    A[-1, :] = A[:, -1] = rng.standard_normal(n)  # arrow: the last variable couples to all
    A = A @ A.T + n * np.eye(n)  # pattern grows to band 4 + arrow; SPD
    C = np.linalg.cholesky(A)
    mask = np.abs(C) > 0  # the (numerical = symbolic here) pattern of the factor
    Lu = np.where(mask, C / np.diag(C)[None, :], 0.0)
    F = selinv.LdlFactor(sp.csc_matrix(Lu), np.diag(C) ** 2, np.arange(n))
    S = selinv.SelectedInverse(F)
    Ainv = np.linalg.inv(A)
    r, c = np.nonzero(np.tril(mask))
    assert np.abs(S.entries(r, c) - Ainv[r, c]).max() <= 1e-12 * np.abs(Ainv).max()
    assert len(S.sn_first) < n  # the band and the arrow merge columns into supernodes


def test_uncoupled_blocks_need_their_pattern_and_get_it():
    """Variables no factor couples (held fixed: identity rows) — their 2×2 block is off the pattern of
    ``H``; ``from_matrix(H, index_blocks)`` adds it as explicit zeros so the lookup is exact."""
    H = sp.csc_matrix(sp.block_diag([_block_spd(10, 2, 5), sp.diags([2.0, 4.0])]))
    idx = np.array([[20, 21], [0, 1]])
    with pytest.raises(ValueError, match="not on the pattern"):
        selinv.SelectedInverse.from_matrix(H).blocks(idx)
    got = selinv.SelectedInverse.from_matrix(H, [idx]).blocks(idx)
    Hinv = np.linalg.inv(H.toarray())
    np.testing.assert_allclose(got[0], [[0.5, 0.0], [0.0, 0.25]], rtol=0, atol=1e-15)
    np.testing.assert_allclose(got[1], Hinv[:2, :2], rtol=1e-12)


def test_not_positive_definite_names_a_column():
    H = sp.csc_matrix(np.array([[2.0, 1.0, 0.0], [1.0, 2.0, 3.0], [0.0, 3.0, 1.0]]))  # eigenvalue < 0
    with pytest.raises(selinv.NotPositiveDefiniteError) as info:
        selinv.SelectedInverse.from_matrix(H)
    assert 0 <= info.value.column < 3
    assert isinstance(info.value, np.linalg.LinAlgError)  # graph reports it as "no covariances"


def _graph_problem(T=60, n_landmarks=8, seed=2):
    from conftest import tiny_dataset

    from slamcli.solvers import frontend

    ds = tiny_dataset(T=T, n_landmarks=n_landmarks, seed=seed, report_ids=True, clutter_every=0)
    inp = ds.inputs
    assoc = frontend.associate_reported(inp.observations)
    p0 = graph.odometry_initial_poses(inp)
    lm0 = frontend.landmarks_from_observations(p0, inp.observations, assoc, int(assoc.max()) + 1)
    gp = graph.build_gtsam_problem(inp, assoc, p0, lm0)
    return ds, gp, nls.solve(gp.problem, gp.x0)


def test_graph_marginals_selected_inverse_equals_dense_inverse_and_the_scipy_path(monkeypatch):
    ds, gp, opt = _graph_problem()
    H = opt.information
    Hinv = np.linalg.inv(H.toarray())
    ip, il = gp.pose_cols(), gp.landmark_cols()
    ref_p, ref_l = Hinv[ip[:, :, None], ip[:, None, :]], Hinv[il[:, :, None], il[:, None, :]]
    pose_cov, lm_cov = graph.laplace_marginals(gp, H)  # CHOLMOD present: the selected inverse
    assert np.abs(pose_cov - ref_p).max() <= 1e-10 * np.abs(ref_p).max()
    assert np.abs(lm_cov - ref_l).max() <= 1e-10 * np.abs(ref_l).max()
    # the previous (SciPy: banded chain + border Schur complement) path gives the same blocks
    monkeypatch.setattr(marginals, "cholmod_available", lambda: False)
    old_p, old_l = graph.laplace_marginals(gp, H)
    assert np.abs(pose_cov - old_p).max() <= 1e-9 * np.abs(old_p).max()
    assert np.abs(lm_cov - old_l).max() <= 1e-9 * np.abs(old_l).max()


def test_graph_solver_result_marginals_same_with_and_without_cholmod(monkeypatch):
    """End to end: ``graph``'s result (default covariance=true) via the selected inverse equals the result
    via the SciPy fallback (the same optimum, so the same H) to 1e-9."""
    from conftest import tiny_dataset

    ds = tiny_dataset(T=80, n_landmarks=10, seed=11, report_ids=True, clutter_every=0)
    params = graph.GraphParams(association="reported")
    new = graph.GraphSlam(params).solve(ds.inputs, rng=np.random.default_rng(0))
    monkeypatch.setattr(marginals, "cholmod_available", lambda: False)
    old = graph.GraphSlam(params).solve(ds.inputs, rng=np.random.default_rng(0))
    assert new.pose_cov is not None and new.landmark_cov is not None
    assert new.pose_cov.shape == (ds.inputs.n_poses, 3, 3) and new.landmark_cov.shape[1:] == (2, 2)
    assert np.abs(new.poses_xyt - old.poses_xyt).max() < 1e-12
    assert np.abs(new.pose_cov - old.pose_cov).max() <= 1e-9 * np.abs(old.pose_cov).max()
    assert np.abs(new.landmark_cov - old.landmark_cov).max() <= 1e-9 * np.abs(old.landmark_cov).max()


def test_result_marginals_from_the_body_chart_lower_triangle_equal_the_world_chart_dense_inverse():
    """``result_marginals`` (the LM's lower triangle at the estimate, body chart, pose blocks rotated after
    the selected inverse) against the dense inverse of ``H`` relinearised in the world chart — a Jacobian
    of its own, not a rotation of the body one — on a landmark graph, ~1e-10 relative."""
    ds, gp, opt = _graph_problem()
    ip, il = gp.pose_cols(), gp.landmark_cols()
    assert opt.information_chart == "body" and marginals._lower_at_estimate(opt, [ip, il]) is not None
    asm = opt.workspace[0]
    Hw = asm.matrix(asm.linearize(opt.x, nls.NlsParams(pose_chart="world"))[1]).toarray()
    Hinv = np.linalg.inv(Hw)
    ref_p, ref_l = Hinv[ip[:, :, None], ip[:, None, :]], Hinv[il[:, :, None], il[:, None, :]]
    pose_cov, lm_cov = nls.result_marginals(opt, (ip, il))
    assert np.abs(pose_cov - ref_p).max() <= 1e-10 * np.abs(ref_p).max()
    assert np.abs(lm_cov - ref_l).max() <= 1e-10 * np.abs(ref_l).max()
    # a set mixing pose and landmark columns cannot be rotated block by block: the full H is used, same values
    mixed = np.concatenate([ip[:4, :2], il[:4]], axis=1)
    assert marginals._lower_at_estimate(opt, [mixed]) is None
    (blk,) = nls.result_marginals(opt, (mixed,))
    ref = Hinv[mixed[:, :, None], mixed[:, None, :]]
    assert np.abs(blk - ref).max() <= 1e-10 * np.abs(ref).max()


def test_result_marginals_in_the_world_chart_need_no_rotation():
    ds, gp, _ = _graph_problem()
    opt = nls.solve(gp.problem, gp.x0, nls.NlsParams(pose_chart="world"))
    assert opt.information_chart == "world"
    ip = gp.pose_cols()
    Hinv = np.linalg.inv(opt.information.toarray())
    ref = Hinv[ip[:, :, None], ip[:, None, :]]
    (pose_cov,) = nls.result_marginals(opt, (ip,))
    assert np.abs(pose_cov - ref).max() <= 1e-10 * np.abs(ref).max()


def test_depths_by_pointer_jumping_equal_a_walk_to_the_root():
    """``_depths`` (vectorised pointer jumping) against walking every node up to its root, on random forests
    whose parents come after their children (as in an elimination tree)."""
    rng = np.random.default_rng(3)
    for n in (1, 2, 17, 500):
        par = np.array([rng.integers(k + 1, n) if k < n - 1 and rng.random() < 0.95 else -1 for k in range(n)])
        ref = []
        for k in range(n):
            d, a = 0, par[k]
            while a >= 0:
                d, a = d + 1, par[a]
            ref.append(d)
        assert np.array_equal(selinv._depths(par), ref)


@pytest.mark.parametrize("max_width", [0, 12, 48])
def test_supernode_parents_follow_the_column_elimination_tree(monkeypatch, max_width):
    """``_Supernodes.par`` against the column elimination tree read off ``L`` column by column: a supernode's
    parent owns the first stored row below its last column (−1 when there is none), for fundamental, default
    and wide relaxed supernodes."""
    monkeypatch.setattr(selinv, "AMALGAMATE_MAX_WIDTH", max_width)
    for H in (_random_spd(200, 0.01, 2), _block_spd(150, 3, 5)):
        L = selinv.factor_ldl(H).L
        sn = selinv._Supernodes(L)
        ref = []
        for j0, w in zip(sn.first.tolist(), sn.width.tolist()):
            col = L.indices[L.indptr[j0 + w - 1] : L.indptr[j0 + w]]
            below = col[col > j0 + w - 1]
            ref.append(int(np.searchsorted(sn.first, below.min(), side="right")) - 1 if below.size else -1)
        assert np.array_equal(sn.par, ref)
        assert (sn.par == -1).sum() >= 1 and np.all((sn.par == -1) | (sn.par > np.arange(sn.par.size)))


def test_result_marginals_with_a_held_fixed_pose_use_the_full_world_chart_matrix():
    """A held-fixed pose column (identity row, not a rotated one): ``result_marginals`` does not rotate body
    blocks but uses ``res.information`` — equal to its dense inverse; the fixed pose's block is the identity."""
    import dataclasses

    ds, gp, _ = _graph_problem()
    prob = dataclasses.replace(gp.problem, fixed_cols=np.arange(3, dtype=np.int64))
    opt = nls.solve(prob, gp.x0)
    ip = gp.pose_cols()
    assert opt.information_chart == "body" and marginals._lower_at_estimate(opt, [ip]) is None
    Hinv = np.linalg.inv(opt.information.toarray())
    ref = Hinv[ip[:, :, None], ip[:, None, :]]
    (pose_cov,) = nls.result_marginals(opt, (ip,))
    assert np.abs(pose_cov - ref).max() <= 1e-10 * np.abs(ref).max()
    assert np.allclose(pose_cov[0], np.eye(3), rtol=0.0, atol=1e-12)
