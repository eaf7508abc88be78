"""Conversions between :class:`~topomatch.stages.mesh.mesh.Mesh` and ``pymeshlab.MeshSet``.

A MeshSet holds a stack of meshes; :func:`to_meshset` makes a set with one mesh
(the current one) and :func:`from_meshset` reads the *current* mesh back. pymeshlab
returns faces as int32 and may leave deleted elements behind until ``compact()``;
:func:`from_meshset` reads the compacted matrices. pymeshlab is imported inside
the functions so that importing this module stays cheap.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from topomatch.stages.mesh.mesh import Mesh

if TYPE_CHECKING:  # pragma: no cover
    import pymeshlab


def to_meshset(mesh: Mesh) -> "pymeshlab.MeshSet":
    """A MeshSet whose current mesh has the vertices and faces of ``mesh``.

    Parameters
    ----------
    mesh : Mesh
        ``V`` (n, 3) float64, ``F`` (m, 3) int64.

    Returns
    -------
    pymeshlab.MeshSet
        One mesh, labelled ``mesh.name``.
    """
    import pymeshlab

    ms = pymeshlab.MeshSet()
    ms.add_mesh(pymeshlab.Mesh(vertex_matrix=mesh.V, face_matrix=mesh.F.astype(np.int32)), mesh.name)
    return ms


def from_meshset(ms: "pymeshlab.MeshSet", name: str = "mesh") -> Mesh:
    """The :class:`Mesh` of the current mesh of ``ms`` (V float64 (n, 3), F int64 (m, 3)).

    Parameters
    ----------
    ms : pymeshlab.MeshSet
    name : str
        Name of the returned mesh.
    """
    m = ms.current_mesh()
    if not m.is_compact():
        m.compact()
    V = np.array(m.vertex_matrix(), dtype=np.float64).reshape(-1, 3)
    F = np.array(m.face_matrix(), dtype=np.int64).reshape(-1, 3)
    return Mesh(V, F, name=name)
