"""Capping holes: every boundary loop closed by a fan to its centroid, orientation kept, nothing else touched."""

from __future__ import annotations

import numpy as np

from topomatch.stages.mesh.fill_holes import FillHolesParams, fill_holes_mesh
from topomatch.stages.mesh.mesh import Mesh
from topomatch.stages.mesh.topology import topology_report


def _with_holes(mesh: Mesh, centres: list[int], radius: float) -> Mesh:
    """``mesh`` without the faces whose centroid lies within ``radius`` of the given vertices."""
    c = mesh.V[mesh.F].mean(axis=1)
    near = np.zeros(mesh.n_faces, dtype=bool)
    for v in centres:
        near |= np.linalg.norm(c - mesh.V[v], axis=1) < radius
    return Mesh(mesh.V, mesh.F[~near], name=mesh.name)


def test_holes_in_a_sphere_and_a_torus_are_capped_to_the_closed_surface(shapes, bundled_mesh):
    """Euler characteristic and genus of the closed surface come back; the caps agree with the faces'
    orientation (a consistently oriented, closed manifold); the original vertices and faces are kept."""
    for mesh, holes, genus in ((shapes.icosphere(3), [0, 40, 100], 0), (bundled_mesh("torus.off"), [0, 300], 1)):
        holed = _with_holes(mesh, holes, 0.25 * np.ptp(mesh.V, axis=0).max() / 4)
        before = topology_report(holed)
        assert before.n_boundary_loops == len(holes) and not before.is_closed
        result = fill_holes_mesh(holed)
        after = topology_report(result.mesh)
        assert after.is_closed and after.is_manifold and after.is_orientable and after.genus == genus
        assert result.filled_loops == len(holes) and result.added_faces == before.n_boundary_edges
        np.testing.assert_array_equal(result.mesh.V[: holed.n_vertices], holed.V)
        np.testing.assert_array_equal(result.mesh.F[: holed.n_faces], holed.F)
        # every interior edge traversed once each way: the caps are oriented as the faces around them
        F = result.mesh.F
        directed = np.column_stack([F.ravel(), F[:, [1, 2, 0]].ravel()])
        assert len(np.unique(directed, axis=0)) == len(directed)


def test_a_cap_restores_the_area_of_a_flat_hole():
    """A square of 8 x 8 cells without its 2 x 2 centre: the cap's area is the hole's (a planar fan)."""
    n = 9
    x, y = np.meshgrid(np.arange(n, dtype=float), np.arange(n, dtype=float), indexing="ij")
    V = np.column_stack([x.ravel(), y.ravel(), np.zeros(n * n)])
    idx = np.arange(n * n).reshape(n, n)
    cells = [(i, j) for i in range(n - 1) for j in range(n - 1) if not (3 <= i <= 4 and 3 <= j <= 4)]
    F = np.array([f for i, j in cells for f in ([idx[i, j], idx[i + 1, j], idx[i + 1, j + 1]],
                                                 [idx[i, j], idx[i + 1, j + 1], idx[i, j + 1]])])
    result = fill_holes_mesh(Mesh(V, F), FillHolesParams(max_loop_vertices=8))  # the hole's loop: 8 vertices
    import igl

    caps = result.mesh.F[len(F):]
    assert result.filled_loops == 1 and len(caps) == 8  # the outer border (32 vertices) is left open
    assert np.isclose(igl.doublearea(result.mesh.V, caps).sum() / 2, 4.0)


def test_a_closed_mesh_comes_back_unchanged(shapes):
    mesh = shapes.icosphere(2)
    result = fill_holes_mesh(mesh)
    assert result.mesh is mesh and result.filled_loops == 0 and result.added_faces == 0
