"""Parameters of :func:`~topomatch.stages.registration.register.register`, in the split that DIPY's
``AffineRegistration`` and SimpleITK's ``ImageRegistrationMethod`` use:

- ``metric`` (:class:`MetricSpec`): which measure of the joint histogram, its order and weights;
- ``optimizer`` (:class:`OptimizerSpec`): SPSA (the thesis's) or Powell, and SPSA's gains;
- ``schedule`` (a list of :class:`LevelSpec`): the coarse-to-fine pyramid, per level its factor,
  bins, interpolation, sample cap, iterations and step lengths;
- ``transform`` (:class:`TransformSpec`): the rigid transform's initialisation;
- ``bounds`` (:class:`BoundsSpec`): the search box around the initial transform;
- ``check`` (:class:`CheckSpec`): the self-check that flags a result it cannot trust;
- ``seed``: SPSA's perturbations and the sample subsets.

Angles in degrees, lengths in pixels. In a config a group may be given by its name alone:
``metric: mi`` is ``metric: {name: mi}``, ``optimizer: powell`` is ``optimizer: {name: powell}``.
"""

from __future__ import annotations

from typing import Any, Literal

from pydantic import Field, model_validator

from topomatch.pipeline.contract import Params


class _Named(Params):
    """A group whose ``name`` alone may stand for it (``metric: mi``)."""

    @model_validator(mode="before")
    @classmethod
    def _name_alone(cls, data: Any) -> Any:
        return {"name": data} if isinstance(data, str) else data


class MetricSpec(_Named):
    """The similarity measure of the joint histogram (thesis ch. 2)."""

    name: Literal["jt", "jr", "mi", "tmi"] = Field("jt", description="jt: Jensen-Tsallis (thesis), jr: Jensen-Renyi, "
                                                                   "mi: mutual information, tmi: Tsallis MI")
    alpha: float = Field(2.0, gt=0, le=10, allow_inf_nan=False, description="entropy order of jt, jr, tmi (thesis: 2)")
    weights: Literal["histogram", "uniform"] = Field("histogram", description="Jensen weights: reference histogram "
                                                                             "(thesis) or uniform")
    tmi_form: Literal["additive", "relative"] = Field("additive", description="Tsallis MI: pseudo-additive form or "
                                                                             "Tsallis relative entropy")
    min_overlap: float = Field(0.25, gt=0, le=1, description="smallest accepted fraction of fixed pixels inside the "
                                                              "moving image (below it the measure is undefined)")

    def label(self) -> str:
        """``jt(alpha=2 histogram)``, ``tmi(alpha=2)``, ``mi``."""
        if self.name in ("jt", "jr"):
            return f"{self.name}(alpha={self.alpha:g} {self.weights})"
        if self.name == "tmi":
            return f"{self.name}(alpha={self.alpha:g})"
        return self.name


class OptimizerSpec(_Named):
    """The optimiser of every level, and the SPSA gain sequences (Spall 1998)."""

    name: Literal["spsa", "powell"] = Field("spsa", description="SPSA (thesis) or scipy's Powell (deterministic)")
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


def default_schedule() -> list[LevelSpec]:
    """Factor 4, 16 bins, 260 normalised SPSA iterations; factor 2, 24 bins, 40; full resolution, 32 bins,
    partial volume, 6,000 samples, 30 iterations of two gradient estimates (chosen on the accuracy sweep
    of docs/registration.md)."""
    return [
        LevelSpec(factor=4, bins=16, iterations=260, step=1.0, c=2.0),
        LevelSpec(factor=2, bins=24, iterations=40, step=0.5, c=1.0),
        LevelSpec(factor=1, bins=32, iterations=30, step=0.3, c=0.5, average=2, gain_alpha=1.0, interpolation="pv",
                  samples=6000),
    ]


class TransformSpec(Params):
    """The rigid transform ``T(x) = R(angle)(x - c) + c + t`` and where it starts."""

    init: Literal["moments", "geometry"] = Field("moments", description="initial translation: map the intensity "
                                                                       "centroids, or the image centres")


class BoundsSpec(Params):
    """The search box around the initial transform."""

    max_translation: float | None = Field(None, gt=0, description="search bound |tx|, |ty| from the initial "
                                                                  "translation (default: half the smaller image side)")
    max_angle: float = Field(60.0, gt=0, le=180, description="search bound |angle| (degrees)")


class CheckSpec(Params):
    """The self-check: flag a result on a search bound, or one that a probe rotation beats."""

    capture: bool = Field(True, description="flag results that a probe rotation beats (outside the capture range)")
    probes: int = Field(24, ge=4, description="angles over the full circle of the coarse search")
    grid: int = Field(13, ge=1, description="translations per axis of the coarse search (over the search box)")
    min_content: float = Field(0.2, ge=0, le=1, allow_inf_nan=False,
                               description="flag a result that maps less than this fraction of the fixed image's "
                                           "content (Otsu foreground) onto the moving image's content (0: off)")
    min_prominence: float = Field(6.0, ge=0, allow_inf_nan=False,
                                  description="flag a result less than this many median absolute deviations "
                                              "above the coarse search's median (0: off)")
    min_flatness: float = Field(0.25, ge=0, le=1, allow_inf_nan=False,
                                description="flag a result from which the coarse search's measure falls, in its "
                                            "flattest direction, less than this fraction of its fall in the "
                                            "steepest (6 search pixels away): a parameter the images do not "
                                            "determine (0: off)")
    margin: float = Field(0.005, ge=0, description="relative margin by which a probe must win to flag the result")
    candidates: int = Field(3, ge=1, description="best probes refined and compared with the result")
    refine: int = Field(20, ge=0, description="first-level iterations from the best probe before it is compared "
                                              "with the result")
    retry: bool = Field(True, description="when a probe wins, run the schedule once more from it (within the bounds)")
    on_failure: Literal["flag", "error"] = Field("flag", description="flag a failed registration, or raise an error")


class RegisterParams(Params):
    """Parameters of :func:`~topomatch.stages.registration.register.register` (module docstring)."""

    metric: MetricSpec = Field(default_factory=MetricSpec, description="the measure: name, alpha, weights, "
                                                                       "tmi_form, min_overlap")
    optimizer: OptimizerSpec = Field(default_factory=OptimizerSpec, description="spsa or powell, and SPSA's gains")
    schedule: list[LevelSpec] = Field(default_factory=default_schedule, min_length=1,
                                      description="coarse-to-fine levels: factor, bins, iterations, step, c, average, "
                                                  "gain_alpha, interpolation, samples")
    transform: TransformSpec = Field(default_factory=TransformSpec, description="initialisation of the transform")
    bounds: BoundsSpec = Field(default_factory=BoundsSpec, description="search box: max_translation, max_angle")
    check: CheckSpec = Field(default_factory=CheckSpec, description="self-check: capture, probes, margin, "
                                                                   "candidates, refine, retry, on_failure")
    seed: int = Field(0, ge=0, description="seed of the SPSA perturbations and of the sample subsets")

    def method(self) -> str:
        """A short label such as ``spsa/jt(alpha=2 histogram)``."""
        return f"{self.optimizer.name}/{self.metric.label()}"
