"""The approximate-nearest-neighbour shortlist of large indexes (usearch HNSW)."""

from __future__ import annotations

import json

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
    back, problem = Shortlist.load(tmp_path / "x.ann")
    assert problem is None and back.parts == ("a", "b") and back.scales == {"a": 1.0, "b": 1.0} and len(back) == 200
    assert back.search({p: v[170] for p, v in vectors.items()}, 1)[0] == keys[170]
    assert Shortlist.load(tmp_path / "missing.ann") == (None, None)
    # the graph knows which index rows it holds: nothing changed, then one row edited and one removed
    assert [len(x) for x in back.changed(keys, vectors)] == [0, 0]
    edited = {p: v.copy() for p, v in vectors.items()}
    edited["a"][7] += 1.0
    stale, gone = back.changed(keys[:-1], {p: v[:-1] for p, v in edited.items()})
    assert stale.tolist() == [7] and gone == [int(keys[-1])]


def test_a_graph_that_is_not_its_records_is_refused(tmp_path):
    vectors = _clustered(50)
    keys = np.array([shape_key(f"m{i}.off") for i in range(50)], dtype=np.uint64)
    ann = Shortlist.build(keys, vectors, {"a": 1.0, "b": 1.0})
    ann.save(tmp_path / "x.ann")
    other = Shortlist.build(keys[:20], {p: v[:20] for p, v in vectors.items()}, {"a": 1.0, "b": 1.0})
    other.index.save(str(tmp_path / "x.ann"))  # a graph saved without its record (an interrupted save)
    back, problem = Shortlist.load(tmp_path / "x.ann")
    assert back is None and "not the one its record was written with" in problem
    (tmp_path / "y.ann").mkdir()
    (tmp_path / "y.ann.json").write_text("{}")
    assert Shortlist.load(tmp_path / "y.ann")[0] is None  # a folder where the graph should be
    ann.save(tmp_path / "z.ann")
    (tmp_path / "z.ann.json").write_text('{"schema": 2}')  # a record without its keys
    back, problem = Shortlist.load(tmp_path / "z.ann")
    assert back is None and "edited" in problem
    ann.sample = {"scales": {"a": 1.0, "b": 1.0}}
    ann.save(tmp_path / "w.ann")
    record = json.loads((tmp_path / "w.ann.json").read_text())
    record["sample"]["scales"]["a"] = 100.0  # a valid-looking value changed by hand: the ranking would change
    (tmp_path / "w.ann.json").write_text(json.dumps(record))
    assert Shortlist.load(tmp_path / "w.ann") == (None, "the record (.json) was edited after it was written")


def test_keys_and_samples_are_stable():
    assert shape_key("a/b.off") == shape_key("a/b.off") != shape_key("a/c.off")
    assert 0 <= shape_key("a/b.off") < 2 ** 63
    np.testing.assert_array_equal(sample_rows(10, 1000), np.arange(10))
    s = sample_rows(5000, 1000)
    assert len(s) == 1000 and np.all(np.diff(s) > 0) and np.array_equal(s, sample_rows(5000, 1000))
