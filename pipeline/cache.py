"""Content-addressed, on-disk cache of stage results (typed data, never pickle).

The key of a stage result is the SHA-256 of (stage name, stage version, the canonical params,
the keys of the state entries it consumed); the key of an input file is the SHA-256 of its
name and bytes. So a key changes exactly when an input's content, a parameter or a stage
version changes, and a re-run or a resumed run recomputes only what changed.

Values are written by :mod:`topomatch.pipeline.codec` (arrays in ``.npz``, the structure as
JSON, loaded with ``allow_pickle=False``) under ``root/<key[:2]>/<key>.npz``, atomically. A
missing entry is a miss; a damaged, foreign or stale entry (another schema, an unknown type, a
result of the wrong type for its stage) is a miss with a warning, and is overwritten by the
recomputed result. Nothing read from a cache folder can run code.
"""

from __future__ import annotations

import hashlib
import json
import warnings
from pathlib import Path
from typing import Any, Callable

from topomatch.pipeline import codec
from topomatch.pipeline.files import atomic_write_bytes

#: File suffix of cache entries.
SUFFIX = ".npz"


class CacheWarning(UserWarning):
    """A cache entry was unusable (damaged, foreign, stale) or a result could not be stored."""


def hash_file(path: str | Path, chunk: int = 1 << 20) -> str:
    """SHA-256 of a file's name and content (hex); of a folder (a DICOM series), its name and the names and
    contents of the regular files directly in it, in name order.

    Raises
    ------
    OSError
        Unreadable, or neither a regular file nor a folder (a FIFO, socket or device would block or never end).
    """
    path = Path(path)
    h = hashlib.sha256(path.name.encode() + b"\0")
    if path.is_dir():
        for member in sorted(p for p in path.iterdir() if p.is_file()):
            h.update(hash_file(member, chunk).encode())
        return h.hexdigest()
    if not path.is_file():
        raise OSError("not a regular file (a FIFO, socket or device): refused")
    with open(path, "rb") as fh:
        while block := fh.read(chunk):
            h.update(block)
    return h.hexdigest()


def stage_key(name: str, version: int, params: dict[str, Any], input_keys: list[str]) -> str:
    """Cache key of a stage result (hex SHA-256)."""
    payload = json.dumps([name, version, params, input_keys], sort_keys=True, default=str)
    return hashlib.sha256(payload.encode()).hexdigest()


class Cache:
    """Stage results under ``root/<key[:2]>/<key>.npz``; ``root=None`` disables caching."""

    def __init__(self, root: str | Path | None):
        self.root = None if root is None else Path(root)

    def _path(self, key: str) -> Path:
        if self.root is None:
            raise ValueError("the cache is disabled")
        return self.root / key[:2] / f"{key}{SUFFIX}"

    def get(self, key: str, check: Callable[[Any], str | None] | None = None) -> tuple[bool, Any]:
        """(hit, value). ``check(value)`` returns why a decoded value is unusable (or None).

        A missing entry is a miss; an unusable one is a miss with a :class:`CacheWarning`.
        """
        if self.root is None:
            return False, None
        path = self._path(key)
        try:
            data = path.read_bytes()
        except FileNotFoundError:
            return False, None
        except OSError as exc:
            warnings.warn(f"cache entry {path} cannot be read ({exc}); recomputing", CacheWarning, stacklevel=2)
            return False, None
        try:
            value = codec.loads(data)
        except codec.CodecError as exc:
            warnings.warn(f"cache entry {path} is unusable ({exc}); recomputing", CacheWarning, stacklevel=2)
            return False, None
        problem = check(value) if check is not None else None
        if problem:
            warnings.warn(f"cache entry {path} is unusable ({problem}); recomputing", CacheWarning, stacklevel=2)
            return False, None
        return True, value

    def put(self, key: str, value: Any) -> bool:
        """Store ``value``; False (with a :class:`CacheWarning`) when it cannot be encoded or written."""
        if self.root is None:
            return False
        try:
            data = codec.dumps(value)
        except codec.CodecError as exc:
            warnings.warn(f"result not cached: {exc}", CacheWarning, stacklevel=2)
            return False
        try:
            atomic_write_bytes(self._path(key), data, durable=False)  # recomputable, checked on read
        except OSError as exc:
            warnings.warn(f"result not cached: cannot write {self._path(key)} ({exc})", CacheWarning, stacklevel=2)
            return False
        return True

    def remove(self, key: str) -> None:
        """Delete the entry of ``key`` if there is one (an entry that cannot be deleted is left)."""
        if self.root is not None:
            try:
                self._path(key).unlink(missing_ok=True)
            except OSError:
                pass

    def __contains__(self, key: str) -> bool:
        return self.root is not None and self._path(key).exists()
