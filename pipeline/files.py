"""Files the engine and the domains write or read: atomic writes and readable-input checks.

Every output (cache entries, tables, figures, exported skeletons, run pages) is written to a
temporary file in the destination folder and moved into place with ``os.replace``: a reader
sees the old file or the whole new one, never a truncated one. The files get the usual
permissions of the process's umask (group- and world-readable under the common 022), not the
0600 of a temporary file.
"""

from __future__ import annotations

import errno
import os
import tempfile
from pathlib import Path

from topomatch.pipeline.errors import InputError

# The process's umask (read once: os.umask can only be read by setting it).
_UMASK = os.umask(0o022)
os.umask(_UMASK)


def atomic_write_bytes(path: str | Path, data: bytes, *, durable: bool = True) -> None:
    """Write ``data`` to ``path`` so that readers see the old file or the whole new one.

    ``durable``: flush the data to the disk (fsync) before the rename, so that it survives a power
    loss; a cache entry that can be recomputed (and is checked when read) skips it.

    Raises
    ------
    OSError
        The folder cannot be created or written (e.g. ``path``'s parent is a file), or ``path`` is a folder; the
        error names ``path``, never the temporary file.
    """
    path = Path(path)
    if path.is_dir():
        raise IsADirectoryError(errno.EISDIR, "is a folder, not a file", str(path))
    tmp = None
    try:
        try:
            path.parent.mkdir(parents=True, exist_ok=True)
        except FileExistsError:  # a file where a folder of the path should be
            in_the_way = next(p for p in (path.parent, *path.parent.parents) if p.exists())
            raise NotADirectoryError(errno.ENOTDIR, f"{in_the_way} is a file, not a folder", str(path)) from None
        # a short prefix: the temporary name must fit where the final one fits (NAME_MAX is 255 bytes)
        fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name[:32]}.", suffix=".tmp")
        with os.fdopen(fd, "wb") as fh:
            fh.write(data)
            if durable:
                fh.flush()
                os.fsync(fh.fileno())
        os.chmod(tmp, 0o666 & ~_UMASK)
        os.replace(tmp, path)
    except OSError as exc:
        if tmp is not None:
            Path(tmp).unlink(missing_ok=True)
        raise type(exc)(exc.errno, exc.strerror or str(exc), str(path)) from None
    except BaseException:
        if tmp is not None:
            Path(tmp).unlink(missing_ok=True)
        raise


def atomic_write_text(path: str | Path, text: str) -> None:
    """:func:`atomic_write_bytes` of ``text`` encoded as UTF-8."""
    atomic_write_bytes(path, text.encode("utf-8"))


def check_readable_file(path: str | Path) -> Path:
    """``path`` as a Path, after checking that it is an existing, readable regular file.

    Raises
    ------
    InputError
        Not found, not a regular file, or not readable; the message names the file.
    """
    path = Path(path)
    if not path.exists():
        raise InputError(path, "file not found")
    if not path.is_file():
        raise InputError(path, "not a regular file")
    if not os.access(path, os.R_OK):
        raise InputError(path, "file is not readable (permission denied)")
    return path


def check_writable_folder(path: str | Path, *, create: bool = True) -> Path:
    """``path`` as a Path, after checking that files can be written there: before a command computes what it
    will write, so that a folder it cannot write does not cost the result. Nothing is created: with
    ``create`` (the writers make the folder later) a missing folder is checked through its nearest existing
    parent; without it, a missing folder is an error.

    Raises
    ------
    InputError
        No such folder (``create=False``), a file in the way, or no file can be created there; the message
        names the folder.
    """
    path = Path(path)
    existing = path
    while not existing.exists() and existing != existing.parent:
        existing = existing.parent
    if existing != path and not create:
        raise InputError(path, "no such folder to write into")
    where = "" if existing == path else f": {existing}"
    if not existing.is_dir():
        raise InputError(path, f"not a folder to write into (a file is in the way{where})")
    try:
        with tempfile.TemporaryFile(dir=existing):
            pass
    except OSError as exc:
        raise InputError(path, f"cannot write into this folder{where} ({exc.strerror or exc})") from None
    return path


def limit_from_env(name: str, default: int) -> int:
    """A size limit: the integer in the environment variable ``name``, else ``default`` (also when
    the variable is empty or not a whole number)."""
    value = os.environ.get(name)
    try:
        return int(value) if value else default
    except ValueError:
        return default
