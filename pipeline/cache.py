"""Content-addressed, on-disk cache of stage results.

The key of a stage result is the SHA-256 of (stage name, stage version, the
canonical params, the keys of the state entries it consumed); the key of an
input file is the SHA-256 of its name and bytes. So a key changes exactly when
an input's content, a parameter or a stage version changes, and a re-run or a
resumed run recomputes only what changed. Values are pickled and written
atomically (temporary file + ``os.replace``); an unreadable entry (truncated,
from an incompatible version) counts as a miss.
"""

from __future__ import annotations

import hashlib
import json
import os
import pickle
import tempfile
from pathlib import Path
from typing import Any

_MISSING = object()


def hash_file(path: str | Path, chunk: int = 1 << 20) -> str:
    """SHA-256 of a file's name and content (hex)."""
    h = hashlib.sha256(Path(path).name.encode() + b"\0")
    with open(path, "rb") as fh:
        while block := fh.read(chunk):
            h.update(block)
    return h.hexdigest()


def stage_key(name: str, version: int, params: dict[str, Any], input_keys: list[str]) -> str:
    """Cache key of a stage result (hex SHA-256)."""
    payload = json.dumps([name, version, params, input_keys], sort_keys=True, default=str)
    return hashlib.sha256(payload.encode()).hexdigest()


def atomic_write_bytes(path: str | Path, data: bytes) -> None:
    """Write ``data`` to ``path`` so that readers see the old file or the whole new one."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
    try:
        with os.fdopen(fd, "wb") as fh:
            fh.write(data)
            fh.flush()
            os.fsync(fh.fileno())
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


def atomic_write_text(path: str | Path, text: str) -> None:
    atomic_write_bytes(path, text.encode("utf-8"))


class Cache:
    """Pickled values under ``root/<key[:2]>/<key>.pkl``; ``root=None`` disables caching."""

    def __init__(self, root: str | Path | None):
        self.root = None if root is None else Path(root)

    def _path(self, key: str) -> Path:
        assert self.root is not None
        return self.root / key[:2] / f"{key}.pkl"

    def get(self, key: str) -> tuple[bool, Any]:
        """(hit, value); a missing or unreadable entry is a miss."""
        if self.root is None:
            return False, None
        path = self._path(key)
        try:
            with open(path, "rb") as fh:
                return True, pickle.load(fh)
        except FileNotFoundError:
            return False, None
        except Exception:  # truncated or incompatible pickle: recompute
            return False, None

    def put(self, key: str, value: Any) -> None:
        if self.root is None:
            return
        atomic_write_bytes(self._path(key), pickle.dumps(value, protocol=pickle.HIGHEST_PROTOCOL))

    def __contains__(self, key: str) -> bool:
        return self.root is not None and self._path(key).exists()
