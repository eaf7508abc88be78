"""Capping the holes of a mesh: every boundary loop closed by a fan of triangles to a new vertex at its centroid.

Retrieval by the intrinsic parts (spectrum, heat kernel, geodesic skeleton) sees a hole as part of the
shape: the Laplace-Beltrami operator with its natural (Neumann) boundary condition on an open mesh has
another spectrum than on the closed surface it was cut from, so two poses of one character, one with a
hole, look less alike. Capping each loop restores a closed surface close to the original one where the
holes are small (scanner gaps, cuts), and the same cap for every mesh of a class where they are large
(the opening of a cup). Measured in docs/retrieval.md (tune collections only).

A boundary loop is a connected component of the boundary edges (edges with one face); its cap is a new
vertex at the mean of the loop's vertices and one triangle per boundary edge, ``(w, u, c)`` for the
boundary half-edge ``u -> w`` of a face, so the cap's orientation agrees with the face's. No ordering
of the loop is needed, so loops through a vertex shared by two holes are capped too (as one loop).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from pydantic import Field

from topomatch.pipeline.contract import Params, StageResult, stage
from topomatch.stages.mesh.mesh import Mesh
from topomatch.stages.mesh.topology import HalfEdges, boundary_loops


class FillHolesParams(Params):
    """Parameters of :func:`fill_holes`."""

    max_loop_vertices: int | None = Field(
        None, ge=3, description="cap only boundary loops of at most this many vertices (None: every loop)")


@dataclass(frozen=True, eq=False)
class FillHolesResult(StageResult):
    """A mesh with its holes capped.

    Attributes
    ----------
    mesh : Mesh
        The input's vertices and faces, then one vertex per capped loop and the cap triangles.
    filled_loops : int
        Boundary loops capped.
    added_faces : int
        Cap triangles (one per boundary edge of the capped loops).
    """

    mesh: Mesh
    filled_loops: int
    added_faces: int

    def summary(self) -> dict:
        return {"vertices": self.mesh.n_vertices, "faces": self.mesh.n_faces, "filled_loops": self.filled_loops,
                "added_faces": self.added_faces}


def fill_holes_mesh(mesh: Mesh, params: FillHolesParams | None = None) -> FillHolesResult:
    """Cap the boundary loops of ``mesh`` (module docstring).

    Parameters
    ----------
    mesh : Mesh
        ``V`` (n, 3) float64, ``F`` (m, 3) int64.
    params : FillHolesParams, optional

    Returns
    -------
    FillHolesResult
        The same mesh object when it has no boundary (nothing to cap).
    """
    params = params or FillHolesParams()
    V, F, n = mesh.V, mesh.F, mesh.n_vertices
    he = HalfEdges(F, n)
    h = np.flatnonzero(he.twin < 0)  # half-edges on an edge of one face
    if not h.size:
        return FillHolesResult(mesh, 0, 0)
    u, w = he.ends(h)
    n_loops, vertices, label = boundary_loops(np.column_stack([u, w]))
    loop = label[np.searchsorted(vertices, u)]  # the loop of each boundary half-edge
    size = np.bincount(label, minlength=n_loops)  # vertices per loop
    keep = size >= 3
    if params.max_loop_vertices is not None:
        keep &= size <= params.max_loop_vertices
    new_id = np.cumsum(keep) - 1
    capped = keep[loop]
    centre = np.stack([np.bincount(label, weights=V[vertices, k], minlength=n_loops) for k in range(3)], axis=1)
    centre = centre[keep] / size[keep, None]
    caps = np.column_stack([w[capped], u[capped], n + new_id[loop[capped]]])
    if not caps.size:
        return FillHolesResult(mesh, 0, 0)
    filled = Mesh(np.vstack([V, centre]), np.vstack([F, caps]), name=mesh.name)
    return FillHolesResult(filled, int(keep.sum()), int(len(caps)))


@stage("fill_holes", params=FillHolesParams, version=1, consumes=("mesh",), produces=("mesh",))
def fill_holes(mesh: Mesh, *, params: FillHolesParams) -> FillHolesResult:
    """Cap every boundary loop with a fan of triangles to a new vertex at its centroid."""
    return fill_holes_mesh(mesh, params)
