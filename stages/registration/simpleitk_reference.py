"""The reference: SimpleITK's Mattes mutual-information rigid registration of the same images, 2D or 3D.

The textbook set-up (the SimpleITK notebooks' recipe): ``Euler2DTransform`` / ``Euler3DTransform`` centred by
``CenteredTransformInitializer`` (``GEOMETRY`` or ``MOMENTS``), Mattes MI on a fixed-seed random sample, linear
interpolation, physical-shift scales, a shrink/smoothing pyramid (smoothing in physical units), and conjugate gradient
with line search (2D default: the most accurate on the ITK cases), regular-step gradient descent (3D default) or
gradient descent. The images keep their geometry (:func:`~.io.to_sitk`), so parameters compare directly with ours."""

from __future__ import annotations

import math
import time
from typing import Literal

import numpy as np
from pydantic import Field, model_validator

from topomatch.pipeline.contract import Params, stage
from topomatch.stages.registration.image import Image
from topomatch.stages.registration.interpolation import inside
from topomatch.stages.registration.io import to_sitk
from topomatch.stages.registration.register import Flag, Registration, RegisterResult
from topomatch.stages.registration.transform import RigidTransform


class SimpleITKParams(Params):
    """Parameters of :func:`register_sitk` (SimpleITK's Mattes MI registration)."""

    bins: int = Field(50, ge=4, description="Mattes histogram bins")
    sampling: float = Field(0.25, gt=0, le=1, description="fraction of fixed pixels sampled at random per iteration")
    sampling_seed: int = Field(42, ge=0, description="seed of the metric's random sampling (runs still differ)")
    init: Literal["geometry", "moments"] = Field("moments", description="CenteredTransformInitializer mode")
    shrink: list[int] = Field(default_factory=lambda: [4, 2, 1], min_length=1, description="pyramid shrink factors")
    smoothing: list[float] = Field(default_factory=lambda: [2.0, 1.0, 0.0], min_length=1,
                                   description="Gaussian smoothing sigma per level (pixels)")
    optimizer: Literal["regular_step", "gradient_descent", "line_search"] = Field(
        "line_search", description="conjugate gradient with golden-section line search (accurate, default), "
                                   "regular-step gradient descent (fast), or gradient descent with the learning rate "
                                   "estimated each iteration")
    learning_rate: float = Field(1.0, gt=0, description="initial step / learning rate")
    min_step: float = Field(1e-3, gt=0, description="stop when the step falls below this")
    relaxation: float = Field(0.5, gt=0, lt=1, description="step reduction when the gradient turns")
    convergence: float = Field(1e-6, gt=0, description="convergence value of the windowed metric change")
    gradient_tolerance: float = Field(1e-8, gt=0, description="regular step: stop when the gradient is smaller")
    iterations: int = Field(100, ge=1, description="iterations per level")
    threads: int | None = Field(None, ge=1, description="ITK threads (default: all cores)")
    min_overlap: float = Field(0.25, gt=0, le=1, description="flag results with less overlap")

    @model_validator(mode="after")
    def _levels(self) -> "SimpleITKParams":
        if len(self.shrink) != len(self.smoothing):
            raise ValueError(f"shrink and smoothing need one value per level ({len(self.shrink)} vs {len(self.smoothing)})")
        return self


def sitk_register(fixed: Image, moving: Image, params: SimpleITKParams = SimpleITKParams()) -> Registration:
    """Register with SimpleITK (Mattes MI, Euler2D / Euler3D, a pyramid: module docstring), 2D or 3D, the images'
    geometry kept: the transform about the fixed grid's centre, ``value`` the final Mattes metric (negative MI, as
    SimpleITK minimises it), flagged only for too little overlap or an exception (SimpleITK has no flag)."""
    import SimpleITK as sitk

    t0 = time.perf_counter()
    F, M = to_sitk(fixed), to_sitk(moving)
    rigid = sitk.Euler2DTransform() if fixed.dim == 2 else sitk.Euler3DTransform()
    reg = sitk.ImageRegistrationMethod()
    if params.threads is not None:
        reg.SetNumberOfThreads(params.threads)
    reg.SetMetricAsMattesMutualInformation(numberOfHistogramBins=params.bins)
    reg.SetMetricSamplingStrategy(reg.RANDOM)
    reg.SetMetricSamplingPercentage(params.sampling, params.sampling_seed)
    reg.SetInterpolator(sitk.sitkLinear)
    steps = dict(learningRate=params.learning_rate, numberOfIterations=params.iterations)
    window = dict(convergenceMinimumValue=params.convergence, convergenceWindowSize=10)
    if params.optimizer == "regular_step":
        reg.SetOptimizerAsRegularStepGradientDescent(**steps, minStep=params.min_step,
                                                     relaxationFactor=params.relaxation,
                                                     gradientMagnitudeTolerance=params.gradient_tolerance)
    elif params.optimizer == "gradient_descent":
        reg.SetOptimizerAsGradientDescent(**steps, **window, estimateLearningRate=reg.EachIteration)
    else:
        reg.SetOptimizerAsConjugateGradientLineSearch(**steps, **window)
    reg.SetOptimizerScalesFromPhysicalShift()
    reg.SetShrinkFactorsPerLevel(list(params.shrink))
    reg.SetSmoothingSigmasPerLevel(list(params.smoothing))
    reg.SmoothingSigmasAreSpecifiedInPhysicalUnitsOn()
    mode = getattr(sitk.CenteredTransformInitializerFilter, params.init.upper())  # GEOMETRY, MOMENTS
    initial = sitk.CenteredTransformInitializer(F, M, rigid, mode)
    reg.SetInitialTransform(initial, inPlace=False)
    iterations = [0]
    reg.AddCommand(sitk.sitkIterationEvent, lambda: iterations.__setitem__(0, iterations[0] + 1))
    start = RigidTransform.from_sitk(initial, fixed.center)
    method = f"simpleitk/mattes({params.optimizer})"
    try:
        transform = RigidTransform.from_sitk(reg.Execute(F, M), fixed.center)
    except RuntimeError as exc:  # e.g. "All samples map outside moving image buffer"
        message = str(exc).strip().splitlines()
        detail = next((m.split(":", 1)[-1].strip() for m in message if "ERROR" in m), message[-1] if message else "")
        return Registration(start, math.nan, (Flag("simpleitk", f"SimpleITK failed: {detail}"),), method,
                            time.perf_counter() - t0, iterations[0], iterations[0], "exception", initial=start)
    seconds = time.perf_counter() - t0
    index = moving.continuous_index(transform.apply(fixed.points(np.arange(0, fixed.data.size, 7))))
    overlap = float(np.mean(inside(index.T, moving.size)))
    flags = () if overlap >= params.min_overlap else (
        Flag("overlap", f"only {overlap:.0%} of the fixed image overlaps the moving image at the result"),)
    return Registration(transform, float(reg.GetMetricValue()), flags, method, seconds, iterations[0], iterations[0],
                        reg.GetOptimizerStopConditionDescription(), initial=start, overlap=overlap)


@stage("register_sitk", params=SimpleITKParams, version=2, consumes=("fixed", "moving"), produces=("registration",))
def register_sitk(fixed: Image, moving: Image, *, params: SimpleITKParams) -> RegisterResult:
    """Reference registration: SimpleITK Mattes MI, Euler2D / Euler3D, centred init, 3-level pyramid."""
    return RegisterResult(sitk_register(fixed, moving, params))


class SimpleITK3DParams(SimpleITKParams):
    """Parameters of the ``register_sitk_3d`` stage: the textbook SimpleITK 3D rigid set-up (Euler3D, Mattes MI,
    regular-step gradient descent, 3-level pyramid with smoothing sigmas in mm, 20 % random sampling,
    geometric-centre initialisation): the fields of :class:`SimpleITKParams` with these defaults."""

    sampling: float = Field(0.2, gt=0, le=1, description="fraction of fixed voxels sampled at random per iteration")
    init: Literal["geometry", "moments"] = Field("geometry", description="CenteredTransformInitializer mode")
    optimizer: Literal["regular_step", "gradient_descent", "line_search"] = Field(
        "regular_step", description="regular-step gradient descent (default), gradient descent, or conjugate "
                                    "gradient with line search")


@stage("register_sitk_3d", params=SimpleITK3DParams, version=2, consumes=("fixed", "moving"),
       produces=("registration",))
def register_sitk_3d(fixed: Image, moving: Image, *, params: SimpleITK3DParams) -> RegisterResult:
    """Reference 3D registration: SimpleITK Mattes MI, Euler3D, regular-step gradient descent, 3-level pyramid."""
    return RegisterResult(sitk_register(fixed, moving, params))
