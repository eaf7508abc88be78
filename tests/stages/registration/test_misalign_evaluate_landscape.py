"""Synthetic misalignments, scoring against a truth, objective landscapes."""

from __future__ import annotations

import numpy as np
import pytest

from topomatch.pipeline.errors import StageError
from topomatch.stages.registration.evaluate import EvaluateParams, evaluate_registration
from topomatch.stages.registration.landscape import LandscapeParams, scan
from topomatch.stages.registration.misalign import MisalignParams, misalign, misalign_pair, random_cases
from topomatch.stages.registration.register import Registration
from topomatch.stages.registration.transform import RigidTransform


def _registration(transform, ok=True):
    return Registration(transform, 0.0, ok, "" if ok else "flagged", "test", 0.01, 1, 2, "max_iterations")


def test_random_cases_are_seeded_bounded_and_independent_of_n():
    a = random_cases(60, seed=2024)
    assert a[:10] == random_cases(10, seed=2024)
    assert a != random_cases(60, seed=2025)
    arr = np.array(a)
    assert np.all(np.abs(arr[:, :2]) <= 20) and np.all(np.abs(arr[:, 2]) <= 25)
    assert arr[:, 2].min() < -15 and arr[:, 2].max() > 15  # spread over the range


def test_misalign_makes_moving_of_T_equal_fixed(blob_image):
    """M(T(x)) = fixed(x): sampling the moving image at T(x) gives back the fixed image (cubic resampling)."""
    from topomatch.stages.registration.interpolation import resample

    res = misalign(blob_image, params=MisalignParams(theta=(3.0, -2.0, 11.0)))
    assert res.fixed is blob_image and res.truth == {"tx": 3.0, "ty": -2.0, "angle": 11.0}
    T = RigidTransform.for_image(blob_image.shape, 3.0, -2.0, 11.0)
    back = resample(res.moving, T, blob_image.shape, order=3)
    interior = np.zeros(blob_image.shape, bool)
    interior[12:-12, 12:-12] = True
    assert np.abs(back - blob_image.data)[interior].max() < 0.5  # two cubic resamplings of a smooth image
    assert res.summary() == {"true_tx": 3.0, "true_ty": -2.0, "true_angle": 11.0}


def test_misalign_pair_needs_an_aligned_pair(pd_slice, t1_slice):
    params = MisalignParams(index=3, seed=2024)
    res = misalign_pair(t1_slice, pd_slice, {"tx": 0, "ty": 0, "angle": 0}, params=params)
    assert res.truth == dict(zip(("tx", "ty", "angle"), random_cases(4, seed=2024)[3]))
    assert res.moving.shape == pd_slice.shape
    with pytest.raises(StageError, match="needs a pair in register"):
        misalign_pair(t1_slice, pd_slice, {"tx": 13, "ty": 17, "angle": 0}, params=params)


def test_evaluate_exact_and_translated(pd_slice):
    truth = {"tx": 5.0, "ty": -3.0, "angle": 7.0}
    exact = RigidTransform.for_image(pd_slice.shape, 5.0, -3.0, 7.0)
    ev = evaluate_registration(pd_slice, _registration(exact), truth)
    assert ev.tre_mean == pytest.approx(0.0, abs=1e-12) and ev.success and not ev.flagged
    off = RigidTransform.for_image(pd_slice.shape, 5.3, -3.4, 7.0)
    ev = evaluate_registration(pd_slice, _registration(off, ok=False), truth)
    assert ev.tre_mean == pytest.approx(0.5) and ev.tre_max == pytest.approx(0.5)
    assert (ev.d_tx, ev.d_ty, ev.d_angle) == pytest.approx((0.3, -0.4, 0.0))
    assert ev.flagged and ev.summary()["success"]
    assert not evaluate_registration(pd_slice, _registration(off), truth, EvaluateParams(threshold=0.4)).success


def test_angle_error_wraps():
    from topomatch.stages.registration.image import Image

    im = Image(np.random.default_rng(0).random((10, 10)))
    ev = evaluate_registration(im, _registration(RigidTransform.for_image(im.shape, 0, 0, 179.0)), {"angle": -179.0})
    assert ev.d_angle == pytest.approx(-2.0)


def test_truth_errors(pd_slice):
    reg = _registration(RigidTransform.for_image(pd_slice.shape))
    with pytest.raises(StageError, match="needs a known transform"):
        evaluate_registration(pd_slice, reg, None)
    with pytest.raises(StageError, match=r"unknown keys \['scale'\]"):
        evaluate_registration(pd_slice, reg, {"tx": 1, "scale": 2})
    assert evaluate_registration(pd_slice, reg, {"tx": 3.0}).tre_mean == pytest.approx(3.0)  # missing keys are 0


def test_landscape_peaks_at_the_misalignment(pd_slice, t1_slice):
    res = misalign(pd_slice, params=MisalignParams(theta=(4.0, -6.0, 8.0)))
    params = LandscapeParams(alphas=[1.0, 2.0], center=(4.0, -6.0, 8.0), translation_range=10, angle_range=10,
                             points=41, bins=24)
    land = scan(res.fixed, res.moving, params)
    for name in ("tx", "ty", "angle"):
        assert land.values[name].shape == (2, 41)
        for curve in land.values[name]:
            assert abs(land.offsets[name][np.argmax(curve)]) <= 0.5  # 0.5 = the scan's step
    assert land.summary()["peak_tx"] == pytest.approx(0.0, abs=0.5)
    multi = scan(t1_slice, pd_slice, params.model_copy(update={"center": (0.0, 0.0, 0.0), "weights": "uniform"}))
    assert abs(multi.offsets["angle"][np.argmax(multi.values["angle"][1])]) <= 0.5


def test_uniform_weights_give_a_sharper_relative_peak(pd_slice):
    """The thesis's observation: with uniform weights JT is a spike at alignment, flat elsewhere."""
    params = LandscapeParams(alphas=[2.0], translation_range=20, points=41, bins=32)
    hist = scan(pd_slice, pd_slice, params)
    unif = scan(pd_slice, pd_slice, params.model_copy(update={"weights": "uniform"}))
    rel = lambda v: np.nanmean(v) / np.nanmax(v)  # noqa: E731
    assert rel(unif.values["tx"][0]) < rel(hist.values["tx"][0])
