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
from topomatch.stages.registration.objective import Level, build_pyramid, intensity_centroid, rms_radius
from topomatch.stages.registration.params import LevelSpec, RegisterParams  # noqa: F401 (LevelSpec: the API)
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
    theta, total_iter, stop = run.schedule_from(run.start)
    value = run.levels[-1].objective(theta)
    problems, probe = run.self_check(theta, value, stop)
    restarts = 0
    if probe is not None and params.check.retry and np.all(probe >= run.lower) and np.all(probe <= run.upper):
        # the capture check found a better basin (the probe was already refined on the first level):
        # continue the first level from it, then run the other levels again
        restarts = 1
        theta, more_iter, stop = run.schedule_from(probe, done=params.check.refine)
        total_iter += more_iter
        value = run.levels[-1].objective(theta)
        problems, _ = run.self_check(theta, value, stop)
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


class _Run:
    """One registration in progress: the pyramid, the parameter scaling, the bounds, the random
    stream and the history, shared by the schedule, the capture-check refinements and the self-check."""

    def __init__(self, fixed: Image, moving: Image, params: RegisterParams,
                 callback: Callable[[int, int, np.ndarray, float], bool | None] | None):
        self.fixed, self.moving, self.params, self.callback = fixed, moving, params, callback
        smallest = min(min(fixed.shape), min(moving.shape))
        # levels too coarse for a small image are skipped
        self.schedule = ([lv for lv in params.schedule if smallest // lv.factor >= 8]
                         or [params.schedule[-1].model_copy(update={"factor": 1})])
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
        max_t = b.max_translation if b.max_translation is not None else 0.5 * min(fixed.shape)
        self.lower = np.array([t_init[0] - max_t, t_init[1] - max_t, -b.max_angle])
        self.upper = np.array([t_init[0] + max_t, t_init[1] + max_t, b.max_angle])
        self.rng = np.random.default_rng(params.seed)
        self.history: list[dict[str, np.ndarray]] = []

    def optimize(self, li: int, spec: LevelSpec, theta: np.ndarray, *, lower: np.ndarray, upper: np.ndarray,
                 callback=None, start: int = 0) -> OptimizeResult:
        """Run the chosen optimiser on level ``li``'s objective from ``theta`` (SPSA gains from iteration ``start``)."""
        level, o = self.levels[li], self.params.optimizer
        f = level.factor
        if o.name == "spsa":
            settings = SPSASettings(
                iterations=spec.iterations, a=o.a, A=o.A, c=spec.c * f, alpha=spec.gain_alpha, gamma=o.gain_gamma,
                step=spec.step * f, average=spec.average, max_step=None if o.max_step is None else o.max_step * f,
                blocking=o.blocking, shrink=o.shrink, tol=o.tol * f,
                average_last=min(o.average_last, spec.iterations), newton=o.newton, normalize=o.normalize,
                c_step_ratio=o.c_step_ratio, start=start)
            return spsa_maximize(level.objective, theta, settings, rng=self.rng, scales=self.scales, lower=lower,
                                 upper=upper, callback=callback)
        settings = PowellSettings(max_evaluations=max(20, 4 * spec.iterations), xtol=0.02 * f, step=spec.step * f)
        return powell_maximize(level.objective, theta, settings, scales=self.scales, lower=lower, upper=upper,
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
            theta = res.theta
            total_iter += res.iterations
            stop = res.stop_reason
            self.history.append({"level": np.full(res.iterations, li), **res.history})
        return theta, total_iter, stop

    def refine(self, start: np.ndarray) -> tuple[np.ndarray, float]:
        """A short run of the first level from a probe (for the capture check; any angle)."""
        spec = self.schedule[0].model_copy(update={"iterations": self.params.check.refine})
        res = self.optimize(0, spec, start, lower=np.r_[self.lower[:2], -np.inf], upper=np.r_[self.upper[:2], np.inf])
        return res.theta, self.levels[0].objective(res.theta)

    def probes(self) -> list[np.ndarray]:
        """Probe rotations spread over the full circle, each with the translation that maps the intensity centroids."""
        out = []
        for angle in np.linspace(-180.0, 180.0, self.params.check.probes, endpoint=False):
            t = initial_translation(self.fixed, self.moving, "moments", angle)
            out.append(np.array([t[0], t[1], angle]))
        return out

    def self_check(self, theta: np.ndarray, value: float, stop: str) -> tuple[list[str], np.ndarray | None]:
        """Reasons to distrust a result (empty list: none), and the probe that beat it (or None).

        An iterate in the second half of a level on a search bound means that the level's optimum
        lies beyond it (every point is clipped into the bounds). Each of the ``check.candidates``
        best probes (leaving out the one nearest to the result's angle) is briefly optimised
        (:meth:`refine`) before it is compared with the result.
        """
        params, levels, check = self.params, self.levels, self.params.check
        problems: list[str] = []
        winner = None
        if stop in ("invalid_start", "flat_objective"):
            problems.append(f"the optimiser could not start ({stop.replace('_', ' ')}): the images do not overlap "
                            f"enough at the initial transform or carry no information")
        if not math.isfinite(value):
            overlap = levels[-1].objective.overlap(theta)
            problems.append(f"only {overlap:.0%} of the fixed image overlaps the moving image at the result "
                            f"(min_overlap {params.metric.min_overlap:.0%})")
            return problems, None
        lower, upper = self.lower, self.upper
        span = upper - lower
        visited = np.vstack([np.atleast_2d(theta)]
                            + [h["theta"].reshape(-1, 3)[len(h["theta"]) // 2:] for h in self.history])
        at_bound = np.any((visited <= lower + 1e-6 * span) | (visited >= upper - 1e-6 * span), axis=0)
        if at_bound.any():
            names = [n for n, b in zip(("tx", "ty", "angle"), at_bound) if b]
            problems.append(f"the estimate is on the search bound of {', '.join(names)} (max_translation / "
                            f"max_angle): the misalignment is probably outside the capture range")
        if check.capture:
            coarse = levels[0].objective
            here = coarse(theta)
            spacing = 360.0 / check.probes
            scored = []
            for probe in self.probes():
                if abs((probe[2] - theta[2] + 180.0) % 360.0 - 180.0) < 0.5 * spacing:
                    continue  # the result's own probe
                scored.append((coarse(probe), probe[2], probe))
            scored.sort(key=lambda t: (-t[0], t[1]))
            best_value, best_theta = -math.inf, None
            r = rms_radius(self.fixed.shape)
            for v, _, probe in scored[: max(1, check.candidates)]:
                if check.refine > 0 and math.isfinite(v):
                    probe, v = self.refine(probe)
                    # a refined probe that came back to the result (within 2 coarse pixels RMS) is its basin
                    d = math.hypot(math.hypot(*(probe[:2] - theta[:2])),
                                   math.radians((probe[2] - theta[2] + 180.0) % 360.0 - 180.0) * r)
                    if d < 2.0 * levels[0].factor:
                        continue
                if v > best_value:
                    best_value, best_theta = v, probe
            if math.isfinite(best_value) and (not math.isfinite(here) or best_value > here + check.margin * abs(here)):
                winner = best_theta
                problems.append(f"a start at {best_theta[2]:+.0f} deg reaches a higher value than the result "
                                f"({best_value:.4g} > {here:.4g} at factor {levels[0].factor}): the registration "
                                f"stopped in a local optimum; the misalignment is probably outside the capture range")
        return problems, winner


@stage("register", params=RegisterParams, version=1, consumes=("fixed", "moving"), produces=("registration",))
def register_stage(fixed: Image, moving: Image, *, params: RegisterParams) -> RegisterResult:
    """Rigid registration by an entropic measure (JT, JR, MI, TMI) with SPSA or Powell, coarse to fine."""
    return RegisterResult(register(fixed, moving, params))
