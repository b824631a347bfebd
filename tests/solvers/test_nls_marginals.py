"""The one marginals path (``slamcli.solvers.nls.marginals.block_marginals``) against dense inverses, on all
three of its algorithms, and its one policy on a singular / indefinite H: refuse, naming the variable."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse as sp

from slamcli.solvers.nls import marginals as mg


def _chain_border(n=6, m=2, seed=0):
    """SPD H: a block-tridiagonal chain of n 3-blocks plus m 2-blocks of border coupled to every pose."""
    rng = np.random.default_rng(seed)
    D = 3 * n + 2 * m
    A = np.zeros((D, D))
    for i in range(n):
        J = rng.normal(size=(3, 6 if i < n - 1 else 3))
        cols = np.arange(3 * i, 3 * i + J.shape[1])
        A[np.ix_(cols, cols)] += J.T @ J
    for j in range(m):
        for i in range(n):
            J = rng.normal(size=(2, 5))
            cols = np.r_[3 * i : 3 * i + 3, 3 * n + 2 * j : 3 * n + 2 * j + 2]
            A[np.ix_(cols, cols)] += J.T @ J
    A += 0.1 * np.eye(D)
    return sp.csc_matrix(A), n, m


def _use_path(monkeypatch, path, n, m):
    """Force ``path`` (the selected inverse when CHOLMOD is there, else a fallback) and return the pose
    ``(n, 3)`` and landmark ``(m, 2)`` index blocks of :func:`_chain_border`'s H."""
    if path == "selinv" and not mg.cholmod_available():
        pytest.skip("CHOLMOD not installed")
    if path != "selinv":
        monkeypatch.setattr(mg, "cholmod_available", lambda: False)
    return np.arange(3 * n).reshape(n, 3), 3 * n + np.arange(2 * m).reshape(m, 2)


@pytest.mark.parametrize("path", ["selinv", "chain", "superlu"])
def test_blocks_equal_the_dense_inverse(monkeypatch, path):
    H, n, m = _chain_border()
    poses, lms = _use_path(monkeypatch, path, n, m)
    pc, lc = mg.block_marginals(H, (poses, lms), names=("pose", "landmark"), chain=n if path == "chain" else 0)
    C = np.linalg.inv(H.toarray())
    for i in range(n):
        np.testing.assert_allclose(pc[i], C[3 * i : 3 * i + 3, 3 * i : 3 * i + 3], rtol=1e-10, atol=1e-13)
    for j in range(m):
        s = 3 * n + 2 * j
        np.testing.assert_allclose(lc[j], C[s : s + 2, s : s + 2], rtol=1e-10, atol=1e-13)


@pytest.mark.parametrize("path", ["selinv", "fallback"])
def test_singular_information_is_refused_with_the_variable_named(monkeypatch, path):
    H, n, m = _chain_border()
    H = H.tolil()
    s = 3 * n + 2  # landmark 1, first column: no factor constrains it
    H[s, :] = 0.0
    H[:, s] = 0.0
    H = H.tocsc()
    poses, lms = _use_path(monkeypatch, path, n, m)

    def locate(c):
        return f"pose {c // 3}" if c < 3 * n else f"landmark {(c - 3 * n) // 2}"

    with pytest.raises(np.linalg.LinAlgError) as exc:
        mg.block_marginals(H, (poses, lms), names=("pose", "landmark"), chain=n, locate=locate)
    assert "landmark" in str(exc.value)


@pytest.mark.parametrize("k", [1, 2, 3, 4])
def test_positive_definiteness_test_of_the_blocks_agrees_with_eigenvalues(k):
    """The closed-form Sylvester test (k ≤ 3) and the Cholesky one (k > 3) behind ``check_covariance_blocks``
    against the sign of the smallest eigenvalue, block by block, on random symmetric (in)definite blocks."""
    rng = np.random.default_rng(k)
    X = rng.standard_normal((400, k, k))
    S = X + X.mT + rng.uniform(0.0, 3.0, (400, 1, 1)) * np.eye(k)
    low = np.linalg.eigvalsh(S)[:, 0]
    pd = low > 0.0
    assert 0 < pd.sum() < pd.size  # both kinds present
    got = np.array([mg._leading_minors_positive(S[i : i + 1]) for i in range(S.shape[0])])
    assert np.array_equal(got, pd)
    assert mg._leading_minors_positive(S[pd]) and not mg._leading_minors_positive(S)
    mg.check_covariance_blocks(S[pd], "pose")
    with pytest.raises(np.linalg.LinAlgError, match=f"pose {int(np.argmin(low))}:"):  # the most negative block
        mg.check_covariance_blocks(S, "pose")
