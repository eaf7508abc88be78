"""The SimpleITK adapter: conventions agree with ours, and the reference registration runs."""

from __future__ import annotations

import math

import numpy as np
import pytest

from topomatch.stages.registration.evaluate import evaluate_registration
from topomatch.stages.registration.simpleitk_reference import (SimpleITKParams, from_sitk_euler, sitk_euler, sitk_register,
                                                     to_sitk)
from topomatch.stages.registration.transform import RigidTransform, grid_points


def test_euler_round_trip_and_same_point_map():
    T = RigidTransform(3.5, -1.25, 17.0, (90.0, 108.0))
    e = sitk_euler(T)
    pts = grid_points((5, 7)) * 20
    np.testing.assert_allclose([e.TransformPoint(tuple(p)) for p in pts], T.apply(pts), atol=1e-9)
    back = from_sitk_euler(e, T.center)
    assert (back.tx, back.ty, back.angle) == pytest.approx((T.tx, T.ty, T.angle))
    other = from_sitk_euler(sitk_euler(T.with_center((0.0, 0.0))), T.center)  # re-expressed about our centre
    assert (other.tx, other.ty, other.angle) == pytest.approx((T.tx, T.ty, T.angle))


def test_to_sitk_index_convention(pd_slice):
    img = to_sitk(pd_slice)
    assert img.GetSize() == (181, 217) and img.GetSpacing() == (1.0, 1.0)
    assert img.GetPixel(10, 3) == pytest.approx(pd_slice.data[3, 10])  # (x = col, y = row)


def test_reference_registration_on_the_itk_translation(itk_dir):
    from topomatch.stages.registration.io import read_image

    fixed = read_image(itk_dir / "BrainProtonDensitySliceBorder20.png")
    moving = read_image(itk_dir / "BrainProtonDensitySliceShifted13x17y.png")
    reg = sitk_register(fixed, moving, SimpleITKParams(optimizer="regular_step", learning_rate=2.0, iterations=300))
    assert reg.ok and reg.method == "simpleitk/mattes(regular_step)"
    assert evaluate_registration(fixed, reg, {"tx": 13, "ty": 17, "angle": 0}).tre_mean < 0.1
    again = sitk_register(fixed, moving, SimpleITKParams(optimizer="regular_step", learning_rate=2.0, iterations=300,
                                                         threads=1))
    assert np.abs(again.transform.params - reg.transform.params).max() < 1e-3  # fixed sampling seed


def test_simpleitk_failure_becomes_a_flag(blob_image):
    """A moving image that is a small corner square: Mattes MI finds no samples; the error becomes a flag."""
    from topomatch.stages.registration.image import Image

    corner = Image(np.pad(np.ones((4, 4)), ((0, 60), (0, 76))))
    reg = sitk_register(blob_image, corner, SimpleITKParams())
    assert not reg.ok and reg.reason.startswith("SimpleITK failed:") and "overlap" in reg.reason
    assert math.isfinite(reg.transform.tx) and reg.stop_reason == "exception"
