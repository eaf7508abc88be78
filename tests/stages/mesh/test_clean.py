"""The clean stage repairs vertex soups, degenerate and duplicated faces, and handles components."""

from __future__ import annotations

import numpy as np
import pytest
from pydantic import ValidationError

from topomatch.pipeline.errors import ConfigError, InputError
from topomatch.stages.mesh.clean import CleanParams, clean, clean_mesh
from topomatch.stages.mesh.mesh import Mesh


def _with_isolated_vertex(mesh: Mesh, position=(5.0, 5.0, 5.0)) -> Mesh:
    return Mesh(np.vstack([mesh.V, position]), mesh.F, name=mesh.name)


def test_soup_with_isolated_vertex_becomes_the_closed_octahedron(shapes):
    octa = shapes.octahedron()
    broken = _with_isolated_vertex(shapes.soup(octa))  # 24 + 1 vertices, 8 faces
    result = clean(broken, params=CleanParams())
    assert result.merged_vertices == 24 - 6
    assert result.unreferenced_vertices == 1
    assert (result.degenerate_faces, result.duplicate_faces, result.dropped_components) == (0, 0, 0)
    assert (result.mesh.n_vertices, result.mesh.n_faces) == (6, 8)
    # the soup: 8 separate triangles, all edges on the boundary; the result: a closed sphere
    assert (result.before.n_components, result.before.n_boundary_edges, result.before.is_closed) == (8, 24, False)
    assert result.after.is_closed and result.after.is_manifold
    assert (result.after.genus, result.after.euler_characteristic, result.after.n_components) == (0, 2, 1)
    # same triangles as the original
    np.testing.assert_allclose(np.sort(result.mesh.V[result.mesh.F].reshape(-1, 9), axis=0),
                               np.sort(octa.V[octa.F].reshape(-1, 9), axis=0))
    assert result.mesh.name == "octahedron"
    s = result.summary()
    assert s["merged_vertices"] == 18 and s["unreferenced_vertices"] == 1 and s["genus"] == 0 and s["closed"]


def test_stl_soup_of_bundled_torus_is_repaired(tmp_path, bundled_mesh):
    import igl

    from topomatch.stages.mesh.io import read_mesh

    torus = bundled_mesh("torus.off")
    path = tmp_path / "torus.stl"
    igl.write_triangle_mesh(str(path), torus.V, torus.F, igl.FileEncoding.Binary)  # float32 corners
    soup, _ = read_mesh(path)
    assert soup.n_vertices == 3 * torus.n_faces
    result = clean_mesh(soup)
    assert (result.mesh.n_vertices, result.mesh.n_faces) == (torus.n_vertices, torus.n_faces)
    assert result.after.genus == 1 and result.after.is_closed


def test_merge_tolerance_is_relative_to_the_bbox_diagonal(shapes):
    octa = shapes.octahedron()
    soup = shapes.soup(octa)
    rng = np.random.default_rng(3)
    diag = 2 * np.sqrt(3)
    jitter = rng.uniform(-1, 1, soup.V.shape) * 1e-13 * diag
    near = clean_mesh(soup.with_vertices(soup.V + jitter))
    # jitter 1e-13 * diag << grid cell 1e-9 * diag, and the coordinates 0, +-1 lie far from cell borders
    assert near.mesh.n_vertices == 6
    exact = clean_mesh(soup.with_vertices(soup.V + jitter), CleanParams(merge_tolerance=0.0))
    assert exact.merged_vertices == 0 and exact.mesh.n_vertices == 24
    coarse = clean_mesh(soup.with_vertices(soup.V + 1e4 * jitter), CleanParams(merge_tolerance=1e-3))
    assert coarse.mesh.n_vertices == 6


def test_degenerate_and_duplicate_faces_are_dropped(shapes):
    octa = shapes.octahedron()
    V = np.vstack([octa.V, [[0.5, 0.5, 0.0]]])  # vertex 6 on the segment 0-2: collinear face (0, 6, 2)
    F = np.vstack([octa.F,
                   [[0, 0, 4]],          # repeated index
                   [[0, 6, 2]],          # zero area (three distinct collinear vertices)
                   octa.F[3][::-1],      # the same face, reversed
                   octa.F[5]])           # an exact copy
    result = clean_mesh(Mesh(V, F, name="octa"))
    assert result.degenerate_faces == 2
    assert result.duplicate_faces == 2
    assert result.unreferenced_vertices == 1  # vertex 6 was used only by the dropped zero-area face
    assert result.mesh.n_faces == 8 and result.after.is_closed and result.after.genus == 0


def test_repairs_can_be_switched_off(shapes):
    octa = shapes.octahedron()
    F = np.vstack([octa.F, octa.F[:1]])
    kept = clean_mesh(Mesh(octa.V, F), CleanParams(drop_duplicate_faces=False))
    assert kept.mesh.n_faces == 9 and kept.after.n_nonmanifold_edges == 3
    F = np.vstack([octa.F, [[0, 0, 1]]])
    kept = clean_mesh(Mesh(octa.V, F), CleanParams(drop_degenerate=False))
    assert kept.mesh.n_faces == 9 and kept.degenerate_faces == 0


def test_components(shapes):
    octa, ico = shapes.octahedron(), shapes.icosphere(1)  # 8 and 80 faces
    two = shapes.disjoint_union(octa, ico, name="pair")
    all_kept = clean_mesh(two)
    assert all_kept.after.n_components == 2 and all_kept.mesh.n_faces == 88

    largest = clean_mesh(two, CleanParams(components="largest"))
    assert (largest.mesh.n_faces, largest.mesh.n_vertices) == (ico.n_faces, ico.n_vertices)
    assert (largest.dropped_components, largest.dropped_component_faces, largest.dropped_component_vertices) == (1, 8, 6)
    np.testing.assert_allclose(largest.mesh.V.mean(axis=0), [3.0, 0.0, 0.0], atol=1e-12)  # the moved icosphere
    assert largest.after.n_components == 1

    with pytest.raises(InputError) as info:
        clean_mesh(two, CleanParams(components="fail"))
    assert "pair" in str(info.value) and "2 connected components" in str(info.value)
    assert "clean.components=largest" in str(info.value)


def test_fail_on_nonmanifold(shapes):
    V = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, -1, 0], [0, 0, 1]], float)
    F = np.array([[0, 1, 2], [1, 0, 3], [0, 1, 4]])
    fan = Mesh(V, F, name="fan")
    assert clean_mesh(fan).after.n_nonmanifold_edges == 1
    with pytest.raises(InputError, match="fan: mesh has 1 non-manifold edges"):
        clean_mesh(fan, CleanParams(fail_on_nonmanifold=True))
    assert clean_mesh(shapes.octahedron(), CleanParams(fail_on_nonmanifold=True)).after.is_manifold


def test_nothing_left_is_an_input_error():
    V = np.array([[0, 0, 0], [1, 0, 0], [2, 0, 0]], float)
    with pytest.raises(InputError, match="line: no faces left"):
        clean_mesh(Mesh(V, np.array([[0, 1, 2]]), name="line"))
    with pytest.raises(InputError, match="nofaces: mesh has no faces"):
        clean_mesh(Mesh(V, np.zeros((0, 3), np.int64), name="nofaces"))


@pytest.mark.parametrize("scale, word", [(1e300, "overflow"), (1e-300, "underflow")])
def test_a_mesh_out_of_double_precision_range_is_refused_by_its_size(shapes, scale, word):
    octa = shapes.octahedron()
    with pytest.raises(InputError, match=rf"the mesh is 2e[+-]300 units across: .* {word} double precision"):
        clean_mesh(Mesh(octa.V * scale, octa.F, name="scaled"))
    # inside the range the octahedron is cleaned unchanged, whatever its size
    for ok in (1e-45, 1e45):
        assert clean_mesh(Mesh(octa.V * ok, octa.F, name="scaled")).after.genus == 0


def test_a_mesh_at_one_point_is_refused():
    with pytest.raises(InputError, match="all vertices are at one point"):
        clean_mesh(Mesh(np.zeros((3, 3)), np.array([[0, 1, 2]]), name="point"))


@pytest.mark.parametrize("name", ["torus.off", "eight_genus2.off", "odedstein_hand_lowres.obj.gz"])
def test_clean_meshes_pass_unchanged(bundled_mesh, name):
    mesh = bundled_mesh(name)
    result = clean_mesh(mesh)
    np.testing.assert_array_equal(result.mesh.V, mesh.V)
    np.testing.assert_array_equal(result.mesh.F, mesh.F)
    assert result.before == result.after


def test_params_validation():
    with pytest.raises(ValidationError):
        CleanParams(merge_tolerance=-1.0)
    with pytest.raises(ConfigError, match=r"stages\[1\].clean.components"):
        CleanParams.parse({"components": "biggest"}, "stages[1].clean")
    with pytest.raises(ConfigError, match="unknown key"):
        CleanParams.parse({"largest_component": True}, "stages[1].clean")


def test_clean_records_closedness_and_moves_keep_it(bundled_mesh):
    from topomatch.stages.mesh.clean import CleanParams, clean_mesh
    from topomatch.stages.reeb.reeb_graph import is_closed_manifold

    torus = clean_mesh(bundled_mesh("torus.off"), CleanParams()).mesh
    assert torus.closed_manifold is True and is_closed_manifold(torus.F)
    assert torus.with_vertices(2.0 * torus.V).closed_manifold is True
    half = Mesh(torus.V, torus.F[: len(torus.F) // 2], name="half")
    opened = clean_mesh(half, CleanParams(components="largest")).mesh
    assert opened.closed_manifold is False and not is_closed_manifold(opened.F)
    assert Mesh(torus.V, torus.F).closed_manifold is None  # unknown unless clean said so


def test_a_clean_mesh_is_passed_through_with_one_topology_report(bundled_mesh, monkeypatch):
    """Nothing to repair: the same arrays come back, and the topology is measured once (before = after)."""
    import topomatch.stages.mesh.clean as clean_module

    mesh = bundled_mesh("eight_genus2.off")
    calls = []
    real = clean_module.topology_report
    monkeypatch.setattr(clean_module, "topology_report", lambda m, *a: calls.append(m) or real(m, *a))
    result = clean_module.clean_mesh(mesh, clean_module.CleanParams(components="largest"))
    assert result.mesh.V is mesh.V and result.mesh.F is mesh.F
    assert result.after is result.before and len(calls) == 1
    assert result.after.genus == 2 and result.mesh.closed_manifold


def test_duplicate_faces_keep_the_first_occurrence():
    from topomatch.stages.mesh.clean import duplicate_faces

    F = np.array([[0, 1, 2], [2, 3, 4], [2, 1, 0], [1, 2, 0], [4, 3, 2], [5, 6, 7]])
    np.testing.assert_array_equal(duplicate_faces(F), [False, False, True, True, True, False])
    big = np.array([[0, 1, 2], [3_000_000, 1, 2], [2, 1, 3_000_000]])  # keys beyond int64: the row-wise path
    np.testing.assert_array_equal(duplicate_faces(big), [False, False, True])


@pytest.mark.parametrize("eps", [0.0, 1e-3, 0.05, 0.1, 0.3])
def test_merging_agrees_with_libigl_on_points_near_grid_cell_borders(eps):
    """The fast no-duplicate check must see exactly the cells ``igl.remove_duplicate_vertices`` compares:
    points on and next to half-cells (rounding half away from zero, -0.0 against 0.0) merge as libigl merges
    them, and a mesh without duplicates comes back as the same arrays."""
    import igl

    from topomatch.stages.mesh.clean import merge_duplicate_vertices

    rng = np.random.default_rng(3)
    for _ in range(40):
        offsets = rng.choice([0.0, 1e-12, -1e-12, 0.01, -0.01, 0.49, -0.49], size=(60, 3))
        V = (rng.integers(-6, 6, size=(60, 3)) * 0.5 + offsets) * (eps or 1.0)
        V[:2] = [[0.0, -0.0, 0.0], [-0.0, 0.0, -0.0]]
        F = np.arange(60).reshape(20, 3)  # every vertex in a face: merged F is the map old -> new vertex
        merged_V, merged_F = merge_duplicate_vertices(V, F, eps)
        SV, _, SVJ, _ = igl.remove_duplicate_vertices(V, F, eps)
        ours, theirs = merged_F.ravel(), np.asarray(SVJ).ravel()
        assert merged_V.shape[0] == SV.shape[0]
        np.testing.assert_array_equal(ours[:, None] == ours[None, :], theirs[:, None] == theirs[None, :])
    for _ in range(300):  # one near pair among well-separated points: the fast check decides alone when it
        V = rng.standard_normal((60, 3)) * 100 * (eps or 1.0)  # finds no duplicate cell
        V[5] = V[7] + 0.3 * (eps or 1.0) * rng.choice([-1, 1], size=3)
        merged_V, _ = merge_duplicate_vertices(V, F, eps)
        assert merged_V.shape[0] == igl.remove_duplicate_vertices(V, F, eps)[0].shape[0]
    distinct = np.random.default_rng(4).standard_normal((50, 3))
    F = np.array([[0, 1, 2]])
    V2, F2 = merge_duplicate_vertices(distinct, F, 1e-6)
    assert V2 is distinct and F2 is F


def test_a_merge_tolerance_too_small_for_double_precision_merges_exact_copies_only(shapes):
    """At 1e-310 of the diagonal, V / eps overflows and libigl's grid would put whole octants in one cell."""
    s = shapes.icosphere(2)
    result = clean_mesh(Mesh(s.V, s.F, name="ico"), CleanParams(merge_tolerance=1e-310))
    assert result.merged_vertices == 0 and result.mesh.n_vertices == len(s.V)


def test_degenerate_faces_are_those_of_herons_formula_on_near_degenerate_triangles():
    """libigl's cross-product areas only clear faces for certain: the mask equals the stable Heron
    formula's (the Laplacian's) on needles and flat triangles at every scale, far from the origin too."""
    from topomatch.stages.mesh.clean import degenerate_faces
    from topomatch.stages.mesh.geometry import double_areas_and_sq_lengths

    rng = np.random.default_rng(0)
    for scale in (1e-45, 1e-8, 1.0, 1e6, 1e45):
        m = 20_000
        P = rng.standard_normal((m, 3, 3))
        t = rng.uniform(-2, 3, (m, 1))
        height = 10.0 ** rng.uniform(-20, -2, (m, 1)) * (rng.random((m, 1)) < 0.8)  # 20 % exactly on the line
        P[:, 2] = P[:, 0] + t * (P[:, 1] - P[:, 0]) + height * rng.standard_normal((m, 3))
        V = (P.reshape(-1, 3) + rng.standard_normal(3) * 1e3) * scale
        F = np.arange(3 * m).reshape(m, 3)
        F[::97, 2] = F[::97, 0]  # repeated indices
        heron = ~(double_areas_and_sq_lengths(V, F)[1] > 0) | (F[:, 0] == F[:, 2])
        mask = degenerate_faces(V, F)
        assert 0.2 < mask.mean() < 0.9  # both kinds are present in numbers
        np.testing.assert_array_equal(mask, heron)
