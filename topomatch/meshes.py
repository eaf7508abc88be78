"""Reading a mesh: the Python API's :func:`read_mesh`."""

from __future__ import annotations

from pathlib import Path

from topomatch.stages.mesh.io import LoadParams
from topomatch.stages.mesh.io import read_mesh as _read
from topomatch.stages.mesh.mesh import Mesh


def read_mesh(path: str | Path, *, reader: str | None = None) -> Mesh:
    """The triangle mesh in ``path`` (OFF, OBJ, PLY, STL, optionally gzip-compressed).

    Parameters
    ----------
    path : path
        The mesh file.
    reader : {'auto', 'igl', 'open3d'}, optional
        libigl first then open3d, or only one of them (default: the ``load`` stage's, 'auto').

    Returns
    -------
    Mesh
        ``V`` (n, 3) float64, ``F`` (m, 3) int64, named after the file's stem.

    Raises
    ------
    InputError
        Missing, unreadable or malformed file (the message names it).
    """
    return _read(path, reader=LoadParams.model_validate({} if reader is None else {"reader": reader}).reader)[0]
