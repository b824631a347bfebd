"""The chordal start's connectivity check (``component_roots``) against scipy's ``csgraph``."""

import numpy as np
import pytest
import scipy.sparse as sp
from scipy.sparse import csgraph

from slamcli.solvers.graph.init import chordal_poses, component_roots


def _reference_roots(n, i, j):
    """Smallest vertex per component from scipy's connected_components (independent implementation)."""
    _, lab = csgraph.connected_components(sp.coo_matrix((np.ones(len(i)), (i, j)), shape=(n, n)), directed=False)
    first = np.full(lab.max() + 1, n)
    np.minimum.at(first, lab, np.arange(n))
    return first[lab]


@pytest.mark.parametrize("seed", range(12))
def test_component_roots_equal_csgraph_on_random_graphs(seed):
    rng = np.random.default_rng(seed)
    n = int(rng.integers(1, 300))
    e = int(rng.integers(0, 2 * n))
    i, j = rng.integers(0, n, e), rng.integers(0, n, e)
    np.testing.assert_array_equal(component_roots(n, i, j), _reference_roots(n, i, j))


def test_component_roots_long_reversed_chain_and_two_parts():
    n = 1000  # a chain listed from its far end, plus a second chain 600..999 not joined to the first
    i = np.r_[np.arange(598, -1, -1), np.arange(600, 999)]
    j = i + 1
    want = _reference_roots(n, i, j)
    np.testing.assert_array_equal(component_roots(n, i, j), want)
    assert set(np.unique(want)) == {0, 600}


def test_chordal_start_names_the_unconnected_pose():
    ij = np.array([[0, 1], [1, 2], [3, 4]])
    xyt = np.tile([1.0, 0.0, 0.0], (3, 1))
    info = np.tile(np.eye(3), (3, 1, 1))
    with pytest.raises(ValueError, match="pose 3 is not connected to pose 0"):
        chordal_poses(5, ij, xyt, info, np.zeros(3))
