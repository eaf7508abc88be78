"""Mixture distance (thesis ch. 3): range, invariance, centres, and the literal variant."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from topomatch.stages.morse.centroid import enclosing_sphere_center, surface_centroid, vertex_mean
from topomatch.stages.morse.height import principal_height
from topomatch.stages.morse.mixture import mixture_distance


def _similarity(V, rng, scale=2.5):
    R = Rotation.random(random_state=rng).as_matrix()
    return scale * V @ R.T + rng.normal(size=3) * 10


@pytest.mark.parametrize("kind", ["mixture", "euclidean", "affine"])
def test_normalised_to_unit_interval(bundled_mesh, kind):
    m = bundled_mesh("odedstein_spot_low_resolution.obj.gz")
    f = mixture_distance(m.V, m.F, kind=kind).values
    assert f.min() == 0.0 and f.max() == 1.0


@pytest.mark.parametrize("centroid", ["vertices", "area", "enclosing_sphere"])
def test_invariant_to_rotation_translation_scale(bundled_mesh, centroid):
    m = bundled_mesh("odedstein_fish_low_resolution.obj.gz")
    rng = np.random.default_rng(1)
    a = mixture_distance(m.V, m.F, centroid=centroid)
    b = mixture_distance(_similarity(m.V, rng), m.F, centroid=centroid)
    tol = 1e-9 if centroid != "enclosing_sphere" else 1e-5  # the iterative centre converges to ~1e-9 of the size
    np.testing.assert_allclose(b.values, a.values, atol=tol)
    assert b.info["lambda"] == pytest.approx(a.info["lambda"], abs=tol)


def test_literal_thesis_formula_is_not_scale_invariant(bundled_mesh):
    m = bundled_mesh("odedstein_fish_low_resolution.obj.gz")
    a = mixture_distance(m.V, m.F, euclidean_scale="none")
    b = mixture_distance(10 * m.V, m.F, euclidean_scale="none")
    assert abs(a.info["lambda"] - b.info["lambda"]) > 1e-3


def test_data_dependent_lambda_is_the_max_ratio(bundled_mesh):
    m = bundled_mesh("torus.off")
    Q = m.V - m.V.mean(axis=0)
    e = (Q**2).sum(1)
    e = e / e.mean()
    A = len(Q) * np.linalg.inv(Q.T @ Q)
    a = np.einsum("ij,jk,ik->i", Q, A, Q)
    assert np.mean(a) == pytest.approx(3.0)  # trace identity of the affine term
    lam = mixture_distance(m.V, m.F).info["lambda"]
    assert lam == pytest.approx(np.max(e / (e + a)))
    fixed = mixture_distance(m.V, m.F, lam=0.3)
    d = 0.3 * e + 0.7 * a
    np.testing.assert_allclose(fixed.values, (d - d.min()) / (d.max() - d.min()), atol=1e-12)


def test_centres_of_a_lopsided_cube_cloud():
    rng = np.random.default_rng(0)
    corners = np.array([[x, y, z] for x in (0, 1) for y in (0, 1) for z in (0, 1)], float)
    cluster = 0.05 * rng.random((200, 3))  # many points near one corner
    V = np.vstack([corners, cluster])
    np.testing.assert_allclose(enclosing_sphere_center(V), [0.5, 0.5, 0.5], atol=1e-4)
    assert np.linalg.norm(vertex_mean(V) - 0.5) > 0.3


def test_surface_centroid_ignores_sampling_density(shapes):
    cube = shapes.unit_cube()
    import igl

    V, F = igl.upsample(cube.V, cube.F, number_of_subdivs=2)
    F = F[: len(F) // 2 + 4]  # not closed anymore but a valid surface patch; compare with per-face formula
    P = V[F]
    area = 0.5 * np.linalg.norm(np.cross(P[:, 1] - P[:, 0], P[:, 2] - P[:, 0]), axis=1)
    expected = (area[:, None] * P.mean(1)).sum(0) / area.sum()
    np.testing.assert_allclose(surface_centroid(V, F), expected, atol=1e-12)
    np.testing.assert_allclose(surface_centroid(cube.V, cube.F), [0.5, 0.5, 0.5], atol=1e-12)


def test_flat_mesh_is_rejected():
    from topomatch.pipeline.errors import StageError

    V = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 1, 0]], float)
    F = np.array([[0, 1, 2], [1, 3, 2]])
    with pytest.raises(StageError, match="plane"):
        mixture_distance(V, F)


def test_height_follows_the_long_axis():
    rng = np.random.default_rng(2)
    V = rng.normal(size=(500, 3)) * [5.0, 1.0, 0.5]
    h = principal_height(V).values
    assert abs(np.corrcoef(h, V[:, 0])[0, 1]) > 0.99
