"""The FEM Laplacian: hand-computed entries, agreement with libigl, structure, input validation, stage."""

from __future__ import annotations

import numpy as np
import pytest

from topomatch.pipeline.errors import ConfigError, InputError
from topomatch.stages.mesh.mesh import Mesh
from topomatch.stages.spectral.laplacian import (LaplacianParams, check_mesh, cotangent_and_full_mass, laplacian,
                                       laplacian_stage)


def right_triangle() -> Mesh:
    """Legs of length 1 along x and y: angles 90 deg at vertex 0, 45 deg at vertices 1 and 2, area 1/2."""
    return Mesh(np.array([[0.0, 0, 0], [1, 0, 0], [0, 1, 0]]), np.array([[0, 1, 2]]), name="right")


def test_right_triangle_cotangent_entries():
    # Q_ij = -1/2 cot(angle opposite ij): edge 12 faces the right angle (cot 0), edges 01 and 02 face 45 deg (cot 1)
    Q = laplacian(right_triangle()).Q.toarray()
    expected = np.array([[1.0, -0.5, -0.5],
                         [-0.5, 0.5, 0.0],
                         [-0.5, 0.0, 0.5]])
    np.testing.assert_allclose(Q, expected, atol=1e-15)


def test_right_triangle_full_mass_entries():
    # consistent P1 mass of one triangle: area/6 on the diagonal, area/12 off it (area = 1/2)
    lap = laplacian(right_triangle(), "full")
    expected = np.full((3, 3), 1.0 / 24.0) + np.eye(3) / 24.0
    np.testing.assert_allclose(lap.K.toarray(), expected, atol=1e-16)
    assert lap.area == pytest.approx(0.5)


def test_right_triangle_voronoi_mass_entries():
    # circumcentre = midpoint of the hypotenuse: the right-angle corner gets 1/4, the two others 1/8 each
    K = laplacian(right_triangle(), "voronoi").K.toarray()
    np.testing.assert_allclose(K, np.diag([0.25, 0.125, 0.125]), atol=1e-15)


def test_equilateral_triangle_is_symmetric():
    # all angles 60 deg: every off-diagonal entry is -cot(60)/2 = -1/(2 sqrt 3)
    h = np.sqrt(3) / 2
    mesh = Mesh(np.array([[0.0, 0, 0], [1, 0, 0], [0.5, h, 0]]), np.array([[0, 1, 2]]))
    Q = laplacian(mesh).Q.toarray()
    off = -1 / (2 * np.sqrt(3))
    np.testing.assert_allclose(Q, np.full((3, 3), off) + np.eye(3) * (-3 * off), atol=1e-15)


@pytest.mark.parametrize("name", ["odedstein_spot_low_resolution.obj.gz", "odedstein_hand_lowres.obj.gz",
                                  "torus.off"])
def test_assembly_matches_libigl(bundled_mesh, name):
    import igl

    mesh = bundled_mesh(name)
    Q, K = cotangent_and_full_mass(mesh.V, mesh.F)
    L = igl.cotmatrix(mesh.V, mesh.F)
    M = igl.massmatrix(mesh.V, mesh.F, igl.MASSMATRIX_TYPE_FULL)
    assert abs(Q + L).max() <= 1e-12 * abs(L).max()
    assert abs(K - M).max() <= 1e-12 * abs(M).max()
    Mv = igl.massmatrix(mesh.V, mesh.F, igl.MASSMATRIX_TYPE_VORONOI)
    assert abs(laplacian(mesh, "voronoi").K - Mv).max() == 0.0


def test_structure(bundled_mesh):
    mesh = bundled_mesh("odedstein_spot_low_resolution.obj.gz")
    lap = laplacian(mesh)
    Q, K = lap.Q, lap.K
    assert Q.shape == K.shape == (mesh.n_vertices, mesh.n_vertices)
    assert abs(Q - Q.T).max() == 0.0 and abs(K - K.T).max() == 0.0
    np.testing.assert_allclose(np.asarray(Q.sum(axis=1)).ravel(), 0.0, atol=1e-12 * abs(Q).max())
    # same sparsity pattern (the eigensolver relies on it to form Q - sigma K cheaply)
    assert np.array_equal(Q.indptr, K.indptr) and np.array_equal(Q.indices, K.indices)
    # PSD Q, PD K (dense check on a small mesh)
    assert np.linalg.eigvalsh(Q.toarray()).min() > -1e-10
    assert np.linalg.eigvalsh(K.toarray()).min() > 0
    import igl

    assert lap.area == pytest.approx(igl.doublearea(mesh.V, mesh.F).sum() / 2, rel=1e-12)
    assert lap.K.sum() == pytest.approx(lap.area, rel=1e-12)
    assert lap.lumped_mass().sum() == pytest.approx(lap.area, rel=1e-12)


def test_rejects_empty_mesh():
    with pytest.raises(InputError, match="empty mesh") as info:
        laplacian(Mesh(np.zeros((0, 3)), np.zeros((0, 3), np.int64), name="nothing"))
    assert "nothing" in str(info.value)


def test_rejects_unreferenced_vertices():
    mesh = Mesh(np.vstack([right_triangle().V, [[5.0, 5, 5]]]), right_triangle().F, name="extra")
    with pytest.raises(InputError, match="1 vertices are used by no face.*clean"):
        laplacian(mesh)


def test_rejects_repeated_index_and_zero_area_triangles():
    V = np.array([[0.0, 0, 0], [1, 0, 0], [0, 1, 0], [2, 0, 0]])
    with pytest.raises(InputError, match="repeated vertex index"):
        laplacian(Mesh(V, np.array([[0, 1, 2], [0, 1, 1]]), name="rep"))
    with pytest.raises(InputError, match="zero area") as info:
        laplacian(Mesh(V, np.array([[0, 1, 2], [0, 1, 3]]), name="collinear"))
    assert "collinear" in str(info.value) and "drop_degenerate" in str(info.value)


def test_rejects_bad_indices_and_coordinates():
    tri = right_triangle()
    with pytest.raises(InputError, match="face indices"):
        check_mesh(Mesh(tri.V, np.array([[0, 1, 3]])))
    with pytest.raises(InputError, match="non-finite"):
        laplacian(Mesh(np.array([[0.0, 0, 0], [1, 0, 0], [0, np.nan, 0]]), tri.F))


def test_several_components_are_rejected_with_a_fix(shapes):
    mesh = shapes.disjoint_union(shapes.octahedron(), shapes.icosphere(1), name="two")
    with pytest.raises(InputError, match="2 connected components") as info:
        laplacian(mesh)
    assert "two" in str(info.value) and "components: largest" in str(info.value)
    lap = laplacian(mesh, require_connected=False)
    assert lap.n == mesh.n_vertices


def test_stage_and_params(bundled_mesh):
    from topomatch.pipeline.registry import get_stage

    spec = get_stage("laplacian")
    assert spec.consumes == ("mesh",) and spec.produces == ("laplacian",)
    mesh = bundled_mesh("odedstein_spot_low_resolution.obj.gz")
    result = laplacian_stage(mesh, params=LaplacianParams.parse({"mass": "voronoi"}, "stages[1].laplacian"))
    assert result.laplacian.mass == "voronoi"
    summary = result.summary()
    assert summary["vertices"] == mesh.n_vertices and summary["area"] > 0 and summary["mass"] == "voronoi"
    with pytest.raises(ConfigError, match="stages\\[1\\].laplacian.mass"):
        LaplacianParams.parse({"mass": "lumped"}, "stages[1].laplacian")
