"""Bilinear and partial-volume sampling, resampling (checked against SimpleITK), joint histograms."""

from __future__ import annotations

import numpy as np
import pytest

from topomatch.stages.registration.histogram import Binning, JointHistogram, joint_histogram_reference
from topomatch.stages.registration.interpolation import bilinear, downsample, partial_volume, resample
from topomatch.stages.registration.transform import RigidTransform, grid_points


def test_bilinear_is_exact_on_affine_images():
    rows, cols = np.mgrid[0:20, 0:30].astype(float)
    data = 2.0 * cols - 3.0 * rows + 7.0
    rng = np.random.default_rng(0)
    u, v = rng.uniform(0, 29, 500), rng.uniform(0, 19, 500)
    values, inside = bilinear(data, u, v)
    assert inside.all()
    np.testing.assert_allclose(values, 2 * u - 3 * v + 7, atol=1e-12)


def test_inside_means_within_the_pixel_centres():
    data = np.zeros((10, 20))
    u = np.array([0.0, 19.0, -1e-9, 19.0 + 1e-9, 5.0, 5.0])
    v = np.array([0.0, 9.0, 3.0, 3.0, -0.5, 9.5])
    _, inside = bilinear(data, u, v)
    np.testing.assert_array_equal(inside, [True, True, False, False, False, False])


def test_partial_volume_weights():
    idx, w, inside = partial_volume((10, 20), np.array([3.25, 30.0]), np.array([4.5, 1.0]))
    np.testing.assert_allclose(w[:, 0], [0.75 * 0.5, 0.25 * 0.5, 0.75 * 0.5, 0.25 * 0.5])
    np.testing.assert_array_equal(idx[:, 0], [4 * 20 + 3, 4 * 20 + 4, 5 * 20 + 3, 5 * 20 + 4])
    assert inside.tolist() == [True, False] and w[:, 1].sum() == 0


def test_resample_agrees_with_simpleitk(pd_slice):
    """Same transform, same convention: our bilinear resampling equals SimpleITK's Resample inside the image."""
    from topomatch.stages.registration.simpleitk_reference import sitk_resample

    T = RigidTransform.for_image(pd_slice.shape, 7.3, -4.1, 12.5)
    ours = resample(pd_slice, T, pd_slice.shape)
    theirs = sitk_resample(pd_slice, T, pd_slice.shape)
    pts = T.apply(grid_points(pd_slice.shape))
    H, W = pd_slice.shape
    inside = ((pts[:, 0] >= 0) & (pts[:, 0] <= W - 1) & (pts[:, 1] >= 0) & (pts[:, 1] <= H - 1)).reshape(H, W)
    assert inside.mean() > 0.8
    np.testing.assert_allclose(ours[inside], theirs[inside], atol=1e-3)  # SimpleITK resamples in float32
    assert np.all(ours[~inside] == 0)


def test_resample_identity_and_cubic(pd_slice):
    I = RigidTransform.for_image(pd_slice.shape)
    np.testing.assert_array_equal(resample(pd_slice, I, pd_slice.shape), pd_slice.data)
    np.testing.assert_allclose(resample(pd_slice, I, pd_slice.shape, order=3), pd_slice.data, atol=1e-6)
    with pytest.raises(ValueError, match="order must be 1"):
        resample(pd_slice, I, pd_slice.shape, order=2)


def test_downsample_block_mean():
    data = np.arange(6 * 8, dtype=float).reshape(6, 8)
    d = downsample(data, 2)
    assert d.shape == (3, 4)
    assert d[0, 0] == np.mean([0, 1, 8, 9])
    assert downsample(np.arange(35.0).reshape(5, 7), 2).shape == (2, 3)  # remainders dropped


def test_binning_covers_the_range():
    b = Binning.of(np.array([2.0, 4.0, 10.0]), 4)
    np.testing.assert_array_equal(b.index(np.array([2.0, 3.99, 4.0, 9.99, 10.0, 11.0, -5.0])), [0, 0, 1, 3, 3, 3, 0])
    with pytest.raises(ValueError, match="constant"):
        Binning.of(np.ones(3), 4)


def test_fast_histogram_equals_reference(pd_slice, t1_slice):
    T = RigidTransform.for_image(pd_slice.shape, 5.5, -3.25, 8.0)
    fb, mb = Binning.of(t1_slice.data, 24), Binning.of(pd_slice.data, 24)
    jh = JointHistogram(t1_slice.data, pd_slice.data, fb, mb, center=t1_slice.center)
    h, n_inside = jh(T.params)
    pts = T.apply(grid_points(t1_slice.shape))
    values, inside = bilinear(pd_slice.data, pts[:, 0], pts[:, 1])
    ref = joint_histogram_reference(t1_slice.data.ravel()[inside], values[inside], fb, mb)
    assert n_inside == inside.sum()
    np.testing.assert_array_equal(h, ref)


def test_partial_volume_histogram_mass_and_identity(pd_slice):
    b = Binning.of(pd_slice.data, 16)
    jh = JointHistogram(pd_slice.data, pd_slice.data, b, b, center=pd_slice.center, interpolation="pv")
    h, n = jh(np.zeros(3))
    assert n == pd_slice.data.size
    np.testing.assert_allclose(h, np.diag(np.diag(h)), atol=1e-9)  # identity: all mass on the diagonal
    h2, n2 = jh(np.array([3.3, -2.7, 4.0]))
    assert h2.sum() == pytest.approx(n2)  # weights of a sample sum to one


def test_pyramid_level_positions_are_full_resolution():
    """At factor f, level pixel [r, c] sits at full-resolution (f c + (f-1)/2, f r + (f-1)/2)."""
    data = np.random.default_rng(1).random((40, 48))
    b = Binning.of(data, 8)
    jh = JointHistogram(downsample(data, 4), downsample(data, 4), b, b, factor=4, center=(23.5, 19.5))
    u, v = jh.positions(np.zeros(3))
    H, W = downsample(data, 4).shape
    np.testing.assert_allclose(u.reshape(H, W)[0], np.arange(W))  # identity maps level pixels to themselves
    np.testing.assert_allclose(v.reshape(H, W)[:, 0], np.arange(H))
    u, _ = jh.positions(np.array([4.0, 0.0, 0.0]))  # 4 full-resolution pixels = 1 level pixel
    np.testing.assert_allclose(u.reshape(H, W)[0], np.arange(W) + 1)


def test_sample_subset_is_seeded():
    data = np.random.default_rng(2).random((50, 60))
    b = Binning.of(data, 8)
    a = JointHistogram(data, data, b, b, center=(29.5, 24.5), samples=500, seed=3)
    c = JointHistogram(data, data, b, b, center=(29.5, 24.5), samples=500, seed=3)
    assert a.n_samples == 500
    np.testing.assert_array_equal(a(np.array([1.0, 2.0, 3.0]))[0], c(np.array([1.0, 2.0, 3.0]))[0])
