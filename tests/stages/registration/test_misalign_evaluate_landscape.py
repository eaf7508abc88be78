"""Synthetic misalignments, scoring against a truth, objective landscapes, 2D and 3D."""

from __future__ import annotations

import math

import numpy as np
import pytest

from topomatch.pipeline.errors import StageError
from topomatch.stages.registration.evaluate import EvaluateParams, evaluate_registration, tre_points
from topomatch.stages.registration.image import Image
from topomatch.stages.registration.interpolation import resample
from topomatch.stages.registration.landscape import LandscapeParams, scan
from topomatch.stages.registration.misalign import (MisalignParams, crop_slab, make_case, misalign, misalign_pair,
                                                    t2_like)
from topomatch.stages.registration.register import Flag, Registration
from topomatch.stages.registration.transform import RigidTransform


def _registration(transform, ok=True):
    return Registration(transform, 0.0, () if ok else (Flag("test", "flagged"),), "test", 0.01, 1, 2, "max_iterations")


def _volume(shape=(16, 18, 20)):
    grids = np.meshgrid(*[np.linspace(-1, 1, n) for n in shape], indexing="ij")
    blob = 100 * np.exp(-((grids[0] - 0.2) ** 2 + grids[1] ** 2 + (grids[2] + 0.1) ** 2) * 3)
    return Image(blob + 20 * grids[2], spacing=(1.5, 1.0, 2.0), origin=(-10.0, 4.0, 7.0))


def test_random_cases_are_seeded_bounded_and_independent_of_n():
    def case(i, seed=2024, d=2):
        c = (0.0,) * d
        return MisalignParams(index=i, seed=seed).transform(c)

    a = [case(i) for i in range(60)]
    assert a[:10] == [case(i) for i in range(10)] and a != [case(i, seed=2025) for i in range(60)]
    arr = np.array([(t.tx, t.ty, t.angle) for t in a])
    assert np.all(np.abs(arr[:, :2]) <= 20) and np.all(np.abs(arr[:, 2]) <= 25)
    assert arr[:, 2].min() < -15 and arr[:, 2].max() > 15  # spread over the range
    t3 = case(0, d=3)
    assert t3.dim == 3 and np.all(np.abs(t3.angles_deg) <= 25) and np.all(np.abs(t3.translation) <= 20)


@pytest.mark.parametrize("d", [2, 3])
def test_misalign_makes_moving_of_T_equal_fixed(blob_image, d):
    """M(T(p)) = fixed(p): sampling the moving image at T(p) gives back the fixed image (cubic resampling)."""
    image = blob_image if d == 2 else _volume()
    theta = [11.0, 3.0, -2.0] if d == 2 else [6.0, -4.0, 9.0, 1.5, -2.0, 1.0]
    res = misalign(image, params=MisalignParams(theta=theta))
    assert res.fixed is image and list(res.truth.values()) == pytest.approx(theta)
    T = RigidTransform(tuple(math.radians(a) for a in theta[: len(theta) - d]) + tuple(theta[-d:]), tuple(image.center))
    back = resample(res.moving, T, image, order=3)
    interior = tuple(slice(12 if d == 2 else 4, -12 if d == 2 else -4) for _ in range(d))
    assert np.abs(back - image.data)[interior].max() < 0.02 * np.ptp(image.data)  # two cubic resamplings
    assert res.summary() == {f"true_{k}": v for k, v in res.truth.items()}
    with pytest.raises(StageError, match="needs 3 values"):
        misalign(blob_image, params=MisalignParams(theta=[1.0]))


def test_misalign_pair_needs_an_aligned_pair(pd_slice, t1_slice):
    params = MisalignParams(index=3, seed=2024)
    res = misalign_pair(t1_slice, pd_slice, {"tx": 0, "ty": 0, "angle": 0}, params=params)
    t = params.transform(pd_slice.center)
    assert res.truth == pytest.approx({"angle": t.angle, "tx": t.tx, "ty": t.ty})
    assert res.moving.shape == pd_slice.shape
    with pytest.raises(StageError, match="needs a pair in register"):
        misalign_pair(t1_slice, pd_slice, {"tx": 13, "ty": 17, "angle": 0}, params=params)


def test_crop_slab_keeps_the_kept_pixels_where_they_were():
    vol = _volume()
    slab = crop_slab(vol, axis=2, fraction=0.5, start_fraction=1.0)  # the last half along k
    assert slab.size == (20, 18, 8)
    np.testing.assert_array_equal(slab.data, vol.data[8:])
    np.testing.assert_allclose(slab.physical(np.zeros((1, 3))), vol.physical(np.array([[0.0, 0.0, 8.0]])))


def test_t2_like_inverts_the_tissue_order_and_keeps_the_background_dark():
    rng = np.random.default_rng(0)
    t1 = np.r_[np.zeros(3000), rng.normal(60, 2, 300), rng.normal(90, 2, 300), rng.normal(120, 2, 300)]  # bg CSF GM WM
    t2 = t2_like(t1)
    assert t2[:3000].max() == pytest.approx(0.0)
    csf, gm, wm = t2[3000:3300].mean(), t2[3300:3600].mean(), t2[3600:].mean()
    assert csf > gm > wm > 0


def test_make_case_is_seeded_and_cropped_along_its_axis():
    vol = _volume()
    a, b = (make_case(vol, 4, seed=1, multimodal=True, crop=True) for _ in range(2))
    np.testing.assert_array_equal(a.moving.data, b.moving.data)
    assert a.truth == b.truth and a.cropped and a.multimodal
    assert sorted(a.moving.size) != sorted(vol.size)


@pytest.mark.parametrize("d", [2, 3])
def test_evaluate_exact_and_translated(pd_slice, d):
    image = pd_slice if d == 2 else _volume()
    k = 1 if d == 2 else 3
    angles = (0.12,) if d == 2 else (0.05, -0.1, 0.12)
    exact = RigidTransform(angles + (5.0, -3.0, 2.0)[:d], tuple(image.center))
    truth = dict(zip(exact.names, (*exact.angles_deg, *exact.translation)))
    ev = evaluate_registration(image, _registration(exact), truth)
    assert ev.tre_mean == pytest.approx(0.0, abs=1e-9) and ev.success and not ev.flagged
    shift = np.array([0.3, -0.4, 1.2])[:d]  # an error in translation only: TRE is its length everywhere
    off = RigidTransform(angles + tuple(exact.translation + shift), tuple(image.center))
    ev = evaluate_registration(image, _registration(off, ok=False), truth)
    assert ev.tre_mean == pytest.approx(np.linalg.norm(shift)) and ev.tre_max == pytest.approx(np.linalg.norm(shift))
    assert [ev.errors[n] for n in exact.names[k:]] == pytest.approx(list(shift))
    assert ev.d_rotation == pytest.approx(0.0, abs=1e-6) and ev.d_translation == pytest.approx(np.linalg.norm(shift))
    assert ev.flagged and ev.summary()["success"] == (np.linalg.norm(shift) <= 1.0)
    assert not evaluate_registration(image, _registration(off), truth, EvaluateParams(threshold=0.4)).success


def test_evaluate_rotation_error_by_hand():
    """A 2-degree rotation about the centre: TRE is the chord 2 r sin(1 deg) averaged over the fixed pixels."""
    im = Image(np.random.default_rng(0).random((21, 31)))
    est = RigidTransform.euler2d(0.0, 0.0, 2.0, im.center)
    ev = evaluate_registration(im, _registration(est), {"angle": 0.0})
    r = np.linalg.norm(im.points() - im.center, axis=1)
    assert ev.tre_mean == pytest.approx(np.mean(2 * r * math.sin(math.radians(1.0))))
    assert ev.d_rotation == pytest.approx(2.0) and ev.errors["angle"] == pytest.approx(2.0)


def test_angle_error_wraps():
    im = Image(np.random.default_rng(0).random((10, 10)))
    ev = evaluate_registration(im, _registration(RigidTransform.euler2d(0, 0, 179.0, im.center)), {"angle": -179.0})
    assert ev.errors["angle"] == pytest.approx(-2.0)


def test_tre_regions():
    vol = _volume()
    assert len(tre_points(vol, "all")) == vol.data.size and len(tre_points(vol)) < vol.data.size  # 3D: foreground
    assert len(tre_points(Image(np.zeros((6, 7)) + np.eye(6, 7)))) == 42  # 2D: every pixel


def test_truth_errors(pd_slice):
    reg = _registration(RigidTransform.identity(tuple(pd_slice.center)))
    with pytest.raises(StageError, match="needs a known transform"):
        evaluate_registration(pd_slice, reg, None)
    with pytest.raises(StageError, match=r"unknown keys \['scale'\]"):
        evaluate_registration(pd_slice, reg, {"tx": 1, "scale": 2})
    assert evaluate_registration(pd_slice, reg, {"tx": 3.0}).tre_mean == pytest.approx(3.0)  # missing keys are 0


def test_landscape_peaks_at_the_misalignment(pd_slice, t1_slice):
    res = misalign(pd_slice, params=MisalignParams(theta=[8.0, 4.0, -6.0]))
    params = LandscapeParams(alphas=[1.0, 2.0], center=[8.0, 4.0, -6.0], translation_range=10, angle_range=10,
                             points=41, bins=24)
    land = scan(res.fixed, res.moving, params)
    for name in ("angle", "tx", "ty"):
        assert land.values[name].shape == (2, 41)
        for curve in land.values[name]:
            assert abs(land.offsets[name][np.argmax(curve)]) <= 0.5  # 0.5 = the scan's step
    assert land.summary()["peak_tx"] == pytest.approx(0.0, abs=0.5)
    multi = scan(t1_slice, pd_slice, params.model_copy(update={"center": None, "weights": "uniform"}))
    assert abs(multi.offsets["angle"][np.argmax(multi.values["angle"][1])]) <= 0.5


def test_landscape_of_a_volume_scans_six_parameters():
    vol = _volume()
    land = scan(vol, vol, LandscapeParams(alphas=[2.0], translation_range=3, angle_range=6, points=7, bins=16,
                                          interpolation="parzen"))
    assert list(land.values) == ["angle_x", "angle_y", "angle_z", "tx", "ty", "tz"]
    assert all(land.offsets[n][np.argmax(v[0])] == 0.0 for n, v in land.values.items())


def test_uniform_weights_give_a_sharper_relative_peak(pd_slice):
    """The thesis's observation: with uniform weights JT is a spike at alignment, flat elsewhere."""
    params = LandscapeParams(alphas=[2.0], translation_range=20, points=41, bins=32)
    hist = scan(pd_slice, pd_slice, params)
    unif = scan(pd_slice, pd_slice, params.model_copy(update={"weights": "uniform"}))
    rel = lambda v: np.nanmean(v) / np.nanmax(v)  # noqa: E731
    assert rel(unif.values["tx"][0]) < rel(hist.values["tx"][0])


def test_landscape_of_a_misaligned_volume_peaks_at_its_truth():
    """3D with a known non-zero misalignment (``misalign``'s theta, degrees and mm): every one of the six scans
    about the truth peaks at offset 0 (the scan's step is 1 mm and 2 degrees)."""
    theta = [4.0, -3.0, 5.0, 2.0, -1.5, 3.0]
    res = misalign(_volume((24, 26, 28)), params=MisalignParams(theta=theta))
    land = scan(res.fixed, res.moving, LandscapeParams(alphas=[2.0], center=theta, translation_range=3,
                                                       angle_range=6, points=7, bins=16, interpolation="parzen"))
    assert all(land.offsets[n][np.argmax(v[0])] == 0.0 for n, v in land.values.items()), {
        n: float(land.offsets[n][np.argmax(v[0])]) for n, v in land.values.items()}
