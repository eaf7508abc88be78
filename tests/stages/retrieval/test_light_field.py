"""The light field descriptor: the dodecahedron's rotation group, Zernike moments of known images, invariances and
discrimination.

Tolerances. A silhouette is rasterised at 96 pixels a side: a shape rotated by one of the dodecahedron's own
rotations is seen from the same axes, but each silhouette is resampled on another pixel grid (another in-plane
orientation), which moves the features by about 2 % (measured on SHREC'07 meshes: per-axis L1 0.03-0.11 against a
feature norm of about 4; 2.4 % of the distance to the nearest other ellipsoid in the test below); the tests
allow 5 %.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from topomatch.pipeline.errors import InputError
from topomatch.stages.mesh.mesh import Mesh
from topomatch.stages.retrieval.baselines import light_field as lf
from topomatch.stages.retrieval.catalogue import METHODS


def ellipsoid(a: float, b: float, c: float) -> Mesh:
    """An ellipsoid with semi-axes a, b, c (a scaled 642-vertex icosphere)."""
    from shapes import icosphere

    sphere = icosphere(3)
    return Mesh(sphere.V * np.array([a, b, c]), sphere.F, name=f"ellipsoid {a}x{b}x{c}")


def disc_image(n: int, radius: float = 1.0, centre=(0.0, 0.0)) -> np.ndarray:
    c = (np.arange(n) + 0.5) / n * 2 - 1
    X, Y = np.meshgrid(c, c)
    return np.hypot(X - centre[0], Y - centre[1]) <= radius


def test_the_dodecahedron_has_60_rotations_permuting_its_10_axes():
    R = lf.dodecahedron_rotations()
    assert R.shape == (60, 3, 3)
    assert np.allclose(np.einsum("rij,rkj->rik", R, R), np.eye(3), atol=1e-12)
    assert np.allclose(np.linalg.det(R), 1.0)
    products = np.einsum("aij,bjk->abik", R[:7], R[:7]).reshape(-1, 9)
    assert all(np.abs(R.reshape(60, 9) - p).max(axis=1).min() < 1e-9 for p in products)  # closed
    axes = lf.dodecahedron_axes()
    assert axes.shape == (10, 3) and np.allclose(np.linalg.norm(axes, axis=1), 1)
    # every pair of axes of a regular dodecahedron makes one of the angles arccos(+-sqrt(5)/3), arccos(+-1/3)
    cosines = np.abs(axes @ axes.T)[~np.eye(10, dtype=bool)]
    assert np.allclose(np.sort(np.unique(np.round(cosines, 9))), [1 / 3, math.sqrt(5) / 3])
    P = lf.axis_permutations()
    assert all(sorted(p) == list(range(10)) for p in P) and len({tuple(p) for p in P}) == 60


def test_zernike_moments_of_the_unit_disc_and_their_invariance():
    basis = lf.zernike_basis(128)
    disc = disc_image(128).astype(float)
    A = np.abs(basis @ disc.ravel())
    assert A[0] == pytest.approx(1.0, abs=5e-3)  # A_00 = (1 / pi) * area of the disc
    assert A[1:].max() < 0.02                     # orthogonality: the disc is V_00
    blob = disc_image(128, 0.3, (0.35, -0.2)) | disc_image(128, 0.2, (-0.4, 0.3))
    F = lf.features(np.stack([blob, np.rot90(blob), np.fliplr(blob)]))
    assert np.allclose(F[1, :36], F[0, :36], rtol=1e-5, atol=1e-6)  # a quarter turn of the pixel grid is exact
    assert np.allclose(F[2, :36], F[0, :36], rtol=1e-5, atol=1e-6)  # magnitudes ignore a reflection
    assert np.allclose(F[1:, 36:], F[0, 36:], atol=0.02)
    assert lf.features(disc_image(128, 0.6)[None])[0, 36:].max() < 0.05  # a disc's centroid distance is constant


def test_a_moved_scaled_shape_is_its_own_nearest_and_shapes_differ():
    params = lf.LightFieldParams(light_fields=2)
    rod, slab, ball = ellipsoid(3, 1, 1), ellipsoid(2, 2, 0.5), ellipsoid(1, 1, 1)
    R = lf.dodecahedron_rotations()[17]
    moved = Mesh(rod.V @ R.T * 2.5 + np.array([4.0, -1, 2]), rod.F)
    X = np.stack([lf.descriptor(m, params) for m in (rod, moved, slab, ball)])
    D = lf.distance_matrix(X)  # its upper triangle, mirrored
    assert np.allclose(lf.distance_matrix(X, X), D, atol=1e-4) and np.allclose(np.diag(D), 0)
    assert D[0, 1] < 0.05 * min(D[0, 2], D[0, 3], D[2, 3])
    assert D[0, 1] < 0.05 * min(D[1, 2], D[1, 3])


def test_distance_matrix_shapes_and_bad_sizes():
    X = np.random.default_rng(0).random((3, 2 * lf.AXES * lf.FEATURES)).astype(np.float32)
    assert lf.distance_matrix(X, X[:2]).shape == (3, 2)
    assert lf.distance(X[0], X[1]) == pytest.approx(lf.distance_matrix(X)[0, 1])
    with pytest.raises(ValueError, match="multiple of 460"):
        lf.distance_matrix(X[:, :-1])
    with pytest.raises(ValueError, match="differ in size"):
        lf.distance_matrix(X, X[:, :lf.AXES * lf.FEATURES])


def test_a_mesh_without_area_names_itself():
    flat = Mesh(np.zeros((3, 3)), np.array([[0, 1, 2]]), name="flat.off")
    with pytest.raises(InputError, match="flat.off"):
        lf.descriptor(flat)


def test_the_catalogue_record_runs_the_stage():
    method = METHODS["lfd"]
    assert method.kind == "vector" and method.chain[-1] == "light_field"
