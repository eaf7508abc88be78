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
   flagged when the measure is not finite (overlap below ``min_overlap``), when an iterate of the
   second half of a level sits on a search bound (``max_translation``, ``max_angle``), or, with
   ``capture_check``, when another basin is better: ``capture_probes`` rotations over the full
   circle (each with the translation that maps the intensity centroids) are scored at the
   coarsest level, the ``capture_candidates`` best ones away from the result's angle are refined
   by ``capture_refine`` first-level iterations, and one that ends elsewhere with a value higher
   than the result's by ``capture_margin`` (relative) flags it. With ``retry`` the schedule then
   runs once more from that refined probe if it lies within the bounds (the first level
   continuing its gain sequence), and the check is repeated. ``on_failure: error`` turns a flag
   into a :class:`~topomatch.pipeline.errors.StageError`.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field
from typing import Callable, Literal

import numpy as np
from pydantic import Field

from topomatch.pipeline.contract import Params, StageError, StageResult, stage
from topomatch.stages.registration.image import Image
from topomatch.stages.registration.objective import build_pyramid, intensity_centroid, rms_radius
from topomatch.stages.registration.powell import PowellSettings, powell_maximize
from topomatch.stages.registration.spsa import OptimizeResult, SPSASettings, spsa_maximize
from topomatch.stages.registration.transform import RigidTransform, rotation_matrix


class LevelSpec(Params):
    """One level of the coarse-to-fine schedule (lengths in the level's own pixels)."""

    factor: int = Field(1, ge=1, description="pyramid factor: both images block-averaged by it")
    bins: int = Field(32, ge=2, le=1024, description="histogram bins of each image")
    iterations: int = Field(50, ge=1, description="optimiser iterations (Powell: 4x this many evaluations at most)")
    step: float = Field(1.0, gt=0, allow_inf_nan=False, description="first step length a_0 (level pixels)")
    c: float = Field(1.0, gt=0, allow_inf_nan=False, description="SPSA perturbation c (level pixels)")
    average: int = Field(1, ge=1, description="SPSA gradient estimates averaged per iteration")
    gain_alpha: float = Field(0.602, gt=0, le=1, allow_inf_nan=False,
                              description="decay exponent of a_k (Spall: 0.602; 1 is the asymptotic optimum)")
    interpolation: Literal["bilinear", "pv"] = Field("bilinear", description="bilinear intensities or "
                                                                            "partial-volume weights")
    samples: int | None = Field(None, ge=100, description="at most this many fixed pixels (random subset)")


def _default_schedule() -> list[LevelSpec]:
    return [
        LevelSpec(factor=4, bins=16, iterations=260, step=1.0, c=2.0),
        LevelSpec(factor=2, bins=24, iterations=40, step=0.5, c=1.0),
        LevelSpec(factor=1, bins=32, iterations=30, step=0.3, c=0.5, average=2, gain_alpha=1.0, interpolation="pv",
                  samples=6000),
    ]


class RegisterParams(Params):
    """Parameters of :func:`register` (angles in degrees; lengths in pixels)."""

    metric: Literal["jt", "jr", "mi", "tmi"] = Field("jt", description="jt: Jensen-Tsallis (thesis), jr: Jensen-Renyi, "
                                                                     "mi: mutual information, tmi: Tsallis MI")
    alpha: float = Field(2.0, gt=0, le=10, allow_inf_nan=False, description="entropy order of jt, jr, tmi (thesis: 2)")
    weights: Literal["histogram", "uniform"] = Field("histogram", description="Jensen weights: reference histogram "
                                                                             "(thesis) or uniform")
    tmi_form: Literal["additive", "relative"] = Field("additive", description="Tsallis MI: pseudo-additive form or "
                                                                             "Tsallis relative entropy")
    optimizer: Literal["spsa", "powell"] = Field("spsa", description="SPSA (thesis) or scipy's Powell (deterministic)")
    schedule: list[LevelSpec] = Field(default_factory=_default_schedule, min_length=1,
                                      description="coarse-to-fine levels: factor, bins, iterations, step, c, average, "
                                                  "gain_alpha, interpolation, samples")
    init: Literal["moments", "geometry"] = Field("moments", description="initial translation: intensity centroids "
                                                                       "or image centres")
    normalize: bool = Field(True, description="SPSA steps of length a_k along the gradient estimate (else a_k g)")
    c_step_ratio: float = Field(1.0, ge=0, allow_inf_nan=False,
                                description="normalised SPSA: perturbation at most this times the step (0: off)")
    a: float | None = Field(None, gt=0, description="SPSA gain a (default: from the level's step)")
    A: float | None = Field(None, ge=0, description="SPSA stability constant A (default: 10 % of the iterations)")
    gain_gamma: float = Field(0.101, gt=0, le=1, description="decay exponent of c_k (Spall: 0.101)")
    newton: float = Field(0.5, ge=0, allow_inf_nan=False, description="unnormalised SPSA: first gain at most this "
                                                                      "fraction of a Newton step (0: off)")
    max_step: float | None = Field(None, gt=0, description="step blocking: longest step (level pixels)")
    blocking: bool = Field(False, description="reject steps that lower the objective (one more evaluation each)")
    shrink: float = Field(1.0, gt=0, le=1, allow_inf_nan=False, description="multiply the gain by this when a step "
                                                                            "is blocked")
    tol: float = Field(0.0, ge=0, description="stop a level when `window` steps are shorter (level pixels)")
    average_last: int = Field(1, ge=1, description="result of a level = mean of its last iterates")
    seed: int = Field(0, description="seed of the SPSA perturbations and of the sample subsets")
    max_translation: float | None = Field(None, gt=0, description="search bound |tx|, |ty| from the initial "
                                                                  "translation (default: half the smaller image side)")
    max_angle: float = Field(60.0, gt=0, le=180, description="search bound |angle| (degrees)")
    min_overlap: float = Field(0.25, gt=0, le=1, description="smallest accepted fraction of fixed pixels inside the "
                                                              "moving image")
    capture_check: bool = Field(True, description="flag results that a probe rotation beats (outside the capture range)")
    capture_probes: int = Field(24, ge=4, description="probe rotations over the full circle for the capture check")
    capture_margin: float = Field(0.005, ge=0, description="relative margin by which a probe must win to flag the result")
    capture_candidates: int = Field(2, ge=1, description="best probes refined and compared with the result")
    capture_refine: int = Field(20, ge=0, description="first-level iterations from the best probe before it is "
                                                        "compared with the result")
    retry: bool = Field(True, description="when a probe wins, run the schedule once more from it (within the bounds)")
    on_failure: Literal["flag", "error"] = Field("flag", description="flag a failed registration, or raise an error")

    def method(self) -> str:
        """A short label such as ``spsa/jt(alpha=2 histogram)``."""
        m = self.metric
        if m in ("jt", "jr"):
            m += f"(alpha={self.alpha:g} {self.weights})"
        elif m == "tmi":
            m += f"(alpha={self.alpha:g})"
        return f"{self.optimizer}/{m}"


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
        With ``ok=False`` and a ``reason`` when the self-check fails (``on_failure='flag'``).

    Raises
    ------
    StageError
        A failed self-check with ``on_failure='error'``.
    """
    t0 = time.perf_counter()
    smallest = min(min(fixed.shape), min(moving.shape))
    schedule = [lv for lv in params.schedule if smallest // lv.factor >= 8] or [params.schedule[-1].model_copy(
        update={"factor": 1})]  # levels too coarse for a small image are skipped
    levels = build_pyramid(fixed, moving, factors=[lv.factor for lv in schedule], bins=[lv.bins for lv in schedule],
                           metric=params.metric, alpha=params.alpha, weights=params.weights, tmi_form=params.tmi_form,
                           interpolation=[lv.interpolation for lv in schedule],
                           samples=[lv.samples for lv in schedule], min_overlap=params.min_overlap, seed=params.seed)
    deg_per_px = math.degrees(1.0 / rms_radius(fixed.shape))
    scales = np.array([1.0, 1.0, deg_per_px])
    t_init = initial_translation(fixed, moving, params.init)
    theta = np.array([t_init[0], t_init[1], 0.0])
    max_t = params.max_translation if params.max_translation is not None else 0.5 * min(fixed.shape)
    lower = np.array([t_init[0] - max_t, t_init[1] - max_t, -params.max_angle])
    upper = np.array([t_init[0] + max_t, t_init[1] + max_t, params.max_angle])
    rng = np.random.default_rng(params.seed)
    hist_rows: list[dict[str, np.ndarray]] = []

    def refine(start: np.ndarray) -> tuple[np.ndarray, float]:
        """A short run of the first level from a probe (for the capture check; any angle)."""
        spec = schedule[0].model_copy(update={"iterations": params.capture_refine})
        free = np.array([np.inf, np.inf, np.inf])
        res = _optimize_level(levels[0], spec, start, params, scales, np.r_[lower[:2], -free[2]],
                              np.r_[upper[:2], free[2]], rng, None)
        return res.theta, levels[0].objective(res.theta)

    theta, total_iter, stop = _run_schedule(theta, levels, schedule, params, scales, lower, upper, rng, callback,
                                            hist_rows)
    value = levels[-1].objective(theta)
    problems, probe = _self_check(theta, value, levels, params, fixed, moving, lower, upper, stop, hist_rows, refine)
    restarts = 0
    if probe is not None and params.retry and np.all(probe >= lower) and np.all(probe <= upper):
        # the capture check found a better basin (the probe was already refined on the first level):
        # continue the first level from it, then run the other levels again
        restarts = 1
        theta, more_iter, stop = _run_schedule(probe, levels, schedule, params, scales, lower, upper, rng, callback,
                                               hist_rows, done=params.capture_refine)
        total_iter += more_iter
        value = levels[-1].objective(theta)
        problems, _ = _self_check(theta, value, levels, params, fixed, moving, lower, upper, stop, hist_rows, refine)
    transform = RigidTransform.from_params(theta, fixed.center)
    ok, reason = not problems, "; ".join(problems)
    history = {key: np.concatenate([h[key] for h in hist_rows]) for key in ("level", "theta", "value", "step", "blocked")}
    evaluations = sum(lv.objective.n_evals for lv in levels)
    reg = Registration(transform, float(value), ok, reason, params.method(), time.perf_counter() - t0, total_iter,
                       evaluations, stop, history, fixed.spacing, restarts)
    if not ok and params.on_failure == "error":
        raise StageError(f"registration failed: {reason} (estimate tx={transform.tx:.3f}, ty={transform.ty:.3f}, "
                         f"angle={transform.angle:.3f})")
    return reg


def _probes(fixed: Image, moving: Image, n: int) -> list[np.ndarray]:
    """``n`` rotations spread over the full circle, each with the translation that maps the intensity centroids."""
    out = []
    for angle in np.linspace(-180.0, 180.0, n, endpoint=False):
        t = initial_translation(fixed, moving, "moments", angle)
        out.append(np.array([t[0], t[1], angle]))
    return out


def _optimize_level(level, spec: LevelSpec, theta, params: RegisterParams, scales, lower, upper, rng,
                    callback, start: int = 0) -> OptimizeResult:
    """Run the chosen optimiser on one level's objective from ``theta`` (SPSA gains from iteration ``start``)."""
    f = level.factor
    if params.optimizer == "spsa":
        settings = SPSASettings(
            iterations=spec.iterations, a=params.a, A=params.A, c=spec.c * f, alpha=spec.gain_alpha,
            gamma=params.gain_gamma, step=spec.step * f, average=spec.average,
            max_step=None if params.max_step is None else params.max_step * f, blocking=params.blocking,
            shrink=params.shrink, tol=params.tol * f, average_last=min(params.average_last, spec.iterations),
            newton=params.newton, normalize=params.normalize, c_step_ratio=params.c_step_ratio, start=start)
        return spsa_maximize(level.objective, theta, settings, rng=rng, scales=scales, lower=lower, upper=upper,
                             callback=callback)
    settings = PowellSettings(max_evaluations=max(20, 4 * spec.iterations), xtol=0.02 * f, step=spec.step * f)
    return powell_maximize(level.objective, theta, settings, scales=scales, lower=lower, upper=upper, callback=callback)


def _run_schedule(theta, levels, schedule, params: RegisterParams, scales, lower, upper, rng, callback,
                  hist_rows: list, done: int = 0) -> tuple[np.ndarray, int, str]:
    """Optimise level by level from ``theta``; append each level's history to ``hist_rows``.

    ``done`` first-level iterations were already made (a refined probe): the first level continues
    its gain sequence from there for the rest of its iterations.
    """
    total_iter, stop = 0, ""
    for li, (level, spec) in enumerate(zip(levels, schedule)):
        cb = None if callback is None else (lambda k, th, v, li=li: callback(li, k, th, v))
        start = 0
        if li == 0 and done > 0:
            start = min(done, spec.iterations - 1)
            spec = spec.model_copy(update={"iterations": spec.iterations - start})
        res = _optimize_level(level, spec, theta, params, scales, lower, upper, rng, cb, start)
        theta = res.theta
        total_iter += res.iterations
        stop = res.stop_reason
        hist_rows.append({"level": np.full(res.iterations, li), **res.history})
    return theta, total_iter, stop


def _self_check(theta, value, levels, params: RegisterParams, fixed: Image, moving: Image, lower, upper,
                stop: str, histories: list[dict], refine=None) -> tuple[list[str], np.ndarray | None]:
    """Reasons to distrust a result (empty list: none), and the probe that beat it (or None).

    ``histories`` are the levels' histories: an iterate in the second half of a level on a search
    bound means that the level's optimum lies beyond it (every point is clipped into the bounds).
    ``refine(theta) -> (theta, value)`` briefly optimises each of the ``capture_candidates`` best
    probes (leaving out the one nearest to the result's angle) before it is compared with the result.
    """
    problems: list[str] = []
    winner = None
    if stop in ("invalid_start", "flat_objective"):
        problems.append(f"the optimiser could not start ({stop.replace('_', ' ')}): the images do not overlap enough "
                        f"at the initial transform or carry no information")
    if not math.isfinite(value):
        overlap = levels[-1].objective.overlap(theta)
        problems.append(f"only {overlap:.0%} of the fixed image overlaps the moving image at the result "
                        f"(min_overlap {params.min_overlap:.0%})")
        return problems, None
    span = upper - lower
    visited = np.vstack([np.atleast_2d(theta)] + [h["theta"].reshape(-1, 3)[len(h["theta"]) // 2:] for h in histories])
    at_bound = np.any((visited <= lower + 1e-6 * span) | (visited >= upper - 1e-6 * span), axis=0)
    if at_bound.any():
        names = [n for n, b in zip(("tx", "ty", "angle"), at_bound) if b]
        problems.append(f"the estimate is on the search bound of {', '.join(names)} (max_translation / max_angle): "
                        f"the misalignment is probably outside the capture range")
    if params.capture_check:
        coarse = levels[0].objective
        here = coarse(theta)
        spacing = 360.0 / params.capture_probes
        scored = []
        for probe in _probes(fixed, moving, params.capture_probes):
            if abs((probe[2] - theta[2] + 180.0) % 360.0 - 180.0) < 0.5 * spacing:
                continue  # the result's own probe
            scored.append((coarse(probe), probe[2], probe))
        scored.sort(key=lambda t: (-t[0], t[1]))
        best_value, best_theta = -math.inf, None
        r = rms_radius(fixed.shape)
        for v, _, probe in scored[: max(1, params.capture_candidates)]:
            if refine is not None and params.capture_refine > 0 and math.isfinite(v):
                probe, v = refine(probe)
                # a refined probe that came back to the result (within 2 coarse pixels RMS) is its basin
                d = math.hypot(math.hypot(*(probe[:2] - theta[:2])),
                               math.radians((probe[2] - theta[2] + 180.0) % 360.0 - 180.0) * r)
                if d < 2.0 * levels[0].factor:
                    continue
            if v > best_value:
                best_value, best_theta = v, probe
        if math.isfinite(best_value) and (not math.isfinite(here) or best_value > here + params.capture_margin * abs(here)):
            winner = best_theta
            problems.append(f"a start at {best_theta[2]:+.0f} deg reaches a higher value than the result "
                            f"({best_value:.4g} > {here:.4g} at factor {levels[0].factor}): the registration stopped in "
                            f"a local optimum; the misalignment is probably outside the capture range")
    return problems, winner


@stage("register", params=RegisterParams, version=1, consumes=("fixed", "moving"), produces=("registration",))
def register_stage(fixed: Image, moving: Image, *, params: RegisterParams) -> RegisterResult:
    """Rigid registration by an entropic measure (JT, JR, MI, TMI) with SPSA or Powell, coarse to fine."""
    return RegisterResult(register(fixed, moving, params))
