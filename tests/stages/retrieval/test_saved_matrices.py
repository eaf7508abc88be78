"""Database dissimilarity matrices are saved by content: read back for the same descriptors and options,
recomputed when either changes."""

from __future__ import annotations

import numpy as np
import pytest

from topomatch.pipeline.cache import Cache, CacheWarning
from topomatch.stages.retrieval import ranking
from topomatch.stages.retrieval.catalogue import get_method
from topomatch.stages.retrieval.descriptor import Descriptor


def _endpoint_sets(seed: int, n: int = 6) -> list[Descriptor]:
    rng = np.random.default_rng(seed)
    sets = [rng.random((int(rng.integers(2, 6)), 11)) for _ in range(n)]
    return [Descriptor("endpoints", s, len(s)) for s in sets]


def test_a_saved_matrix_is_read_back_and_equals_the_computed_one(tmp_path, monkeypatch):
    cache = Cache(tmp_path / "c")
    descriptors = _endpoint_sets(0)
    options = get_method("agd").match_options()
    first = ranking.saved_dissimilarity_matrix(descriptors, "agd", options, cache, "all")
    np.testing.assert_array_equal(first, ranking.dissimilarity_matrix(descriptors, "agd", options))
    calls = []
    real = ranking.dissimilarity_matrix
    monkeypatch.setattr(ranking, "dissimilarity_matrix", lambda *a: calls.append(a) or real(*a))
    again = ranking.saved_dissimilarity_matrix(descriptors, "agd", options, cache, "all")
    np.testing.assert_array_equal(again, first)
    assert calls == []  # read back, not recomputed


def test_other_descriptors_options_or_methods_are_not_served_a_saved_matrix(tmp_path):
    descriptors = _endpoint_sets(0)
    options = get_method("agd").match_options()
    base = ranking.matrix_key(descriptors, "agd", options)
    changed = list(descriptors)
    data = changed[2].data.copy()
    data[0, 0] += 1e-12
    changed[2] = Descriptor("endpoints", data, len(data))
    assert ranking.matrix_key(changed, "agd", options) != base
    assert ranking.matrix_key(descriptors[::-1], "agd", options) != base  # order matters: rows are shapes
    assert ranking.matrix_key(descriptors, "agd", get_method("agd").match_options(unmatched_cost=0.1)) != base
    assert ranking.matrix_key(descriptors, "rgpd", get_method("rgpd").match_options()) != base
    vectors = [Descriptor("vector", np.arange(4.0) + i, None) for i in range(3)]
    assert ranking.matrix_key(vectors, "hks") != ranking.matrix_key(vectors, "shapedna")


def test_an_unusable_saved_entry_is_recomputed(tmp_path):
    cache = Cache(tmp_path / "c")
    descriptors = _endpoint_sets(1)
    options = get_method("agd").match_options()
    cache.put(ranking.matrix_key(descriptors, "agd", options), np.zeros((2, 2)))  # wrong shape under the key
    with pytest.warns(CacheWarning, match="not an"):
        M = ranking.saved_dissimilarity_matrix(descriptors, "agd", options, cache, "all")
    np.testing.assert_array_equal(M, ranking.dissimilarity_matrix(descriptors, "agd", options))


def test_one_matrix_is_kept_per_slot(tmp_path):
    """A changed collection replaces its slot's saved matrix instead of adding one more file."""
    cache = Cache(tmp_path / "c")
    options = get_method("agd").match_options()
    files = lambda: sorted(p.name for p in (tmp_path / "c").rglob("*") if p.is_file())  # noqa: E731
    ranking.saved_dissimilarity_matrix(_endpoint_sets(0), "agd", options, cache, "all")
    first = files()
    ranking.saved_dissimilarity_matrix(_endpoint_sets(0)[:4], "agd", options, cache, "labelled")
    assert len(files()) == len(first) + 2  # another slot: its matrix and its record
    ranking.saved_dissimilarity_matrix(_endpoint_sets(2), "agd", options, cache, "all")
    assert len(files()) == len(first) + 2  # the same slot: the old matrix was replaced
    assert ranking.matrix_key(_endpoint_sets(2), "agd", options) in cache
    assert ranking.matrix_key(_endpoint_sets(0), "agd", options) not in cache
