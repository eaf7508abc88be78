"""Checks of a mesh file's structure before a reader parses it, so that nothing is silently wrong.

Readers are lenient: libigl reads the number of faces an OFF header declares and ignores the
rest, drops or invents faces with fewer than three vertices, and allocates what a header claims
before it finds the file too short; open3d reads a truncated file up to where it ends. So the
file is checked first, cheaply (counts and sizes, no geometry):

- **size**: a gzip file is decompressed with a cap (:data:`MAX_BYTES`, or
  ``$TOPOMATCH_MAX_MESH_BYTES``), so a small file cannot inflate to gigabytes;
- **OFF**: the header's vertex and face counts must match the lines that follow (neither fewer:
  truncated, nor more: an under-counted header); every face has at least three vertices;
- **OBJ**: every face has at least three vertex references, and the file has faces;
- **PLY**: the header's element counts must fit in the file (lines for ASCII, bytes for binary);
- **STL**: a binary file's size must be 84 + 50 x its triangle count; an ASCII file's facets
  must be complete.

Faces with more than three vertices (OFF, OBJ and PLY allow polygons) are counted: the reader
triangulates them as fans, and the load stage reports how many there were.
"""

from __future__ import annotations

import contextlib
import gzip
import os
import re
import tempfile
from dataclasses import dataclass
from pathlib import Path
from typing import Iterator

from topomatch.pipeline.contract import InputError

#: Largest decompressed mesh file (bytes); ``$TOPOMATCH_MAX_MESH_BYTES`` overrides it.
MAX_BYTES = 512 * 2**20


def max_bytes() -> int:
    value = os.environ.get("TOPOMATCH_MAX_MESH_BYTES")
    try:
        return int(value) if value else MAX_BYTES
    except ValueError:
        return MAX_BYTES


@dataclass(frozen=True)
class FileFacts:
    """What the checks learnt of a file: declared vertex and face counts (None when the format has
    no header) and the number of faces with more than three vertices."""

    vertices: int | None
    faces: int | None
    polygons: int


@contextlib.contextmanager
def plain_file(path: Path, fmt: str) -> Iterator[Path]:
    """Yield a path to the uncompressed content of ``path`` (decompressed with a size cap)."""
    limit = max_bytes()
    if path.suffix.lower() != ".gz":
        if path.stat().st_size > limit:
            raise InputError(path, f"file is {path.stat().st_size / 2**20:.0f} MiB, above the {limit / 2**20:.0f} MiB "
                                   "limit for a mesh (set TOPOMATCH_MAX_MESH_BYTES to raise it)")
        yield path
        return
    with tempfile.TemporaryDirectory(prefix="topomatch-") as tmp:
        plain = Path(tmp) / f"mesh{fmt}"
        written = 0
        try:
            with gzip.open(path, "rb") as src, open(plain, "wb") as dst:
                while block := src.read(1 << 20):
                    written += len(block)
                    if written > limit:
                        raise InputError(path, f"decompresses to more than {limit / 2**20:.0f} MiB, the limit for "
                                               "a mesh (set TOPOMATCH_MAX_MESH_BYTES to raise it)")
                    dst.write(block)
        except (OSError, EOFError) as exc:
            raise InputError(path, f"cannot decompress gzip file ({exc})") from None
        yield plain


def _content_lines(data: bytes) -> list[bytes]:
    """Lines without comments (``#`` to the end of the line) and without blank lines."""
    out = []
    for line in data.splitlines():
        hashed = line.find(b"#")
        if hashed >= 0:
            line = line[:hashed]
        line = line.strip()
        if line:
            out.append(line)
    return out


def _int(token: bytes, path: Path, what: str) -> int:
    try:
        value = int(token)
    except ValueError:
        raise InputError(path, f"malformed header: {what} is {token[:20]!r}, not a whole number") from None
    if value < 0:
        raise InputError(path, f"malformed header: {what} is negative ({value})")
    return value


def _face_sizes(face_lines: list[bytes], path: Path, line_offset: int) -> int:
    """Number of polygons among OFF face lines (leading vertex count); raises for faces of fewer than 3."""
    polygons = 0
    for i, line in enumerate(face_lines):
        if line[:2] == b"3 ":
            continue
        count = _int(line.split(None, 1)[0], path, f"the vertex count of face {i}")
        if count < 3:
            raise InputError(path, f"face {i} (line {line_offset + i + 1} of the content) has {count} vertices; "
                                   "a face needs at least 3")
        polygons += count > 3
    return polygons


def check_off(plain: Path, path: Path) -> FileFacts:
    lines = _content_lines(plain.read_bytes())
    if not lines or not lines[0].split()[0].upper().endswith(b"OFF"):
        raise InputError(path, "malformed OFF file: the first line is not an OFF header")
    head = lines[0].split()
    rest = lines[1:]
    if len(head) >= 3:  # 'OFF nv nf ne' on one line
        counts = head[1:]
    elif rest:
        counts, rest = rest[0].split(), rest[1:]
    else:
        raise InputError(path, "malformed OFF file: no vertex and face counts after the header")
    if len(counts) < 2:
        raise InputError(path, "malformed OFF file: the counts line needs the numbers of vertices and faces")
    nv, nf = _int(counts[0], path, "the vertex count"), _int(counts[1], path, "the face count")
    if len(rest) < nv + nf:
        raise InputError(path, f"malformed OFF file: truncated, the header declares {nv} vertices and {nf} faces "
                               f"({nv + nf} lines) but only {len(rest)} lines follow")
    if len(rest) > nv + nf:
        raise InputError(path, f"malformed OFF file: the header declares {nv} vertices and {nf} faces but "
                               f"{len(rest) - nv - nf} more lines follow (an under-counted header?)")
    return FileFacts(nv, nf, _face_sizes(rest[nv:], path, 2 + nv))


_OBJ_FACE = re.compile(rb"^f\s+(.*)$", re.MULTILINE)


def check_obj(plain: Path, path: Path) -> FileFacts:
    data = plain.read_bytes()
    polygons = 0
    n_faces = 0
    for m in _OBJ_FACE.finditer(data):
        refs = m.group(1).split(b"#", 1)[0].split()
        n_faces += 1
        if len(refs) < 3:
            raise InputError(path, f"face {n_faces} ({m.group(0)[:60].decode('utf-8', 'replace')!r}) has "
                                   f"{len(refs)} vertices; a face needs at least 3")
        polygons += len(refs) > 3
    if n_faces == 0:
        raise InputError(path, "OBJ file has no faces ('f' lines)")
    return FileFacts(None, n_faces, polygons)


_PLY_SIZES = {b"char": 1, b"uchar": 1, b"int8": 1, b"uint8": 1, b"short": 2, b"ushort": 2, b"int16": 2,
              b"uint16": 2, b"int": 4, b"uint": 4, b"int32": 4, b"uint32": 4, b"float": 4, b"float32": 4,
              b"double": 8, b"float64": 8}


def check_ply(plain: Path, path: Path) -> FileFacts:
    with open(plain, "rb") as fh:
        header = fh.read(1 << 16)
    end = header.find(b"end_header")
    if not header.startswith(b"ply") or end < 0:
        raise InputError(path, "malformed PLY file: no 'ply ... end_header' header")
    body_start = header.index(b"\n", end) + 1 if b"\n" in header[end:] else len(header)
    lines = header[:end].splitlines()
    fmt = next((l.split()[1] for l in lines if l.startswith(b"format ")), b"")
    elements: list[list] = []  # [name, count, min record bytes]
    for line in lines:
        tokens = line.split()
        if tokens[:1] == [b"element"] and len(tokens) >= 3:
            elements.append([tokens[1], _int(tokens[2], path, f"the count of element {tokens[1]!r}"), 0])
        elif tokens[:1] == [b"property"] and elements:
            if tokens[1:2] == [b"list"] and len(tokens) >= 5:  # a list: its count, then at least 3 items
                elements[-1][2] += _PLY_SIZES.get(tokens[2], 1) + 3 * _PLY_SIZES.get(tokens[3], 4)
            elif len(tokens) >= 3:
                elements[-1][2] += _PLY_SIZES.get(tokens[1], 4)
    counts = {e[0]: e[1] for e in elements}
    body = plain.stat().st_size - body_start
    if fmt == b"ascii":
        n_lines = sum(1 for line in plain.read_bytes()[body_start:].splitlines() if line.strip())
        needed = sum(e[1] for e in elements)
        if n_lines < needed:
            raise InputError(path, f"malformed PLY file: truncated, the header declares {needed} element lines "
                                   f"but only {n_lines} follow")
    else:
        needed = sum(e[1] * e[2] for e in elements)
        if body < needed:
            raise InputError(path, f"malformed PLY file: truncated, the header's elements need at least {needed} "
                                   f"bytes but {body} follow")
    return FileFacts(counts.get(b"vertex"), counts.get(b"face"), 0)


def check_stl(plain: Path, path: Path) -> FileFacts:
    size = plain.stat().st_size
    with open(plain, "rb") as fh:
        head = fh.read(84)
    if len(head) == 84:
        n = int.from_bytes(head[80:84], "little")
        if size == 84 + 50 * n:
            return FileFacts(None, n, 0)
    data = plain.read_bytes()
    if data.lstrip()[:5].lower() == b"solid" and b"facet" in data:
        facets, ends = data.count(b"facet normal"), data.count(b"endfacet")
        if facets != ends or data.count(b"vertex") != 3 * facets:
            raise InputError(path, f"malformed STL file: truncated ASCII STL, {facets} facets begin, {ends} end, "
                                   f"{data.count(b'vertex')} vertices for them")
        return FileFacts(None, facets, 0)
    if len(head) == 84:
        raise InputError(path, f"malformed STL file: truncated binary STL, {size} bytes where its {n} triangles "
                               f"need {84 + 50 * n}")
    raise InputError(path, "malformed STL file: neither a binary nor an ASCII STL")


CHECKS = {".off": check_off, ".obj": check_obj, ".ply": check_ply, ".stl": check_stl}


def check_structure(plain: Path, fmt: str, path: Path) -> FileFacts:
    """Check the structure of the uncompressed file ``plain`` of format ``fmt`` (errors name ``path``)."""
    return CHECKS[fmt](plain, path)
