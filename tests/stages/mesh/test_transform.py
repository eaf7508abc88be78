"""Similarity transforms: known rotations, invariants, and the 4x4 matrix."""

from __future__ import annotations

import numpy as np
import pytest
from pydantic import ValidationError

from topomatch.pipeline.errors import ConfigError
from topomatch.stages.mesh.mesh import Mesh
from topomatch.stages.mesh.transform import TransformParams, transform


def _point(p) -> Mesh:
    return Mesh(np.array([p], float), np.zeros((0, 3), np.int64), name="point")


@pytest.mark.parametrize("axis,angle,p,expected", [
    ((0.0, 0.0, 1.0), 90.0, (1, 0, 0), (0, 1, 0)),
    ((0.0, 0.0, 2.0), -90.0, (1, 0, 0), (0, -1, 0)),       # axis length does not matter
    ((1.0, 0.0, 0.0), 90.0, (0, 1, 0), (0, 0, 1)),
    ((1.0, 1.0, 1.0), 120.0, (1, 0, 0), (0, 1, 0)),          # cyclic permutation of the axes
    ((0.0, 1.0, 0.0), 180.0, (1, 2, 3), (-1, 2, -3)),
])
def test_known_rotations(axis, angle, p, expected):
    result = transform(_point(p), params=TransformParams(axis=axis, angle_deg=angle))
    np.testing.assert_allclose(result.mesh.V[0], expected, atol=1e-12)


def test_full_formula_about_the_centroid():
    V = np.array([[0, 0, 0], [2, 0, 0], [0, 2, 0]], float)  # centroid (2/3, 2/3, 0)
    tri = Mesh(V, np.array([[0, 1, 2]]), name="tri")
    params = TransformParams(angle_deg=90.0, scale=2.0, translation=(1.0, 0.0, 0.0), center="centroid")
    result = transform(tri, params=params)
    c = V.mean(axis=0)
    R = np.array([[0, -1, 0], [1, 0, 0], [0, 0, 1]], float)
    np.testing.assert_allclose(result.mesh.V, 2.0 * (V - c) @ R.T + c + [1, 0, 0], atol=1e-12)
    hom = np.c_[V, np.ones(3)] @ result.matrix.T
    np.testing.assert_allclose(hom[:, :3], result.mesh.V, atol=1e-12)
    np.testing.assert_allclose(hom[:, 3], 1.0)


def test_rotation_and_translation_keep_edge_lengths_and_topology(bundled_mesh):
    import igl

    mesh = bundled_mesh("eight_genus2.off")
    params = TransformParams(axis=(0.3, -1.0, 2.0), angle_deg=37.0, translation=(4.0, -2.0, 9.0))
    out = transform(mesh, params=params).mesh
    E = igl.edges(mesh.F)
    before = np.linalg.norm(mesh.V[E[:, 0]] - mesh.V[E[:, 1]], axis=1)
    after = np.linalg.norm(out.V[E[:, 0]] - out.V[E[:, 1]], axis=1)
    np.testing.assert_allclose(after, before, rtol=1e-12)
    np.testing.assert_array_equal(out.F, mesh.F)


@pytest.mark.parametrize("s", [0.5, 3.0])
def test_scale_multiplies_area_by_s_squared(bundled_mesh, s):
    import igl

    mesh = bundled_mesh("torus.off")
    out = transform(mesh, params=TransformParams(scale=s, angle_deg=10.0, center="centroid")).mesh
    assert igl.doublearea(out.V, out.F).sum() == pytest.approx(s ** 2 * igl.doublearea(mesh.V, mesh.F).sum(), rel=1e-12)
    np.testing.assert_allclose(out.V.mean(axis=0), mesh.V.mean(axis=0), atol=1e-12)  # the centre is fixed


def test_identity_by_default(shapes):
    octa = shapes.octahedron()
    result = transform(octa, params=TransformParams())
    np.testing.assert_array_equal(result.mesh.V, octa.V)
    np.testing.assert_array_equal(result.matrix, np.eye(4))


def test_invalid_params():
    with pytest.raises(ValidationError, match="non-zero"):
        TransformParams(axis=(0.0, 0.0, 0.0), angle_deg=10.0)
    with pytest.raises(ConfigError, match=r"stages\[0\].transform.scale"):
        TransformParams.parse({"scale": 0.0}, "stages[0].transform")
    with pytest.raises(ConfigError, match=r"stages\[0\].transform.axis"):
        TransformParams.parse({"axis": [0, 1]}, "stages[0].transform")
    with pytest.raises(ConfigError, match=r"stages\[0\].transform.center"):
        TransformParams.parse({"center": "bbox"}, "stages[0].transform")
    assert TransformParams.parse({"axis": [0, 1, 0], "translation": [1, 2, 3]}, "s").axis == (0.0, 1.0, 0.0)
