"""Conversions between :class:`~topomatch.stages.mesh.mesh.Mesh` and ``open3d.geometry.TriangleMesh``.

open3d stores vertices as ``Vector3dVector`` (float64) and triangles as
``Vector3iVector`` (int32); the conversion copies in both directions. open3d is
imported inside the functions so that importing this module stays cheap.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from topomatch.stages.mesh.mesh import Mesh

if TYPE_CHECKING:  # pragma: no cover
    import open3d


def to_open3d(mesh: Mesh) -> "open3d.geometry.TriangleMesh":
    """An open3d triangle mesh with the vertices and faces of ``mesh``.

    Parameters
    ----------
    mesh : Mesh
        ``V`` (n, 3) float64, ``F`` (m, 3) int64.

    Returns
    -------
    open3d.geometry.TriangleMesh
        Vertices (n, 3) and triangles (m, 3, int32); no normals or colours.
    """
    import open3d as o3d

    return o3d.geometry.TriangleMesh(
        o3d.utility.Vector3dVector(mesh.V),
        o3d.utility.Vector3iVector(mesh.F.astype(np.int32)),
    )


def from_open3d(tm: "open3d.geometry.TriangleMesh", name: str = "mesh") -> Mesh:
    """The :class:`Mesh` of an open3d triangle mesh (copies ``V`` as float64, ``F`` as int64).

    Parameters
    ----------
    tm : open3d.geometry.TriangleMesh
    name : str
        Name of the returned mesh.
    """
    V = np.asarray(tm.vertices, dtype=np.float64).reshape(-1, 3)
    F = np.asarray(tm.triangles, dtype=np.int64).reshape(-1, 3)
    return Mesh(V.copy(), F.copy(), name=name)
