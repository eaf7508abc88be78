"""Registration end to end: known transforms recovered, ITK cases, determinism, failures flagged."""

from __future__ import annotations

import csv

import numpy as np
import pytest

from topomatch.pipeline.errors import ConfigError, StageError
from topomatch.stages.registration.evaluate import evaluate_registration
from topomatch.stages.registration.io import read_image
from topomatch.stages.registration.misalign import moved
from topomatch.stages.registration.register import LevelSpec, RegisterParams, register
from topomatch.stages.registration.transform import RigidTransform


def _truth(theta):
    return dict(zip(("tx", "ty", "angle"), theta))


@pytest.mark.parametrize("theta", [(5, 5, 5), (10, 20, 20)])
def test_thesis_misalignments_recovered(pd_slice, theta):
    moving = moved(pd_slice, RigidTransform.for_image(pd_slice.shape, *theta))
    reg = register(pd_slice, moving)
    ev = evaluate_registration(pd_slice, reg, _truth(theta))
    assert reg.ok, reg.reason
    assert ev.tre_mean < 0.2, (reg.transform, ev)


def test_multimodal_misalignment_recovered(pd_slice, t1_slice):
    theta = (-12.0, 8.0, -17.0)
    moving = moved(pd_slice, RigidTransform.for_image(pd_slice.shape, *theta))
    reg = register(t1_slice, moving, RegisterParams(metric="mi"))
    assert evaluate_registration(t1_slice, reg, _truth(theta)).tre_mean < 0.3


def _itk_cases(itk_dir):
    with open(itk_dir / "registration_pairs.csv", newline="") as fh:
        rows = [r for r in csv.DictReader(fh) if r["consensus_tx"]]
    return {r["moving"] + "|" + r["fixed"]: r for r in rows}


@pytest.mark.parametrize("key", [
    "BrainProtonDensitySliceShifted13x17y.png|BrainProtonDensitySliceBorder20.png",
    "BrainProtonDensitySliceShifted13x17y.png|BrainT1SliceBorder20.png",
    "BrainProtonDensitySliceR10X13Y17.png|BrainProtonDensitySliceBorder20.png",
    "BrainProtonDensitySlice.png|BrainT1Slice.png",
])
def test_itk_cases_within_a_tenth_of_a_pixel(itk_dir, key):
    r = _itk_cases(itk_dir)[key]
    fixed, moving = read_image(itk_dir / r["fixed"]), read_image(itk_dir / r["moving"])
    truth = {"tx": float(r["consensus_tx"]), "ty": float(r["consensus_ty"]), "angle": float(r["consensus_rotation_deg"])}
    reg = register(fixed, moving)
    ev = evaluate_registration(fixed, reg, truth)
    assert reg.ok and ev.tre_mean <= 0.1, (key, reg.transform, ev.tre_mean)


def test_itk_rotated10_is_the_rotation_about_itks_physical_centre(itk_dir):
    """The CSV's Rotated10 row, (0.094, -0.079, 10) about ((W-1)/2, (H-1)/2), is 10 degrees about ITK's
    physical centre (W/2, H/2): (I - R(10 deg)) (0.5, 0.5) = (0.094, -0.079)."""
    import math

    rows = _itk_cases(itk_dir)
    r = next(r for r in rows.values() if r["moving"] == "BrainProtonDensitySliceRotated10.png")
    c, s_ = math.cos(math.radians(10)), math.sin(math.radians(10))
    expected = (0.5 - (c * 0.5 - s_ * 0.5), 0.5 - (s_ * 0.5 + c * 0.5))
    assert (float(r["consensus_tx"]), float(r["consensus_ty"])) == pytest.approx(expected, abs=5e-4)


def test_same_seed_same_result(pd_slice):
    moving = moved(pd_slice, RigidTransform.for_image(pd_slice.shape, 4, -6, 9))
    a = register(pd_slice, moving, RegisterParams(seed=3))
    b = register(pd_slice, moving, RegisterParams(seed=3))
    c = register(pd_slice, moving, RegisterParams(seed=4))
    np.testing.assert_array_equal(a.transform.params, b.transform.params)
    np.testing.assert_array_equal(a.history["theta"], b.history["theta"])
    assert not np.array_equal(a.transform.params, c.transform.params)
    assert np.abs(a.transform.params - c.transform.params).max() < 0.2


def test_history_levels_and_counts(pd_slice):
    moving = moved(pd_slice, RigidTransform.for_image(pd_slice.shape, 2, 3, 4))
    seen = []
    reg = register(pd_slice, moving, callback=lambda level, k, theta, value: seen.append(level))
    h = reg.history
    assert len(h["level"]) == reg.iterations == len(seen) == 260 + 40 + 30
    assert h["theta"].shape == (reg.iterations, 3) and sorted(set(h["level"])) == [0, 1, 2]
    assert reg.evaluations > 2 * reg.iterations and reg.seconds > 0 and reg.stop_reason == "max_iterations"
    assert reg.summary()["method"] == "spsa/jt(alpha=2 histogram)"


def test_powell_deterministic(pd_slice):
    moving = moved(pd_slice, RigidTransform.for_image(pd_slice.shape, 5, 10, 15))
    a = register(pd_slice, moving, RegisterParams(optimizer="powell"))
    b = register(pd_slice, moving, RegisterParams(optimizer="powell"))
    np.testing.assert_array_equal(a.transform.params, b.transform.params)
    assert evaluate_registration(pd_slice, a, _truth((5, 10, 15))).tre_mean < 0.1


def test_outside_the_capture_range_is_flagged(pd_slice):
    moving = moved(pd_slice, RigidTransform.for_image(pd_slice.shape, 0, 0, 120))
    reg = register(pd_slice, moving)
    assert not reg.ok
    assert "capture range" in reg.reason
    with pytest.raises(StageError, match="registration failed: .*capture range"):
        register(pd_slice, moving, RegisterParams(check={"on_failure": "error"}))


def test_estimate_on_the_search_bound_is_flagged(pd_slice):
    moving = moved(pd_slice, RigidTransform.for_image(pd_slice.shape, 18, 0, 0))
    params = RegisterParams(bounds={"max_translation": 6}, transform={"init": "geometry"}, check={"capture": False})
    reg = register(pd_slice, moving, params)
    assert not reg.ok and "search bound of tx" in reg.reason


def test_retry_from_a_probe_extends_the_capture_range(pd_slice):
    """A 45-degree misalignment: the first pass may stop short, the capture check finds the probe and retries."""
    theta = (3.0, -4.0, 45.0)
    moving = moved(pd_slice, RigidTransform.for_image(pd_slice.shape, *theta))
    reg = register(pd_slice, moving)
    assert reg.ok and evaluate_registration(pd_slice, reg, _truth(theta)).tre_mean < 0.3


def test_small_images_skip_coarse_levels(blob_image):
    moving = moved(blob_image, RigidTransform.for_image(blob_image.shape, 2.0, -1.5, 6.0))
    reg = register(blob_image, moving, RegisterParams(schedule=[LevelSpec(factor=16, iterations=10),
                                                                LevelSpec(factor=1, iterations=200, step=0.5, c=0.5)]))
    assert evaluate_registration(blob_image, reg, _truth((2.0, -1.5, 6.0))).tre_mean < 0.3
    assert set(reg.history["level"]) == {0}  # only the full-resolution level ran


def test_params_are_validated():
    with pytest.raises(ConfigError, match=r"register.metric.name: Input should be 'jt', 'jr', 'mi' or 'tmi'"):
        RegisterParams.parse({"metric": "nmi"}, "register")
    with pytest.raises(ConfigError, match=r"register.schedule\[0\].bins: Input should be greater than or equal to 2"):
        RegisterParams.parse({"schedule": [{"bins": 1}]}, "register")
    with pytest.raises(ConfigError, match="register.schedule: List should have at least 1 item"):
        RegisterParams.parse({"schedule": []}, "register")
    with pytest.raises(ConfigError, match="register.metric.alpha: Input should be greater than 0"):
        RegisterParams.parse({"metric": {"alpha": 0}}, "register")
