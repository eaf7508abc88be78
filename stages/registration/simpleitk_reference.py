"""The reference: SimpleITK's Mattes mutual-information rigid registration, on the same images.

The adapter between :class:`~topomatch.stages.registration.image.Image` and ``SimpleITK.Image`` lives here
(origin 0, spacing 1, identity direction: pixel units, so that parameters compare directly with
ours). The registration is the textbook SimpleITK set-up (the SimpleITK notebooks'
"registration initialization" recipe):

- ``Euler2DTransform`` initialised by ``CenteredTransformInitializer`` (``GEOMETRY``: centre of the
  fixed image, centres matched; or ``MOMENTS``: intensity centroids matched), so the rotation
  centre is ``((W - 1) / 2, (H - 1) / 2)`` of the fixed image, as in our convention;
- Mattes mutual information with ``bins`` bins, random sampling of ``sampling`` of the fixed
  pixels with a fixed seed (deterministic);
- linear interpolation; scales from physical shift; an optimiser: conjugate gradient with line
  search (``line_search``, the default: the most accurate on the ITK cases, ~0.6 s per case) or
  regular-step gradient descent (``regular_step``: ~0.15 s, but it often stops short in angle);
  plain gradient descent with a per-iteration learning-rate estimate oscillated by ~2 px here;
- a ``shrink`` pyramid with Gaussian ``smoothing`` (sigmas in pixels).

The result is a :class:`~topomatch.stages.registration.register.Registration` (method
``simpleitk/mattes``); SimpleITK reports no failure flag, so ``ok`` is False only when the result
leaves less than ``min_overlap`` of the fixed image overlapping the moving one or SimpleITK raises.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass
from typing import Literal

import numpy as np
from pydantic import Field, model_validator

from topomatch.pipeline.contract import Params, StageResult, stage
from topomatch.stages.registration.image import Image
from topomatch.stages.registration.register import Registration
from topomatch.stages.registration.transform import RigidTransform, grid_points


def to_sitk(image: Image | np.ndarray):
    """A ``SimpleITK.Image`` (float32) with origin 0 and spacing 1: pixel ``[r, c]`` at (c, r)."""
    import SimpleITK as sitk

    data = image.data if isinstance(image, Image) else np.asarray(image)
    out = sitk.GetImageFromArray(np.ascontiguousarray(data, dtype=np.float32))
    out.SetOrigin((0.0, 0.0))
    out.SetSpacing((1.0, 1.0))
    return out


def sitk_euler(transform: RigidTransform):
    """Our transform as a ``SimpleITK.Euler2DTransform`` (same map of (col, row) points)."""
    import SimpleITK as sitk

    return sitk.Euler2DTransform(transform.center, math.radians(transform.angle), (transform.tx, transform.ty))


def from_sitk_euler(tx_sitk, center: tuple[float, float]) -> RigidTransform:
    """A SimpleITK Euler2D transform as our :class:`RigidTransform`, written about ``center``."""
    import SimpleITK as sitk

    e = sitk.Euler2DTransform(tx_sitk)
    angle, ttx, tty = e.GetParameters()
    ours = RigidTransform(float(ttx), float(tty), math.degrees(angle), tuple(float(c) for c in e.GetCenter()))
    return ours.with_center(center)


def sitk_resample(moving: Image, transform: RigidTransform, shape: tuple[int, int], fill: float = 0.0) -> np.ndarray:
    """``moving(T(x))`` on a grid of ``shape`` computed by SimpleITK's linear ``Resample`` (for cross-checks)."""
    import SimpleITK as sitk

    reference = sitk.Image(int(shape[1]), int(shape[0]), sitk.sitkFloat32)
    reference.SetOrigin((0.0, 0.0))
    reference.SetSpacing((1.0, 1.0))
    out = sitk.Resample(to_sitk(moving), reference, sitk_euler(transform), sitk.sitkLinear, float(fill), sitk.sitkFloat64)
    return sitk.GetArrayFromImage(out)


class SimpleITKParams(Params):
    """Parameters of :func:`register_sitk` (SimpleITK's Mattes MI registration)."""

    bins: int = Field(50, ge=4, description="Mattes histogram bins")
    sampling: float = Field(0.25, gt=0, le=1, description="fraction of fixed pixels sampled at random per iteration")
    sampling_seed: int = Field(42, ge=0, description="seed of the metric's random sampling (fixed: deterministic)")
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


def _registration_method(params: "SimpleITKParams", F, M, transform):
    """SimpleITK's ``ImageRegistrationMethod`` set up by ``params`` (metric, random sampling, linear
    interpolation, optimiser, physical-shift scales, pyramid with smoothing in physical units, the rigid
    ``transform`` centred by ``CenteredTransformInitializer``), 2D and 3D alike; with the initial transform
    and a one-element list counting the iterations."""
    import SimpleITK as sitk

    reg = sitk.ImageRegistrationMethod()
    if params.threads is not None:
        reg.SetNumberOfThreads(params.threads)
    reg.SetMetricAsMattesMutualInformation(numberOfHistogramBins=params.bins)
    reg.SetMetricSamplingStrategy(reg.RANDOM)
    reg.SetMetricSamplingPercentage(params.sampling, params.sampling_seed)
    reg.SetInterpolator(sitk.sitkLinear)
    if params.optimizer == "regular_step":
        reg.SetOptimizerAsRegularStepGradientDescent(learningRate=params.learning_rate, minStep=params.min_step,
                                                     numberOfIterations=params.iterations,
                                                     relaxationFactor=params.relaxation,
                                                     gradientMagnitudeTolerance=params.gradient_tolerance)
    elif params.optimizer == "gradient_descent":
        reg.SetOptimizerAsGradientDescent(learningRate=params.learning_rate, numberOfIterations=params.iterations,
                                          convergenceMinimumValue=params.convergence, convergenceWindowSize=10,
                                          estimateLearningRate=reg.EachIteration)
    else:
        reg.SetOptimizerAsConjugateGradientLineSearch(learningRate=params.learning_rate,
                                                      numberOfIterations=params.iterations,
                                                      convergenceMinimumValue=params.convergence,
                                                      convergenceWindowSize=10)
    reg.SetOptimizerScalesFromPhysicalShift()
    reg.SetShrinkFactorsPerLevel(list(params.shrink))
    reg.SetSmoothingSigmasPerLevel(list(params.smoothing))
    reg.SmoothingSigmasAreSpecifiedInPhysicalUnitsOn()
    mode = {"geometry": sitk.CenteredTransformInitializerFilter.GEOMETRY,
            "moments": sitk.CenteredTransformInitializerFilter.MOMENTS}[params.init]
    initial = sitk.CenteredTransformInitializer(F, M, transform, mode)
    reg.SetInitialTransform(initial, inPlace=False)
    iterations = [0]
    reg.AddCommand(sitk.sitkIterationEvent, lambda: iterations.__setitem__(0, iterations[0] + 1))
    return reg, initial, iterations


def sitk_register(fixed: Image, moving: Image, params: SimpleITKParams = SimpleITKParams()) -> Registration:
    """Register with SimpleITK (Mattes MI, Euler2D, regular-step gradient descent, pyramid).

    Returns
    -------
    Registration
        ``transform`` about the fixed image's centre (ITK convention, pixels, degrees);
        ``value`` is the final Mattes metric (negative MI, as SimpleITK minimises it).
    """
    import SimpleITK as sitk

    t0 = time.perf_counter()
    F, M = to_sitk(fixed), to_sitk(moving)
    reg, initial, iterations = _registration_method(params, F, M, sitk.Euler2DTransform())
    try:
        out = reg.Execute(F, M)
    except RuntimeError as exc:  # e.g. "All samples map outside moving image buffer"
        message = str(exc).strip().splitlines()
        detail = next((m.split(":", 1)[-1].strip() for m in message if "ERROR" in m), message[-1] if message else "")
        initial_ours = from_sitk_euler(initial, fixed.center)
        return Registration(initial_ours, math.nan, False, f"SimpleITK failed: {detail}", f"simpleitk/mattes({params.optimizer})",
                            time.perf_counter() - t0, iterations[0], iterations[0], "exception", {}, fixed.spacing)
    if out.GetName() == "CompositeTransform":
        out = sitk.CompositeTransform(out).GetNthTransform(0)
    transform = from_sitk_euler(out, fixed.center)
    value = float(reg.GetMetricValue())
    seconds = time.perf_counter() - t0
    pts = transform.apply(grid_points(fixed.shape))
    Hm, Wm = moving.shape
    overlap = float(np.mean((pts[:, 0] >= 0) & (pts[:, 0] <= Wm - 1) & (pts[:, 1] >= 0) & (pts[:, 1] <= Hm - 1)))
    ok = overlap >= params.min_overlap
    reason = "" if ok else f"only {overlap:.0%} of the fixed image overlaps the moving image at the result"
    return Registration(transform, value, ok, reason, f"simpleitk/mattes({params.optimizer})", seconds, iterations[0], iterations[0],
                        reg.GetOptimizerStopConditionDescription(), {}, fixed.spacing)


@dataclass(frozen=True, eq=False)
class SimpleITKResult(StageResult):
    """SimpleITK's registration of the current pair."""

    registration: Registration

    def summary(self) -> dict:
        return self.registration.summary()


@stage("register_sitk", params=SimpleITKParams, version=1, consumes=("fixed", "moving"), produces=("registration",))
def register_sitk(fixed: Image, moving: Image, *, params: SimpleITKParams) -> SimpleITKResult:
    """Reference registration: SimpleITK Mattes MI, Euler2D, centred init, 3-level pyramid."""
    return SimpleITKResult(sitk_register(fixed, moving, params))


# --------------------------------------------------------------------------- 3D volumes


class SimpleITK3DParams(SimpleITKParams):
    """Parameters of :func:`sitk_register_3d`: the textbook SimpleITK 3D rigid set-up (Euler3D, Mattes MI,
    regular-step gradient descent, 3-level pyramid with smoothing sigmas in mm, 20 % random sampling,
    geometric-centre initialisation): the fields of :class:`SimpleITKParams` with these defaults."""

    sampling: float = Field(0.2, gt=0, le=1, description="fraction of fixed voxels sampled at random per iteration")
    init: Literal["geometry", "moments"] = Field("geometry", description="CenteredTransformInitializer mode")
    optimizer: Literal["regular_step", "gradient_descent", "line_search"] = Field(
        "regular_step", description="regular-step gradient descent (default), gradient descent, or conjugate "
                                    "gradient with line search")
    min_step: float = Field(1e-3, gt=0, description="stop when the step falls below this")


def sitk_register_3d(fixed, moving, params: SimpleITK3DParams = SimpleITK3DParams()):
    """Register two :class:`~topomatch.stages.registration.volume.Volume` objects with SimpleITK (physical
    geometry kept). Returns a :class:`~topomatch.stages.registration.register3d.VolumeRegistration` about the
    fixed centre; ``value`` is the final Mattes metric; ``ok`` is False only for too little overlap or an
    exception (SimpleITK has no failure flag)."""
    import SimpleITK as sitk

    from topomatch.stages.registration.register3d import VolumeRegistration
    from topomatch.stages.registration.transform3d import RigidTransform3D
    from topomatch.stages.registration.volume_io import volume_to_sitk

    t0 = time.perf_counter()
    F, M = volume_to_sitk(fixed), volume_to_sitk(moving)
    reg, initial, iterations = _registration_method(params, F, M, sitk.Euler3DTransform())
    center = tuple(fixed.center)
    start = RigidTransform3D.from_sitk(initial, center)
    method = f"simpleitk/mattes({params.optimizer})/3d"
    try:
        out = reg.Execute(F, M)
    except RuntimeError as exc:
        message = str(exc).strip().splitlines()
        detail = next((m.split(":", 1)[-1].strip() for m in message if "ERROR" in m), message[-1] if message else "")
        return VolumeRegistration(transform=start, value=math.nan, ok=False, reason=f"SimpleITK failed: {detail}",
                                  method=method, seconds=time.perf_counter() - t0, iterations=iterations[0],
                                  evaluations=iterations[0], stop_reason="exception", spacing=fixed.spacing,
                                  initial=start)
    transform = RigidTransform3D.from_sitk(out, center)
    seconds = time.perf_counter() - t0
    idx = moving.continuous_index(transform.apply(fixed.voxel_points(np.arange(0, fixed.data.size, 7))))
    hi = np.asarray(moving.size) - 1.0
    overlap = float(np.mean(((idx >= 0) & (idx <= hi)).all(axis=1)))
    ok = overlap >= params.min_overlap
    reason = "" if ok else f"only {overlap:.0%} of the fixed volume overlaps the moving volume at the result"
    return VolumeRegistration(transform=transform, value=float(reg.GetMetricValue()), ok=ok, reason=reason,
                              method=method, seconds=seconds, iterations=iterations[0], evaluations=iterations[0],
                              stop_reason=reg.GetOptimizerStopConditionDescription(), spacing=fixed.spacing,
                              initial=start, overlap=overlap)


@stage("register_sitk_3d", params=SimpleITK3DParams, version=1, consumes=("fixed", "moving"),
       produces=("registration",))
def register_sitk_3d(fixed, moving, *, params: SimpleITK3DParams):
    """Reference 3D registration: SimpleITK Mattes MI, Euler3D, regular-step gradient descent, 3-level pyramid."""
    from topomatch.stages.registration.register3d import Register3DResult

    return Register3DResult(sitk_register_3d(fixed, moving, params))
