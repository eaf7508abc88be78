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
unchanged meshes are not recomputed and an interrupted index resumes. One process writes the
index, the client of ``topomatch index``, from the small records its workers send back; it
commits at most once a second (:data:`COMMIT_SECONDS`: a commit cost 2-17 ms here, more on a
network filesystem) and when it stops for any reason, so a killed client loses at most a
second of rows, whose stage results are in the cache (docs/cluster.md: the measured choice).

Every SQLite error becomes an :class:`~topomatch.pipeline.errors.InputError` naming the file:
a database another process holds is waited for (:data:`BUSY_SECONDS`) and then reported as
locked, not as foreign; a damaged file or page, a foreign database and a descriptor that is not
a plain numeric array (e.g. a pickle) are reported as such.
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
CREATE INDEX IF NOT EXISTS shapes_path ON shapes (path);
CREATE TABLE IF NOT EXISTS index_state (key TEXT PRIMARY KEY, value INTEGER NOT NULL);
INSERT OR IGNORE INTO index_state VALUES ('generation', 0);
INSERT OR IGNORE INTO index_state VALUES ('index_id', abs(random()));
CREATE TRIGGER IF NOT EXISTS shapes_inserted AFTER INSERT ON shapes
    BEGIN UPDATE index_state SET value = value + 1 WHERE key = 'generation'; END;
CREATE TRIGGER IF NOT EXISTS shapes_updated AFTER UPDATE ON shapes
    BEGIN UPDATE index_state SET value = value + 1 WHERE key = 'generation'; END;
CREATE TRIGGER IF NOT EXISTS shapes_deleted AFTER DELETE ON shapes
    BEGIN UPDATE index_state SET value = value + 1 WHERE key = 'generation'; END;
"""
#: ``index_state.generation`` counts every change of the shapes table (triggers: topomatch's writes and anyone
#: else's, e.g. the sqlite3 shell), so that files built from the rows (the shortlist graph) know whether they
#: are current. An index made before the table existed gets it on its next writable open.


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
    problem: str | None = None  # why the stored descriptor cannot be used (None: it was read)


def _to_blob(array: np.ndarray) -> bytes:
    buf = io.BytesIO()
    np.save(buf, np.asarray(array), allow_pickle=False)
    return buf.getvalue()


#: Largest stored descriptor read (bytes): an endpoint descriptor is a few hundred bytes, a vector a few KB.
MAX_BLOB_BYTES = 4 * 2**20


def _from_blob(blob: bytes | None, where: Path, mesh: str) -> np.ndarray | None:
    if blob is None:
        return None
    if not isinstance(blob, (bytes, bytearray, memoryview)):
        raise InputError(where, f"the descriptor of {mesh} is stored as {type(blob).__name__} {str(blob)[:40]!r}, "
                                f"not as the saved array topomatch writes")
    if len(blob) > MAX_BLOB_BYTES:
        raise InputError(where, f"the descriptor of {mesh} is {len(blob):,} bytes, more than any descriptor "
                                f"({MAX_BLOB_BYTES:,}): not one topomatch wrote")
    try:
        array = np.load(io.BytesIO(blob), allow_pickle=False)
    except Exception as exc:  # a pickle (refused), a truncated or foreign blob
        raise InputError(where, f"the descriptor of {mesh} is damaged or not a plain array ({type(exc).__name__}: "
                                f"{exc}); delete its rows or re-create the index") from None
    if array.dtype.kind not in "biuf":
        raise InputError(where, f"the descriptor of {mesh} has dtype {array.dtype}, not numbers")
    return array


def _row(r: tuple, where: Path) -> Row:
    """A :class:`Row` from a SELECT of the shapes table; a descriptor that cannot be read is None, with the
    ``problem`` (the caller decides: :func:`topomatch.retrieval.usable_rows` skips and counts such rows)."""
    try:
        return Row(r[0], r[1], r[2], r[3], r[4], r[5], r[6], r[7], _from_blob(r[8], where, r[1]))
    except InputError as exc:
        return Row(r[0], r[1], r[2], r[3], r[4], r[5], r[6], r[7], None, exc.problem)


#: How long a database locked by another process is waited for (seconds).
BUSY_SECONDS = 60.0
#: ``topomatch index`` commits its rows at most this often (seconds), and when it stops.
COMMIT_SECONDS = 1.0


def _problem(exc: sqlite3.Error) -> str:
    """What an SQLite error means for a user."""
    text = str(exc)
    if "locked" in text or "busy" in text:
        return (f"the index is locked by another process ({text}, after {BUSY_SECONDS:.0f} s); try again when "
                "it has finished")
    if isinstance(exc, sqlite3.DatabaseError) and ("not a database" in text or "malformed" in text):
        return f"the file is damaged or not a topomatch index ({text})"
    if "no such table" in text or "no such column" in text:
        return f"not a topomatch index ({text})"
    return f"database error ({type(exc).__name__}: {text})"


class ShapeIndex:
    """Open (or create) the index at ``path``; ``readonly`` opens an existing index without writing to it."""

    def __init__(self, path: str | Path, *, readonly: bool = False):
        self.path = Path(path)
        if self.path.exists() and not self.path.is_file():
            raise InputError(self.path, "not a regular file (a folder, device or pipe), so not an index")
        if readonly and not self.path.is_file():
            raise InputError(self.path, "index not found (create it with topomatch index)")
        try:
            self.path.parent.mkdir(parents=True, exist_ok=True)
        except OSError as exc:
            raise InputError(self.path, f"cannot create the index's folder ({exc.strerror or exc})") from None
        try:
            if readonly:
                self.db = sqlite3.connect(f"{self.path.resolve().as_uri()}?mode=ro", uri=True, timeout=BUSY_SECONDS)
                self.db.execute("SELECT content_hash, path, label, method, params_hash, status, descriptor "
                                "FROM shapes LIMIT 1").fetchall()
            else:
                self.db = sqlite3.connect(self.path, timeout=BUSY_SECONDS)
                tables = {r[0] for r in self.db.execute("SELECT name FROM sqlite_master WHERE type = 'table'")}
                if tables - {"shapes", "index_state"}:  # someone else's database: never add our table to it
                    self.db.close()
                    raise InputError(self.path, f"not a topomatch index: a SQLite database with other tables "
                                                f"({', '.join(sorted(tables)[:5])}); choose another --db")
                self.db.executescript(SCHEMA)
        except sqlite3.Error as exc:
            raise InputError(self.path, _problem(exc)) from None

    def _sql(self, sql: str, args=()) -> list:
        """Run one statement; SQLite errors become InputErrors naming the index."""
        try:
            return list(self.db.execute(sql, args))
        except sqlite3.Error as exc:
            raise InputError(self.path, _problem(exc)) from None

    def close(self) -> None:
        self.db.close()

    def generation(self) -> list[int] | None:
        """[this index's random id, how many changes its shapes table has seen]; None when the index cannot vouch
        for it (made before the counter existed, a trigger removed, a value edited into something else)."""
        try:
            triggers = {r[0] for r in self.db.execute("SELECT name FROM sqlite_master WHERE type = 'trigger'")}
            values = dict(self.db.execute("SELECT key, value FROM index_state"))
        except sqlite3.Error:
            return None
        if not {"shapes_inserted", "shapes_updated", "shapes_deleted"} <= triggers:
            return None
        state = [values.get("index_id"), values.get("generation")]
        return state if all(isinstance(v, int) for v in state) else None

    def __enter__(self) -> "ShapeIndex":
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def known(self, method: str, params_hash: str, *, include_failed: bool = True) -> set[str]:
        """Content hashes already indexed for this method and params."""
        sql = "SELECT content_hash FROM shapes WHERE method = ? AND params_hash = ?"
        if not include_failed:
            sql += " AND status = 'ok'"
        return {r[0] for r in self._sql(sql, (method, params_hash))}

    def failed(self, method: str, params_hash: str) -> set[str]:
        """Content hashes recorded as failed for this method and params."""
        return {r[0] for r in self._sql("SELECT content_hash FROM shapes WHERE method = ? AND params_hash = ? AND "
                                        "status = 'failed'", (method, params_hash))}

    def put(self, *, content_hash: str, path: str, label: str | None, method: str, params_hash: str, params: dict,
            status: str, reason: str | None = None, n_endpoints: int | None = None, kind: str | None = None,
            descriptor: np.ndarray | None = None, seconds: float | None = None, commit: bool = True) -> None:
        """Insert or replace one row and commit (a lock held by another process is waited for); a row of an
        earlier content of the same file (same path, method and params) is replaced too. ``commit=False`` leaves
        the commit to a later :meth:`commit` (rows written together: one commit for many)."""
        self._sql("DELETE FROM shapes WHERE path = ? AND method = ? AND params_hash = ? AND content_hash != ?",
                  (path, method, params_hash, content_hash))
        if label is None:  # the file's label from another method's row (labels belong to files, not methods)
            known = self._sql("SELECT label FROM shapes WHERE path = ? AND label IS NOT NULL LIMIT 1", (path,))
            label = known[0][0] if known else None
        self._sql(
            "INSERT OR REPLACE INTO shapes (content_hash, path, label, method, params_hash, params, status, reason,"
            " n_endpoints, kind, descriptor, seconds, created) VALUES (?,?,?,?,?,?,?,?,?,?,?,?,?)",
            (content_hash, path, label, method, params_hash, json.dumps(params), status, reason, n_endpoints, kind,
             None if descriptor is None else _to_blob(descriptor), seconds,
             datetime.now(timezone.utc).isoformat(timespec="seconds")))
        if commit:
            self._commit()

    def remove_missing(self, folders: list[Path], present: set[str], methods: tuple[str, ...]) -> int:
        """Delete the rows of ``methods`` whose file lies under one of ``folders`` but is not in ``present``
        (resolved paths): files deleted or renamed since they were indexed. Returns the count."""
        removed = 0
        marks = ",".join("?" * len(methods))
        for row_id, path in self._sql(f"SELECT id, path FROM shapes WHERE method IN ({marks})", methods):
            if path not in present and any(Path(path).is_relative_to(f) for f in folders):
                self._sql("DELETE FROM shapes WHERE id = ?", (row_id,))
                removed += 1
        self._commit()
        return removed

    def commit(self) -> None:
        """Commit the rows written with ``put(commit=False)``."""
        self._commit()

    def _commit(self) -> None:
        try:
            self.db.commit()
        except sqlite3.Error as exc:
            raise InputError(self.path, _problem(exc)) from None

    def set_labels(self, labels: dict[str, str]) -> int:
        """Set the label of every row whose resolved path is a key of ``labels``; returns the count."""
        changed = 0
        for (row_id, path) in self._sql("SELECT id, path FROM shapes"):
            label = labels.get(str(Path(path).resolve()))
            if label is not None:
                self._sql("UPDATE shapes SET label = ? WHERE id = ?", (label, row_id))
                changed += 1
        self._commit()
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
        return [_row(r, self.path) for r in self._sql(sql, args)]

    def methods(self) -> list[tuple[str, str, int]]:
        """(method, params_hash, ok rows) present in the index."""
        return self._sql("SELECT method, params_hash, SUM(status = 'ok') FROM shapes GROUP BY method, params_hash")
