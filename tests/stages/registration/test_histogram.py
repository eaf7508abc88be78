"""Joint histograms, 2D and 3D: the compiled pass against numpy, exact answers for whole-pixel shifts, mass."""

from __future__ import annotations

import numpy as np
import pytest

from topomatch.stages.registration.histogram import Binning, JointHistogram, compiled
from topomatch.stages.registration.image import Image


def _image(shape, seed=0, **geometry):
    rng = np.random.default_rng(seed)
    grids = np.meshgrid(*[np.linspace(0, 3, n) for n in shape], indexing="ij")
    return Image(np.sin(sum(grids)) * 40 + rng.random(shape) * 20 + 50, **geometry)


def test_binning_covers_the_range():
    b = Binning.of(np.array([2.0, 4.0, 10.0]), 4)
    np.testing.assert_array_equal(b.index(np.array([2.0, 3.99, 4.0, 9.99, 10.0, 11.0, -5.0])), [0, 0, 1, 3, 3, 3, 0])
    with pytest.raises(ValueError, match="constant"):
        Binning.of(np.ones(3), 4)


@pytest.mark.parametrize("shape", [(30, 40), (12, 14, 16)])
@pytest.mark.parametrize("mode", ["linear", "parzen", "pv"])
def test_compiled_pass_equals_numpy(shape, mode):
    """On rotated, shifted and partly outside positions: the same inside counts and histograms (to round-off; a
    'linear' sample exactly on a bin edge may fall on either side, at most a few of them)."""
    if not compiled():
        pytest.skip("the compiled extension is not built: numpy is the only path")
    d = len(shape)
    fixed = _image(shape, 1, spacing=(1.0, 1.2, 0.9)[:d])
    moving = _image(shape, 2, spacing=(1.1, 0.8, 1.0)[:d], origin=(2.0, -1.0, 0.5)[:d])
    jh = JointHistogram(fixed, moving, Binning.of(fixed.data, 12), Binning.of(moving.data, 10),
                        center=fixed.center, mode=mode, jitter=True, seed=3)
    jh.threads = 3  # the compiled pass split over threads adds up to the same histogram
    rng = np.random.default_rng(4)
    for _ in range(10):
        theta = np.r_[rng.uniform(-0.4, 0.4, 1 if d == 2 else 3), rng.uniform(-8, 8, d)]
        (h, n), (ref, n_ref) = jh(theta), jh.histogram_numpy(theta)
        assert n == n_ref and 0 < n
        tol = 4.0 if mode == "linear" else 1e-9 * n
        np.testing.assert_allclose(h, ref, rtol=0, atol=tol)
        assert h.sum() == pytest.approx(n)  # every inside sample adds a mass of one


@pytest.mark.parametrize("shape", [(30, 40), (10, 12, 14)])
def test_whole_pixel_shift_gives_the_exact_joint_histogram(shape):
    """Shifting by whole pixels samples pixel values exactly: the histogram is the count of (fixed bin, moving
    bin) pairs of the overlapping pixels, computed here by slicing, for every mode."""
    d = len(shape)
    fixed, moving = _image(shape, 5), _image(shape, 6)
    shift = np.array([3, -2, 1][:d])  # ITK order
    fb, mb = Binning.of(fixed.data, 8), Binning.of(moving.data, 8)
    src = tuple(slice(max(0, -s), n - max(0, s)) for s, n in zip(shift[::-1], shape))
    dst = tuple(slice(max(0, s), n - max(0, -s)) for s, n in zip(shift[::-1], shape))
    expected = np.zeros((8, 8))
    np.add.at(expected, (fb.index(fixed.data[src]).ravel(), mb.index(moving.data[dst]).ravel()), 1.0)
    theta = np.r_[np.zeros(1 if d == 2 else 3), shift.astype(float)]
    for mode in ("linear", "pv"):
        h, n = JointHistogram(fixed, moving, fb, mb, center=fixed.center, mode=mode)(theta)
        assert n == expected.sum()
        np.testing.assert_allclose(h, expected, atol=1e-9)


def test_identity_puts_all_mass_on_the_diagonal():
    im = _image((20, 24, 10))
    b = Binning.of(im.data, 16)
    for mode in ("linear", "pv"):
        h, n = JointHistogram(im, im, b, b, center=im.center, mode=mode)(np.zeros(6))
        assert n == im.data.size
        np.testing.assert_allclose(h, np.diag(np.diag(h)), atol=1e-9)


def test_samples_outside_are_dropped_and_counted():
    im = _image((12, 14, 16))
    b = Binning.of(im.data, 8)
    jh = JointHistogram(im, im, b, b, center=im.center, samples=1000, seed=1)
    assert jh.n_samples == 1000 and jh(np.zeros(6))[1] == 1000
    far = np.array([0, 0, 0, 1000.0, 0, 0])
    assert jh(far)[1] == 0 and jh.overlap(far) == 0.0
    half, n = jh(np.array([0, 0, 0, 8.0, 0, 0]))
    assert 0 < n < 1000 and half.sum() == pytest.approx(n) and jh.overlap(np.array([0, 0, 0, 8.0, 0, 0])) == n / 1000


def test_subsets_masks_and_jitter_are_seeded():
    im = _image((50, 60))
    b = Binning.of(im.data, 8)
    mask = np.zeros(im.shape, bool)
    mask[10:20, 10:30] = True
    a = JointHistogram(im, im, b, b, center=im.center, samples=150, mask=mask, jitter=True, seed=3)
    c = JointHistogram(im, im, b, b, center=im.center, samples=150, mask=mask, jitter=True, seed=3)
    assert a.n_samples == 150
    theta = np.array([0.1, 2.0, 3.0])
    np.testing.assert_array_equal(a(theta)[0], c(theta)[0])
    idx = np.rint(a.positions(np.zeros(3))).astype(int)  # identity: the jittered samples stay in their pixels
    assert mask[idx[1], idx[0]].all()
    with pytest.raises(ValueError, match="selects no pixel"):
        JointHistogram(im, im, b, b, center=im.center, mask=np.zeros(im.shape, bool))


def test_shuffled_keeps_the_marginals():
    im = _image((30, 40))
    b = Binning.of(im.data, 8)
    jh = JointHistogram(im, im, b, b, center=im.center)
    h, s = jh(np.zeros(3))[0], jh.shuffled(1)(np.zeros(3))[0]
    np.testing.assert_allclose(h.sum(axis=0), s.sum(axis=0))
    np.testing.assert_allclose(h.sum(axis=1), s.sum(axis=1))
    assert np.trace(s) < 0.5 * np.trace(h)
