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


def _grid(n: int, removed: set[tuple[int, int]]) -> tuple[np.ndarray, np.ndarray]:
    """A flat n x n grid of unit cells (two triangles each, counter-clockwise) without the cells ``removed``."""
    x, y = np.meshgrid(np.arange(n + 1, dtype=float), np.arange(n + 1, dtype=float), indexing="ij")
    V = np.column_stack([x.ravel(), y.ravel(), np.zeros((n + 1) ** 2)])
    idx = np.arange((n + 1) ** 2).reshape(n + 1, n + 1)
    F = np.array([f for i in range(n) for j in range(n) if (i, j) not in removed
                  for f in ([idx[i, j], idx[i + 1, j], idx[i + 1, j + 1]], [idx[i, j], idx[i + 1, j + 1], idx[i, j + 1]])])
    return V, F


def _cap_edges_manifold(result) -> bool:
    F = result.mesh.F
    edges = np.sort(np.column_stack([F.ravel(), F[:, [1, 2, 0]].ravel()]), axis=1)
    return int(np.unique(edges, axis=0, return_counts=True)[1].max()) <= 2


def test_two_holes_touching_at_a_corner_get_one_cap_each():
    """Two removed cells sharing only a corner: one boundary component with a vertex of four boundary edges.
    One fan over it would repeat that vertex (non-manifold spokes) and put its apex on it (caps of no area);
    split into its two loops, each hole gets its own cap, of the hole's area, and no edge has three faces."""
    import igl

    V, F = _grid(6, {(2, 2), (3, 3)})
    result = fill_holes_mesh(Mesh(V, F), FillHolesParams(max_loop_vertices=4))  # the outer border stays open
    caps = result.mesh.F[len(F):]
    assert result.filled_loops == 2 and len(caps) == 8
    assert result.mesh.n_vertices == len(V) + 2
    assert _cap_edges_manifold(result)
    areas = igl.doublearea(result.mesh.V, caps) / 2
    assert np.all(areas > 0.1) and np.isclose(areas.sum(), 2.0)


def test_a_cap_whose_centroid_lies_on_its_rim_is_lifted_off_it():
    """A U-shaped hole (five cells) in a flat grid: its centroid lies on the line of the notch's edges, so a
    fan to it has triangles of no area, which the cotangent Laplacian refuses. The apex is lifted off the
    plane (a tent over the hole): every cap triangle has area and the capped mesh has a Laplacian."""
    from topomatch.stages.spectral.laplacian import laplacian

    V, F = _grid(7, {(2, 2), (3, 2), (4, 2), (2, 3), (4, 3)})
    result = fill_holes_mesh(Mesh(V, F), FillHolesParams(max_loop_vertices=12))
    caps = result.mesh.F[len(F):]
    assert result.filled_loops == 1 and len(caps) == 12
    apex = result.mesh.V[-1]
    assert abs(apex[2]) > 0.1  # lifted out of the plane
    a, b, c = (result.mesh.V[caps[:, k]] for k in range(3))
    double_area = np.linalg.norm(np.cross(b - a, c - a), axis=1)
    assert np.all(double_area > 1e-3)
    capped = Mesh(result.mesh.V, result.mesh.F)
    assert laplacian(capped).Q.shape == (capped.n_vertices, capped.n_vertices)


def test_boundary_edges_that_close_no_loop_stay_open(shapes):
    """A face flipped at the rim of a hole: its boundary half-edges run against the others, so no cycle
    closes through them. They are left open rather than capped by a fan that would fold over the face."""
    from topomatch.stages.mesh.topology import HalfEdges

    mesh = _with_holes(shapes.icosphere(3), [0], 0.3)
    assert topology_report(mesh).n_boundary_loops == 1
    he = HalfEdges(mesh.F, mesh.n_vertices)
    rim = int(np.flatnonzero(he.twin < 0)[0] // 3)  # a face with an edge on the hole's rim
    F = mesh.F.copy()
    F[rim] = F[rim, ::-1]
    result = fill_holes_mesh(Mesh(mesh.V, F))
    assert result.filled_loops == 0 and result.mesh.n_faces == len(F)
