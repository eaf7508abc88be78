"""Resampling volumes and synthetic 3D misalignments with a known answer.

For a source volume S and a rigid T (fixed-to-moving, :mod:`~topomatch.stages.registration.transform3d`)
the moving volume is ``M(q) = S(T^-1(q))`` on S's grid, so ``M(T(p)) = S(p)``: registering M to S
must return T. A case may then be cropped to a slab (the moving volume covers only part of the
fixed field of view), get a tissue-contrast remapping (a T2-like contrast from a T1 volume: a
non-monotonic intensity map, for multi-modal cases) and Gaussian noise.

Random cases draw each Euler angle uniformly in ``[-max_angle, max_angle]`` and each translation
in ``[-max_translation, max_translation]`` from ``numpy.random.default_rng([seed, index])``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from pydantic import Field

from topomatch.pipeline.contract import Params, StageResult, stage
from topomatch.stages.registration.histogram3d import trilinear
from topomatch.stages.registration.search import otsu_threshold
from topomatch.stages.registration.transform3d import RigidTransform3D, target_registration_error
from topomatch.stages.registration.volume import Volume, foreground_mask


def resample_volume(moving: Volume, transform: RigidTransform3D, reference: Volume, *, fill: float = 0.0,
                    chunk: int = 1 << 20) -> np.ndarray:
    """``moving(T(p))`` (trilinear) at the voxels p of ``reference``'s grid, shape ``reference.shape``;
    ``fill`` where T(p) falls outside the moving grid."""
    n = reference.data.size
    out = np.empty(n)
    for start in range(0, n, chunk):
        flat = np.arange(start, min(n, start + chunk))
        out[flat] = resample_at(moving, transform, reference, flat, fill=fill)
    return out.reshape(reference.shape)


def resample_at(moving: Volume, transform: RigidTransform3D, reference: Volume, flat: np.ndarray, *,
                fill: float = 0.0) -> np.ndarray:
    """``moving(T(p))`` (trilinear) at the voxels p of ``reference`` with flat indices ``flat`` (m,)."""
    q = transform.apply(reference.voxel_points(flat))
    idx = ((q - np.asarray(moving.origin)) @ np.linalg.inv(moving.index_matrix).T).T
    v, inside = trilinear(moving.data, idx)
    return np.where(inside, v, fill)


def t2_like(data: np.ndarray) -> np.ndarray:
    """A T2-like contrast of a T1-weighted volume: background stays dark, the darkest tissue (CSF) becomes the
    brightest, the brightest (white matter) dark; piecewise linear over the foreground's quantiles."""
    d = np.asarray(data, dtype=np.float64)
    t = otsu_threshold(d)
    fg = d[d > t]
    if fg.size == 0:
        return d.copy()
    lo = float(d.min())
    q = np.quantile(fg, [0.0, 0.25, 0.5, 0.75, 0.99])
    xs = np.array([lo, lo + 0.5 * (t - lo), t, q[1], q[2], q[3], q[4], max(q[4], float(d.max())) + 1e-9])
    ys = np.array([0.0, 0.1, 0.9, 0.75, 0.45, 0.25, 0.35, 0.35])
    xs = np.maximum.accumulate(xs + np.arange(len(xs)) * 1e-9)
    return np.interp(d, xs, ys) * float(fg.max())


@dataclass(frozen=True)
class Case3D:
    """A synthetic misalignment: ``fixed``, ``moving``, and the true T (``fixed(p) ~ moving(T(p))``)."""

    name: str
    fixed: Volume
    moving: Volume
    truth: RigidTransform3D
    multimodal: bool
    cropped: bool


def random_transform(rng: np.random.Generator, center, *, max_angle: float = 15.0,
                     max_translation: float = 15.0) -> RigidTransform3D:
    angles = np.radians(rng.uniform(-max_angle, max_angle, 3))
    t = rng.uniform(-max_translation, max_translation, 3)
    return RigidTransform3D(tuple(angles) + tuple(t), tuple(np.asarray(center, dtype=np.float64)))


def crop_slab(volume: Volume, axis: int, fraction: float, start_fraction: float) -> Volume:
    """Keep ``fraction`` of the voxels along grid axis ``axis`` (0 = i, 1 = j, 2 = k), starting at
    ``start_fraction`` of the remainder; the origin moves so that the kept voxels stay where they were."""
    n = volume.size[axis]
    keep = max(2, int(round(fraction * n)))
    start = int(round(start_fraction * (n - keep)))
    sl = [slice(None)] * 3
    sl[2 - axis] = slice(start, start + keep)
    idx = np.zeros(3)
    idx[axis] = start
    origin = volume.physical(idx[None, :])[0]
    return Volume(volume.data[tuple(sl)].copy(), volume.spacing, tuple(origin), volume.direction, volume.name,
                  f"{volume.source} cropped")


def make_case(source: Volume, index: int, *, seed: int, multimodal: bool, crop: bool, max_angle: float = 15.0,
              max_translation: float = 15.0, noise: float = 0.03, crop_fraction: float = 0.7) -> Case3D:
    """Case ``index`` of a sweep from ``source`` (the fixed volume, with its own noise)."""
    rng = np.random.default_rng([seed, index])
    truth = random_transform(rng, source.center, max_angle=max_angle, max_translation=max_translation)
    scale = float(np.quantile(source.data, 0.99)) - float(source.data.min())
    fixed = source.with_data(source.data + rng.normal(0.0, noise * scale, source.shape), name=f"{source.name}_fixed")
    moved = resample_volume(source, truth.inverse(), source, fill=float(source.data.min()))
    if multimodal:
        moved = t2_like(moved)
    moved = moved + rng.normal(0.0, noise * (float(np.quantile(moved, 0.99)) - float(moved.min())), moved.shape)
    moving = source.with_data(moved, name=f"{source.name}_moving{index}")
    if crop:
        moving = crop_slab(moving, int(rng.integers(0, 3)), crop_fraction, float(rng.uniform(0.0, 1.0)))
    kind = ("multi" if multimodal else "mono") + ("-crop" if crop else "")
    return Case3D(f"{source.name}-{kind}-{index}", fixed, moving, truth, multimodal, crop)


def mean_tre(truth: RigidTransform3D, estimate: RigidTransform3D, fixed: Volume, mask: np.ndarray | None = None,
             max_points: int = 50000) -> float:
    """Mean target registration error (mm) over the fixed voxels of ``mask`` (default: Otsu foreground)."""
    if mask is None:
        mask = foreground_mask(fixed)
    flat = np.flatnonzero(mask.ravel())
    if len(flat) > max_points:
        flat = flat[:: int(math.ceil(len(flat) / max_points))]
    return float(np.mean(target_registration_error(truth, estimate, fixed.voxel_points(flat))))


# --------------------------------------------------------------------------- stages (configs)


class MisalignVolumeParams(Params):
    """Parameters of :func:`misalign_volume` (case ``index`` of a random sweep; see :func:`make_case`)."""

    index: int = Field(0, ge=0, description="case of the random sweep")
    seed: int = Field(0, ge=0, description="seed of the random cases")
    multimodal: bool = Field(False, description="remap the moving volume to a T2-like contrast")
    crop: bool = Field(False, description="crop the moving volume to a slab")
    crop_fraction: float = Field(0.7, gt=0, le=1, description="slab thickness as a fraction of the axis")
    max_angle: float = Field(15.0, ge=0, le=90, allow_inf_nan=False, description="bound on each Euler angle (degrees)")
    max_translation: float = Field(15.0, ge=0, allow_inf_nan=False, description="bound on each translation (mm)")
    noise: float = Field(0.03, ge=0, allow_inf_nan=False, description="Gaussian noise sigma, fraction of the "
                                                                      "intensity range")


@dataclass(frozen=True, eq=False)
class MisalignVolumeResult(StageResult):
    """A fixed volume, a moving volume and the true transform (``truth``: its six parameters and centre)."""

    fixed: Volume
    moving: Volume
    truth: dict

    def summary(self) -> dict:
        return dict(self.truth)


def truth_dict(t: RigidTransform3D) -> dict:
    """The six parameters (degrees, mm) and the centre of a true transform, as a config's ``truth``."""
    ax, ay, az = t.angles_deg
    tx, ty, tz = t.translation
    return {"angle_x": ax, "angle_y": ay, "angle_z": az, "tx": float(tx), "ty": float(ty), "tz": float(tz),
            "cx": t.center[0], "cy": t.center[1], "cz": t.center[2]}


def truth_transform_3d(truth: dict) -> RigidTransform3D:
    """Inverse of :func:`truth_dict`."""
    angles = tuple(math.radians(truth[k]) for k in ("angle_x", "angle_y", "angle_z"))
    return RigidTransform3D(angles + tuple(float(truth[k]) for k in ("tx", "ty", "tz")),
                            tuple(float(truth[k]) for k in ("cx", "cy", "cz")))


@stage("misalign_volume", params=MisalignVolumeParams, version=1, consumes=("volume",),
       produces=("fixed", "moving", "truth"))
def misalign_volume(volume: Volume, *, params: MisalignVolumeParams) -> MisalignVolumeResult:
    """A synthetic 3D case with a known rigid transform (mono- or multi-modal, optionally cropped, noisy)."""
    case = make_case(volume, params.index, seed=params.seed, multimodal=params.multimodal, crop=params.crop,
                     max_angle=params.max_angle, max_translation=params.max_translation, noise=params.noise,
                     crop_fraction=params.crop_fraction)
    return MisalignVolumeResult(case.fixed, case.moving, truth_dict(case.truth))


class Evaluate3DParams(Params):
    """Parameters of :func:`evaluate_3d`."""

    threshold: float = Field(1.0, gt=0, description="success: mean TRE over the fixed foreground at most this (mm)")


@stage("evaluate_3d", params=Evaluate3DParams, version=1, consumes=("fixed", "registration", "truth"))
def evaluate_3d(fixed: Volume, registration, truth, *, params: Evaluate3DParams):
    """Mean / max target registration error (mm) over the fixed foreground against the known transform; the
    translation error (``d_tx``, ``d_ty``: its norm and the z component) and the rotation error (``d_angle``,
    degrees) in the 2D table's columns."""
    from topomatch.stages.registration.evaluate import EvaluateResult

    true_t = truth_transform_3d(truth)
    est = registration.transform.with_center(true_t.center)
    pts = fixed.voxel_points(np.flatnonzero(foreground_mask(fixed).ravel())[::7])
    tre = target_registration_error(true_t, est, pts)
    dR = est.rotation @ true_t.rotation.T
    d_angle = math.degrees(math.acos(max(-1.0, min(1.0, (np.trace(dR) - 1.0) / 2.0))))
    dt = est.translation - true_t.translation
    mean = float(tre.mean())
    return EvaluateResult(registration.method, float(np.linalg.norm(dt)), float(dt[2]), d_angle, mean,
                          float(tre.max()), bool(mean <= params.threshold), not registration.ok,
                          registration.seconds, dict(truth))
