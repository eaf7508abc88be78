"""Capping the holes of a mesh: every boundary loop closed by a fan of triangles to a new vertex at its centroid.

Retrieval by the intrinsic parts (spectrum, heat kernel, geodesic skeleton) sees a hole as part of the
shape: the Laplace-Beltrami operator with its natural (Neumann) boundary condition on an open mesh has
another spectrum than on the closed surface it was cut from, so two poses of one character, one with a
hole, look less alike. Capping each loop restores a closed surface close to the original one where the
holes are small (scanner gaps, cuts), and the same cap for every mesh of a class where they are large
(the opening of a cup). Measured in docs/retrieval.md (tune collections only).

A boundary loop is a simple cycle of boundary half-edges (the half-edges ``u -> w`` of faces whose edge
has no other face); its cap is a new vertex at the mean of the loop's vertices and one triangle per
boundary edge, ``(w, u, c)``, so the cap's orientation agrees with the face's and every boundary edge
gets one more face. A connected component of the boundary edges where every vertex has one boundary
half-edge in and one out is one loop (vectorised; the usual case). A component with a vertex shared by
several holes (two holes touching at a corner, a decimated ragged border) is walked and split at every
vertex it visits twice into simple cycles, each capped on its own: one fan over the whole component
would repeat a vertex and make its spoke edges non-manifold (found by a fuzzing pass, 2026-12-02).
Boundary half-edges that close no cycle (inconsistent orientation, a non-manifold edge) stay open.

A cap triangle through the centroid may have no area (the centroid on the line of a boundary edge: a
U-shaped flat hole, two flat holes touching at a corner, a collinear rim), which would break the cotangent
Laplacian. Such a loop's apex is lifted off the loop, along the cap's vector area (else the normal of the
loop's best-fit plane), by half the loop's RMS radius; a loop still degenerate after that stays open.
Every other loop keeps its centroid, so meshes without such loops are capped as before (version 1).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from pydantic import Field

from topomatch.pipeline.contract import Params, StageResult, stage
from topomatch.stages.mesh.geometry import double_areas_and_sq_lengths
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


#: A cap triangle is degenerate when its double area is below this times its longest squared edge (the
#: bound :func:`topomatch.stages.mesh.clean.degenerate_faces` clears faces by).
DEGENERATE_CAP = 1e-6


def _simple_cycles(u: np.ndarray, w: np.ndarray) -> list[np.ndarray]:
    """Simple cycles of the directed boundary half-edges ``u[i] -> w[i]`` (k,): lists of indices into them.

    Each walk (at a vertex with several boundary half-edges out, the next unused one) is split at every
    vertex it visits twice; the part of a walk that cannot return to its start is left out.
    A Python walk: it runs only on the few boundary components that are not simple loops.
    """
    out: dict[int, list[int]] = {}
    for i in range(len(u) - 1, -1, -1):
        out.setdefault(int(u[i]), []).append(i)
    used = np.zeros(len(u), dtype=bool)
    cycles = []
    for start in range(len(u)):
        if used[start]:
            continue
        used[start] = True
        walk, v0, at = [start], int(u[start]), int(w[start])
        while at != v0:
            choices = out.get(at, [])
            while choices and used[choices[-1]]:
                choices.pop()
            if not choices:
                break
            step = choices.pop()
            used[step] = True
            walk.append(step)
            at = int(w[step])
        position: dict[int, int] = {}
        edges: list[int] = []
        for e in walk:
            v = int(u[e])
            if v in position:  # back at v: the edges since its first visit form a simple cycle
                i = position[v]
                cycles.append(np.array(edges[i:]))
                for x in edges[i:]:
                    position.pop(int(u[x]), None)
                del edges[i:]
            position[v] = len(edges)
            edges.append(e)
        if at == v0:  # else the rest is an open path (a vertex with more boundary half-edges in than out): left open
            cycles.append(np.array(edges))
    return cycles


def _cap_geometry(V: np.ndarray, u: np.ndarray, w: np.ndarray, cycle: np.ndarray, apex: np.ndarray
                  ) -> np.ndarray:
    """(k,) bool: cap triangles ``(w, u, apex[cycle])`` of the half-edges that are degenerate, measured as the
    cotangent Laplacian measures them (:func:`~topomatch.stages.mesh.geometry.double_areas_and_sq_lengths`)."""
    k = len(u)
    corners = np.vstack([V[w], V[u], apex[cycle]])
    sq, double_area = double_areas_and_sq_lengths(corners, np.arange(3 * k).reshape(3, k).T)
    return ~(double_area > DEGENERATE_CAP * sq.max(axis=1))


def _lifted(V: np.ndarray, u: np.ndarray, w: np.ndarray, edges: np.ndarray, centre: np.ndarray) -> np.ndarray:
    """The apex of one loop (its half-edges ``edges``) lifted off it: along the cap's vector area, else the
    normal of the loop's best-fit plane, by half the loop's RMS radius."""
    P, Q = V[u[edges]] - centre, V[w[edges]] - centre
    normal = np.cross(Q, P).sum(axis=0)  # twice the vector area of the caps (w, u, centre)
    radius = float(np.sqrt(np.mean(np.sum(P ** 2, axis=1))))
    if not np.linalg.norm(normal) > 1e-9 * radius ** 2:
        normal = np.linalg.svd(P, full_matrices=True)[2][-1]
    return centre + 0.5 * radius * normal / np.linalg.norm(normal)


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
    component = label[np.searchsorted(vertices, u)]  # the component of each boundary half-edge
    size = np.bincount(label, minlength=n_loops)  # vertices per component
    centre = np.stack([np.bincount(label, weights=V[vertices, k], minlength=n_loops) for k in range(3)], axis=1)
    centre = centre / np.maximum(size, 1)[:, None]
    # a component is one simple loop when each of its vertices has one boundary half-edge out and one in
    simple = np.ones(n_loops, dtype=bool)
    odd = (np.bincount(u, minlength=n) != 1) | (np.bincount(w, minlength=n) != 1)
    simple[label[odd[vertices]]] = False
    cycle = np.where(simple[component], component, -1)  # loop of each half-edge (-1: left open)
    if not simple.all():
        rest = np.flatnonzero(~simple[component])
        split = _simple_cycles(u[rest], w[rest])
        extra = np.array([V[u[rest[c]]].mean(axis=0) for c in split]).reshape(-1, 3)
        for j, c in enumerate(split):
            cycle[rest[c]] = n_loops + j
        size = np.concatenate([np.where(simple, size, 0), [len(c) for c in split]])
        centre = np.vstack([centre, extra])
    keep = size >= 3
    if params.max_loop_vertices is not None:
        keep &= size <= params.max_loop_vertices
    capped = (cycle >= 0) & keep[np.maximum(cycle, 0)]
    bad = np.zeros(len(keep), dtype=bool)
    bad[cycle[capped][_cap_geometry(V, u[capped], w[capped], cycle[capped], centre)]] = True
    for c in np.flatnonzero(bad):  # lift the apex of a loop with a cap of no area; still flat: leave it open
        edges = np.flatnonzero(cycle == c)
        centre[c] = _lifted(V, u, w, edges, centre[c])
        if _cap_geometry(V, u[edges], w[edges], np.zeros(len(edges), np.int64), centre[c][None]).any():
            keep[c] = False
    capped = (cycle >= 0) & keep[np.maximum(cycle, 0)]
    new_id = np.cumsum(keep) - 1
    caps = np.column_stack([w[capped], u[capped], n + new_id[cycle[capped]]])
    if not caps.size:
        return FillHolesResult(mesh, 0, 0)
    filled = Mesh(np.vstack([V, centre[keep]]), np.vstack([F, caps]), name=mesh.name)
    return FillHolesResult(filled, int(keep.sum()), int(len(caps)))


@stage("fill_holes", params=FillHolesParams, version=2, consumes=("mesh",), produces=("mesh",))
def fill_holes(mesh: Mesh, *, params: FillHolesParams) -> FillHolesResult:
    """Cap every boundary loop with a fan of triangles to a new vertex at its centroid."""
    return fill_holes_mesh(mesh, params)
