"""glibc's allocator set for a process that makes and frees many large numpy arrays (the CLI).

By default glibc serves every allocation above a threshold (128 KiB, raised on the fly up to 32 MiB)
with a fresh ``mmap`` and gives it back on ``free``, so each large temporary of a mesh pass is
page-faulted and zeroed again. :func:`keep_freed_memory` fixes the threshold at its maximum (32 MiB)
and keeps freed heap memory in the process (trim threshold 1 GiB, 256 MiB of padding per heap
extension), so arrays up to 32 MiB reuse pages already touched. Measured on the mixture skeleton of a
1.55 M-face mesh, in alternating runs of the command: stages 2.9-3.2 s without, 2.3-2.6 s with
(docs/speed.md). The price: the process keeps up to 1 GiB it no longer uses until it exits. Only the
command's own process: pool workers (``forkserver``, a fresh interpreter) keep glibc's defaults, so
parallel ``index`` and ``run`` are unchanged. Only on glibc (``mallopt``; any ``MALLOC_*_`` or
``GLIBC_TUNABLES`` malloc setting of the user is overridden); elsewhere nothing changes. The Python API
leaves the allocator alone.
"""

from __future__ import annotations

import sys

#: ``mallopt`` parameters (glibc's malloc.h).
M_TRIM_THRESHOLD, M_TOP_PAD, M_MMAP_THRESHOLD = -1, -2, -3

SETTINGS = {M_MMAP_THRESHOLD: 32 << 20, M_TRIM_THRESHOLD: 1 << 30, M_TOP_PAD: 256 << 20}


def keep_freed_memory() -> bool:
    """Apply :data:`SETTINGS` with glibc's ``mallopt``; True when all were accepted (False off glibc)."""
    if not sys.platform.startswith("linux"):
        return False
    import ctypes

    try:
        mallopt = ctypes.CDLL(None).mallopt
    except (OSError, AttributeError):  # not glibc (e.g. musl has no mallopt)
        return False
    mallopt.argtypes, mallopt.restype = [ctypes.c_int, ctypes.c_int], ctypes.c_int
    return all(mallopt(param, value) == 1 for param, value in SETTINGS.items())
