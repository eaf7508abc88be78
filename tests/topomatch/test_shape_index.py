"""The index's state counter: what the shortlist graph beside an index checks before trusting itself."""

from __future__ import annotations

import sqlite3

from topomatch.shape_index import ShapeIndex


def _put(store: ShapeIndex, path: str) -> None:
    store.put(content_hash=path, path=path, label=None, method="d2", params_hash="p", params={}, status="ok",
              reason=None, n_endpoints=None, kind="vector", descriptor=None, seconds=0.0)


def test_every_change_counts_and_each_index_is_its_own(tmp_path):
    with ShapeIndex(tmp_path / "a.db") as a, ShapeIndex(tmp_path / "b.db") as b:
        first = a.generation()
        _put(a, "x.off")
        assert a.generation()[0] == first[0] and a.generation()[1] > first[1]
        assert b.generation()[0] != a.generation()[0]  # another index: another id, even at the same count
    con = sqlite3.connect(tmp_path / "a.db")  # a change made outside topomatch counts too (the triggers)
    before = ShapeIndex(tmp_path / "a.db", readonly=True).generation()
    con.execute("UPDATE shapes SET label = 'edited'")
    con.commit()
    assert ShapeIndex(tmp_path / "a.db", readonly=True).generation()[1] > before[1]
    con.execute("DROP TRIGGER shapes_updated")  # the index can no longer vouch for its count
    con.commit()
    assert ShapeIndex(tmp_path / "a.db", readonly=True).generation() is None
    con.execute("UPDATE index_state SET value = 'abc' WHERE key = 'generation'")
    con.commit()
    con.close()
    assert ShapeIndex(tmp_path / "a.db", readonly=True).generation() is None
