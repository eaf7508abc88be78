"""Topology report: genus, boundary loops, components and manifoldness against known answers and libigl."""

from __future__ import annotations

import numpy as np
import pytest

from topomatch.stages.mesh.mesh import Mesh
from topomatch.stages.mesh.topology import edge_incidence, topology_report


@pytest.mark.parametrize("name,genus", [("torus.off", 1), ("eight_genus2.off", 2),
                                        ("odedstein_spot_low_resolution.obj.gz", 0)])
def test_genus_of_bundled_closed_meshes(bundled_mesh, name, genus):
    import igl

    mesh = bundled_mesh(name)
    r = topology_report(mesh)
    assert r.genus == genus
    assert r.euler_characteristic == 2 - 2 * genus == igl.euler_characteristic(mesh.F)
    assert r.is_closed and r.is_manifold and r.is_orientable
    assert r.n_components == 1 and r.n_boundary_loops == 0 and r.n_boundary_edges == 0
    assert r.n_edges == igl.edges(mesh.F).shape[0]


@pytest.mark.parametrize("builder,args", [("octahedron", ()), ("icosphere", (0,)), ("icosphere", (2,)),
                                          ("unit_cube", ())])
def test_sphere_like_meshes_have_genus_0(shapes, builder, args):
    mesh = getattr(shapes, builder)(*args)
    r = topology_report(mesh)
    assert (r.genus, r.euler_characteristic, r.n_components) == (0, 2, 1)
    assert r.n_edges == 3 * mesh.n_faces // 2  # closed triangle mesh: 3F = 2E
    assert r.is_closed and r.is_manifold


def test_one_missing_face_is_one_boundary_loop(shapes):
    import igl

    octa = shapes.octahedron()
    disc = Mesh(octa.V, octa.F[1:])
    r = topology_report(disc)
    assert r.n_boundary_loops == 1 == len(igl.boundary_loop_all(disc.F))
    assert r.n_boundary_edges == 3
    assert (r.euler_characteristic, r.genus) == (1, 0)
    assert not r.is_closed and r.is_manifold


def test_two_holes_in_a_torus(bundled_mesh):
    torus = bundled_mesh("torus.off")
    # remove two faces that share no vertex: two boundary loops, genus still 1
    f0 = torus.F[0]
    far = next(i for i, f in enumerate(torus.F) if not set(f) & set(f0) and i > 0)
    keep = np.ones(torus.n_faces, bool)
    keep[[0, far]] = False
    r = topology_report(Mesh(torus.V, torus.F[keep]))
    assert (r.n_boundary_loops, r.n_boundary_edges, r.genus) == (2, 6, 1)
    assert r.euler_characteristic == -2


def test_disjoint_components_are_counted_and_genus_adds(bundled_mesh, shapes):
    two = shapes.disjoint_union(shapes.octahedron(), shapes.icosphere(1))
    r = topology_report(two)
    assert (r.n_components, r.euler_characteristic, r.genus) == (2, 4, 0)

    mixed = shapes.disjoint_union(bundled_mesh("torus.off"), shapes.octahedron(), offsets=[(0, 0, 0), (10, 0, 0)])
    r = topology_report(mixed)
    assert (r.n_components, r.euler_characteristic, r.genus) == (2, 2, 1)


def test_three_triangles_on_one_edge_are_non_manifold():
    import igl

    V = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, -1, 0], [0, 0, 1]], float)
    F = np.array([[0, 1, 2], [1, 0, 3], [0, 1, 4]])
    r = topology_report(Mesh(V, F))
    assert r.n_nonmanifold_edges == 1
    assert not r.is_manifold and r.genus is None and r.is_orientable is None
    assert igl.is_edge_manifold(F)[0] is False
    E, counts = edge_incidence(F)
    assert counts[(E[:, 0] == 0) & (E[:, 1] == 1)].tolist() == [3]


def test_bow_tie_vertex_is_non_manifold():
    V = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [-1, 0, 0], [-1, -1, 0]], float)
    F = np.array([[0, 1, 2], [0, 3, 4]])
    r = topology_report(Mesh(V, F))
    assert (r.n_nonmanifold_vertices, r.n_nonmanifold_edges, r.n_components) == (1, 0, 1)
    assert not r.is_manifold and r.genus is None


def _moebius(n: int = 12) -> Mesh:
    V, F = [], []
    for i in range(n):
        a = 2 * np.pi * i / n
        for s in (-0.3, 0.3):
            r = 1 + s * np.cos(a / 2)
            V.append([r * np.cos(a), r * np.sin(a), s * np.sin(a / 2)])
    for i in range(n):
        a0, a1 = 2 * i, 2 * i + 1
        b0, b1 = (2 * i + 2, 2 * i + 3) if i < n - 1 else (1, 0)  # the half twist
        F += [[a0, b0, a1], [a1, b0, b1]]
    return Mesh(np.array(V), np.array(F))


def test_moebius_strip_is_non_orientable_with_one_boundary_loop():
    r = topology_report(_moebius())
    assert r.is_manifold and r.is_orientable is False
    assert (r.n_boundary_loops, r.euler_characteristic) == (1, 0)
    assert r.genus is None


def test_unreferenced_vertices_do_not_change_the_euler_characteristic(shapes):
    octa = shapes.octahedron()
    V = np.insert(octa.V, 2, [9.0, 9.0, 9.0], axis=0)  # an isolated vertex in the middle of V
    F = np.where(octa.F >= 2, octa.F + 1, octa.F)
    r = topology_report(Mesh(V, F))
    assert (r.euler_characteristic, r.genus, r.n_unreferenced_vertices, r.n_components) == (2, 0, 1, 1)
    # (igl.euler_characteristic(F) would count max(F) + 1 = 7 vertices here and give 3)


def test_empty_mesh():
    r = topology_report(Mesh(np.zeros((2, 3)), np.zeros((0, 3), np.int64)))
    assert (r.n_faces, r.n_unreferenced_vertices, r.genus, r.is_closed) == (0, 2, None, False)


def test_nonmanifold_vertices_agree_with_libigl(bundled_mesh):
    import igl

    from topomatch.stages.mesh.topology import nonmanifold_vertices

    mesh = bundled_mesh("odedstein_hand_lowres.obj.gz")
    F = mesh.F
    # two cones glued at one apex (a bow tie of fans) and a dangling fin on an edge
    bowtie = np.array([[0, 1, 2], [0, 2, 3], [0, 3, 1], [0, 4, 5], [0, 5, 6], [0, 6, 4], [1, 2, 7], [1, 2, 8]])
    # without the fin the mesh is edge-manifold and consistently oriented: the walk around vertices
    # (two closed fans at the apex; two open fans sharing a vertex; a closed and an open fan)
    cones, two_open = bowtie[:6], np.array([[0, 1, 2], [0, 3, 4]])
    cone_and_flap = np.vstack([bowtie[:3], [[0, 4, 5]]])
    for faces in (F, bowtie, F[: len(F) // 2], cones, two_open, cone_and_flap, F[::3]):
        n = int(faces.max()) + 1
        used = np.bincount(faces.ravel(), minlength=n) > 0  # libigl also flags unreferenced vertices
        expected = ~np.asarray(igl.is_vertex_manifold(faces), dtype=bool)[:n] & used
        np.testing.assert_array_equal(nonmanifold_vertices(faces, n), expected)
    assert nonmanifold_vertices(bowtie, 9)[0] and nonmanifold_vertices(bowtie, 9).sum() == 1


def test_inconsistently_oriented_faces_are_still_orientable(bundled_mesh):
    """Flipping half the faces breaks the orientation but not orientability (the bfs_orient fallback)."""
    torus = bundled_mesh("torus.off")
    F = torus.F.copy()
    F[::2] = F[::2, ::-1]
    r = topology_report(Mesh(torus.V, F))
    assert r.is_orientable and r.genus == 1


def test_unreferenced_vertices_do_not_count(bundled_mesh):
    torus = bundled_mesh("torus.off")
    V = np.vstack([np.zeros((3, 3)), torus.V])  # three unused vertices first: every index shifts
    r = topology_report(Mesh(V, torus.F + 3))
    assert r.n_unreferenced_vertices == 3 and r.euler_characteristic == 0 and r.genus == 1


def test_half_edge_sort_equals_a_stable_argsort_on_both_paths():
    from topomatch.stages.mesh.topology import _argsort_with_keys

    rng = np.random.default_rng(0)
    for size, bound in ((0, 5), (1, 5), (1000, 10 ** 6), (50_000, 10 ** 10), (100, 2 ** 62)):  # last: argsort path
        key = rng.integers(0, bound, size)
        order, sorted_key = _argsort_with_keys(key, bound)
        np.testing.assert_array_equal(order, np.argsort(key, kind="stable"))
        np.testing.assert_array_equal(sorted_key, np.sort(key))


def test_nonmanifold_vertices_of_a_mesh_broken_in_a_few_places_agree_with_libigl(bundled_mesh):
    """One mesh with a fin on an edge, a glued (bow-tie) vertex, faces of flipped orientation and a face
    with a repeated index: the walk answers for the vertices away from them, the corner graph at them."""
    import igl

    from topomatch.stages.mesh.topology import nonmanifold_vertices

    F = bundled_mesh("odedstein_hand_lowres.obj.gz").F.copy()
    n = int(F.max()) + 1
    F[F == 40] = 7  # glue two vertices: a bow tie at 7 (unless they shared a face)
    F[100:103] = F[100:103, ::-1]  # three faces flipped
    F = np.vstack([F, [[F[0, 0], F[0, 1], F[500, 2]], [F[300, 0], F[300, 0], F[300, 1]]]])  # a fin, a repeated index
    used = np.bincount(F.ravel(), minlength=n) > 0
    expected = ~np.asarray(igl.is_vertex_manifold(F), dtype=bool)[:n] & used
    assert expected.any()
    np.testing.assert_array_equal(nonmanifold_vertices(F, n), expected)


def test_half_edges_of_closed_and_open_meshes_match_a_plain_unique(bundled_mesh):
    """Every edge twice (the closed-manifold shortcut) or not (the run-length pass): the same edges, counts
    and pairs of half-edges as numpy's unique on the sorted vertex pairs."""
    from topomatch.stages.mesh.topology import HalfEdges

    torus = bundled_mesh("torus.off").F
    for F in (torus, torus[1:], np.vstack([torus, torus[:1]])):  # closed; one hole; a doubled face (counts 3)
        n = int(F.max()) + 1
        he = HalfEdges(F, n)
        pairs = np.sort(np.column_stack([F.ravel(), F[:, [1, 2, 0]].ravel()]), axis=1)
        E, inverse, counts = np.unique(pairs, axis=0, return_inverse=True, return_counts=True)
        np.testing.assert_array_equal(he.E, E)
        np.testing.assert_array_equal(he.counts, counts)
        order = np.argsort(inverse.ravel(), kind="stable")  # half-edges by edge, in index order
        same = inverse.ravel()[order][1:] == inverse.ravel()[order][:-1]
        np.testing.assert_array_equal(he.pair_a, order[:-1][same])
        np.testing.assert_array_equal(he.pair_b, order[1:][same])


def test_half_edges_of_vertex_indices_beyond_32_bits_are_not_wrapped():
    """Over 2^31 vertices a shifted edge key would overflow: the edges keep their true vertex indices."""
    from topomatch.stages.mesh.topology import edge_incidence

    b = 2 ** 31
    E, counts = edge_incidence(np.array([[b, b + 1, b + 2], [b + 2, b + 1, b + 3]]))
    np.testing.assert_array_equal(E, [[b, b + 1], [b, b + 2], [b + 1, b + 2], [b + 1, b + 3], [b + 2, b + 3]])
    np.testing.assert_array_equal(counts, [1, 1, 2, 1, 1])


def test_a_vertex_with_many_corners_whose_walk_ends_early_is_non_manifold_quickly():
    """Many closed three-face cones sharing an apex: one vertex with 3k corners whose walk ends after 3
    steps (several fans); the walks stop once every walk left has ended, not after 3k steps."""
    from topomatch.stages.mesh.topology import nonmanifold_vertices

    k = 2000
    base = 1 + 3 * np.arange(k)[:, None]  # cone i: apex 0 and the ring base_i, base_i + 1, base_i + 2
    ring = base + np.array([0, 1, 2])
    F = np.concatenate([np.column_stack([np.zeros(k, int), ring[:, j], ring[:, (j + 1) % 3]]) for j in range(3)])
    bad = nonmanifold_vertices(F, 1 + 3 * k)
    assert bad[0] and bad.sum() == 1
