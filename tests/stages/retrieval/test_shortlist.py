"""The approximate-nearest-neighbour shortlist of large indexes (usearch HNSW)."""

from __future__ import annotations

import numpy as np
from scipy.spatial.distance import cdist

from topomatch.stages.retrieval.shortlist import Shortlist, embedding, sample_rows, shape_key


def _clustered(n=3000, seed=0):
    rng = np.random.default_rng(seed)
    centres = rng.random((60, 16))
    X = centres[rng.integers(0, 60, n)] + 0.02 * rng.normal(size=(n, 16))
    return {"a": X[:, :10], "b": X[:, 10:] * 5.0}


def test_search_finds_the_exact_nearest_neighbours_of_the_embedding():
    vectors = _clustered()
    scales = {"a": 0.5, "b": 2.0}
    keys = np.arange(len(vectors["a"]), dtype=np.uint64) * 7 + 3
    ann = Shortlist.build(keys, vectors, scales)
    E = embedding(vectors, scales)
    np.testing.assert_allclose(E[:, 10:], vectors["b"] / 2.0, rtol=1e-6)
    hits = []
    for q in range(0, 3000, 97):
        exact = keys[np.argsort(cdist(E[q:q + 1], E, "sqeuclidean")[0], kind="stable")[:10]]
        found = ann.search({p: v[q] for p, v in vectors.items()}, 10)
        hits.append(len(set(exact.tolist()) & set(found.tolist())) / 10)
    assert np.mean(hits) >= 0.95


def test_incremental_add_replace_and_persistence(tmp_path):
    vectors = _clustered(200)
    keys = np.array([shape_key(f"m{i}.off") for i in range(200)], dtype=np.uint64)
    ann = Shortlist.build(keys[:150], {p: v[:150] for p, v in vectors.items()}, {"a": 1.0, "b": 1.0})
    ann.add(keys[140:], {p: v[140:] for p, v in vectors.items()})  # 10 replaced, 50 new
    assert len(ann) == 200
    ann.save(tmp_path / "x.ann")
    back = Shortlist.load(tmp_path / "x.ann")
    assert back.parts == ("a", "b") and back.scales == {"a": 1.0, "b": 1.0} and len(back) == 200
    assert back.search({p: v[170] for p, v in vectors.items()}, 1)[0] == keys[170]
    assert Shortlist.load(tmp_path / "missing.ann") is None


def test_keys_and_samples_are_stable():
    assert shape_key("a/b.off") == shape_key("a/b.off") != shape_key("a/c.off")
    assert 0 <= shape_key("a/b.off") < 2 ** 63
    np.testing.assert_array_equal(sample_rows(10, 1000), np.arange(10))
    s = sample_rows(5000, 1000)
    assert len(s) == 1000 and np.all(np.diff(s) > 0) and np.array_equal(s, sample_rows(5000, 1000))
