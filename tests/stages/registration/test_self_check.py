"""The self-check is right both ways: correct results pass, wrong ones are flagged (issue 11).

Cases: self-registration (the answer is the identity), small images (33 x 41 px, the size of
nibabel's ``anatomical.nii`` slices), moving images shifted until too little of them is left,
unrelated images, and a probe of the coarse search against the full measure.
"""

from __future__ import annotations

import numpy as np
import pytest

from topomatch.stages.registration.divergence import jensen_tsallis_histogram
from topomatch.stages.registration.image import Image
from topomatch.stages.registration.interpolation import downsample
from topomatch.stages.registration.misalign import moved
from topomatch.stages.registration.register import register
from topomatch.stages.registration.search import SearchImages, batch_jensen_tsallis2, grid_search, otsu_threshold
from topomatch.stages.registration.transform import RigidTransform, target_registration_error

ANATOMICAL = "images/nibabel_testdata/anatomical.nii"


def _tre(fixed: Image, reg, theta) -> float:
    truth = RigidTransform.for_image(fixed.shape, *theta)
    return float(np.mean(target_registration_error(reg.transform, truth, fixed.shape)))


def _small(image: Image, factor: int) -> Image:
    return image.with_data(downsample(image.data, factor), name=f"{image.name}_small")


def test_batch_jensen_tsallis_matches_the_histogram_formula():
    rng = np.random.default_rng(3)
    h = rng.integers(0, 20, size=(5, 16, 16)).astype(float)
    h[2, 3] = 0  # an empty row
    expected = [jensen_tsallis_histogram(x, 2.0, "histogram") for x in h]
    np.testing.assert_allclose(batch_jensen_tsallis2(h), expected, rtol=1e-12)


def test_otsu_threshold_matches_simpleitk(pd_slice, t1_slice):
    sitk = pytest.importorskip("SimpleITK")
    for image in (pd_slice, t1_slice):
        f = sitk.OtsuThresholdImageFilter()
        f.SetNumberOfHistogramBins(256)
        f.Execute(sitk.GetImageFromArray(image.data.astype(np.float32)))
        width = (image.data.max() - image.data.min()) / 256
        assert otsu_threshold(image.data) == pytest.approx(f.GetThreshold(), abs=1.01 * width)


def test_grid_scores_equal_single_scores(pd_slice):
    moving = moved(pd_slice, RigidTransform.for_image(pd_slice.shape, 12, -7, 20))
    images = SearchImages(pd_slice, moving, min_overlap=0.25)
    grid = grid_search(images, lambda angle: np.array([3.0, -2.0]), angles=8, steps=5, half_width=40.0)
    for i in range(0, len(grid.thetas), 37):
        assert grid.values[i] == pytest.approx(images.score(grid.thetas[i]), rel=1e-12, abs=1e-15)


@pytest.mark.parametrize("factor", [5, 6])
def test_small_images_register_to_themselves(pd_slice, factor):
    small = _small(pd_slice, factor)  # 43 x 36 and 36 x 30 px
    reg = register(small, small)
    assert reg.ok, reg.reason
    assert _tre(small, reg, (0, 0, 0)) < 0.1


@pytest.mark.parametrize("theta", [(2.5, -1.5, 8.0), (-3.0, 2.0, -12.0)])
def test_small_images_recover_a_known_transform(pd_slice, theta):
    small = _small(pd_slice, 5)
    reg = register(small, moved(small, RigidTransform.for_image(small.shape, *theta)))
    assert reg.ok, reg.reason
    assert _tre(small, reg, theta) < 0.6


def test_every_anatomical_slice_registers_to_itself():
    from topomatch.pipeline.paths import data_root
    from topomatch.stages.registration.io import read_image

    root = data_root()
    if root is None or not (root / ANATOMICAL).exists():
        pytest.skip("needs nibabel's anatomical.nii in the external data root (TOPOMATCH_DATA_ROOT)")
    path = root / ANATOMICAL
    for index in range(25):
        image = read_image(path, slice_index=index)
        reg = register(image, image)
        assert reg.ok and _tre(image, reg, (0, 0, 0)) < 0.1, (index, reg.transform, reg.reason)


@pytest.mark.parametrize("theta", [(150.0, 45.0, 0.0), (170.0, 51.0, 30.0)])
def test_a_moving_image_shifted_out_of_view_is_flagged(pd_slice, theta):
    reg = register(pd_slice, moved(pd_slice, RigidTransform.for_image(pd_slice.shape, *theta)))
    assert not reg.ok
    assert "content" in reg.reason or "overlap" in reg.reason


@pytest.mark.parametrize("theta", [(90.0, 27.0, 0.0), (120.0, 36.0, 30.0)])
def test_large_shifts_are_found_by_the_coarse_search(pd_slice, theta):
    reg = register(pd_slice, moved(pd_slice, RigidTransform.for_image(pd_slice.shape, *theta)))
    assert reg.ok, reg.reason
    assert _tre(pd_slice, reg, theta) < 0.5


def test_a_result_pressed_against_the_overlap_bound_is_flagged(pd_slice):
    theta = (84.0, -112.0, -40.0)  # 23 % of the fixed image overlaps the moving one at the truth
    reg = register(pd_slice, moved(pd_slice, RigidTransform.for_image(pd_slice.shape, *theta)))
    assert _tre(pd_slice, reg, theta) > 1.0 and not reg.ok
    assert "overlap" in reg.reason


def test_noise_is_not_registered(pd_slice):
    noise = pd_slice.with_data(np.random.default_rng(0).normal(100.0, 50.0, size=pd_slice.shape), name="noise")
    reg = register(pd_slice, noise)
    assert not reg.ok
    assert "not a distinct optimum" in reg.reason


def test_flatness_of_a_quadratic_is_its_eigenvalue_ratio():
    """On an exact quadratic ``-(t' A t)`` the flattest direction is A's least eigenvector and the
    ratio its eigenvalue over the largest (the arc unit: 1 px at radius r)."""
    from topomatch.stages.registration.search import flatness

    radius = 50.0
    Q = np.linalg.qr(np.random.default_rng(3).normal(size=(3, 3)))[0]
    A = Q @ np.diag([0.1, 1.0, 2.0]) @ Q.T
    to_unit = np.array([1.0, 1.0, radius * np.pi / 180.0])  # (tx, ty, deg) -> (tx, ty, arc)
    ratio, u = flatness(lambda t: -float((t * to_unit) @ A @ (t * to_unit)), np.zeros(3), step=1.0, reach=3.0,
                        radius=radius)
    assert ratio == pytest.approx(0.05, abs=0.01)
    assert abs(u @ Q[:, 0]) > 0.99


def test_an_edge_is_flagged_as_undetermined_not_ok(pd_slice):
    """A straight edge moved along and across itself: translation along it is not determined, and
    the self-check says so instead of returning an arbitrary point of the valley."""
    H, W = pd_slice.shape
    yy, xx = np.mgrid[0:H, 0:W].astype(float)
    edge = pd_slice.with_data(200.0 * (xx + yy < H) + np.random.default_rng(1).normal(0, 3, (H, W)), name="edge")
    reg = register(edge, moved(edge, RigidTransform.for_image(edge.shape, 5.0, 7.0, 0.0)))
    assert not reg.ok and "hardly changes along" in reg.reason
