"""Synthetic misalignments with a known answer, 2D and 3D: the moving image is an image moved by a rigid T.

For a source image S and a rigid T (fixed-to-moving, :mod:`~topomatch.stages.registration.transform`) the moving image
is ``M(q) = S(T^-1(q))`` on S's grid, so ``M(T(p)) = S(p)``: registering M to S must return T. Pixels whose preimage
falls outside S are ``fill``. The resampling is a cubic B-spline by default, not the N-linear interpolation the
registration uses, so the test is not answered by the interpolation that made it. A case may also get another contrast
(:func:`t2_like`), be cropped to a slab (:func:`crop_slab`) and get Gaussian noise.

Random case ``index`` of a sweep (:func:`random_transform`) is drawn from ``numpy.random.default_rng([seed, index])``:
the same whatever the other cases are."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

import numpy as np
from pydantic import Field

from topomatch.pipeline.contract import Params, StageError, StageResult, stage
from topomatch.stages.registration.image import Image, otsu_threshold
from topomatch.stages.registration.interpolation import resample
from topomatch.stages.registration.transform import RigidTransform, n_angles


def random_transform(rng: np.random.Generator, center, *, max_angle: float, max_translation: float) -> RigidTransform:
    """A rigid transform about ``center`` with each translation in ``[-max_translation, max_translation]`` and
    each angle in ``[-max_angle, max_angle]`` degrees (the translation drawn first)."""
    d = len(center)
    t = rng.uniform(-max_translation, max_translation, size=d)
    angles = np.radians(rng.uniform(-max_angle, max_angle, size=n_angles(d)))
    return RigidTransform(tuple(angles) + tuple(t), tuple(center))


def moved(source: Image, transform: RigidTransform, *, order: int = 3, noise: float = 0.0, fill: float = 0.0,
          rng: np.random.Generator | None = None) -> Image:
    """``M(q) = source(T^-1(q))`` on the source's grid (so that ``M(T(p)) = source(p)``), plus Gaussian noise of
    ``noise`` times the source's intensity range."""
    data = resample(source, transform.inverse(), source, order=order, fill=fill)
    if noise > 0:
        rng = rng if rng is not None else np.random.default_rng(0)
        data = data + rng.normal(0.0, noise * (source.data.max() - source.data.min()), size=data.shape)
    values = ", ".join(f"{n} {v:g}" for n, v in transform.degrees().items())
    return source.with_data(data, name=f"{source.name}_moved", source=f"{source.name} moved by ({values})")


T2_LEVELS = (0.0, 0.1, 0.9, 0.75, 0.45, 0.25, 0.35, 0.35)
""":func:`tissue_contrast` levels of a T2-like image: CSF brightest, white matter dark."""


def tissue_contrast(data: np.ndarray, levels) -> np.ndarray:
    """Another contrast of a T1-weighted image, piecewise linear in its intensity: ``levels`` (8 values, times
    the foreground's maximum) at the minimum, halfway to Otsu's threshold, the threshold, and the foreground's
    25th, 50th, 75th and 99th percentiles and maximum (the background, then CSF ... white matter)."""
    d = np.asarray(data, dtype=np.float64)
    t = otsu_threshold(d)
    if (fg := d[d > t]).size == 0:
        return d.copy()
    lo = float(d.min())
    q = np.quantile(fg, [0.25, 0.5, 0.75, 0.99])
    xs = np.array([lo, lo + 0.5 * (t - lo), t, q[0], q[1], q[2], q[3], max(q[3], float(d.max())) + 1e-9])
    xs = np.maximum.accumulate(xs + np.arange(len(xs)) * 1e-9)
    return np.interp(d, xs, np.asarray(levels, dtype=np.float64)) * float(fg.max())


def t2_like(data: np.ndarray) -> np.ndarray:
    """A T2-like contrast of a T1-weighted image: background stays dark, the darkest tissue (CSF) becomes the
    brightest, the brightest (white matter) dark (:data:`T2_LEVELS`)."""
    return tissue_contrast(data, T2_LEVELS)


def crop_slab(image: Image, axis: int, fraction: float, start_fraction: float) -> Image:
    """Keep ``fraction`` of the pixels along ITK axis ``axis`` (0 = i, 1 = j, 2 = k), starting at
    ``start_fraction`` of the remainder; the origin moves so that the kept pixels stay where they were."""
    n = image.size[axis]
    keep = max(2, int(round(fraction * n)))
    start = int(round(start_fraction * (n - keep)))
    first = start * np.eye(image.dim)[axis]  # the first kept pixel's index, ITK order
    return Image(np.take(image.data, range(start, start + keep), axis=image.dim - 1 - axis), image.spacing,
                 tuple(image.physical(first[None, :])[0]), image.direction, image.name, f"{image.source} cropped")


@dataclass(frozen=True)
class Case:
    """A synthetic misalignment: ``fixed``, ``moving``, and the true T (``fixed(p) ~ moving(T(p))``)."""

    name: str
    fixed: Image
    moving: Image
    truth: RigidTransform
    multimodal: bool
    cropped: bool


def make_case(source: Image, index: int, *, seed: int, multimodal: bool, crop: bool, max_angle: float = 15.0,
              max_translation: float = 15.0, noise: float = 0.03, crop_fraction: float = 0.7) -> Case:
    """Case ``index`` of a sweep from ``source`` (the fixed image, with its own noise): moved by a random T
    (trilinear), optionally T2-like, noisy, optionally cropped to a slab along a random axis."""
    rng = np.random.default_rng([seed, index])
    truth = random_transform(rng, source.center, max_angle=max_angle, max_translation=max_translation)
    scale = float(np.quantile(source.data, 0.99)) - float(source.data.min())
    fixed = source.with_data(source.data + rng.normal(0.0, noise * scale, source.shape), name=f"{source.name}_fixed")
    data = resample(source, truth.inverse(), source, fill=float(source.data.min()))
    if multimodal:
        data = t2_like(data)
    data = data + rng.normal(0.0, noise * (float(np.quantile(data, 0.99)) - float(data.min())), data.shape)
    moving = source.with_data(data, name=f"{source.name}_moving{index}")
    if crop:
        moving = crop_slab(moving, int(rng.integers(0, source.dim)), crop_fraction, float(rng.uniform(0.0, 1.0)))
    kind = ("multi" if multimodal else "mono") + ("-crop" if crop else "")
    return Case(f"{source.name}-{kind}-{index}", fixed, moving, truth, multimodal, crop)


class MisalignParams(Params):
    """Parameters of :func:`misalign` and :func:`misalign_pair`."""

    theta: list[float] | None = Field(None, description="the transform's parameters in SimpleITK's order, angles in "
                                                        "degrees: 2D (angle, tx, ty), 3D (angle_x, angle_y, angle_z, "
                                                        "tx, ty, tz); unused when `index` is set")
    index: int | None = Field(None, ge=0, description="draw case `index` of a random sweep instead of `theta`")
    seed: int = Field(0, ge=0, description="seed of the random cases")
    max_translation: float = Field(20.0, ge=0, allow_inf_nan=False, description="random translation bound per axis")
    max_angle: float = Field(25.0, ge=0, le=180, allow_inf_nan=False, description="random angle bound (degrees)")
    order: Literal[1, 3] = Field(3, description="resampling: 1 N-linear, 3 cubic B-spline")
    noise: float = Field(0.0, ge=0, allow_inf_nan=False, description="Gaussian noise sigma added to the moving image, "
                                                                    "as a fraction of its intensity range")
    fill: float = Field(0.0, allow_inf_nan=False, description="intensity of pixels moved in from outside the image")
    contrast: Literal["same", "t2_like"] = Field("same", description="the moving image's contrast: the source's, or "
                                                                    "a T2-like remapping of a T1 source (t2_like)")
    crop: float = Field(0.0, ge=0, lt=1, allow_inf_nan=False,
                        description="keep this fraction of the moving image along a random axis (a slab; 0: whole)")

    def transform(self, center) -> RigidTransform:
        """The misalignment about ``center``: ``theta``, or random case ``index``."""
        if self.index is not None:
            rng = np.random.default_rng([self.seed, self.index])
            return random_transform(rng, center, max_angle=self.max_angle, max_translation=self.max_translation)
        names = RigidTransform.identity(center).names
        theta = self.theta if self.theta is not None else [0.0] * len(names)
        if len(theta) != len(names):
            raise StageError(f"misalign.theta needs {len(names)} values for a {len(center)}D image "
                             f"({', '.join(names)}), got {len(theta)}")
        return RigidTransform.from_degrees(theta, center)


@dataclass(frozen=True, eq=False)
class MisalignResult(StageResult):
    """A fixed image, a moving image made from a source by a known transform, and that transform."""

    fixed: Image
    moving: Image
    truth: dict[str, float]

    def summary(self) -> dict:
        return {f"true_{k}": v for k, v in self.truth.items()}


def _moving(source: Image, T: RigidTransform, params: MisalignParams, stream: int) -> Image:
    rng = np.random.default_rng([params.seed, params.index or 0, stream])
    if params.contrast == "t2_like":
        source = source.with_data(t2_like(source.data))
    out = moved(source, T, order=params.order, noise=params.noise, fill=params.fill, rng=rng)
    return crop_slab(out, int(rng.integers(0, out.dim)), params.crop, float(rng.uniform())) if params.crop else out


@stage("misalign", params=MisalignParams, version=2, consumes=("image",), produces=("fixed", "moving", "truth"))
def misalign(image: Image, *, params: MisalignParams) -> MisalignResult:
    """Fixed = the image; moving = the image moved by a known rigid transform (given or random)."""
    T = params.transform(image.center)
    return MisalignResult(image, _moving(image, T, params, 1), T.degrees())


@stage("misalign_pair", params=MisalignParams, version=2, consumes=("fixed", "moving", "truth"),
       produces=("moving", "truth"))
def misalign_pair(fixed: Image, moving: Image, truth, *, params: MisalignParams) -> MisalignResult:
    """Move the moving image of an aligned pair (e.g. T1/PD) by a known rigid transform."""
    if truth and any(abs(float(v)) > 1e-9 for v in truth.values()):
        raise StageError(f"misalign_pair needs a pair in register (truth all 0), got truth {truth}")
    if moving.shape != fixed.shape:
        raise StageError(f"misalign_pair needs images of one size, got fixed {fixed.shape} and moving {moving.shape}")
    T = params.transform(fixed.center)
    return MisalignResult(fixed, _moving(moving, T, params, 2), T.degrees())
