"""Synthetic misalignments with a known answer: the moving image is an image moved by a rigid T.

For a source image S and parameters theta the moving image is ``M(y) = S(T^{-1}(y))``, i.e.
``M(T(x)) = S(x)``: registering M to the fixed image S must return theta (ITK convention, see
:mod:`topomatch.stages.registration.transform`). Pixels whose preimage falls outside S are ``fill`` (0,
the background of the bundled MRI slices). The resampling is a cubic B-spline by default, not
the bilinear interpolation the registration uses, so the test is not answered by the same
interpolation that made it.

Random misalignments draw ``tx, ty`` uniformly in ``[-max_translation, max_translation]`` and the
angle uniformly in ``[-max_angle, max_angle]`` from ``numpy.random.default_rng([seed, index])``:
case ``index`` of a sweep is the same whatever the other cases are.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

import numpy as np
from pydantic import Field

from topomatch.pipeline.contract import Params, StageError, StageResult, stage
from topomatch.stages.registration.image import Image
from topomatch.stages.registration.interpolation import resample
from topomatch.stages.registration.transform import RigidTransform


class MisalignParams(Params):
    """Parameters of :func:`misalign` and :func:`misalign_pair`."""

    theta: tuple[float, float, float] = Field((0.0, 0.0, 0.0), description="(tx, ty, angle): pixels, degrees "
                                                                           "(ITK convention); unused when `index` is set")
    index: int | None = Field(None, ge=0, description="draw case `index` of a random sweep instead of `theta`")
    seed: int = Field(0, ge=0, description="seed of the random cases")
    max_translation: float = Field(20.0, ge=0, allow_inf_nan=False, description="random |tx|, |ty| bound (pixels)")
    max_angle: float = Field(25.0, ge=0, le=180, allow_inf_nan=False, description="random |angle| bound (degrees)")
    order: Literal[1, 3] = Field(3, description="resampling: 1 bilinear, 3 cubic B-spline")
    noise: float = Field(0.0, ge=0, allow_inf_nan=False, description="Gaussian noise sigma added to the moving image, "
                                                                    "as a fraction of its intensity range")
    fill: float = Field(0.0, allow_inf_nan=False, description="intensity of pixels moved in from outside the image")

    def parameters(self) -> tuple[float, float, float]:
        """The misalignment ``(tx, ty, angle)``: ``theta``, or random case ``index``."""
        if self.index is None:
            return tuple(float(v) for v in self.theta)  # type: ignore[return-value]
        rng = np.random.default_rng([self.seed, self.index])
        tx, ty = rng.uniform(-self.max_translation, self.max_translation, size=2)
        angle = rng.uniform(-self.max_angle, self.max_angle)
        return float(tx), float(ty), float(angle)


def random_cases(n: int, *, seed: int = 0, max_translation: float = 20.0, max_angle: float = 25.0) -> list[tuple[float, float, float]]:
    """The first ``n`` random misalignments of a sweep (as :meth:`MisalignParams.parameters`)."""
    return [MisalignParams(index=i, seed=seed, max_translation=max_translation, max_angle=max_angle).parameters()
            for i in range(n)]


def moved(source: Image, transform: RigidTransform, *, order: int = 3, noise: float = 0.0, fill: float = 0.0,
          rng: np.random.Generator | None = None) -> Image:
    """``M(y) = source(T^{-1}(y))`` on the source's grid (so that ``M(T(x)) = source(x)``)."""
    data = resample(source, transform.inverse(), source.shape, order=order, fill=fill)
    if noise > 0:
        rng = rng if rng is not None else np.random.default_rng(0)
        data = data + rng.normal(0.0, noise * (source.data.max() - source.data.min()), size=data.shape)
    return source.with_data(data, name=f"{source.name}_moved",
                            source=f"{source.name} moved by ({transform.tx:g}, {transform.ty:g}, {transform.angle:g})")


@dataclass(frozen=True, eq=False)
class MisalignResult(StageResult):
    """A fixed image, a moving image made from a source by a known transform, and that transform."""

    fixed: Image
    moving: Image
    truth: dict[str, float]

    def summary(self) -> dict:
        return {f"true_{k}": v for k, v in self.truth.items()}


def _truth(theta: tuple[float, float, float]) -> dict[str, float]:
    return {"tx": theta[0], "ty": theta[1], "angle": theta[2]}


@stage("misalign", params=MisalignParams, version=1, consumes=("image",), produces=("fixed", "moving", "truth"))
def misalign(image: Image, *, params: MisalignParams) -> MisalignResult:
    """Fixed = the image; moving = the image moved by a known rigid transform (given or random)."""
    theta = params.parameters()
    T = RigidTransform.for_image(image.shape, *theta)
    rng = np.random.default_rng([params.seed, params.index or 0, 1])
    return MisalignResult(image, moved(image, T, order=params.order, noise=params.noise, fill=params.fill, rng=rng),
                          _truth(theta))


@stage("misalign_pair", params=MisalignParams, version=1, consumes=("fixed", "moving", "truth"),
       produces=("moving", "truth"))
def misalign_pair(fixed: Image, moving: Image, truth, *, params: MisalignParams) -> MisalignResult:
    """Move the moving image of an aligned pair (e.g. T1/PD) by a known rigid transform."""
    if truth and any(abs(float(v)) > 1e-9 for v in truth.values()):
        raise StageError(f"misalign_pair needs a pair in register (truth all 0), got truth {truth}")
    if moving.shape != fixed.shape:
        raise StageError(f"misalign_pair needs images of one size, got fixed {fixed.shape} and moving {moving.shape}")
    theta = params.parameters()
    T = RigidTransform.for_image(fixed.shape, *theta)
    rng = np.random.default_rng([params.seed, params.index or 0, 2])
    return MisalignResult(fixed, moved(moving, T, order=params.order, noise=params.noise, fill=params.fill, rng=rng),
                          _truth(theta))
