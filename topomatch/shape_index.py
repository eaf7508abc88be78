"""The shape index: a SQLite database of descriptors, one row per (mesh content, method, params).

Schema (table ``shapes``)::

    content_hash  SHA-256 of the mesh file's name and bytes
    path          the file as indexed
    label         class label, if known (from --labels CSV)
    method        a method of topomatch.stages.retrieval.catalogue (a fusion stores its parts)
    params_hash   hash of the method's resolved stage chain (params and versions)
    params        that chain as JSON
    status        ok | failed
    reason        why it failed
    n_endpoints   endpoint count (skeleton methods)
    kind          endpoints | vector
    descriptor    the descriptor array (numpy .npy bytes)
    seconds       compute time of the chain
    created       UTC time

Re-indexing skips rows whose (content_hash, method, params_hash) exist, so
unchanged meshes are not recomputed and an interrupted index resumes; each row
is committed as soon as its mesh is done.
"""

from __future__ import annotations

import io
import json
import sqlite3
from dataclasses import dataclass
from datetime import datetime, timezone
from pathlib import Path

import numpy as np

from topomatch.pipeline.contract import InputError

SCHEMA = """
CREATE TABLE IF NOT EXISTS shapes (
    id INTEGER PRIMARY KEY,
    content_hash TEXT NOT NULL,
    path TEXT NOT NULL,
    label TEXT,
    method TEXT NOT NULL,
    params_hash TEXT NOT NULL,
    params TEXT NOT NULL,
    status TEXT NOT NULL,
    reason TEXT,
    n_endpoints INTEGER,
    kind TEXT,
    descriptor BLOB,
    seconds REAL,
    created TEXT,
    UNIQUE (content_hash, method, params_hash)
);
CREATE INDEX IF NOT EXISTS shapes_method ON shapes (method, params_hash, status);
"""


@dataclass(frozen=True)
class Row:
    """One indexed mesh."""

    id: int
    path: str
    label: str | None
    method: str
    status: str
    reason: str | None
    n_endpoints: int | None
    kind: str | None
    descriptor: np.ndarray | None


def _to_blob(array: np.ndarray) -> bytes:
    buf = io.BytesIO()
    np.save(buf, np.asarray(array), allow_pickle=False)
    return buf.getvalue()


def _from_blob(blob: bytes | None) -> np.ndarray | None:
    return None if blob is None else np.load(io.BytesIO(blob), allow_pickle=False)


class ShapeIndex:
    """Open (or create) the index at ``path``."""

    def __init__(self, path: str | Path):
        self.path = Path(path)
        try:
            self.path.parent.mkdir(parents=True, exist_ok=True)
            self.db = sqlite3.connect(self.path)
            self.db.executescript(SCHEMA)
        except sqlite3.DatabaseError as exc:
            raise InputError(self.path, f"not a topomatch index ({exc})") from None

    def close(self) -> None:
        self.db.close()

    def __enter__(self) -> "ShapeIndex":
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def known(self, method: str, params_hash: str, *, include_failed: bool = True) -> set[str]:
        """Content hashes already indexed for this method and params."""
        sql = "SELECT content_hash FROM shapes WHERE method = ? AND params_hash = ?"
        if not include_failed:
            sql += " AND status = 'ok'"
        return {r[0] for r in self.db.execute(sql, (method, params_hash))}

    def put(self, *, content_hash: str, path: str, label: str | None, method: str, params_hash: str, params: dict,
            status: str, reason: str | None = None, n_endpoints: int | None = None, kind: str | None = None,
            descriptor: np.ndarray | None = None, seconds: float | None = None) -> None:
        """Insert or replace one row and commit."""
        self.db.execute(
            "INSERT OR REPLACE INTO shapes (content_hash, path, label, method, params_hash, params, status, reason,"
            " n_endpoints, kind, descriptor, seconds, created) VALUES (?,?,?,?,?,?,?,?,?,?,?,?,?)",
            (content_hash, path, label, method, params_hash, json.dumps(params), status, reason, n_endpoints, kind,
             None if descriptor is None else _to_blob(descriptor), seconds,
             datetime.now(timezone.utc).isoformat(timespec="seconds")))
        self.db.commit()

    def set_labels(self, labels: dict[str, str]) -> int:
        """Set the label of every row whose resolved path is a key of ``labels``; returns the count."""
        changed = 0
        for (row_id, path) in list(self.db.execute("SELECT id, path FROM shapes")):
            label = labels.get(str(Path(path).resolve()))
            if label is not None:
                self.db.execute("UPDATE shapes SET label = ? WHERE id = ?", (label, row_id))
                changed += 1
        self.db.commit()
        return changed

    def rows(self, method: str, params_hash: str | None = None, *, status: str | None = "ok") -> list[Row]:
        """Rows of one method (and params), ordered by path."""
        sql = ("SELECT id, path, label, method, status, reason, n_endpoints, kind, descriptor FROM shapes"
               " WHERE method = ?")
        args: list = [method]
        if params_hash is not None:
            sql += " AND params_hash = ?"
            args.append(params_hash)
        if status is not None:
            sql += " AND status = ?"
            args.append(status)
        sql += " ORDER BY path, id"
        return [Row(r[0], r[1], r[2], r[3], r[4], r[5], r[6], r[7], _from_blob(r[8]))
                for r in self.db.execute(sql, args)]

    def methods(self) -> list[tuple[str, str, int]]:
        """(method, params_hash, ok rows) present in the index."""
        return list(self.db.execute(
            "SELECT method, params_hash, SUM(status = 'ok') FROM shapes GROUP BY method, params_hash"))
