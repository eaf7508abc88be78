"""Coarse-to-fine rigid registration of 2D images and 3D volumes: any measure (JT, JR, MI, TMI), SPSA or Powell.

:func:`register` finds the parameters of ``T(p) = R (p - c) + c + t`` (:mod:`~topomatch.stages.registration.transform`)
maximising a measure of chapter 2 of the joint histogram of ``fixed(p)`` and ``moving(T(p))``: a start (the intensity
centroids; in 3D a search of translations), a pyramid of levels in physical units (each a :class:`~.objective.Objective`
on its own :class:`JointHistogram`), SPSA or Powell per level with angles scaled by the RMS radius, and a self-check
(:data:`CHECKS`, each test returning typed :class:`Flag` s). One run loop for both dimensions: the dimension enters
through the transform's parametrisation and :func:`~.params.for_dimension`. See docs/registration.md."""

from __future__ import annotations

import math
import time
from concurrent.futures import Future, ThreadPoolExecutor
from dataclasses import dataclass, field
from typing import Callable

import numpy as np

from topomatch.pipeline.contract import StageError, StageResult, stage
from topomatch.stages.registration.histogram import Binning, JointHistogram, histogram_threads
from topomatch.stages.registration.image import Image, foreground_mask, gaussian_blur, grow, rms_radius
from topomatch.stages.registration.objective import Objective
from topomatch.stages.registration.params import DIMENSION_DEFAULTS, LevelSpec, RegisterParams, StartSpec, for_dimension
from topomatch.stages.optimize.powell import PowellSettings, powell_maximize
from topomatch.stages.registration.search import GridSearch, SearchImages, flatness, grid_search, search_spacing
from topomatch.stages.optimize.spsa import OptimizeResult, SPSASettings, spsa_maximize
from topomatch.stages.registration.structure import (distinct_levels, interior_spread, interior_structure, once_per_image,
                                                     outline_gap, outline_in_view, plateau_share, two_class_residual)
from topomatch.stages.registration.transform import RigidTransform, euler_angles, euler_matrix, n_angles

MIN_LEVEL_VOXELS = 8
"""Fewest pixels along any axis of a pyramid level; a coarser level shrinks that axis less."""
MIN_LEVEL_SAMPLES = 2000
"""Fewest fixed samples of a level's measure; a coarser level with fewer is measured, smoothed, on the grid of the first finer one with enough."""
SMALL_FIELD, LARGE_FIELD = 64.0, 512.0
"""Physical units: the defaults' lengths (levels, steps, start grid, margin, the self-check's distances) were chosen on
fields of view of 82-388; a fixed grid whose largest extent E is below the first (twenty-fifth round) or above the
second (twenty-seventh) is registered in working units of E over it (``measures['unit']``), the result scaled back."""
DROP_SAMPLES = 8  # the outline test's drop must be positive on average over this many other samples (29th round)
SMALL_FOV_SIGMA = 0.3
"""Gaussian sigma (of the level's spacing) standing in for its block average on a finer grid (s / sqrt(12) = 0.29 s)."""


@dataclass(frozen=True)
class Flag:
    """One reason to distrust a result: the test that raised it and what it found."""

    check: str
    message: str


@dataclass(frozen=True, eq=False)
class Registration:
    """The outcome of one registration (any method, either dimension). ``transform``: T, ``fixed(p) ~ moving(T(p))``,
    about the fixed grid's centre; ``value``: the measure there (finest level; NaN for methods without one);
    ``method``: e.g. ``spsa/jt(alpha=2 histogram)``; ``seconds``: wall time (images in memory); ``iterations``,
    ``evaluations``: over all levels; ``stop_reason``: the finest level's; ``history``: per iteration over all levels,
    ``level`` (k,), ``theta`` (k, p), ``value``, ``step``, ``blocked``; ``initial``: where the schedule started;
    ``overlap``: fraction of the finest level's fixed samples inside the moving image at the result; ``restarts``:
    runs of the schedule adopted after the first (a capture retry); ``measures``: what each self-check test measured,
    flagged or not (``chance``: the measure over its chance level; ``consistency``: a coarser level's largest relative
    drop; ``agreement``: the distance to a second measure's optimum; ``label``: to the answer of a label map's
    object; ``content``, ``prominence``, ``flatness``)."""

    transform: RigidTransform
    value: float
    flags: tuple[Flag, ...]
    method: str
    seconds: float
    iterations: int
    evaluations: int
    stop_reason: str
    history: dict[str, np.ndarray] = field(default_factory=dict)
    initial: RigidTransform | None = None
    overlap: float = math.nan
    restarts: int = 0
    measures: dict[str, float] = field(default_factory=dict)

    @property
    def ok(self) -> bool:
        return not self.flags

    @property
    def reason(self) -> str:
        return "; ".join(f.message for f in self.flags)

    def summary(self) -> dict:
        return {**self.transform.degrees(), "objective": self.value, "ok": self.ok, "reason": self.reason,
                "flags": ",".join(f.check for f in self.flags), "method": self.method, "iterations": self.iterations,
                "evaluations": self.evaluations, "restarts": self.restarts, "overlap": self.overlap,
                "stop": self.stop_reason, "seconds": self.seconds}


@dataclass(frozen=True, eq=False)
class RegisterResult(StageResult):
    """The registration of the current fixed/moving pair."""

    registration: Registration

    def summary(self) -> dict:
        return self.registration.summary()


def initial_translation(fixed: Image, moving: Image, mode: str, angles=None) -> np.ndarray:
    """Translation t such that ``T(p) = R(angles)(p - c) + c + t`` maps the fixed reference point (intensity
    centroid for ``'moments'``, grid centre for ``'geometry'``) onto the moving one; c the fixed centre."""
    if mode not in ("moments", "geometry"):
        raise ValueError(f"init must be 'moments' or 'geometry', got {mode!r}")
    pf, pm = (_centroid(fixed), _centroid(moving)) if mode == "moments" else (fixed.center, moving.center)
    angles = np.zeros(n_angles(fixed.dim)) if angles is None else angles
    c = fixed.center
    return pm - c - euler_matrix(angles) @ (pf - c)


_centroid = once_per_image(Image.centroid)  # the intensity centroid, once per image (the start search asks often)


def sample_mask(fixed: Image, params: RegisterParams) -> np.ndarray | None:
    """The fixed pixels the histograms sample (None: all): the Otsu foreground grown by ``sampling.margin`` (``grow``)."""
    if params.sampling.region == "all":
        return None
    return grow(foreground_mask(fixed), params.sampling.margin, fixed.spacing)


OUTLINE_TESTS = {
    "structure": (interior_structure, "has almost no structure inside its outline (interior gradient {:.3f} of the outline's"),
    "spread": (interior_spread, "is almost uniform inside its object (intensity spread {:.3f} of its contrast"),
    "residual": (two_class_residual, "fills the grid with two intensity levels only, or two exact plateaus and a "
                                     "ramp (its Otsu classes vary by {:.4f} of their contrast squared, 0 for plateaus"),
}
"""The outline-only tests: name -> (measure of one image, how a flag words a low value: a format string); each
is compared with ``check.min_<name>`` and is off at 0."""


def _below_outline_thresholds(run: "_Run") -> list[tuple[str, float, str, float]]:
    """(measure key, value, test, threshold) of each recorded outline-only measure below its threshold."""
    tests = [(key, value, key.partition("_")[0]) for key, value in run.structures.items()]
    return [(key, value, test, limit) for key, value, test in tests if value < (limit := getattr(run.params.check, f"min_{test}"))]


@dataclass(frozen=True)
class _Level:
    spec: LevelSpec
    objective: Objective
    spacing: float
    images: tuple  # (fixed, moving, mask) on the level's grid: another sample of them for the stability test


class _Run:
    """One registration in progress: the pyramid, scaling, bounds, random stream, history and level ends."""

    def __init__(self, fixed: Image, moving: Image, params: RegisterParams, mask: np.ndarray | None, callback, metric=None):
        self.params, self.callback = params, callback
        self.fixed, self.moving, self.dim = fixed, moving, fixed.dim
        self.k = n_angles(fixed.dim)
        self.center, self.mask = fixed.center, mask
        self.structures = self._structures()
        self.outline_only = bool(_below_outline_thresholds(self))
        self.levels_count = self._levels_count()
        self.outline_measure = self.outline_only or self.levels_count is not None
        spread = min((v for k, v in self.structures.items() if k.startswith("spread_")), default=math.inf)
        self.metric = metric or (params.metric.for_outline() if self.outline_measure or spread < params.metric.outline_spread
                                 else params.metric)  # metric: given (check_mirror)
        self.levels = self._pyramid()
        self.radius = rms_radius(fixed, mask)
        self.scales = np.r_[[1.0 / self.radius] * self.k, [1.0] * self.dim]
        self.rng = np.random.default_rng(params.seed)
        self.start = self.start_search(initial_translation(fixed, moving, params.transform.init))
        b = params.bounds
        extent = np.asarray(fixed.size) * np.asarray(fixed.spacing)
        reach = float(extent.max() + np.max(np.asarray(moving.size) * np.asarray(moving.spacing)))  # overlap's limit
        self.max_translation = min(b.max_translation or 0.5 * float(extent.min()), reach)
        a = math.radians(b.max_angle)
        self.lower, self.upper = (np.r_[[s * a] * self.k, self.start[self.k:] + s * self.max_translation] for s in (-1.0, 1.0))
        self.history: list[dict[str, np.ndarray]] = []
        self.ends: list[np.ndarray] = []
        self._grids: dict[bool, GridSearch | Future] = {}  # mirrored or not: a Future while prefetch()'s search runs

    def _structures(self) -> dict[str, float]:
        """``<test>_fixed`` / ``<test>_moving`` for each outline-only test whose threshold ``check.min_<test>`` is
        above 0 (:data:`OUTLINE_TESTS`), left out when NaN (nothing to judge). Either image below a threshold makes
        the pair outline-only (``outline_only``): a mask or silhouette, whose outline is all the measure can align
        (``metric.outline_alpha``, ``outline_smoothing``, :func:`check_outline`)."""
        c = self.params.check
        values = {f"{test}_{role}": measure(image) for test, (measure, _) in OUTLINE_TESTS.items()
                  if getattr(c, f"min_{test}") > 0 for role, image in (("fixed", self.fixed), ("moving", self.moving))}
        return {k: v for k, v in values.items() if math.isfinite(v)}

    def at(self, theta) -> RigidTransform:
        """The transform of parameters ``theta`` about the fixed grid's centre."""
        return RigidTransform(tuple(theta), tuple(self.center))

    def _levels_count(self) -> int | None:
        """The fewer distinct intensities of the two images when at most ``metric.discrete_levels`` (a label map, a
        thresholded mask: measured as an outline-only pair is, not flagged as one), else None."""
        if (limit := self.params.metric.discrete_levels) <= 0:
            return None
        count = min(distinct_levels(image, limit) for image in (self.fixed, self.moving))
        return count if count <= limit else None

    def _pyramid(self) -> list[_Level]:
        """One measure per schedule level, coarse to fine (module docstring, point 2); each level's images smoothed by its
        ``smoothing`` in its pixels (a discrete pair's finest: ``outline_smoothing``, ``label_smoothing``, ``label_samples``)."""
        p, m = self.params, self.metric
        mask_image = None if self.mask is None else self.fixed.with_data(self.mask.astype(np.float64))
        last = len(p.schedule) - 1
        labels = not (self.outline_only or self.levels_count in (1, 2))  # a label map of three labels or more
        finest_blur = p.label_smoothing if labels else p.outline_smoothing

        def build(i: int, spec: LevelSpec, grid: LevelSpec, sigma: float) -> _Level:
            F, M = (self.fixed.smoothed(sigma), self.moving.smoothed(sigma)) if sigma > 0 else (self.fixed, self.moving)
            F, M = F.shrink_to(grid.spacing, MIN_LEVEL_VOXELS), M.shrink_to(grid.spacing, MIN_LEVEL_VOXELS)
            blur = finest_blur if i == last and self.outline_measure and finest_blur > 0 else spec.smoothing
            if i == last and self.outline_measure and labels and spec.samples:
                spec = grid = spec.model_copy(update={"samples": round(p.label_samples * spec.samples)})
            if blur > 0:
                F, M = (X.with_data(gaussian_blur(X.data, [blur] * X.dim)) for X in (F, M))
            mask = None if mask_image is None else mask_image.shrink_to(grid.spacing, MIN_LEVEL_VOXELS).data >= 0.5
            mask = mask if mask is not None and mask.any() else None
            power = p.coarse_overlap_power if i < last else 0.0
            objective = Objective(self.histogram(spec, (F, M, mask), grid.samples, p.seed + i), m.name, alpha=m.alpha,
                                  weights=m.weights, tmi_form=m.tmi_form, min_overlap=m.min_overlap,
                                  overlap_power=power)
            return _Level(spec, objective, float(np.mean(F.spacing)), (F, M, mask))

        levels = [build(i, spec, spec, 0.0) for i, spec in enumerate(p.schedule)]
        enough = next((i for i, lv in enumerate(levels) if lv.objective.histogram.n_samples >= MIN_LEVEL_SAMPLES),
                      len(levels) - 1)
        for i in range(enough):
            levels[i] = build(i, p.schedule[i], p.schedule[enough], SMALL_FOV_SIGMA * p.schedule[i].spacing)
        return levels

    def histogram(self, spec: LevelSpec, images: tuple, samples: int | None, seed: int) -> JointHistogram:
        """The joint histogram of a level's images (fixed, moving, mask), binned over the full images' ranges."""
        F, M, mask = images
        return JointHistogram(F, M, Binning.of(self.fixed.data, spec.bins), Binning.of(self.moving.data, spec.bins),
                              center=self.center, mode=spec.interpolation, samples=samples, mask=mask,
                              jitter=self.params.sampling.jitter, seed=seed)

    def start_search(self, t_init: np.ndarray, st: StartSpec | None = None) -> np.ndarray:
        """The start: ``transform.init``'s translation, or with ``start.steps`` (or ``st``'s) the best at the coarsest
        level of ``(2 steps + 1)^d`` shifts of ``start.spacing`` about it, the other centre-mapping translation and the
        identity (the files' own placement); each centre and the ``start.candidates`` best shifts then run
        ``start.iterations`` coarsest-level iterations: the highest end is the start (a crop moves a centroid)."""
        st, zeros = st or self.params.start, np.zeros(self.k)
        theta0 = np.r_[zeros, t_init]
        if st.steps == 0:
            return theta0
        coarse = self.levels[0].objective
        offsets = np.arange(-st.steps, st.steps + 1) * st.spacing
        grid = np.stack(np.meshgrid(*[offsets] * self.dim, indexing="ij"), axis=-1).reshape(-1, self.dim)
        centres = [t_init] + [initial_translation(self.fixed, self.moving, m) for m in ("moments", "geometry")]
        centres.append(np.zeros(self.dim))
        thetas = [theta0] + [np.r_[zeros, c + off] for c in centres for off in grid]
        scored = sorted((-value, i) for i, theta in enumerate(thetas) if math.isfinite(value := coarse(theta)))
        if not scored:
            return theta0
        chosen: list[np.ndarray] = []
        for theta in [np.r_[zeros, c] for c in centres] + [thetas[i] for _, i in scored]:
            if len(chosen) >= len(centres) + st.candidates:
                break
            if math.isfinite(coarse(theta)) and all(np.linalg.norm(theta[self.k:] - other[self.k:]) >= 0.5 * st.spacing
                                                    for other in chosen):
                chosen.append(theta)
        if st.iterations == 0 or len(chosen) == 1:
            return chosen[0]
        spec = self.levels[0].spec.model_copy(update={"iterations": st.iterations})
        box = np.r_[[math.radians(self.params.bounds.max_angle)] * self.k, [np.inf] * self.dim]
        ends = [self.optimize(0, spec, theta, lower=-box, upper=box).theta for theta in chosen]
        values = [coarse(e) for e in ends]
        best = int(np.argmax([v if math.isfinite(v) else -math.inf for v in values]))
        return ends[best] if math.isfinite(values[best]) else chosen[0]

    def optimize(self, li: int, spec: LevelSpec, theta: np.ndarray, *, lower, upper, callback=None, start: int = 0,
                 objective: Objective | None = None, rng: np.random.Generator | None = None) -> OptimizeResult:
        """The chosen optimiser on level ``li``'s objective (or ``objective``) from ``theta`` (SPSA's gains
        continued from iteration ``start``; SPSA's perturbations from the run's stream, or ``rng``)."""
        o = self.params.optimizer
        objective = self.levels[li].objective if objective is None else objective
        last = o.average_finest if li == len(self.levels) - 1 and not self.outline_measure else o.average_last
        shared = dict(scales=self.scales, lower=lower, upper=upper, callback=callback)  # the two optimisers' arguments
        if o.name == "spsa":
            settings = SPSASettings(
                iterations=spec.iterations, a=o.a, A=o.A, c=spec.c, alpha=spec.gain_alpha, gamma=o.gain_gamma,
                step=spec.step, average=spec.average, max_step=o.max_step, blocking=o.blocking, shrink=o.shrink,
                tol=o.tol, average_last=min(last, spec.iterations), newton=o.newton, normalize=o.normalize,
                c_step_ratio=o.c_step_ratio, start=start)
            return spsa_maximize(objective, theta, settings, rng=self.rng if rng is None else rng, **shared)
        settings = PowellSettings(max_evaluations=max(20, 4 * spec.iterations), xtol=0.02 * self.levels[li].spacing,
                                  step=spec.step)
        return powell_maximize(objective, theta, settings, **shared)

    def schedule_from(self, theta: np.ndarray, done: int = 0) -> tuple[np.ndarray, str, list[np.ndarray]]:
        """Optimise level by level from ``theta`` (the first level continuing its gains after ``done`` iterations already
        made from a refined probe), recording each level's history: (the end, its stop reason, each level's end)."""
        stop, ends = "", []
        for li, level in enumerate(self.levels):
            cb = None if self.callback is None else (lambda k, th, v, li=li: self.callback(li, k, th, v))
            spec, start = level.spec, 0
            if li == 0 and done > 0:
                start = min(done, spec.iterations - 1)
                spec = spec.model_copy(update={"iterations": spec.iterations - start})
            for _ in range(1 + spec.reruns):
                res = self.optimize(li, spec, theta, lower=self.lower, upper=self.upper, callback=cb, start=start)
                if level.objective(res.theta) >= level.objective(theta):
                    theta = res.theta
                stop = res.stop_reason
                self.history.append({"level": np.full(res.iterations, li), **res.history})
                path = res.history["theta"]  # its last half moved more than settle: the decaying steps ran out
                if not (spec.settle > 0 and len(path) >= 4 and self.distance(path[-1], path[len(path) // 2]) > spec.settle):
                    break
            ends.append(np.asarray(theta, dtype=np.float64))
        return np.asarray(theta, dtype=np.float64), stop, ends

    def on_sample(self, level: _Level, seed: int) -> Objective:
        """``level``'s measure on another sample of its images (another subset, another jitter), drawn with ``seed``."""
        return level.objective.on(self.histogram(level.spec, level.images, level.spec.samples, seed))

    def ensemble(self, theta: np.ndarray) -> np.ndarray:
        """``theta`` and the ends within one unit of it of ``optimizer.ensemble`` finest-level runs from it on other samples
        (own stream), averaged: the finest optimum moves with the sample (31st round); not for pairs measured as outlines."""
        n = 0 if self.outline_measure else self.params.optimizer.ensemble  # none: the mean of theta alone is theta
        li, fine, rng = len(self.levels) - 1, self.levels[-1], np.random.default_rng(self.params.seed + 15485863)
        ends = [self.optimize(li, fine.spec, theta, lower=self.lower, upper=self.upper, rng=rng,
                              objective=self.on_sample(fine, self.params.seed + 7919 * (20 + k))).theta for k in range(n)]
        return np.mean([theta] + [e for e in ends if self.distance(e, theta) <= 1.0], axis=0)

    def drops(self, theta, seed: int | None = None):
        """(level, relative drop of its measure from its end to ``theta``: 1 if unscored) of each coarser level that
        ended over a quarter of its spacing away, lazily; ``seed``: on another sample (other subset, other jitter)."""
        for li, lv in enumerate(self.levels[:-1]):
            f = lv.objective if seed is None else self.on_sample(lv, seed)
            there, here = f(self.ends[li]), f(theta)
            if math.isfinite(there) and there > 0 and self.distance(theta, self.ends[li]) > 0.25 * lv.spacing:
                yield li, 1.0 - here / there if math.isfinite(here) else 1.0

    def distance(self, a: np.ndarray, b: np.ndarray) -> float:
        """Approximate RMS displacement between two transforms: the translation and each angle's arc at the RMS
        radius (angles wrapped)."""
        da = (np.subtract(a[: self.k], b[: self.k]) + math.pi) % (2 * math.pi) - math.pi
        return float(math.hypot(np.linalg.norm(np.subtract(a[self.k:], b[self.k:])), np.linalg.norm(da) * self.radius))

    def refine(self, start: np.ndarray, objective: Objective | None = None) -> tuple[np.ndarray, float]:
        """``check.refine`` iterations of the first level (or of ``objective`` there) from ``start``, any angle."""
        objective = self.levels[0].objective if objective is None else objective
        spec = self.levels[0].spec.model_copy(update={"iterations": max(1, self.params.check.refine)})
        lower, upper = np.r_[[-np.inf] * self.k, self.lower[self.k:]], np.r_[[np.inf] * self.k, self.upper[self.k:]]
        res = self.optimize(0, spec, start, lower=lower, upper=upper, objective=objective)
        return res.theta, objective(res.theta)

    def grid(self, mirrored: bool = False) -> GridSearch:
        """The coarse search (:meth:`coarse_search`), once, or the one :meth:`prefetch` started."""
        found = self._grids.get(mirrored) or self.coarse_search(mirrored)
        self._grids[mirrored] = found = found.result() if isinstance(found, Future) else found
        return found

    def prefetch(self, pool: ThreadPoolExecutor) -> None:
        """Start in ``pool`` the coarse searches (own search copies; the mirror test's too), which the checks need and the
        result does not, with a second CPU (not in the engine's workers) and images overlapping at the start."""
        c = self.params.check
        if c.search and histogram_threads() > 1 and self.levels[0].objective.overlap(self.start) >= self.params.metric.min_overlap:
            self._grids[False] = pool.submit(self.coarse_search)
            if c.mirror > 0:
                self._grids[True] = pool.submit(self.coarse_search, True)

    def coarse_search(self, mirrored: bool = False) -> GridSearch:
        """The coarse exhaustive search on a search copy of its own: 2D ``check.probes`` angles over the full circle, 3D
        no rotation and ``check.angles`` about each axis; x a ``check.grid``^d square of translations over the search
        box about the centroid-mapping translation of each rotation. ``mirrored``: of the moving image mirrored along x,
        in 3D turned by no or half a turn about one of its grid's axes instead (a flip along any: :func:`check_mirror`)."""
        c = self.params.check
        moving = self.moving.with_data(self.moving.data[..., ::-1].copy()) if mirrored else self.moving
        if self.dim == 2:
            rotations = np.radians(np.linspace(-180.0, 180.0, c.probes, endpoint=False))[:, None]
            polish = [np.array([s * math.pi / c.probes / 2]) for s in (-1.0, 0.0, 1.0)]  # quarter probe steps
        else:
            turns = [np.eye(3)[axis] * math.radians(a) for axis in range(3) for a in c.angles] if not mirrored else [
                euler_angles(2 * np.outer(u, u) - np.eye(3)) for u in self.moving.direction.T]  # half turns: any flip
            rotations, polish = np.vstack([np.zeros(3)] + turns), [np.zeros(3)]
        images = SearchImages(self.fixed, moving, center=self.center, min_overlap=self.params.metric.min_overlap,
                              region=self.mask if c.search_region else None)
        return grid_search(images, rotations, lambda angles: initial_translation(self.fixed, moving, "moments", angles),
                           steps=c.grid, half_width=self.max_translation, polish_rotations=polish)

    def candidates(self, theta: np.ndarray, n: int | None = None) -> list[np.ndarray]:
        """The ``n`` (``check.candidates``) best grid transforms away from the result, a grid cell apart."""
        grid, chosen = self.grid(), []
        n = self.params.check.candidates if n is None else n
        for i in np.argsort(-grid.values, kind="stable"):
            if not math.isfinite(grid.values[i]) or len(chosen) == n:
                break
            if all(self.distance(grid.thetas[i], other) >= grid.spacing for other in [theta, *chosen]):
                chosen.append(grid.thetas[i])
        return chosen

    def shortlisted(self, theta: np.ndarray) -> list[np.ndarray]:
        """The ``check.candidates`` best by the first level's measure of the ``check.shortlist`` best grid transforms:
        the search copy's coarse grid can miss a narrow peak that the first level sees from a grid cell away."""
        c, first = self.params.check, self.levels[0].objective
        chosen = self.candidates(theta, c.shortlist)
        order = np.argsort([-first(t) for t in chosen], kind="stable")  # a measure is finite or -inf
        return [chosen[i] for i in order[: c.candidates]]


# ------------------------------------------- self-check: ``check(run, theta, value, stop) -> list[Flag]`` (and run.better)


def check_start(run: _Run, theta, value, stop) -> list[Flag]:
    """The optimiser could not start: no overlap at the start, or nothing to climb."""
    coarse = run.levels[0].objective
    if (why := stop if stop in ("invalid_start", "flat_objective") else "") or not math.isfinite(coarse(run.start)):
        return [Flag("start", f"the optimiser could not start ({why.replace('_', ' ') or 'no overlap'}): only "
                              f"{coarse.overlap(run.start):.1%} of the fixed samples overlap the moving image at the "
                              f"start ({run.params.transform.init}; min_overlap {run.params.metric.min_overlap:.0%}; a "
                              f"moving image much smaller than the fixed: swap them), or the images carry no information")]
    return []


def check_overlap(run: _Run, theta, value, stop) -> list[Flag]:
    """The measure is undefined at the result: too little overlap."""
    return [] if math.isfinite(value) else [Flag("overlap", f"only {run.levels[-1].objective.overlap(theta):.1%} of the "
                                                 f"fixed samples overlap the moving image at the result (min_overlap "
                                                 f"{run.params.metric.min_overlap:.0%})")]


def check_bounds(run: _Run, theta, value, stop) -> list[Flag]:
    """Clipped iterates pile up on a bound when the optimum lies beyond it: a result within one unit
    (translation, or arc at the RMS radius) of a bound."""
    at = (theta <= run.lower + run.scales) | (theta >= run.upper - run.scales)
    if not at.any():
        return []
    names = [n for n, b in zip(run.at(theta).names, at) if b]
    return [Flag("bounds", f"the estimate is on the search bound of {', '.join(names)} (bounds.max_translation / "
                           f"max_angle): the misalignment is probably outside the capture range")]


def check_chance(run: _Run, theta, value, stop) -> list[Flag]:
    """The measure is near what the same samples give paired at random: no shared structure."""
    fine = run.levels[-1].objective
    chance = fine.on(fine.histogram.shuffled(run.params.seed))(theta)
    if math.isfinite(chance) and chance > 0:
        run.measures["chance"] = value / chance
    if run.params.check.chance > 0 and math.isfinite(chance) and chance > 0 and value < run.params.check.chance * chance:
        return [Flag("chance", f"the measure at the result ({value:.3g}) is only {value / chance:.2f} times its chance "
                               f"level ({chance:.3g}: the same samples paired at random): the images share no "
                               f"structure that this measure can align")]
    return []


def check_gain(run: _Run, theta, value, stop) -> list[Flag]:
    """The optimiser did not climb: the result moved from the start but scores no better there, or one unit from it
    along some parameter (an angle: its arc at the RMS radius) the finest measure is higher by more than
    ``check.margin`` of it (``ascent``; twenty-sixth round): it stopped short of an optimum; or the measure is 0."""
    fine = run.levels[-1].objective
    start_value = fine(run.start)
    if run.distance(theta, run.start) > 0.5 * run.levels[-1].spacing and math.isfinite(start_value) \
            and not value > start_value:
        return [Flag("gain", f"the measure at the result ({value:.4g}) is no better than at the start "
                             f"({start_value:.4g})")]
    if not (math.isfinite(value) and value > 0):  # 0: independent, e.g. a pair smoothed to constants (no information)
        return [Flag("gain", "the measure is 0 at the result: the images carry no information there")] if value == 0 else []
    ascent = run.measures["ascent"] = max((fine(theta + s * u) - value) / value for u in np.diag(run.scales)
                                          for s in (-1.0, 1.0))  # one unit: run.scales, as check_bounds
    if ascent <= run.params.check.margin:
        return []
    return [Flag("gain", f"the measure rises by {ascent:.1%} one unit from the result (margin {run.params.check.margin:g}"
                         f"): the optimiser stopped short of an optimum (check the schedule's steps)")]


def check_consistency(run: _Run, theta, value, stop) -> list[Flag]:
    """A finer level walked away from the basin a coarser one found: at the result, some coarser level's measure
    is lower than at that level's own end by more than ``check.consistency`` of it (and the two are more than a
    quarter of that level's spacing apart: a coarse optimum is as good as its pixels)."""
    threshold = run.params.check.consistency
    if len(run.ends) != len(run.levels):
        return []
    worst = -math.inf
    for li, drop in run.drops(theta):
        worst = run.measures["consistency"] = max(worst, drop)
        if threshold > 0 and drop > threshold:
            return [Flag("consistency", f"the finer levels left the basin that the {run.levels[li].spacing:g}-unit level found "
                                        f"({run.distance(theta, run.ends[li]):.1f} units away, where that level's "
                                        f"measure is {drop:.0%} lower; consistency {threshold:.0%}): the finest "
                                        f"measure has no clear optimum at the coarse answer")]
    return []


def check_agreement(run: _Run, theta, value, stop) -> list[Flag]:
    """A biased optimum: from the result, the finest level climbs a second measure on the same samples and ends more
    than a limit away: JT (alpha 2) for every other measure (``check.agreement``), mutual information for JT itself
    (``check.mi_agreement``, twelfth round). Not asked on outline and discrete pairs, nor where JT is at order 1 already."""
    m, c = run.params.metric, run.params.check
    thesis = m.name == "jt" and m.alpha == 2.0 and m.weights == "histogram"
    key = "mi_" * thesis + "agreement"
    if (limit := getattr(c, key)) <= 0 or run.outline_measure or run.metric is not m:
        return []
    name, second = ("mutual information", "mi") if thesis else ("Jensen-Tsallis (alpha 2, the thesis's measure)", "jt")
    finest = run.levels[-1]
    other = Objective(finest.objective.histogram, second, alpha=2.0, weights="histogram", min_overlap=m.min_overlap)
    rng = np.random.default_rng(run.params.seed + 104729) if thesis else None  # JT's own: later checks draw as before
    end = run.optimize(len(run.levels) - 1, finest.spec, theta, lower=run.lower, upper=run.upper, objective=other,
                       rng=rng).theta
    run.measures["agreement"] = run.distance(end, theta) if other(end) > other(theta) else 0.0
    if run.measures["agreement"] <= limit:
        return []
    return [Flag("agreement", f"the optimum of {name} is {run.distance(end, theta):.2f} units from the result of "
                              f"{m.label()} ({key} {limit:g}): this measure's optimum is biased on these images; "
                              f"compare with --metric {second}")]


def check_label(run: _Run, theta, value, stop) -> list[Flag]:
    """A label map whose inner boundaries mislead the measure (the kind attack's parcellations): with each image read
    as a label map (:func:`~.structure.plateau_share` at least ``check.label_plateau``, three values or more)
    replaced by its object, the pair registered again (default sampling) ends more than ``check.label`` from the result
    and passes its own self-check (the outline's own answer, right where the parcels fooled the measure)."""
    c, pair = run.params.check, {"fixed": run.fixed, "moving": run.moving}
    if c.label <= 0 or run.outline_only:
        return []
    if not (labels := [r for r, im in pair.items() if plateau_share(im) >= c.label_plateau and distinct_levels(im, 2) > 2]):
        return []
    if getattr(run, "label_answer", None) is None:  # once a run: it does not depend on the result (a retry asks again)
        pair.update({r: pair[r].with_data((pair[r].data > pair[r].data.min()).astype(np.float64)) for r in labels})
        run.label_answer = register(pair["fixed"], pair["moving"], run.params)
    outline = run.label_answer  # an answer its own self-check does not trust: no flag
    apart = run.measures["label"] = run.distance(np.asarray(outline.transform.parameters), theta)
    if apart <= c.label or not outline.ok:
        return []
    return [Flag("label", f"the {' and '.join(labels)} image reads as a label map, and its object alone (the pixels "
                          f"above its minimum) registers at {describe(outline.transform)}, {apart:.2f} units from the "
                          f"result (label {c.label:g}): its inner boundaries may pull the measure off the outline's "
                          f"pose; check the overlay, or register the object (--set check.label=0 turns this test off)")]


def check_stability(run: _Run, theta, value, stop) -> list[Flag]:
    """The result is not pinned down to ``check.stability``: the finest level run again from it on another sample
    of the same images (another subset, another jitter) ends farther away (a broad or flat optimum: a silhouette
    whose outline hardly constrains the rotation, an undetermined direction)."""
    if (limit := run.params.check.stability) <= 0:
        return []
    li, fine, other = len(run.levels) - 1, run.levels[-1], run.on_sample(run.levels[-1], run.params.seed + 7919)
    end = run.optimize(li, fine.spec, theta, lower=run.lower, upper=run.upper, objective=other).theta
    shift = run.measures["stability"] = run.distance(end, theta)
    if shift <= limit:
        return []
    return [Flag("stability", f"the finest level run again from the result on another sample of the images ends "
                              f"{shift:.2f} units away (stability {limit:g}): the images do not pin the transform "
                              f"down to that precision")]


def check_overlap_bound(run: _Run, theta, value, stop) -> list[Flag]:
    """From the result, or the best transform of a coarse search accepting half the overlap, the first level's measure
    with half the ``min_overlap`` climbs higher where the images overlap less than ``min_overlap``: they match best
    out of the accepted overlap (a moving image shifted out of view); the result is the best on the bound, not the answer."""
    if not run.params.check.overlap_bound:
        return []
    coarse, m = run.levels[0].objective, run.params.metric.min_overlap
    relaxed = coarse.on(coarse.histogram, min_overlap=0.5 * m)
    here = relaxed(theta)
    grid = run.grid()  # its best transform when the smaller overlap is accepted, if it needs it
    starts = [theta] + [t for t in grid.thetas[np.argsort(-grid.values_at(0.5 * m))[:1]] if coarse.overlap(t) < m]
    for start in starts:
        end, there = run.refine(start, relaxed)
        overlap = coarse.overlap(end)
        if overlap < m and math.isfinite(here) and there > here + run.params.check.margin * abs(here) \
                and run.distance(end, theta) >= 2.0 * run.levels[0].spacing:
            return [Flag("overlap_bound", f"the measure keeps rising where the images overlap less than min_overlap "
                                          f"({m:.0%}): it climbs to {describe(run.at(end))}, {overlap:.1%} "
                                          f"overlap; the true alignment probably lies outside the accepted overlap")]
    return []


def check_content(run: _Run, theta, value, stop) -> list[Flag]:
    """Too little of the fixed image's content lands on the moving image's content."""
    if not (c := run.params.check).search:
        return []
    content = run.measures["content"] = run.grid().images.content_overlap(theta)
    return [Flag("content", f"only {content:.1%} of the fixed content (Otsu foreground) lands on the moving image's "
                            f"content at the result (min_content {c.min_content:.0%}): too little shared content")
            ] if content < c.min_content else []


def check_outline(run: _Run, theta, value, stop) -> list[Flag]:
    """An outline-only pair (``run.outline_only``: a mask, a silhouette) whose outline does not pin the result down: the
    outlines lie over ``check.outline_gap`` apart, a coarser level's measure fell from its end to the result by over
    ``check.outline_drop`` (and on other samples: 29th round), less than ``check.min_outline_view`` of the object's
    boundary is outline both images see (:func:`~.structure.outline_in_view`), or under 1.2 times it and the measure one
    unit away within ``check.outline_flat`` of the result (``ascent``, :func:`check_gain`). Else it is accepted."""
    c = run.params.check
    if not run.outline_only:
        return []
    below = _below_outline_thresholds(run)
    flat = [f"the {key.partition('_')[2]} image {OUTLINE_TESTS[test][1].format(value)}; min_{test} {limit:g})"
            for key, value, test, limit in below]
    roles = sorted({key.partition("_")[2] for key, *_ in below})  # the outline-only image(s): fixed, moving
    at = run.at(theta)  # each role's partner image and the map of its points into it (check.outline_view_partner)
    partner = {"fixed": (run.moving, at), "moving": (run.fixed, at.inverse())} if c.outline_view_partner else {}
    views = [(outline_in_view(getattr(run, r), *partner.get(r, ())), r) for r in roles]
    view, role = min(((v, r) for v, r in views if math.isfinite(v)), default=(1.0, None))
    if role is not None:
        run.measures["outline_view"] = view
    gap = run.measures["outline_gap"] = outline_gap(run.fixed, run.moving, at)
    drop, ascent = run.measures.get("consistency", 0.0), run.measures.get("ascent", -1.0)  # absent: levels agree; no gain test
    if drop > c.outline_drop:  # a drop whose mean over other samples of the levels is not positive is the sample's
        run.measures["outline_drop"] = float(np.mean([max((d for _, d in run.drops(theta, run.params.seed + 7919 * k)),
                                                          default=0.0) for k in range(2, 2 + DROP_SAMPLES)]))
        drop = drop if run.measures["outline_drop"] > 0 else 0.0
    why = ([f"the outlines lie {gap:.2f} units apart at the result (outline_gap {c.outline_gap:g}): they do not "
            f"correspond there" if math.isfinite(gap) else "the outlines cannot be compared at the result"]
           if not gap <= c.outline_gap else []) + \
          ([f"the finest level left the optimum a coarser level found (its measure {drop:.1%} lower there, lower on "
            f"{DROP_SAMPLES} other samples too; outline_drop {c.outline_drop:.1%})"] if drop > c.outline_drop else []) + \
          ([f"only {view:.0%} of the {role} image's object boundary is outline that both images see, the rest is cut "
            f"by a grid's border (min_outline_view {c.min_outline_view:.0%})"] if view < c.min_outline_view else []) + \
          ([f"the measure one unit from it is within {-ascent:.1%} of it, with {view:.0%} of the outline in view "
            f"(outline_flat {c.outline_flat:.0%}): nothing pins the result to a unit"]
           if c.outline_flat > 0 and view < 1.2 * c.min_outline_view and ascent > -c.outline_flat else [])
    if not why:
        return []
    return [Flag("outline", f"{'; '.join(flat)}: a mask or silhouette, and {' and '.join(why)}; check the overlay, "
                            f"or set check.min_structure, check.min_spread and check.min_residual to 0 to "
                            f"register it as an ordinary pair (topomatch register --set check.min_structure=0 ...)")]


def check_prominence(run: _Run, theta, value, stop) -> list[Flag]:
    """The result does not stand out of the coarse search's landscape (outline-only pairs: check.outline_prominence)."""
    if not (c := run.params.check).search:
        return []
    prominence = run.measures["prominence"] = (grid := run.grid()).prominence(grid.images.score(theta, min_overlap=0.0))
    if prominence < c.min_prominence and (c.outline_prominence or not run.outline_only):
        score = (f"it scores {prominence:.1f} median absolute deviations above a typical transform of a coarse search"
                 if math.isfinite(prominence) else "no transform of a coarse search overlaps enough to compare it with")
        return [Flag("prominence", f"the result is not a distinct optimum: {score} (min_prominence "
                                   f"{c.min_prominence:g}); the images may share too little content")]
    return []


def check_flatness(run: _Run, theta, value, stop) -> list[Flag]:
    """Some combination of the parameters is undetermined (:func:`~topomatch.stages.registration.search.flatness`
    on a copy of the images scaled to the fixed content, 6 of its pixels from the result, angles as arcs at the
    content's RMS radius)."""
    if (threshold := run.params.check.min_flatness) <= 0:
        return []
    content = foreground_mask(run.fixed)  # a search copy scaled to the fixed content's extent
    images = SearchImages(run.fixed, run.moving, center=run.center, min_overlap=run.params.metric.min_overlap,
                          spacing=max(search_spacing([run.fixed, run.moving]) / 4, search_spacing([run.fixed], content)))
    radius = rms_radius(run.fixed, content)
    ratio, u = flatness(lambda t: images.score(t, min_overlap=0.0), theta, dim=run.dim, reach=6.0 * images.spacing,
                        radius=radius)
    run.measures["flatness"] = ratio
    if ratio >= threshold:
        return []
    u = u * np.sign(u[np.abs(u).argmax()])
    parts = [f"{math.degrees(a / radius):+.2f} deg" for a in u[: run.k]] + [f"{v:+.2f} {n}" for v, n in
                                                                           zip(u[run.k:], ("tx", "ty", "tz"))]
    return [Flag("flatness", f"the measure hardly changes along ({', '.join(parts)}) per unit from the result (it "
                             f"falls {ratio:.0%} as much as in the steepest direction; min_flatness {threshold:.0%}): "
                             f"the images do not determine that combination of the parameters (a straight edge, "
                             f"stripes, a disc?)")]


def check_capture(run: _Run, theta, value, stop) -> list[Flag]:
    """Another basin is better (:func:`_better_basin`): found by the grid's ``check.candidates`` best transforms
    (adopted with ``check.retry``), else by :meth:`_Run.shortlisted` (adopted too); a fixed mask sampled over every
    pixel, adopted where higher at full resolution; on a pair read as an image that no start search began
    (``check.start_search``), the 3D start search's end, which only flags (own stream, no history)."""
    if not (c := run.params.check).search:
        return []
    probes = run.candidates(theta)
    flags = _better_basin(run, theta, value, probes, adopt=True)
    if not flags and c.shortlist > c.candidates:
        more = [p for p in run.shortlisted(theta) if not any(np.array_equal(p, q) for q in probes)]
        flags = _better_basin(run, theta, value, more, adopt=True)
    if run.mask is not None and any(k.endswith("_fixed") for k, *_ in _below_outline_thresholds(run)):
        if getattr(run, "whole_end", None) is None:  # a fixed mask sampled over every pixel (30th round), once a run
            run.whole_end = (whole := _Run(run.fixed, run.moving, run.params, None, None)).schedule_from(whole.start)[0]
        end, end_stop, better_ends = run.schedule_from(run.whole_end)
        best = (fine := run.levels[-1].objective)(theta if run.better is None else run.better[0])
        if fine(end) > best + c.margin * abs(best) and run.distance(end, theta) >= 2.0 * run.levels[0].spacing:
            run.better, flags = (end, end_stop, better_ends), flags + [Flag("capture", f"sampled over every fixed pixel, "
                f"it ends at {describe(run.at(end))}, {fine(end):.4g} > {best:.4g} at full resolution: a local optimum")]
    if flags or run.outline_measure or run.params.start.steps or not c.start_search:
        return flags
    rng, n, run.rng = run.rng, len(run.history), np.random.default_rng(run.params.seed + 104729)
    probe = run.start_search(run.start[run.k:], StartSpec(**DIMENSION_DEFAULTS[3]["start"]))
    flags = _better_basin(run, theta, value, [probe], adopt=False)
    run.rng = rng
    del run.history[n:]
    return flags


def check_mirror(run: _Run, theta, value, stop) -> list[Flag]:
    """The moving image mirrored along x fits better (a flip no rigid transform undoes; 2D: the full circle, 3D: half turns
    cover a flip along any axis): with ``check.mirror_refine`` (2D) its two best grid transforms, refined at the first
    level with the result's measure, beat the result there by over ``check.mirror``; without (3D) its search's best score
    beats the pair's own search's best (or its score at the result) by over that. ``measures['mirror']``: the ratio."""
    if (c := run.params.check).mirror <= 0 or not (here := run.levels[0].objective(theta)) > 0:
        return []
    grid = run.grid(mirrored=True)
    if c.mirror_refine:
        mirror = _Run(run.fixed, run.moving.with_data(run.moving.data[..., ::-1].copy()), run.params, run.mask, None, run.metric)
        probes = [grid.thetas[i] for i in np.argsort(-grid.values, kind="stable")[:2] if math.isfinite(grid.values[i])]
        ratio = max((mirror.refine(p)[1] for p in probes), default=-math.inf) / here
    else:
        best = max(float(np.max((own := run.grid()).values)), own.images.score(theta, min_overlap=0.0))
        ratio = float(np.max(grid.values)) / best if best > 0 else -math.inf
    run.measures["mirror"] = ratio
    if not ratio > 1.0 + c.mirror:
        return []
    where = "the result at the coarsest level, refined" if c.mirror_refine else "the pair's own best in a coarse search"
    return [Flag("mirror", f"the moving image mirrored (flipped along an axis) fits better: it scores {ratio:.2f} times "
                           f"{where} (mirror {c.mirror:g}): a file flipped along some axis, which no rigid transform "
                           f"undoes, or a wrong result; check the files' orientation")]


def _better_basin(run: _Run, theta, value, probes: list[np.ndarray], *, adopt: bool) -> list[Flag]:
    """The capture flag if the best of ``probes``, refined at the first level (kept as it is where higher: 38th round),
    beats the result there by ``check.margin`` and, run through the schedule, ends higher (``adopt``: ``run.better``)."""
    c, levels = run.params.check, run.levels
    coarse, fine = levels[0].objective, levels[-1].objective
    here = coarse(theta)
    best_value, best = -math.inf, None
    for probe in probes:
        v = coarse(probe)
        if c.refine > 0 and math.isfinite(v):
            probe, v = max([run.refine(probe), (probe, v)], key=lambda pv: pv[1])
            if run.distance(probe, theta) < 2.0 * levels[0].spacing:
                continue  # back in the result's basin
        if v > best_value:
            best_value, best = v, probe
    # a result the coarsest level cannot score loses to any probe it can (-inf + margin * inf would be nan)
    if not math.isfinite(best_value) or (math.isfinite(here) and best_value <= here + c.margin * abs(here)):
        return []
    if np.all(best >= run.lower) and np.all(best <= run.upper):
        end, end_stop, better_ends = run.schedule_from(best, done=c.refine)
        confirmed = fine(end) > value and run.distance(end, theta) >= 2.0 * levels[0].spacing
        if adopt:
            run.better = (end, end_stop, better_ends) if confirmed else None
        where = f"and ends at {describe(run.at(end))}, higher at full resolution"
    else:
        confirmed = fine(best) > value
        where = "outside the search bounds (max_translation / max_angle)"
    if not confirmed:
        return []
    kind = ("the registration stopped in a local optimum; the misalignment is probably outside the capture range"
            if adopt else "a basin the 3D start search found (check.start_search), not adopted: such basins are as "
            "often wrong where the measure cannot be trusted (a mask read as an image); check the overlay")
    return [Flag("capture", f"a start at {describe(run.at(best))} reaches a higher value than the result "
                            f"({best_value:.4g} > {here:.4g} at the {levels[0].spacing:g}-unit level) {where}: {kind}")]


CHECKS: tuple[Callable[..., list[Flag]], ...] = (
    check_start, check_overlap, check_bounds, check_chance, check_gain, check_consistency, check_stability,
    check_agreement, check_label, check_overlap_bound, check_content, check_outline, check_prominence, check_flatness,
    check_capture, check_mirror)
"""The self-check, in order; after ``check_overlap`` flags an undefined measure nothing else is asked."""


def describe(t: RigidTransform) -> str:
    """``(angle +10.0 deg, 13.1, 15.9)``-style text of a transform's parameters."""
    angles = " ".join(f"{a:+.1f}" for a in t.angles_deg)
    return f"(angle{'s' if t.dim == 3 else ''} {angles} deg, t = {', '.join(f'{v:.1f}' for v in t.translation)})"


def self_check(run: _Run, theta: np.ndarray, value: float, stop: str) -> list[Flag]:
    """The flags of every test of :data:`CHECKS` at the result; ``run.better`` is the capture test's better end."""
    run.better, run.measures = None, dict(run.structures)
    if run.metric.alpha != run.params.metric.alpha:
        run.measures["outline_alpha"] = run.metric.alpha
    if run.levels_count is not None:
        run.measures["discrete_levels"] = run.levels_count
    flags: list[Flag] = []
    for check in CHECKS:
        flags += check(run, theta, value, stop)
        if flags and flags[-1].check == "overlap":
            break
    return flags


def register(fixed: Image, moving: Image, params: RegisterParams = RegisterParams(), *,
             fixed_mask: np.ndarray | None = None,
             callback: Callable[[int, int, np.ndarray, float], bool | None] | None = None) -> Registration:
    """Register ``moving`` to ``fixed`` (both 2D or both 3D; any sizes, spacings and orientations): T with
    ``moving(T(p)) ~ fixed(p)``, flagged with a ``reason`` when the self-check fails (``check.on_failure='flag'``).

    ``params`` fields not set take the dimension's defaults (:func:`~.params.for_dimension`); ``fixed_mask`` (bool,
    shape of ``fixed.data``): the fixed pixels to sample instead of ``params.sampling``; ``callback(level, k, theta,
    value)`` after every optimiser iteration, True stopping the level. StageError: images of different dimensionality, a
    mask not of finite numbers, of another shape or selecting nothing, a failed self-check (``on_failure='error'``)."""
    t0 = time.perf_counter()
    if fixed.dim != moving.dim:
        raise StageError(f"cannot register a {moving.dim}D moving image to a {fixed.dim}D fixed image")
    params = for_dimension(RegisterParams.model_validate(params), fixed.dim)  # a dict of its fields too
    if fixed_mask is not None:
        given, fixed_mask = np.asarray(fixed_mask), np.asarray(fixed_mask, dtype=bool)  # non-zero: sampled
        if fixed_mask.shape != fixed.shape or not fixed_mask.any() or not (given.dtype.kind in "biuf" and np.isfinite(given).all()):
            raise StageError(f"the fixed mask (shape {fixed_mask.shape}, {given.dtype}, {int(fixed_mask.sum())} pixels) must be "
                             f"finite numbers or bools, non-zero on pixels of the fixed image (shape {fixed.shape})")
    unit = (extent := float(np.max(np.asarray(fixed.size) * fixed.spacing))) / min(max(extent, SMALL_FIELD), LARGE_FIELD)
    if unit != 1.0:  # a small or large field: registered in working units, the answer (and what callback sees) scaled back
        scale = np.r_[[1.0] * n_angles(fixed.dim), [unit] * fixed.dim]
        fixed, moving = fixed.scaled(1.0 / unit), moving.scaled(1.0 / unit)
        if callback is not None:
            callback = (lambda user: lambda level, k, theta, value: user(level, k, theta * scale, value))(callback)
    run = _Run(fixed, moving, params, fixed_mask if fixed_mask is not None else sample_mask(fixed, params), callback)
    with ThreadPoolExecutor(1) as pool:  # the compiled pass releases the interpreter's lock: prefetched work overlaps
        run.prefetch(pool)
        theta, stop, run.ends = run.schedule_from(run.start)
        theta, fine = run.ensemble(theta), run.levels[-1].objective
        value = fine(theta)
        flags = self_check(run, theta, value, stop)
        if restarts := int(run.better is not None and params.check.retry):  # the capture check's better end adopted
            theta, stop, run.ends = run.better
            value = fine(theta := run.ensemble(theta))
            flags = self_check(run, theta, value, stop)
    history = {k: np.concatenate([h[k] for h in run.history]) if run.history else np.zeros(0)
               for k in ("level", "theta", "value", "step", "blocked")}
    if unit != 1.0:
        history["theta"] = history["theta"] * scale if run.history else np.zeros(0)
        run.measures["unit"] = unit
        flags = [Flag(f.check, f"{f.message} (lengths in working units of {unit:.4g})") for f in flags]
    evaluations = sum({id(lv.objective): lv.objective.n_evals for lv in run.levels}.values())
    reg = Registration(run.at(theta).scaled(unit), float(value), tuple(flags), params.method(),
                       time.perf_counter() - t0, int(len(history["level"])), evaluations, stop, history,
                       run.at(run.start).scaled(unit), fine.overlap(theta), restarts, dict(run.measures))
    if flags and params.check.on_failure == "error":
        raise StageError(f"registration failed: {reg.reason} (estimate {describe(reg.transform)})")
    return reg


@stage("register", params=RegisterParams, version=2, consumes=("fixed", "moving"), produces=("registration",))
def register_stage(fixed: Image, moving: Image, *, params: RegisterParams) -> RegisterResult:
    """Rigid registration (2D or 3D) by an entropic measure (JT, JR, MI, TMI) with SPSA or Powell, coarse to fine."""
    return RegisterResult(register(fixed, moving, params))
