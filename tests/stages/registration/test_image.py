"""The image type, 2D and 3D: ITK's geometry checked against SimpleITK, pyramid levels, centroid, Otsu, radius."""

from __future__ import annotations

import math

import numpy as np
import pytest

from topomatch.stages.registration.image import Image, foreground_mask, grow, otsu_threshold, rms_radius

SimpleITK = pytest.importorskip("SimpleITK")


def _sitk_image(shape, spacing, origin, angle):
    """A SimpleITK image with an oblique direction (rotated by ``angle`` in the first two axes)."""
    img = SimpleITK.GetImageFromArray(np.arange(np.prod(shape), dtype=np.float32).reshape(shape))
    img.SetSpacing(spacing)
    img.SetOrigin(origin)
    c, s = math.cos(angle), math.sin(angle)
    direction = np.eye(len(shape))
    direction[:2, :2] = [[c, -s], [s, c]]
    img.SetDirection(tuple(direction.ravel()))
    return img


@pytest.mark.parametrize("shape,spacing,origin", [((6, 7), (0.9, 1.3), (3.0, -7.0)),
                                                  ((6, 7, 8), (0.9, 1.3, 2.5), (3.0, -7.0, 11.0))])
def test_geometry_matches_simpleitk(shape, spacing, origin):
    img = _sitk_image(shape, spacing, origin, 0.4)
    d = len(shape)
    ours = Image(SimpleITK.GetArrayFromImage(img), img.GetSpacing(), img.GetOrigin(),
                 np.reshape(img.GetDirection(), (d, d)))
    assert ours.dim == d and ours.size == img.GetSize()
    rng = np.random.default_rng(0)
    idx = rng.uniform(0, 5, (5, d))
    theirs = np.array([img.TransformContinuousIndexToPhysicalPoint(tuple(i)) for i in idx])
    np.testing.assert_allclose(ours.physical(idx), theirs, atol=1e-12)
    np.testing.assert_allclose(ours.continuous_index(theirs), idx, atol=1e-12)
    corner = np.array(img.TransformContinuousIndexToPhysicalPoint(tuple(float(n - 1) for n in img.GetSize())))
    np.testing.assert_allclose(ours.center, (np.asarray(img.GetOrigin()) + corner) / 2, atol=1e-12)
    # pixel flat index f of data.ravel() is at its ITK index: data[j, i] (2D) at (i, j)
    flat = np.array([0, 1, ours.data.size - 1])
    np.testing.assert_allclose(ours.points(flat), [img.TransformIndexToPhysicalPoint(
        tuple(int(v) for v in np.unravel_index(f, ours.shape)[::-1])) for f in flat], atol=1e-12)


def test_a_png_has_pixel_coordinates():
    im = Image(np.zeros((217, 181)))
    assert im.spacing == (1.0, 1.0) and im.origin == (0.0, 0.0)
    np.testing.assert_array_equal(im.center, [90.0, 108.0])  # ((W - 1) / 2, (H - 1) / 2)
    np.testing.assert_array_equal(im.points(np.array([181 * 3 + 5])), [[5.0, 3.0]])  # pixel [r, c] at (c, r)


@pytest.mark.parametrize("d", [2, 3])
def test_shrink_is_a_block_mean_centred_on_its_block(d):
    shape = (6, 8) if d == 2 else (6, 8, 5)
    im = Image(np.arange(np.prod(shape), dtype=float).reshape(shape), spacing=(0.5,) * d, origin=(1.0,) * d)
    half = im.shrink((2,) * d)
    assert half.shape == tuple(n // 2 for n in shape) and half.spacing == (1.0,) * d
    block = im.data[tuple(slice(0, 2) for _ in range(d))]
    assert half.data.flat[0] == block.mean()
    np.testing.assert_allclose(half.physical(np.zeros((1, d)))[0], im.physical(np.full((1, d), 0.5))[0])
    assert im.shrink((1,) * d) is im


def test_shrink_to_a_spacing_keeps_enough_pixels():
    vol = Image(np.zeros((62, 128, 128)), spacing=(2.0, 2.0, 3.0))
    assert vol.shrink_to(8.0).size == (32, 32, 20)  # factors 4, 4, 3 (8 / 3 rounds to 3)
    assert vol.shrink_to(8.0, min_size=24).size == (32, 32, 31)  # k keeps 24 voxels or more: factor 2
    assert vol.shrink_to(0.0) is vol


@pytest.mark.parametrize("d", [2, 3])
def test_centroid_of_a_single_bright_pixel_is_its_position(d):
    shape = (9, 11) if d == 2 else (9, 11, 7)
    data = np.zeros(shape)
    where = (2, 7) if d == 2 else (2, 7, 4)
    data[where] = 5.0
    im = Image(data, spacing=(0.5, 2.0, 3.0)[:d], origin=(10.0, -3.0, 1.0)[:d])
    np.testing.assert_allclose(im.centroid(), im.physical(np.array(where[::-1], dtype=float)[None, :])[0])


def test_otsu_matches_simpleitk_and_splits_two_levels():
    rng = np.random.default_rng(5)
    values = np.r_[rng.normal(20, 3, 4000), rng.normal(100, 5, 2000)]
    img = SimpleITK.GetImageFromArray(values.reshape(60, 100).astype(np.float32))
    f = SimpleITK.OtsuThresholdImageFilter()
    f.SetNumberOfHistogramBins(256)
    f.Execute(img)
    assert otsu_threshold(values) == pytest.approx(f.GetThreshold(), abs=(values.max() - values.min()) / 256)
    assert foreground_mask(Image(values.reshape(60, 100))).sum() == 2000


@pytest.mark.parametrize("d", [2, 3])
def test_content_is_the_otsu_class_off_the_border(d):
    """A bright object on a dark background and its negative have the same content: the object."""
    shape = (24, 30, 20)[:d]
    grids = np.meshgrid(*[np.arange(n) - (n - 1) / 2 for n in shape], indexing="ij")
    disc = sum(g ** 2 for g in grids) < 8.0 ** 2
    data = np.where(disc, 100.0, 10.0)
    assert np.array_equal(foreground_mask(Image(data)), disc)
    assert np.array_equal(foreground_mask(Image(110.0 - data)), disc)
    half = np.where(grids[0] < 0, 100.0, 10.0)  # half the border bright, half dark: the bright half
    assert np.array_equal(foreground_mask(Image(half)), grids[0] < 0)
    filled = np.where(disc, 10.0, 100.0)
    filled[:3] = 10.0  # bright on 60-80 % of the border: no background, all is content
    assert foreground_mask(Image(filled)).all()


def test_rms_radius_of_a_full_grid_is_closed_form():
    H, W = 41, 61
    assert rms_radius(Image(np.zeros((H, W)))) == pytest.approx(math.sqrt((W * W - 1) / 12 + (H * H - 1) / 12))
    vol = Image(np.zeros((5, 6, 7)), spacing=(2.0, 3.0, 4.0))
    sizes = np.array([7, 6, 5]) * np.array([2.0, 3.0, 4.0])
    expected = math.sqrt(sum(((n * n - 1) / 12.0) * s * s for n, s in zip((7, 6, 5), (2.0, 3.0, 4.0))))
    assert rms_radius(vol) == pytest.approx(expected) and sizes.all()


def test_bad_geometry_is_refused():
    with pytest.raises(ValueError, match="2D .* or 3D"):
        Image(np.zeros(5))
    with pytest.raises(ValueError, match="spacing"):
        Image(np.zeros((4, 4)), spacing=(1.0, 0.0))
    with pytest.raises(ValueError, match="singular"):
        Image(np.zeros((4, 4)), direction=np.zeros((2, 2)))


@pytest.mark.parametrize("d", [2, 3])
def test_grow_is_a_box_of_half_width_distance_over_spacing(d):
    shape = (9, 11) if d == 2 else (9, 11, 7)
    mask = np.zeros(shape, bool)
    centre = tuple(n // 2 for n in shape)
    mask[centre] = True
    spacing = (1.0, 2.0, 0.5)[:d]  # ITK order: x (the last array axis) first
    grown = grow(mask, 2.0, spacing)
    half = [int(round(2.0 / s)) for s in spacing][::-1]  # array order
    expected = np.zeros(shape, bool)
    expected[tuple(slice(c - h, c + h + 1) for c, h in zip(centre, half))] = True
    np.testing.assert_array_equal(grown, expected)
    np.testing.assert_array_equal(grow(mask, 0.0, spacing), mask)
