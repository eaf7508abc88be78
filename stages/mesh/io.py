"""Reading triangle meshes: OFF, OBJ, PLY, STL and the gzip of each.

The file's structure is checked first (:mod:`topomatch.stages.mesh.file_checks`: header counts
against the file, faces of at least three vertices, a decompression cap), then libigl's
``read_triangle_mesh`` reads OFF, OBJ and STL; open3d is the fallback only for the STL variants
libigl cannot read, never for a file libigl rejects as malformed (a lenient reader would drop data),
and its result must match the header's counts. PLY files are read by MeshLab's reader (pymeshlab):
libigl's PLY reader aborts the whole process (a C++ double free) on polygons, list counts that do
not match and unknown property types, which no ``try`` can catch. Polygons are triangulated as fans and counted in the
result. Gzipped files are decompressed to a temporary file with the inner suffix. Every failure
becomes an :class:`~topomatch.pipeline.contract.InputError` naming the file and the problem.
"""

from __future__ import annotations

import contextlib
import os
import tempfile
from dataclasses import dataclass
from pathlib import Path
from typing import Iterator, Literal

import numpy as np
from pydantic import Field

from topomatch.pipeline.contract import InputError, Params, StageResult, check_readable_file, stage
from topomatch.stages.mesh.file_checks import FileFacts, check_structure, plain_file
from topomatch.stages.mesh.mesh import Mesh

SUPPORTED_SUFFIXES = (".off", ".obj", ".ply", ".stl")


class LoadParams(Params):
    """Parameters of :func:`load`."""

    reader: Literal["auto", "igl", "open3d", "pymeshlab"] = Field(
        "auto", description="mesh reader: MeshLab's for PLY, libigl for the others with open3d for STL files "
                            "libigl cannot read (auto), or only one")


@dataclass(frozen=True, eq=False)
class LoadResult(StageResult):
    """A mesh read from ``path``; ``polygons``: faces of more than three vertices, triangulated as fans."""

    mesh: Mesh
    path: str
    reader: str
    polygons: int = 0

    def summary(self) -> dict:
        return {"vertices": self.mesh.n_vertices, "faces": self.mesh.n_faces, "reader": self.reader,
                "polygons_triangulated": self.polygons}


def mesh_format(path: str | Path) -> str:
    """The mesh format of ``path`` ('.off', '.obj', ...), looking through a '.gz' suffix."""
    suffixes = [s.lower() for s in Path(path).suffixes]
    if suffixes and suffixes[-1] == ".gz":
        suffixes = suffixes[:-1]
    fmt = suffixes[-1] if suffixes else ""
    if fmt not in SUPPORTED_SUFFIXES:
        raise InputError(path, f"unsupported mesh format {fmt or '(no suffix)'!r}; expected one of "
                               f"{', '.join(SUPPORTED_SUFFIXES)} (optionally gzipped)")
    return fmt


@contextlib.contextmanager
def _captured_stderr() -> Iterator[list[str]]:
    """Capture what C++ code writes to file descriptors 1 and 2 (libigl's parse messages)."""
    lines: list[str] = []
    with tempfile.TemporaryFile(mode="w+b") as buf:
        saved = [os.dup(1), os.dup(2)]
        try:
            os.dup2(buf.fileno(), 1)
            os.dup2(buf.fileno(), 2)
            yield lines
        finally:
            os.dup2(saved[0], 1)
            os.dup2(saved[1], 2)
            os.close(saved[0])
            os.close(saved[1])
            buf.seek(0)
            lines.extend(buf.read().decode("utf-8", "replace").splitlines())


def _summarised(messages: list[str], keep: int = 5) -> str:
    """The distinct messages in order, each with its count when repeated, at most ``keep`` of them."""
    counts: dict[str, int] = {}
    for m in messages:
        if m.strip():
            counts[m.strip()] = counts.get(m.strip(), 0) + 1
    parts = [f"{m} (x{n})" if n > 1 else m for m, n in counts.items()]
    more = f"; and {len(parts) - keep} other messages" if len(parts) > keep else ""
    return "; ".join(parts[:keep]) + more


def _read_igl(plain: Path) -> tuple[np.ndarray, np.ndarray, str]:
    import igl

    with _captured_stderr() as messages:
        try:
            V, F = igl.read_triangle_mesh(str(plain))
            ok = True
        except RuntimeError:
            ok = False
    if not ok:
        raise ValueError(_summarised(messages) or "libigl could not parse it")
    return V, F, "igl"


def _read_pymeshlab(plain: Path) -> tuple[np.ndarray, np.ndarray, str]:
    import pymeshlab

    ms = pymeshlab.MeshSet()
    with _captured_stderr():
        try:
            ms.load_new_mesh(str(plain))
        except pymeshlab.PyMeshLabException as exc:
            detail = str(exc).strip().splitlines()
            raise ValueError(next((d.removeprefix("Error details: ") for d in detail if d.startswith("Error details")),
                                  "MeshLab could not parse it")) from None
    m = ms.current_mesh()
    return np.asarray(m.vertex_matrix(), dtype=np.float64), np.asarray(m.face_matrix(), dtype=np.int64), "pymeshlab"


def _read_plyfile(plain: Path) -> tuple[np.ndarray, np.ndarray, str]:
    """A binary big-endian PLY, read with plyfile: MeshLab's reader byte-swaps them wrongly (double
    coordinates read as 1e306, a ``ushort`` list count as a truncated file). Polygons become fans."""
    from plyfile import PlyData

    try:
        data = PlyData.read(str(plain))
        vertex = data["vertex"]
        V = np.column_stack([np.asarray(vertex[a], dtype=np.float64) for a in ("x", "y", "z")])
        face = data["face"]
        name = next(p.name for p in face.properties if p.name in ("vertex_indices", "vertex_index"))
        lists = face[name]
    except (KeyError, StopIteration) as exc:
        raise ValueError(f"no vertex x, y, z or face vertex_indices ({exc})") from None
    except Exception as exc:  # plyfile's PlyParseError, numpy's ValueError for short data
        raise ValueError(f"{type(exc).__name__}: {exc}") from None
    sizes = np.fromiter((len(f) for f in lists), dtype=np.int64, count=len(lists))
    if np.any(sizes < 3):
        raise ValueError(f"face {int(np.argmax(sizes < 3))} has fewer than 3 vertices")
    if np.all(sizes == 3):
        F = np.vstack(lists).astype(np.int64) if len(lists) else np.zeros((0, 3), np.int64)
    else:
        F = np.array([(f[0], f[k], f[k + 1]) for f in lists for k in range(1, len(f) - 1)], np.int64).reshape(-1, 3)
    return V, F, "plyfile"


def _big_endian_ply(plain: Path) -> bool:
    with open(plain, "rb") as fh:
        head = fh.read(4096)
    return head.startswith(b"ply") and b"binary_big_endian" in head.split(b"end_header")[0]


def _read_open3d(plain: Path) -> tuple[np.ndarray, np.ndarray, str]:
    import open3d as o3d

    with _captured_stderr():
        tm = o3d.io.read_triangle_mesh(str(plain))
    V = np.asarray(tm.vertices, dtype=np.float64)
    F = np.asarray(tm.triangles, dtype=np.int64)
    if V.size == 0:
        raise ValueError("open3d read no vertices")
    return V, F, "open3d"


#: Formats whose files libigl may not read (binary variants): open3d is tried after libigl for these.
OPEN3D_FALLBACK = (".stl",)


def read_mesh(path: str | Path, *, reader: str = "auto") -> tuple[Mesh, str]:
    """Read a triangle mesh file.

    Parameters
    ----------
    path : str or Path
        An OFF, OBJ, PLY or STL file, optionally gzipped (``.off.gz``).
    reader : {'auto', 'igl', 'open3d', 'pymeshlab'}
        'auto': pymeshlab for PLY; libigl for the others and, for STL only, open3d second.

    Returns
    -------
    mesh : Mesh
        ``V`` (n, 3) float64 and ``F`` (m, 3) int64, named after the file stem.
    reader : str
        The reader that succeeded.

    Raises
    ------
    InputError
        Missing or unreadable file, unknown format, a structure that does not match its header
        (truncated, under-counted, faces of fewer than 3 vertices), a file too large, parse
        failure, no faces, non-finite coordinates or face indices out of range.
    """
    mesh, used, _ = read_mesh_checked(path, reader=reader)
    return mesh, used


def read_mesh_checked(path: str | Path, *, reader: str = "auto") -> tuple[Mesh, str, FileFacts]:
    """:func:`read_mesh`, with what the structure checks found (counts, polygons)."""
    path = check_readable_file(path)
    fmt = mesh_format(path)
    auto = ([_read_pymeshlab] if fmt == ".ply" else
            [_read_igl, _read_open3d] if fmt in OPEN3D_FALLBACK else [_read_igl])
    readers = {"igl": [_read_igl], "open3d": [_read_open3d], "pymeshlab": [_read_pymeshlab], "auto": auto}[reader]
    problems = []
    with plain_file(path, fmt) as plain:
        if plain.stat().st_size == 0:
            raise InputError(path, "file is empty")
        facts = check_structure(plain, fmt, path)
        if reader == "auto" and fmt == ".ply" and _big_endian_ply(plain):
            readers = [_read_plyfile]
        for read in readers:
            try:
                V, F, used = read(plain)
            except ValueError as exc:
                problems.append(str(exc))
                continue
            if V.ndim == 2 and V.shape[0] > 0 and F.ndim == 2 and F.shape[0] > 0:
                break
            problems.append(f"{read.__name__.removeprefix('_read_')} found {len(V)} vertices and {len(F)} faces")
        else:
            raise InputError(path, f"malformed {fmt[1:].upper()} file: " + "; ".join(problems))
    _check_counts(path, fmt, V, F, facts, used)
    return _checked_mesh(path, V, F, used), used, facts


def _check_counts(path: Path, fmt: str, V: np.ndarray, F: np.ndarray, facts: FileFacts, reader: str) -> None:
    """The reader must have read what the header declares (no silently dropped vertices or faces)."""
    if fmt == ".stl":
        if facts.faces is not None and F.shape[0] != facts.faces:
            raise InputError(path, f"{reader} read {F.shape[0]} of the {facts.faces} triangles the file holds")
        return
    if facts.vertices is not None and V.shape[0] != facts.vertices:
        raise InputError(path, f"{reader} read {V.shape[0]} of the {facts.vertices} vertices the header declares")
    if facts.faces is not None and F.shape[0] < facts.faces:
        raise InputError(path, f"{reader} read {F.shape[0]} triangles from the {facts.faces} faces the file holds")


def _checked_mesh(path: Path, V: np.ndarray, F: np.ndarray, reader: str) -> Mesh:
    if V.shape[1] != 3:
        raise InputError(path, f"expected 3D vertices, got shape {V.shape}")
    if F.shape[1] != 3:
        raise InputError(path, f"expected triangles, got faces of shape {F.shape} (polygons are not supported)")
    if not np.all(np.isfinite(V)):
        raise InputError(path, f"{int((~np.isfinite(V)).any(axis=1).sum())} vertices have non-finite coordinates")
    if F.min() < 0 or F.max() >= len(V):
        raise InputError(path, f"face indices out of range [0, {len(V) - 1}] (min {F.min()}, max {F.max()})")
    name = path.name
    for suffix in (".gz",) + SUPPORTED_SUFFIXES:
        name = name.removesuffix(suffix).removesuffix(suffix.upper())
    return Mesh(V, F, name=name)


@stage("load", params=LoadParams, version=1, consumes=("path",), produces=("mesh",))
def load(path: str, *, params: LoadParams) -> LoadResult:
    """Read a mesh file (OFF, OBJ, PLY, STL, optionally gzipped), its structure checked first."""
    mesh, used, facts = read_mesh_checked(path, reader=params.reader)
    return LoadResult(mesh=mesh, path=str(path), reader=used, polygons=facts.polygons)
