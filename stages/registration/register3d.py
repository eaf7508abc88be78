"""Rigid registration of 3D volumes (6 parameters) in physical space: thesis ch. 2 extended to volumes.

:func:`register_volumes` finds ``theta = (ax, ay, az, tx, ty, tz)`` (SimpleITK's ``Euler3DTransform``
parameters, radians and mm, about the fixed volume's physical centre; see
:mod:`~topomatch.stages.registration.transform3d`) maximising a measure of chapter 2 (JT, JR, MI,
Tsallis MI; :mod:`~topomatch.stages.registration.divergence`) of the joint histogram of
``fixed(p)`` and ``moving(T(p))`` over sampled fixed voxels (:mod:`~topomatch.stages.registration.histogram3d`):

1. **Initialisation**: ``moments`` maps the fixed intensity centroid onto the moving one,
   ``geometry`` the grid centres (ITK's ``CenteredTransformInitializer`` modes), angles 0; then
   (``start``) the best of a grid of translations about both at the coarsest level (a moving volume
   cropped to a slab, or with another contrast, has its centroid elsewhere).
2. **Physical-space pyramid**, coarse to fine: each :class:`Level3DSpec` block-averages both
   volumes to about ``spacing`` mm (per axis, so anisotropic voxels become near-isotropic ones) and
   samples ``samples`` fixed voxels; the optimiser (the modified SPSA of
   :mod:`~topomatch.stages.registration.spsa`, or Powell) starts from the previous level's result.
   Step and perturbation lengths are millimetres. A coarse level with fewer than
   :data:`MIN_LEVEL_SAMPLES` samples (a small field of view) is measured on the grid of the first
   level that has enough, Gaussian-smoothed to its own resolution instead. Every level but the finest
   multiplies its measure by the overlap fraction (``coarse_overlap_power``), so that a sliver of
   overlap whose few samples happen to agree cannot outscore the aligned position. A level with
   ``settle > 0`` (the finest, by default) runs again from its end, at most ``reruns`` times, while
   the last half of its iterations still moved the estimate by more than ``settle`` mm (its decaying
   steps ran out before it converged).
3. **Parameter scaling**: angles are optimised in units of ``1 / r`` radians, r the RMS distance of
   the fixed foreground from the centre, so that one unit of any parameter moves the volume by
   about 1 mm.
4. **Self-check** (a failure is a flag with a reason, never a silent wrong answer): the result is
   flagged when the objective could not be evaluated at the start (no overlap after
   initialisation), when less than ``metric.min_overlap`` of the fixed samples overlap the moving
   volume at the result, when it sits on a search bound, when the measure at the result is below
   ``check.chance`` times its chance level (the same samples with the fixed intensities paired at
   random: unrelated content), when it is not better than at the start, or when a coarse search (rotations about each axis and shifts along
   each, refined briefly) finds a higher coarsest-level value elsewhere; with ``check.retry`` the
   schedule then runs once more from there, and the higher of the two ends is checked again.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass
from typing import Callable, Literal

import numpy as np
from pydantic import Field

from topomatch.pipeline.contract import Params, StageError, StageResult, stage
from topomatch.stages.registration.histogram import Binning
from topomatch.stages.registration.histogram3d import VolumeHistogram
from topomatch.stages.registration.objective import Objective
from topomatch.stages.registration.params import MetricSpec, OptimizerSpec, TransformSpec
from topomatch.stages.registration.register import Registration
from topomatch.stages.registration.powell import PowellSettings, powell_maximize
from topomatch.stages.registration.spsa import OptimizeResult, SPSASettings, spsa_maximize
from topomatch.stages.registration.transform3d import RigidTransform3D
from topomatch.stages.registration.volume import Volume, foreground_mask


class Level3DSpec(Params):
    """One level of the coarse-to-fine schedule (lengths in mm)."""

    spacing: float = Field(0.0, ge=0, allow_inf_nan=False,
                           description="voxel size of the level (mm; each axis shrunk by the integer factor that "
                                       "comes closest, never finer than the native voxels; 0: native)")
    bins: int = Field(32, ge=2, le=1024, description="histogram bins of each volume")
    iterations: int = Field(50, ge=1, description="optimiser iterations (Powell: 4x this many evaluations at most)")
    step: float = Field(1.0, gt=0, allow_inf_nan=False, description="SPSA first step length a_0 (mm)")
    c: float = Field(1.0, gt=0, allow_inf_nan=False, description="SPSA perturbation c (mm)")
    average: int = Field(1, ge=1, description="SPSA gradient estimates averaged per iteration")
    gain_alpha: float = Field(0.602, gt=0, le=1, allow_inf_nan=False, description="decay exponent of a_k")
    samples: int | None = Field(None, ge=100, description="at most this many fixed voxels (fixed-seed random subset)")
    settle: float = Field(0.0, ge=0, allow_inf_nan=False,
                          description="run the level again from its end while the last half of its iterations moved "
                                      "the estimate by more than this (mm, RMS displacement; 0: never)")
    reruns: int = Field(0, ge=0, le=10, description="at most this many runs again (see settle)")


def default_schedule_3d() -> list[Level3DSpec]:
    """Three levels at 8, 4 and 2 mm (see docs/registration.md, "3D volumes", for how it was chosen)."""
    return [
        Level3DSpec(spacing=8.0, bins=16, iterations=150, step=4.0, c=4.0, samples=4000),
        Level3DSpec(spacing=4.0, bins=24, iterations=60, step=1.0, c=2.0, samples=8000),
        Level3DSpec(spacing=2.0, bins=64, iterations=40, step=0.3, c=1.0, average=2, gain_alpha=1.0, samples=100000,
                    settle=0.2, reruns=2),
    ]


class Bounds3DSpec(Params):
    """The search box around the initial transform."""

    max_translation: float | None = Field(None, gt=0, description="bound on each translation from the initial one "
                                                                  "(mm; default: a quarter of the fixed extent)")
    max_angle: float = Field(45.0, gt=0, le=90, description="bound on each Euler angle (degrees)")


class Start3DSpec(Params):
    """The search for a start: translations about the centre-mapping ones, scored at the coarsest level."""

    steps: int = Field(2, ge=0, le=5, description="grid of (2 steps + 1)^3 shifts about each centre-mapping "
                                                 "translation (0: start at transform.init's)")
    spacing: float = Field(12.0, gt=0, allow_inf_nan=False, description="grid spacing (mm)")
    candidates: int = Field(2, ge=0, description="best grid shifts optimised briefly at the coarsest level, besides "
                                                 "the centres themselves")
    iterations: int = Field(80, ge=0, description="coarsest-level iterations from each candidate")


class Check3DSpec(Params):
    """The self-check of a 3D registration."""

    search: bool = Field(True, description="coarse search: rotations and shifts, refined briefly, that would beat "
                                           "the result flag it")
    angles: list[float] = Field(default_factory=lambda: [-30.0, 30.0], description="probe rotations about each axis "
                                                                                   "(degrees)")
    shift: float = Field(0.25, ge=0, le=1, description="probe shifts along each axis as a fraction of the fixed "
                                                       "extent")
    refine: int = Field(30, ge=0, description="coarsest-level iterations from the best probes")
    candidates: int = Field(2, ge=1, description="best probes refined")
    margin: float = Field(0.01, ge=0, description="relative margin by which a probe must win to flag the result")
    chance: float = Field(3.0, ge=0, description="flag a result whose measure is below this multiple of its chance "
                                                 "level (the same samples with the fixed intensities paired at random; "
                                                 "0: no test)")
    retry: bool = Field(True, description="when a probe wins, run the schedule once more from it and keep the "
                                          "higher end")
    on_failure: Literal["flag", "error"] = Field("flag", description="flag a failed registration, or raise an error")


class Register3DParams(Params):
    """Parameters of :func:`register_volumes`."""

    metric: MetricSpec = Field(default_factory=MetricSpec, description="the measure: name, alpha, weights, "
                                                                       "tmi_form, min_overlap")
    optimizer: OptimizerSpec = Field(default_factory=OptimizerSpec, description="spsa or powell, and SPSA's gains "
                                                                                "(lengths in mm)")
    schedule: list[Level3DSpec] = Field(default_factory=default_schedule_3d, min_length=1,
                                        description="coarse-to-fine levels: spacing, bins, iterations, step, c, "
                                                    "average, gain_alpha, samples")
    transform: TransformSpec = Field(default_factory=TransformSpec, description="initialisation of the transform "
                                                                                 "(moments or geometry)")
    start: Start3DSpec = Field(default_factory=Start3DSpec, description="coarse search for the initial translation")
    bounds: Bounds3DSpec = Field(default_factory=Bounds3DSpec, description="search box: max_translation, max_angle")
    check: Check3DSpec = Field(default_factory=Check3DSpec, description="self-check")
    sample_mask: Literal["none", "foreground"] = Field(
        "foreground", description="fixed voxels sampled: all, or the Otsu foreground (a mask given to the API wins)")
    jitter: bool = Field(True, description="move each sample by a fixed random offset within its voxel")
    seed: int = Field(0, ge=0, description="seed of the SPSA perturbations and of the voxel samples")
    coarse_overlap_power: float = Field(1.0, ge=0, le=4, allow_inf_nan=False,
                                        description="every level but the finest multiplies its measure by the "
                                                    "overlap fraction to this power (0: not): a sliver of overlap "
                                                    "cannot outscore the aligned position")

    def method(self) -> str:
        return f"{self.optimizer.name}/{self.metric.label()}/3d"


@dataclass(frozen=True, eq=False)
class VolumeRegistration(Registration):
    """The outcome of one 3D registration: :class:`~topomatch.stages.registration.register.Registration`'s
    fields, with

    Attributes
    ----------
    transform : RigidTransform3D
        T with ``fixed(p) ~ moving(T(p))``, about the fixed volume's physical centre.
    initial : RigidTransform3D
        Where the optimiser started.
    overlap : float
        Fraction of the finest level's fixed samples inside the moving volume at the result.
    history : dict of ndarray
        Per iteration: ``level``, ``theta`` (k, 6), ``value``, ``step``, ``blocked``.
    spacing : (sx, sy, sz)
        The fixed volume's voxel size (mm).
    """

    initial: RigidTransform3D | None = None
    overlap: float = math.nan

    def summary(self) -> dict:
        ax, ay, az = self.transform.angles_deg
        tx, ty, tz = self.transform.translation
        return {"angle_x": ax, "angle_y": ay, "angle_z": az, "tx": tx, "ty": ty, "tz": tz, "objective": self.value,
                "ok": self.ok, "reason": self.reason, "method": self.method, "iterations": self.iterations,
                "evaluations": self.evaluations, "overlap": self.overlap, "stop": self.stop_reason,
                "seconds": self.seconds}


@dataclass(frozen=True, eq=False)
class Register3DResult(StageResult):
    """The 3D registration of the current fixed/moving pair."""

    registration: VolumeRegistration

    def summary(self) -> dict:
        return self.registration.summary()


def initial_translation_3d(fixed: Volume, moving: Volume, mode: str) -> np.ndarray:
    """Translation t (angles 0) mapping the fixed reference point (centroid or grid centre) onto the moving one."""
    if mode == "moments":
        return moving.centroid() - fixed.centroid()
    if mode == "geometry":
        return moving.center - fixed.center
    raise ValueError(f"init must be 'moments' or 'geometry', got {mode!r}")


def rms_radius_3d(volume: Volume, mask: np.ndarray | None = None) -> float:
    """RMS distance (mm) of the (masked) voxels from the volume's centre: a rotation by d radians moves them
    by about ``d * radius``."""
    flat = np.flatnonzero(mask.ravel()) if mask is not None and mask.any() else None
    if flat is not None and len(flat) > 20000:
        flat = flat[:: len(flat) // 20000]
    pts = volume.voxel_points(flat) if flat is not None else volume.voxel_points(
        np.arange(0, volume.data.size, max(1, volume.data.size // 20000)))
    return float(np.sqrt(np.mean(np.sum((pts - volume.center) ** 2, axis=1))))


@dataclass(frozen=True)
class _Level:
    spec: Level3DSpec
    objective: Objective
    spacing: float


def register_volumes(fixed: Volume, moving: Volume, params: Register3DParams = Register3DParams(), *,
                     fixed_mask: np.ndarray | None = None,
                     callback: Callable[[int, int, np.ndarray, float], bool | None] | None = None) -> VolumeRegistration:
    """Register ``moving`` to ``fixed`` (rigid, 3D, physical space).

    Parameters
    ----------
    fixed, moving : Volume
    params : Register3DParams
    fixed_mask : ndarray of bool, shape of ``fixed.data``, optional
        Fixed voxels to sample (overrides ``params.sample_mask``).
    callback : callable, optional
        ``callback(level, k, theta, value)`` after every optimiser iteration; True stops the level.

    Returns
    -------
    VolumeRegistration
        ``ok=False`` with a ``reason`` when the self-check fails (``check.on_failure='flag'``).

    Raises
    ------
    StageError
        A failed self-check with ``check.on_failure='error'``; a mask that selects nothing.
    """
    t0 = time.perf_counter()
    run = _Run3D(fixed, moving, params, fixed_mask, callback)
    theta, stop = run.schedule_from(run.start)
    fine = run.levels[-1].objective
    value = fine(theta)
    problems = run.self_check(theta, value, stop)
    if run.better is not None and params.check.retry:
        # the coarse search found a higher basin: run the schedule from it, adopt it if it ends higher
        other, other_stop = run.schedule_from(run.better)
        other_value = fine(other)
        if other_value > value:
            theta, value, stop = other, other_value, other_stop
            problems = run.self_check(theta, value, stop)
    transform = RigidTransform3D(tuple(theta), tuple(run.center))
    ok, reason = not problems, "; ".join(problems)
    keys = ("level", "theta", "value", "step", "blocked")
    history = {k: np.concatenate([h[k] for h in run.history]) if run.history else np.zeros(0) for k in keys}
    reg = VolumeRegistration(transform=transform, value=float(value), ok=ok, reason=reason, method=params.method(),
                             seconds=time.perf_counter() - t0, iterations=int(len(history["level"])),
                             evaluations=sum({id(lv.objective): lv.objective.n_evals for lv in run.levels}.values()), stop_reason=stop,
                             history=history, spacing=fixed.spacing,
                             initial=RigidTransform3D(tuple(run.start), tuple(run.center)), overlap=fine.overlap(theta))
    if not ok and params.check.on_failure == "error":
        a, t = transform.angles_deg, transform.translation
        raise StageError(f"3D registration failed: {reason} (estimate angles {a[0]:.2f}, {a[1]:.2f}, {a[2]:.2f} deg, "
                         f"translation {t[0]:.2f}, {t[1]:.2f}, {t[2]:.2f} mm)")
    return reg


MIN_LEVEL_VOXELS = 8
"""Smallest number of voxels along every axis of a pyramid level; a coarser level uses less shrinking."""

MIN_LEVEL_SAMPLES = 2000
"""Fewest fixed samples of a pyramid level's measure; a coarser level with fewer is measured on the grid of the
first finer level with enough, smoothed (its schedule entry is kept)."""

SMALL_FOV_SIGMA = 0.3
"""Gaussian sigma, as a fraction of the level's spacing, that stands in for a coarse level's block average on a
finer grid (a block of width s has a standard deviation of s / sqrt(12) = 0.29 s)."""


class _Run3D:
    """One 3D registration in progress: the pyramid, scaling, bounds, random stream and history."""

    def __init__(self, fixed: Volume, moving: Volume, params: Register3DParams, fixed_mask: np.ndarray | None,
                 callback):
        self.params, self.callback = params, callback
        self.fixed, self.moving = fixed, moving
        self.center = fixed.center
        if fixed_mask is not None:
            fixed_mask = np.asarray(fixed_mask, dtype=bool)
            if fixed_mask.shape != fixed.shape:
                raise StageError(f"the fixed mask has shape {fixed_mask.shape}, the fixed volume {fixed.shape}")
            if not fixed_mask.any():
                raise StageError("the fixed mask selects no voxel")
        elif params.sample_mask == "foreground":
            fixed_mask = foreground_mask(fixed)
        mask_volume = None if fixed_mask is None else fixed.with_data(fixed_mask.astype(np.float64))
        self.levels = self._pyramid(mask_volume)
        self.radius = rms_radius_3d(fixed, fixed_mask if fixed_mask is not None else foreground_mask(fixed))
        self.scales = np.array([1.0 / self.radius] * 3 + [1.0] * 3)
        self.rng = np.random.default_rng(params.seed)
        self.start = self.start_search(initial_translation_3d(fixed, moving, params.transform.init))
        t_init = self.start[3:]
        b = params.bounds
        extent = np.asarray(fixed.size) * np.asarray(fixed.spacing)
        self.max_translation = b.max_translation if b.max_translation is not None else 0.25 * float(extent.max())
        a = math.radians(b.max_angle)
        self.lower = np.r_[-a, -a, -a, t_init - self.max_translation]
        self.upper = np.r_[a, a, a, t_init + self.max_translation]
        self.history: list[dict[str, np.ndarray]] = []
        self.better: np.ndarray | None = None

    def _pyramid(self, mask_volume: Volume | None) -> list[_Level]:
        """One measure per schedule level, coarse to fine.

        A level whose grid would hold fewer than :data:`MIN_LEVEL_SAMPLES` samples (a small field of view
        shrunk a lot: its measure would be dominated by chance and by the overlap) is measured instead on the
        grid of the first level with enough, after a Gaussian of sigma = :data:`SMALL_FOV_SIGMA` x its spacing
        (about the low-pass of its block average, without losing samples). Every level but the finest
        weighs its measure by the overlap (``coarse_overlap_power``)."""
        p, m = self.params, self.params.metric
        fixed, moving = self.fixed, self.moving

        def build(i: int, spec: Level3DSpec, grid: Level3DSpec, sigma: float) -> _Level:
            F, M = (fixed.smoothed(sigma), moving.smoothed(sigma)) if sigma > 0 else (fixed, moving)
            F, M = _level_volume(F, grid.spacing), _level_volume(M, grid.spacing)
            mask = None if mask_volume is None else _level_volume(mask_volume, grid.spacing).data >= 0.5
            if mask is not None and not mask.any():
                mask = None
            jh = VolumeHistogram(F, M, Binning.of(fixed.data, spec.bins), Binning.of(moving.data, spec.bins),
                                 center=self.center, samples=grid.samples, mask=mask, jitter=p.jitter, seed=p.seed + i)
            power = p.coarse_overlap_power if i < len(p.schedule) - 1 else 0.0
            obj = Objective(jh, m.name, alpha=m.alpha, weights=m.weights, tmi_form=m.tmi_form,
                            min_overlap=m.min_overlap, overlap_power=power)
            return _Level(spec, obj, float(np.mean(F.spacing)))

        levels = [build(i, spec, spec, 0.0) for i, spec in enumerate(p.schedule)]
        enough = next((i for i, lv in enumerate(levels) if lv.objective.histogram.n_samples >= MIN_LEVEL_SAMPLES),
                      len(levels) - 1)
        for i in range(enough):
            levels[i] = build(i, p.schedule[i], p.schedule[enough], SMALL_FOV_SIGMA * p.schedule[i].spacing)
        return levels

    def start_search(self, t_init: np.ndarray) -> np.ndarray:
        """The starting parameters. With ``start.steps > 0``: a grid of ``(2 steps + 1)^3`` shifts of
        ``start.spacing`` mm about each centre-mapping translation (``transform.init``'s, moments and geometry:
        a moving volume cropped to a slab, or with another contrast, moves its centroid) and about the
        identity (the files' own placement) is scored at the
        coarsest level; the coarsest level's optimiser then runs ``start.iterations`` iterations from each
        centre and from the ``start.candidates`` best shifts (at least half ``start.spacing`` apart), and the
        highest end is the start."""
        st = self.params.start
        theta0 = np.r_[0.0, 0.0, 0.0, t_init]
        if st.steps == 0:
            return theta0
        coarse = self.levels[0].objective
        offsets = np.arange(-st.steps, st.steps + 1) * st.spacing
        grid = np.stack(np.meshgrid(offsets, offsets, offsets, indexing="ij"), axis=-1).reshape(-1, 3)
        # the files' own placement (identity) too: volumes of one subject often share a physical frame
        centres = [t_init] + [initial_translation_3d(self.fixed, self.moving, m) for m in ("moments", "geometry")]
        centres.append(np.zeros(3))
        scored = [(coarse(theta0), 0, theta0)]
        for c in centres:
            for off in grid:
                theta = np.r_[0.0, 0.0, 0.0, c + off]
                scored.append((coarse(theta), len(scored), theta))
        scored = [x for x in scored if math.isfinite(x[0])]
        if not scored:
            return theta0
        scored.sort(key=lambda x: (-x[0], x[1]))
        # every centre itself (a large rotation can make a zero-rotation score rank it low), then the best shifts
        chosen: list[np.ndarray] = []
        for theta in [np.r_[0.0, 0.0, 0.0, c] for c in centres] + [x[2] for x in scored]:
            if len(chosen) >= len(centres) + st.candidates:
                break
            if math.isfinite(coarse(theta)) and all(np.linalg.norm(theta[3:] - other[3:]) >= 0.5 * st.spacing
                                                    for other in chosen):
                chosen.append(theta)
        if not chosen:
            return scored[0][2]
        if st.iterations == 0 or len(chosen) == 1:
            return chosen[0]
        spec = self.levels[0].spec.model_copy(update={"iterations": st.iterations})
        box = np.r_[[math.radians(self.params.bounds.max_angle)] * 3, [np.inf] * 3]
        ends = []
        for theta in chosen:
            res = self.optimize(0, spec, theta, lower=-box, upper=box)
            ends.append((coarse(res.theta), res.theta))
        value, best = max(ends, key=lambda e: e[0] if math.isfinite(e[0]) else -math.inf)
        return best if math.isfinite(value) else chosen[0]

    def optimize(self, li: int, spec: Level3DSpec, theta: np.ndarray, *, lower, upper, callback=None,
                 start: int = 0) -> OptimizeResult:
        o = self.params.optimizer
        objective = self.levels[li].objective
        if o.name == "spsa":
            settings = SPSASettings(
                iterations=spec.iterations, a=o.a, A=o.A, c=spec.c, alpha=spec.gain_alpha, gamma=o.gain_gamma,
                step=spec.step, average=spec.average, max_step=o.max_step, blocking=o.blocking, shrink=o.shrink,
                tol=o.tol, average_last=min(o.average_last, spec.iterations), newton=o.newton, normalize=o.normalize,
                c_step_ratio=o.c_step_ratio, start=start)
            return spsa_maximize(objective, theta, settings, rng=self.rng, scales=self.scales, lower=lower,
                                 upper=upper, callback=callback)
        settings = PowellSettings(max_evaluations=max(30, 4 * spec.iterations), xtol=0.02 * self.levels[li].spacing,
                                  step=spec.step)
        return powell_maximize(objective, theta, settings, scales=self.scales, lower=lower, upper=upper,
                               callback=callback)

    def schedule_from(self, theta: np.ndarray) -> tuple[np.ndarray, str]:
        stop = ""
        for li, level in enumerate(self.levels):
            cb = None if self.callback is None else (lambda k, th, v, li=li: self.callback(li, k, th, v))
            for _ in range(1 + level.spec.reruns):
                res = self.optimize(li, level.spec, theta, lower=self.lower, upper=self.upper, callback=cb)
                if level.objective(res.theta) >= level.objective(theta):  # a level never ends worse than it started
                    theta = res.theta
                stop = res.stop_reason
                self.history.append({"level": np.full(res.iterations, li), **res.history})
                if not self.still_moving(res.history["theta"], level.spec.settle):
                    break
        return np.asarray(theta, dtype=np.float64), stop

    def still_moving(self, path: np.ndarray, settle: float) -> bool:
        """Whether the last half of an optimiser's iterates ``path`` (k, 6) moved the estimate by more than
        ``settle`` mm: the level's step lengths ran out before it converged (a coarser level left the estimate
        further away than the level's steps can travel: a small field of view with few coarse samples)."""
        if settle <= 0 or len(path) < 4:
            return False
        return self.distance(path[-1], path[len(path) // 2]) > settle

    def distance(self, a: np.ndarray, b: np.ndarray) -> float:
        """Approximate RMS displacement (mm) between two parameter vectors."""
        return float(np.linalg.norm((a - b) / self.scales))

    def probes(self, theta: np.ndarray) -> list[np.ndarray]:
        c = self.params.check
        out = []
        extent = np.asarray(self.fixed.size) * np.asarray(self.fixed.spacing)
        for axis in range(3):
            for ang in c.angles:
                p = theta.copy()
                p[axis] += math.radians(ang)
                out.append(p)
            for sign in (-1.0, 1.0):
                p = theta.copy()
                p[3 + axis] += sign * c.shift * extent[axis]
                out.append(p)
        return [np.clip(p, self.lower, self.upper) for p in out]

    def self_check(self, theta: np.ndarray, value: float, stop: str) -> list[str]:
        params, check = self.params, self.params.check
        problems: list[str] = []
        self.better = None
        coarse, fine = self.levels[0].objective, self.levels[-1].objective
        start_coarse = coarse(self.start)
        if stop in ("invalid_start", "flat_objective") or not math.isfinite(start_coarse):
            problems.append(f"the optimiser could not start ({'no overlap' if not math.isfinite(start_coarse) else stop}"
                            f"): only {coarse.overlap(self.start):.1%} of the fixed samples overlap the moving volume "
                            f"after initialisation ({params.transform.init}; min_overlap "
                            f"{params.metric.min_overlap:.0%}), or the volumes carry no information")
        if not math.isfinite(value):
            problems.append(f"only {fine.overlap(theta):.1%} of the fixed samples overlap the moving volume at the "
                            f"result (min_overlap {params.metric.min_overlap:.0%})")
            return problems
        tol = np.r_[[1.0 / self.radius] * 3, [1.0] * 3]
        at_bound = (theta <= self.lower + tol) | (theta >= self.upper - tol)
        if at_bound.any():
            names = [n for n, b in zip(("angle_x", "angle_y", "angle_z", "tx", "ty", "tz"), at_bound) if b]
            problems.append(f"the estimate is on the search bound of {', '.join(names)} (bounds.max_translation / "
                            f"max_angle): the misalignment is probably outside the capture range")
        if check.chance > 0:
            chance = fine.on(fine.histogram.shuffled(self.params.seed))(theta)
            if math.isfinite(chance) and chance > 0 and value < check.chance * chance:
                problems.append(f"the measure at the result ({value:.3g}) is only {value / chance:.2f} times its chance "
                                f"level ({chance:.3g}: the same samples paired at random): the volumes share no "
                                f"structure that this measure can align")
        start_fine = fine(self.start)
        if self.distance(theta, self.start) > 0.5 * self.levels[-1].spacing and math.isfinite(start_fine) \
                and not value > start_fine:
            problems.append(f"the measure at the result ({value:.4g}) is no better than at the start ({start_fine:.4g})")
        if check.search and not problems:
            here = coarse(theta)
            scored = [(coarse(p), i, p) for i, p in enumerate(self.probes(theta))]
            scored = [s for s in scored if math.isfinite(s[0])]
            scored.sort(key=lambda s: -s[0])
            spec = self.levels[0].spec.model_copy(update={"iterations": max(1, check.refine)})
            for v, _, probe in scored[: check.candidates]:
                if check.refine > 0:
                    res = self.optimize(0, spec, probe, lower=self.lower, upper=self.upper)
                    probe, v = res.theta, coarse(res.theta)
                # a result the coarsest level cannot score (its overlap there is below min_overlap) loses to any
                # probe it can score: -inf + margin * inf would be nan, and a comparison with nan never flags
                beats = v > here + check.margin * abs(here) if math.isfinite(here) else True
                if math.isfinite(v) and beats and self.distance(probe, theta) > 2.0 * self.levels[0].spacing:
                    self.better = probe
                    problems.append(f"a coarse search finds a higher value ({v:.4g} > {here:.4g} at "
                                    f"{self.levels[0].spacing:.0f} mm) {self.distance(probe, theta):.0f} mm away "
                                    f"from the result: it is probably a local optimum")
                    break
        return problems


def _level_volume(volume: Volume, spacing: float) -> Volume:
    """The volume shrunk to about ``spacing`` mm, keeping at least MIN_LEVEL_VOXELS voxels along every axis."""
    if spacing <= 0:
        return volume
    factors = []
    for n, s in zip(volume.size, volume.spacing):
        f = max(1, int(round(spacing / s)))
        while f > 1 and n // f < MIN_LEVEL_VOXELS:
            f -= 1
        factors.append(f)
    return volume.shrink(tuple(factors))  # type: ignore[arg-type]


@stage("register_3d", params=Register3DParams, version=1, consumes=("fixed", "moving"), produces=("registration",))
def register_3d_stage(fixed: Volume, moving: Volume, *, params: Register3DParams) -> Register3DResult:
    """Rigid 3D registration by an entropic measure (JT, JR, MI, TMI) with SPSA or Powell, physical-space pyramid."""
    return Register3DResult(register_volumes(fixed, moving, params))
