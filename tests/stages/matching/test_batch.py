"""The vectorised one-to-many matching equals the per-pair reference."""

from __future__ import annotations

import numpy as np
import pytest

from topomatch.stages.matching.batch import many_to_many, one_to_many, pad_features
from topomatch.stages.matching.dissimilarity import match_features


@pytest.mark.parametrize("dissimilarity", ["matched", "double_sum"])
@pytest.mark.parametrize("unmatched_cost", [0.0, 0.3])
def test_batch_equals_pairwise(dissimilarity, unmatched_cost):
    rng = np.random.default_rng(7)
    sets = [rng.random((int(rng.integers(0, 9)), 3)) for _ in range(40)]
    M = many_to_many(sets, dissimilarity=dissimilarity, unmatched_cost=unmatched_cost)
    for i, a in enumerate(sets):
        for j, b in enumerate(sets):
            ref = match_features(a, b, dissimilarity=dissimilarity, unmatched_cost=unmatched_cost).dissimilarity
            assert M[i, j] == pytest.approx(ref, abs=1e-12)


def test_optimal_falls_back_to_pairwise():
    rng = np.random.default_rng(8)
    sets = [rng.random((int(rng.integers(1, 6)), 3)) for _ in range(10)]
    padded, counts = pad_features(sets)
    d = one_to_many(sets[0], padded, counts, correspondence="optimal")
    ref = [match_features(sets[0], s, correspondence="optimal").dissimilarity for s in sets]
    np.testing.assert_allclose(d, ref)


def test_chunking_does_not_change_results():
    rng = np.random.default_rng(9)
    sets = [rng.random((int(rng.integers(1, 8)), 3)) for _ in range(50)]
    padded, counts = pad_features(sets)
    np.testing.assert_array_equal(one_to_many(sets[3], padded, counts, chunk=7),
                                  one_to_many(sets[3], padded, counts))


def test_a_database_of_shapes_without_endpoints_keeps_its_feature_width():
    """Every set empty (e.g. an index of tori, whose skeletons have no endpoints): the padding keeps the sets'
    own width, and a query without endpoints is at distance 0 from them (nothing to match, nothing unmatched)."""
    empty = [np.zeros((0, 11)), np.zeros((0, 11))]
    padded, counts = pad_features(empty)
    assert padded.shape[2] == 11 and counts.tolist() == [0, 0]
    np.testing.assert_array_equal(one_to_many(np.zeros((0, 11)), padded, counts, unmatched_cost=0.3), [0.0, 0.0])
