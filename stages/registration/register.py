"""Coarse-to-fine rigid registration: any measure (JT, JR, MI, TMI) with any optimiser (SPSA, Powell).

:func:`register` finds ``theta = (tx, ty, angle)`` (ITK convention, see
:mod:`topomatch.stages.registration.transform`) maximising the chosen measure of the joint histogram of
``fixed(x)`` and ``moving(T_theta(x))``:

1. **Initialisation**: ``moments`` maps the fixed image's intensity centroid onto the moving
   image's (angle 0); ``geometry`` maps centre onto centre (ITK's two
   ``CenteredTransformInitializer`` modes).
2. **Schedule** (coarse to fine): each :class:`LevelSpec` block-averages both images by its
   ``factor`` and computes the measure with its own ``bins``, ``interpolation`` and sample cap;
   the optimiser starts from the previous level's result. Step and perturbation lengths are in
   the level's own pixels. The default schedule (factor 4, 16 bins, 260 normalised SPSA
   iterations; factor 2, 24 bins, 40; full resolution, 32 bins, partial-volume interpolation,
   6,000 samples, 30 iterations with two gradient estimates each) was chosen on the accuracy
   sweep of ``docs/registration.md``: coarse levels win the capture range cheaply, the last one
   the accuracy (bilinear interpolation biases multimodal optima by ~0.5 px, partial volume
   does not).
3. **Parameter scaling**: the angle is optimised in units of ``degrees(1 / r)`` with r the RMS
   distance of the fixed pixels from the centre, so one unit moves the image by about one pixel,
   like one unit of translation.
4. **Self-check** (a failure is a flag and a reason, never a silent wrong answer): the result is
   flagged when the measure is not finite (overlap below ``metric.min_overlap``), when an iterate of
   the second half of a level sits on a search bound (``bounds``), or, with
   ``check.capture``, when another basin is better: ``check.probes`` rotations over the full
   circle (each with the translation that maps the intensity centroids) are scored at the
   coarsest level, the ``check.candidates`` best ones away from the result's angle are refined
   by ``check.refine`` first-level iterations, and one that ends elsewhere with a value higher
   than the result's by ``check.margin`` (relative) flags it. With ``check.retry`` the schedule then
   runs once more from that refined probe if it lies within the bounds (the first level
   continuing its gain sequence), and the check is repeated. ``check.on_failure: error`` turns a flag
   into a :class:`~topomatch.pipeline.contract.StageError`.

The parameters (:mod:`topomatch.stages.registration.params`) are grouped as DIPY and SimpleITK
group them: metric, optimizer, schedule, transform (initialisation), bounds, check.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field
from typing import Callable

import numpy as np

from topomatch.pipeline.contract import StageError, StageResult, stage
from topomatch.stages.registration.image import Image
from topomatch.stages.registration.objective import Level, Objective, build_pyramid, intensity_centroid, rms_radius
from topomatch.stages.registration.params import LevelSpec, RegisterParams  # noqa: F401 (LevelSpec: the API)
from topomatch.stages.registration.search import GridSearch, SearchImages, flatness, grid_search
from topomatch.stages.registration.powell import PowellSettings, powell_maximize
from topomatch.stages.registration.spsa import OptimizeResult, SPSASettings, spsa_maximize
from topomatch.stages.registration.transform import RigidTransform, rotation_matrix


@dataclass(frozen=True, eq=False)
class Registration:
    """The outcome of one registration (any method).

    Attributes
    ----------
    transform : RigidTransform
        ``T`` with ``moving(T(x)) ~ fixed(x)``, about the fixed image's centre.
    value : float
        The measure at ``transform`` (finest level; NaN for methods without one).
    ok : bool
        False when the self-check flagged the result; ``reason`` says why.
    reason : str
    method : str
        E.g. ``spsa/jt(alpha=2 histogram)`` or ``simpleitk/mattes(line_search)``.
    seconds : float
        Wall time of the registration (images already in memory).
    iterations, evaluations : int
        Optimiser iterations and objective evaluations over all levels.
    stop_reason : str
        The finest level's stop reason.
    history : dict of ndarray
        Per iteration over all levels: ``level`` (k,), ``theta`` (k, 3), ``value`` (k,),
        ``step`` (k,), ``blocked`` (k,).
    spacing : (row, col)
        Pixel spacing of the fixed image (for translations in physical units).
    restarts : int
        Runs of the schedule after the first (a capture-check retry).
    """

    transform: RigidTransform
    value: float
    ok: bool
    reason: str
    method: str
    seconds: float
    iterations: int
    evaluations: int
    stop_reason: str
    history: dict[str, np.ndarray] = field(default_factory=dict)
    spacing: tuple[float, float] = (1.0, 1.0)
    restarts: int = 0

    def summary(self) -> dict:
        return {"tx": self.transform.tx, "ty": self.transform.ty, "angle": self.transform.angle,
                "objective": self.value, "ok": self.ok, "reason": self.reason, "method": self.method,
                "iterations": self.iterations, "evaluations": self.evaluations, "restarts": self.restarts,
                "stop": self.stop_reason, "seconds": self.seconds}


@dataclass(frozen=True, eq=False)
class RegisterResult(StageResult):
    """The registration of the current fixed/moving pair."""

    registration: Registration

    def summary(self) -> dict:
        return self.registration.summary()


def initial_translation(fixed: Image, moving: Image, mode: str, angle: float = 0.0) -> np.ndarray:
    """Translation t such that ``T(x) = R(angle)(x - c) + c + t`` maps the fixed reference point
    (intensity centroid for ``'moments'``, image centre for ``'geometry'``) onto the moving one."""
    c = np.asarray(fixed.center)
    if mode == "moments":
        pf, pm = intensity_centroid(fixed), intensity_centroid(moving)
    elif mode == "geometry":
        pf, pm = c, np.asarray(moving.center)
    else:
        raise ValueError(f"init must be 'moments' or 'geometry', got {mode!r}")
    return pm - c - rotation_matrix(angle) @ (pf - c)


def register(fixed: Image, moving: Image, params: RegisterParams = RegisterParams(), *,
             callback: Callable[[int, int, np.ndarray, float], bool | None] | None = None) -> Registration:
    """Register ``moving`` to ``fixed`` (rigid, 2D): the transform T with ``moving(T(x)) ~ fixed(x)``.

    Parameters
    ----------
    fixed, moving : Image
        2D images (any sizes).
    params : RegisterParams
    callback : callable, optional
        ``callback(level, k, theta, value)`` after every optimiser iteration; True stops the level.

    Returns
    -------
    Registration
        With ``ok=False`` and a ``reason`` when the self-check fails (``check.on_failure='flag'``).

    Raises
    ------
    StageError
        A failed self-check with ``check.on_failure='error'``.
    """
    t0 = time.perf_counter()
    run = _Run(fixed, moving, params, callback)
    theta, _, stop = run.schedule_from(run.start)
    value = run.levels[-1].objective(theta)
    problems, better = run.self_check(theta, value, stop)
    restarts = 0
    if better is not None and params.check.retry:
        # the capture check found a better basin and ran the schedule from it: adopt that result
        restarts = 1
        theta, stop = better
        value = run.levels[-1].objective(theta)
        problems, _ = run.self_check(theta, value, stop)
    total_iter = sum(len(h["level"]) for h in run.history)
    transform = RigidTransform.from_params(theta, fixed.center)
    ok, reason = not problems, "; ".join(problems)
    history = {key: np.concatenate([h[key] for h in run.history]) for key in ("level", "theta", "value", "step",
                                                                               "blocked")}
    evaluations = sum(lv.objective.n_evals for lv in run.levels)
    reg = Registration(transform, float(value), ok, reason, params.method(), time.perf_counter() - t0, total_iter,
                       evaluations, stop, history, fixed.spacing, restarts)
    if not ok and params.check.on_failure == "error":
        raise StageError(f"registration failed: {reason} (estimate tx={transform.tx:.3f}, ty={transform.ty:.3f}, "
                         f"angle={transform.angle:.3f})")
    return reg


MIN_LEVEL_SIDE = 16
"""Smallest side (pixels) of a pyramid level; coarser levels of the schedule are skipped."""


class _Run:
    """One registration in progress: the pyramid, the parameter scaling, the bounds, the random
    stream and the history, shared by the schedule, the capture-check refinements and the self-check."""

    def __init__(self, fixed: Image, moving: Image, params: RegisterParams,
                 callback: Callable[[int, int, np.ndarray, float], bool | None] | None):
        self.fixed, self.moving, self.params, self.callback = fixed, moving, params, callback
        smallest = min(min(fixed.shape), min(moving.shape))
        # levels too coarse for a small image are skipped: below MIN_LEVEL_SIDE pixels a side the
        # histogram holds too few samples for a gradient estimate and SPSA random-walks
        kept = [lv for lv in params.schedule if smallest // lv.factor >= MIN_LEVEL_SIDE]
        skipped = params.schedule[: len(params.schedule) - max(1, len(kept))]  # the coarsest levels
        if not kept:
            kept = [params.schedule[-1].model_copy(update={"factor": 1})]
        if skipped:  # the first kept level also does the skipped levels' work: it wins the capture range now
            extra = sum(lv.iterations for lv in skipped)
            kept[0] = kept[0].model_copy(update={"iterations": kept[0].iterations + extra})
        self.schedule = kept
        m = params.metric
        self.levels: list[Level] = build_pyramid(
            fixed, moving, factors=[lv.factor for lv in self.schedule], bins=[lv.bins for lv in self.schedule],
            metric=m.name, alpha=m.alpha, weights=m.weights, tmi_form=m.tmi_form,
            interpolation=[lv.interpolation for lv in self.schedule], samples=[lv.samples for lv in self.schedule],
            min_overlap=m.min_overlap, seed=params.seed)
        self.scales = np.array([1.0, 1.0, math.degrees(1.0 / rms_radius(fixed.shape))])  # one angle unit ~ 1 px
        t_init = initial_translation(fixed, moving, params.transform.init)
        self.start = np.array([t_init[0], t_init[1], 0.0])
        b = params.bounds
        max_t = self.max_translation = (b.max_translation if b.max_translation is not None
                                         else 0.5 * min(fixed.shape))
        self.lower = np.array([t_init[0] - max_t, t_init[1] - max_t, -b.max_angle])
        self.upper = np.array([t_init[0] + max_t, t_init[1] + max_t, b.max_angle])
        self.rng = np.random.default_rng(params.seed)
        self.radius = rms_radius(fixed.shape)
        self._grid: GridSearch | None = None
        self.history: list[dict[str, np.ndarray]] = []

    def optimize(self, li: int, spec: LevelSpec, theta: np.ndarray, *, lower: np.ndarray, upper: np.ndarray,
                 callback=None, start: int = 0, objective: Objective | None = None) -> OptimizeResult:
        """Run the chosen optimiser on level ``li``'s objective (or ``objective`` at that level) from ``theta``
        (SPSA gains from iteration ``start``)."""
        level, o = self.levels[li], self.params.optimizer
        objective = level.objective if objective is None else objective
        f = level.factor
        if o.name == "spsa":
            settings = SPSASettings(
                iterations=spec.iterations, a=o.a, A=o.A, c=spec.c * f, alpha=spec.gain_alpha, gamma=o.gain_gamma,
                step=spec.step * f, average=spec.average, max_step=None if o.max_step is None else o.max_step * f,
                blocking=o.blocking, shrink=o.shrink, tol=o.tol * f,
                average_last=min(o.average_last, spec.iterations), newton=o.newton, normalize=o.normalize,
                c_step_ratio=o.c_step_ratio, start=start)
            return spsa_maximize(objective, theta, settings, rng=self.rng, scales=self.scales, lower=lower,
                                 upper=upper, callback=callback)
        settings = PowellSettings(max_evaluations=max(20, 4 * spec.iterations), xtol=0.02 * f, step=spec.step * f)
        return powell_maximize(objective, theta, settings, scales=self.scales, lower=lower, upper=upper,
                               callback=callback)

    def schedule_from(self, theta: np.ndarray, done: int = 0) -> tuple[np.ndarray, int, str]:
        """Optimise level by level from ``theta``; append each level's history.

        ``done`` first-level iterations were already made (a refined probe): the first level continues
        its gain sequence from there for the rest of its iterations.
        """
        total_iter, stop = 0, ""
        for li, spec in enumerate(self.schedule):
            cb = None if self.callback is None else (lambda k, th, v, li=li: self.callback(li, k, th, v))
            start = 0
            if li == 0 and done > 0:
                start = min(done, spec.iterations - 1)
                spec = spec.model_copy(update={"iterations": spec.iterations - start})
            res = self.optimize(li, spec, theta, lower=self.lower, upper=self.upper, callback=cb, start=start)
            # a level never ends worse than it started (ITK's ReturnBestParametersAndValue, for the end points)
            if self.levels[li].objective(res.theta) >= self.levels[li].objective(theta):
                theta = res.theta
            total_iter += res.iterations
            stop = res.stop_reason
            self.history.append({"level": np.full(res.iterations, li), **res.history})
        return theta, total_iter, stop

    def refine(self, start: np.ndarray, objective: Objective | None = None) -> tuple[np.ndarray, float]:
        """A short run of the first level (or of ``objective`` there) from ``start``, any angle: the end and its value."""
        objective = self.levels[0].objective if objective is None else objective
        spec = self.schedule[0].model_copy(update={"iterations": self.params.check.refine})
        res = self.optimize(0, spec, start, lower=np.r_[self.lower[:2], -np.inf], upper=np.r_[self.upper[:2], np.inf],
                            objective=objective)
        return res.theta, objective(res.theta)

    def overlap_bound_check(self, theta: np.ndarray) -> list[str]:
        """Is the result pressed against the overlap bound? From it, the first level's measure with half
        the ``metric.min_overlap`` is climbed briefly; ending elsewhere, higher and with less overlap
        than ``min_overlap`` means the true alignment probably overlaps less than accepted (a moving
        image shifted out of view), and the result is the best transform on the bound, not the answer."""
        coarse, m = self.levels[0].objective, self.params.metric.min_overlap
        relaxed = coarse.with_min_overlap(0.5 * m)
        here = relaxed(theta)
        end, there = self.refine(theta, relaxed)
        overlap = coarse.overlap(end)
        if (overlap < m and math.isfinite(here) and there > here + self.params.check.margin * abs(here)
                and self.distance(end, theta) >= 2.0 * self.levels[0].factor):
            return [f"the measure keeps rising where the images overlap less than min_overlap "
                    f"({m:.0%}): from the result it climbs to ({end[0]:.0f}, {end[1]:.0f}, {end[2]:+.0f} deg), "
                    f"{overlap:.1%} overlap; the true alignment probably lies outside the accepted overlap"]
        return []

    def grid(self) -> GridSearch:
        """The coarse exhaustive search (computed once): ``check.probes`` angles over the full circle x a
        ``check.grid`` square of translations over the search box about the centroid-mapping translation."""
        if self._grid is None:
            self.search_images = SearchImages(self.fixed, self.moving, min_overlap=self.params.metric.min_overlap)
            self._grid = grid_search(
                self.search_images, lambda angle: initial_translation(self.fixed, self.moving, "moments", angle),
                angles=self.params.check.probes, steps=self.params.check.grid, half_width=self.max_translation)
        return self._grid

    def distance(self, a: np.ndarray, b: np.ndarray) -> float:
        """RMS pixel displacement between two transforms, approximately: translation and arc at the RMS radius."""
        arc = math.radians((a[2] - b[2] + 180.0) % 360.0 - 180.0) * self.radius
        return math.hypot(math.hypot(*(a[:2] - b[:2])), arc)

    def candidates(self, grid: GridSearch, theta: np.ndarray) -> list[np.ndarray]:
        """The ``check.candidates`` best grid transforms outside the result's cell, one per cell."""
        chosen: list[np.ndarray] = []
        for i in np.argsort(-grid.values, kind="stable"):
            probe = grid.thetas[i]
            if not math.isfinite(grid.values[i]) or len(chosen) == self.params.check.candidates:
                break
            if all(self.distance(probe, other) >= grid.spacing for other in [theta, *chosen]):
                chosen.append(probe)
        return chosen

    def flatness_check(self, theta: np.ndarray) -> list[str]:
        """Is some combination of the parameters undetermined? (:func:`~topomatch.stages.registration.search.flatness`
        on the coarse search's measure, 2 and 6 search pixels from the result.)"""
        if self.params.check.min_flatness <= 0:
            return []
        self.grid()  # builds the search images (once)
        f = self.search_images.factor
        ratio, u = flatness(lambda t: self.search_images.score(t, min_overlap=0.0), theta, step=2.0 * f,
                            reach=6.0 * f, radius=self.radius)
        if ratio >= self.params.check.min_flatness:
            return []
        u = u * np.sign(u[np.abs(u).argmax()])
        return [f"the measure hardly changes along ({u[0]:+.2f} tx, {u[1]:+.2f} ty, "
                f"{math.degrees(u[2] / self.radius):+.2f} deg) per pixel from the result (it falls {ratio:.0%} as "
                f"much as in the steepest direction; min_flatness {self.params.check.min_flatness:.0%}): the images "
                f"do not determine that combination of the parameters (a straight edge, stripes, a disc?)"]

    def self_check(self, theta: np.ndarray, value: float,
                   stop: str) -> tuple[list[str], tuple[np.ndarray, str] | None]:
        """Reasons to distrust a result (empty list: none), and a better result found by the capture
        check (its theta and stop reason), or None.

        Checks, in order: the optimiser started; the overlap; the search bounds; and with
        ``check.capture`` the coarse search (:mod:`~topomatch.stages.registration.search`): the
        content overlap, the prominence, the flatness (:meth:`flatness_check`), and the ``check.candidates`` best grid transforms away from
        the result, each refined (:meth:`refine`) and, if one beats the result at the first level,
        run through the whole schedule to confirm it at full resolution.
        """
        params, levels, check = self.params, self.levels, self.params.check
        problems: list[str] = []
        winner = None
        if stop in ("invalid_start", "flat_objective"):
            problems.append(f"the optimiser could not start ({stop.replace('_', ' ')}): the images do not overlap "
                            f"enough at the initial transform or carry no information")
        if not math.isfinite(value):
            overlap = levels[-1].objective.overlap(theta)
            problems.append(f"only {overlap:.1%} of the fixed image overlaps the moving image at the result "
                            f"(min_overlap {params.metric.min_overlap:.0%})")
            return problems, None
        # clipped iterates pile up on a bound when the optimum lies beyond it: flag a result within
        # one pixel (translation, or arc at the RMS radius) of a bound
        tol = np.array([1.0, 1.0, math.degrees(1.0 / self.radius)])
        at_bound = (theta <= self.lower + tol) | (theta >= self.upper - tol)
        if at_bound.any():
            names = [n for n, b in zip(("tx", "ty", "angle"), at_bound) if b]
            problems.append(f"the estimate is on the search bound of {', '.join(names)} (max_translation / "
                            f"max_angle): the misalignment is probably outside the capture range")
        if check.capture:
            problems += self.overlap_bound_check(theta)
            here = levels[0].objective(theta)
            grid = self.grid()
            content = self.search_images.content_overlap(theta)
            if content < check.min_content:
                problems.append(f"only {content:.1%} of the fixed image's content (Otsu foreground) lands on the "
                                f"moving image's content at the result (min_content {check.min_content:.0%}): "
                                f"too little shared content to trust it")
            prominence = grid.prominence(self.search_images.score(theta, min_overlap=0.0))  # overlap: checked above
            if prominence < check.min_prominence:
                problems.append(f"the result is not a distinct optimum: it scores {prominence:.1f} median absolute "
                                f"deviations above a typical transform of a coarse search (min_prominence "
                                f"{check.min_prominence:g}); the images may share too little content to register")
            problems += self.flatness_check(theta)
            best_value, best_theta = -math.inf, None
            for probe in self.candidates(grid, theta):
                v = levels[0].objective(probe)
                if check.refine > 0 and math.isfinite(v):
                    probe, v = self.refine(probe)
                    # a refined probe that came back to the result (within 2 coarse pixels RMS) is its basin
                    if self.distance(probe, theta) < 2.0 * levels[0].factor:
                        continue
                if v > best_value:
                    best_value, best_theta = v, probe
            if math.isfinite(best_value) and (not math.isfinite(here) or best_value > here + check.margin * abs(here)):
                # a better start at the coarsest level; confirmed only if it also ends higher at full
                # resolution (coarse levels of small images can prefer a wrong basin)
                if np.all(best_theta >= self.lower) and np.all(best_theta <= self.upper):
                    end, _, end_stop = self.schedule_from(best_theta, done=check.refine)
                    confirmed = (levels[-1].objective(end) > value
                                 and self.distance(end, theta) >= 2.0 * levels[0].factor)
                    winner = (end, end_stop) if confirmed else None
                    where = f"and ends at ({end[0]:.1f}, {end[1]:.1f}, {end[2]:+.1f} deg) higher at full resolution"
                else:
                    confirmed = levels[-1].objective(best_theta) > value
                    where = "outside the search bounds (max_translation / max_angle)"
                if confirmed:
                    problems.append(f"a start at ({best_theta[0]:.0f}, {best_theta[1]:.0f}, {best_theta[2]:+.0f} deg) "
                                    f"reaches a higher value than the result ({best_value:.4g} > {here:.4g} at factor "
                                    f"{levels[0].factor}) {where}: the registration stopped in a local optimum; "
                                    f"the misalignment is probably outside the capture range")
        return problems, winner


@stage("register", params=RegisterParams, version=1, consumes=("fixed", "moving"), produces=("registration",))
def register_stage(fixed: Image, moving: Image, *, params: RegisterParams) -> RegisterResult:
    """Rigid registration by an entropic measure (JT, JR, MI, TMI) with SPSA or Powell, coarse to fine."""
    return RegisterResult(register(fixed, moving, params))
