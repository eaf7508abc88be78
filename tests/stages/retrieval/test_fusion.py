"""Fusion of dissimilarities and manifold ranking (Zhou et al. 2004)."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.distance import cdist

from topomatch.stages.retrieval.fusion import Fusion, fuse, fused_matrix, fused_query, manifold_ranking, median_scale


def two_moons(n=60, seed=0):
    """Two interleaved half circles: the nearest points of the other moon are closer than the far end of one's own."""
    t = np.linspace(0, np.pi, n)
    a = np.column_stack([np.cos(t), np.sin(t)])
    b = np.column_stack([1 - np.cos(t), 0.5 - np.sin(t)])
    X = np.vstack([a, b]) + 0.01 * np.random.default_rng(seed).standard_normal((2 * n, 2))
    return X, np.repeat([0, 1], n)


def first_tier(D, y):
    hits = []
    for i in range(len(D)):
        order = [j for j in np.argsort(D[i], kind="stable") if j != i][: (y == y[i]).sum() - 1]
        hits.append(np.mean(y[order] == y[i]))
    return float(np.mean(hits))


def test_manifold_ranking_follows_the_data_manifold():
    X, y = two_moons()
    D = cdist(X, X)
    assert first_tier(D, y) < 0.8  # Euclidean ranking mixes the moons
    R = manifold_ranking(D, k=5, alpha=0.99)
    assert first_tier(R, y) > 0.98
    np.testing.assert_allclose(R, R.T)
    assert R.min() >= 0 and R.max() <= 1


def test_median_scale_and_equal_weights():
    A = np.array([[0, 1, 3], [1, 0, 2], [3, 2, 0]], float)
    assert median_scale(A) == 2.0
    np.testing.assert_allclose(fuse([A, 10 * A], [2.0, 20.0]), A)
    assert median_scale(np.zeros((3, 3))) == 1.0


def test_fused_query_of_a_duplicate_ranks_it_first():
    X, _ = two_moons(30)
    parts = [cdist(X, X), cdist(X, X, "cityblock")]
    q = X[7] + 1e-9
    rows = [cdist(q[None], X)[0], cdist(q[None], X, "cityblock")[0]]
    for k in (None, 5):
        d = fused_query(rows, parts, Fusion(("a", "b"), k, 0.9))
        assert np.argmin(d) == 7 and d.shape == (60,)
    # without re-ranking the fused row is the scaled sum
    d = fused_query(rows, parts, Fusion(("a", "b"), None, 0.9))
    np.testing.assert_allclose(d, rows[0] / median_scale(parts[0]) + rows[1] / median_scale(parts[1]))
    assert fused_matrix(parts, Fusion(("a", "b"), None, 0.9)) == pytest.approx(fuse(parts, [median_scale(p) for p in parts]))


def test_one_row_ranks_as_the_full_ranking():
    from topomatch.stages.retrieval.fusion import manifold_ranking_row

    X, _ = two_moons(40, seed=2)
    D = cdist(X, X)
    R = manifold_ranking(D, k=6, alpha=0.9)
    for i in (0, 17, 79):
        r = manifold_ranking_row(D, i, k=6, alpha=0.9)
        np.testing.assert_array_equal(np.argsort(r, kind="stable")[:20], np.argsort(R[i], kind="stable")[:20])
        assert r[i] == pytest.approx(0.0)
