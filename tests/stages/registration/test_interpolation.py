"""N-linear sampling and resampling, 2D and 3D: exact on affine images, the inside rule, SimpleITK's Resample."""

from __future__ import annotations

import math

import numpy as np
import pytest

from topomatch.stages.registration.image import Image
from topomatch.stages.registration.interpolation import linear, resample
from topomatch.stages.registration.transform import RigidTransform

SimpleITK = pytest.importorskip("SimpleITK")


@pytest.mark.parametrize("shape", [(20, 30), (12, 14, 16)])
def test_linear_is_exact_on_affine_images(shape):
    """N-linear interpolation reproduces an affine function of the index exactly."""
    coefficients = np.array([2.0, -3.0, 0.5])[: len(shape)]
    grids = np.meshgrid(*[np.arange(n, dtype=float) for n in shape], indexing="ij")  # array order
    data = 7.0 + sum(c * g for c, g in zip(coefficients, grids[::-1]))  # c0 * i + c1 * j (+ c2 * k)
    rng = np.random.default_rng(0)
    index = np.stack([rng.uniform(0, n - 1, 300) for n in shape[::-1]])  # ITK order
    values, inside = linear(data, index)
    assert inside.all()
    np.testing.assert_allclose(values, 7.0 + coefficients @ index, atol=1e-10)


def test_inside_means_within_the_pixel_centres():
    data = np.zeros((10, 20))
    index = np.array([[0.0, 19.0, -1e-9, 19.0 + 1e-9, 5.0, 5.0], [0.0, 9.0, 3.0, 3.0, -0.5, 9.5]])
    np.testing.assert_array_equal(linear(data, index)[1], [True, True, False, False, False, False])


def _sitk(image: Image):
    from topomatch.stages.registration.io import to_sitk

    return to_sitk(image)


@pytest.mark.parametrize("d", [2, 3])
def test_resample_equals_simpleitk(d):
    """Same transform and geometry (anisotropic, oblique, offset): our linear resampling equals SimpleITK's
    Resample wherever T(p) is inside the moving grid, and is the fill value elsewhere."""
    rng = np.random.default_rng(d)
    shape = (30, 40) if d == 2 else (14, 16, 18)
    direction = np.eye(d)
    c, s = math.cos(0.3), math.sin(0.3)
    direction[:2, :2] = [[c, -s], [s, c]]
    moving = Image(rng.random(shape) * 100, spacing=(1.2, 0.8, 1.5)[:d], origin=(5.0, -3.0, 2.0)[:d],
                   direction=direction)
    fixed = Image(np.zeros(shape), spacing=(1.0, 1.1, 1.3)[:d], origin=(4.0, -2.0, 1.0)[:d])
    t = RigidTransform(tuple(rng.uniform(-0.2, 0.2, 1 if d == 2 else 3)) + tuple(rng.uniform(-3, 3, d)),
                       tuple(fixed.center))
    ours = resample(moving, t, fixed, fill=-1.0)
    theirs = SimpleITK.GetArrayFromImage(SimpleITK.Resample(_sitk(moving), _sitk(fixed), t.to_sitk(),
                                                            SimpleITK.sitkLinear, -1.0, SimpleITK.sitkFloat64))
    index = moving.continuous_index(t.apply(fixed.points())).T
    inside = linear(moving.data, index)[1].reshape(shape)
    assert 0.3 < inside.mean() < 1.0
    np.testing.assert_allclose(ours[inside], theirs[inside], atol=1e-3)  # SimpleITK's input is float32
    assert np.all(ours[~inside] == -1.0)


def test_resample_identity_cubic_and_chunks():
    data = np.random.default_rng(1).random((17, 23))
    im = Image(data)
    identity = RigidTransform.identity(tuple(im.center))
    np.testing.assert_allclose(resample(im, identity, im), data, atol=1e-12)
    np.testing.assert_allclose(resample(im, identity, im, order=3), data, atol=1e-6)
    np.testing.assert_allclose(resample(im, identity, im, chunk=7), data, atol=1e-12)
    flat = np.array([[0, 5], [22, 17 * 23 - 1]])
    np.testing.assert_allclose(resample(im, identity, im, flat=flat), data.ravel()[flat], atol=1e-12)
