"""The SimpleITK reference, 2D and 3D: geometry kept, the reference registration runs, failures become flags."""

from __future__ import annotations

import math

import numpy as np
import pytest

from tests_paths import ITK_DIR
from topomatch.stages.registration.evaluate import evaluate_registration
from topomatch.stages.registration.image import Image
from topomatch.stages.registration.io import read_image, to_sitk
from topomatch.stages.registration.misalign import make_case
from topomatch.stages.registration.simpleitk_reference import SimpleITK3DParams, SimpleITKParams, sitk_register


def test_to_sitk_index_convention(pd_slice):
    img = to_sitk(pd_slice)
    assert img.GetSize() == (181, 217) and img.GetSpacing() == (1.0, 1.0)
    assert img.GetPixel(10, 3) == pytest.approx(pd_slice.data[3, 10])  # (x = col, y = row)


def test_reference_registration_on_the_itk_translation():
    fixed = read_image(ITK_DIR / "BrainProtonDensitySliceBorder20.png")
    moving = read_image(ITK_DIR / "BrainProtonDensitySliceShifted13x17y.png")
    params = SimpleITKParams(optimizer="regular_step", learning_rate=2.0, iterations=300)
    reg = sitk_register(fixed, moving, params)
    assert reg.ok and reg.method == "simpleitk/mattes(regular_step)"
    assert evaluate_registration(fixed, reg, {"tx": 13, "ty": 17, "angle": 0}).tre_mean < 0.1
    again = sitk_register(fixed, moving, params.model_copy(update={"threads": 1}))
    assert np.abs(np.subtract(again.transform.parameters, reg.transform.parameters)).max() < 1e-3  # fixed seed


def test_reference_registration_of_a_volume():
    source = read_image(ITK_DIR / "KmeansTest_T1UCharRaw.nii.gz").shrink((2, 2, 1))
    case = make_case(source, 0, seed=11, multimodal=False, crop=False)
    reg = sitk_register(case.fixed, case.moving, SimpleITK3DParams())
    truth = dict(zip(case.truth.names, (*case.truth.angles_deg, *case.truth.translation)))
    assert reg.transform.dim == 3 and reg.method == "simpleitk/mattes(regular_step)" and reg.overlap > 0.5
    assert evaluate_registration(case.fixed, reg, truth).tre_mean < 2.0


def test_simpleitk_failure_becomes_a_flag(blob_image):
    """A moving image that is a small corner square: Mattes MI finds no samples; the error becomes a flag."""
    corner = Image(np.pad(np.ones((4, 4)), ((0, 60), (0, 76))))
    reg = sitk_register(blob_image, corner, SimpleITKParams())
    assert not reg.ok and reg.reason.startswith("SimpleITK failed:") and "overlap" in reg.reason
    assert math.isfinite(reg.transform.tx) and reg.stop_reason == "exception" and reg.flags[0].check == "simpleitk"
