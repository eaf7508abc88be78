"""Parameters of :func:`~topomatch.stages.registration.register.register`, 2D and 3D alike, grouped as DIPY's
``AffineRegistration`` and SimpleITK's ``ImageRegistrationMethod`` group them: ``metric``, ``optimizer``, ``schedule``
(a list of :class:`LevelSpec`), ``transform`` and ``start``, ``bounds``, ``sampling``, ``check``, ``seed``. Angles in
degrees, lengths in physical units (pixels for a PNG, mm for a volume); in a config ``metric: mi`` is ``metric: {name:
mi}``.

**The dimension enters here, once**: :data:`DIMENSION_DEFAULTS` holds what differs between 2D and 3D, applied by
:func:`for_dimension` under whatever the caller set (a value from a config, the command line or the API wins)."""

from __future__ import annotations

from typing import Any, Literal

from pydantic import Field, FiniteFloat, model_validator

from topomatch.pipeline.contract import Params, deep_merge


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
    alpha: float = Field(2.0, gt=0, le=10, allow_inf_nan=False, description="entropy order of jt, jr, tmi, in (0, 10] "
                                                                           "(thesis: 2; mi ignores it)")
    weights: Literal["histogram", "uniform"] = Field("histogram", description="Jensen weights: reference histogram "
                                                                             "(thesis) or uniform")
    tmi_form: Literal["additive", "relative"] = Field("additive", description="Tsallis MI: pseudo-additive form or "
                                                                             "Tsallis relative entropy")
    min_overlap: float = Field(0.25, gt=0, le=1, description="smallest accepted fraction of fixed samples inside the "
                                                              "moving image (below it the measure is undefined)")
    outline_alpha: float | None = Field(1.0, gt=0, le=10, allow_inf_nan=False,
                                        description="entropy order of jt, jr, tmi on an outline-only pair (either "
                                                    "image with less interior structure than check.min_structure: a "
                                                    "silhouette, a mask): order 1, where all three are mutual "
                                                    "information, keeps the outline on the object's edge; order 2 "
                                                    "pulls it onto the largest bins' band (null: alpha)")
    outline_spread: float = Field(0.12, ge=0, le=1, description="a pair in which either image is less spread inside "
                                  "its solid object than this (structure.interior_spread: a saturated image) is measured "
                                  "at outline_alpha, not flagged (fortieth round; off at 0, or with check.min_spread 0)")
    discrete_levels: int = Field(16, ge=0, le=1024,
                                 description="a pair in which either image holds at most this many distinct "
                                             "intensities (a label map, a thresholded mask) is measured as an "
                                             "outline-only pair is, at outline_alpha with the finest level smoothed "
                                             "(outline_smoothing, label_smoothing), but not flagged as one (0: off)")

    def label(self) -> str:
        """``jt(alpha=2 histogram)``, ``tmi(alpha=2)``, ``mi``."""
        if self.name == "mi":
            return self.name
        return f"{self.name}(alpha={self.alpha:g}{' ' + self.weights if self.name in ('jt', 'jr') else ''})"

    def for_outline(self) -> "MetricSpec":
        """The measure of an outline-only pair: ``alpha`` replaced by ``outline_alpha`` (jt, jr, tmi)."""
        if self.outline_alpha is None or self.name == "mi":
            return self
        return self.model_copy(update={"alpha": self.outline_alpha})


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
    max_step: float | None = Field(None, gt=0, description="step blocking: longest step (physical units)")
    blocking: bool = Field(False, description="reject steps that lower the objective (one more evaluation each)")
    shrink: float = Field(1.0, gt=0, le=1, allow_inf_nan=False, description="multiply the gain by this when a step is blocked")
    tol: float = Field(0.0, ge=0, description="stop a level when `window` steps are shorter (physical units)")
    average_last: int = Field(1, ge=1, description="result of a level = mean of its last iterates")
    average_finest: int = Field(10, ge=1, description="the finest level's average_last (pairs not measured as outlines)")
    ensemble: int = Field(0, ge=0, le=16, description="finest-level re-runs on other samples averaged into the result")


class LevelSpec(Params):
    """One level of the coarse-to-fine schedule (lengths in physical units: pixels for a PNG, mm for a volume)."""

    spacing: float = Field(0.0, ge=0, allow_inf_nan=False,
                           description="pixel size of the level: each axis block-averaged by the integer factor that "
                                       "comes closest, never finer than native (0: native)")
    bins: int = Field(32, ge=2, le=1024, description="histogram bins of each image")
    iterations: int = Field(50, ge=1, description="optimiser iterations (Powell: 4x this many evaluations at most)")
    step: float = Field(1.0, gt=0, allow_inf_nan=False, description="SPSA first step length a_0")
    c: float = Field(1.0, gt=0, allow_inf_nan=False, description="SPSA perturbation c")
    average: int = Field(1, ge=1, description="SPSA gradient estimates averaged per iteration")
    gain_alpha: float = Field(0.602, gt=0, le=1, allow_inf_nan=False,
                              description="decay exponent of a_k (Spall: 0.602; 1 is the asymptotic optimum)")
    interpolation: Literal["linear", "parzen", "pv"] = Field(
        "parzen", description="linear: interpolated intensity to its bin; parzen: split between its two nearest "
                              "bins; pv: partial volume (each neighbour's weight to its own bin)")
    samples: int | None = Field(None, ge=100, description="at most this many fixed pixels (fixed-seed random subset)")
    settle: float = Field(0.0, ge=0, allow_inf_nan=False,
                          description="run the level again from its end while the last half of its iterations moved "
                                      "the estimate by more than this (RMS displacement; 0: never)")
    reruns: int = Field(0, ge=0, le=10, description="at most this many runs again (see settle)")
    smoothing: float = Field(0.0, ge=0, allow_inf_nan=False,
                             description="Gaussian sigma, in the level's pixels, applied to both images after the "
                                         "block average (0: none)")


class TransformSpec(Params):
    """The rigid transform ``T(p) = R (p - c) + c + t`` and where it starts."""

    init: Literal["moments", "geometry"] = Field("moments", description="initial translation: map the intensity "
                                                                       "centroids, or the grid centres")


class StartSpec(Params):
    """A search for the start: translations about the centre-mapping ones, scored at the coarsest level."""

    steps: int = Field(0, ge=0, le=5, description="grid of (2 steps + 1)^d shifts about each centre-mapping "
                                                 "translation and the identity (0: start at transform.init's)")
    spacing: float = Field(12.0, gt=0, allow_inf_nan=False, description="grid spacing (physical units)")
    candidates: int = Field(2, ge=0, description="best grid shifts optimised briefly at the coarsest level, besides "
                                                 "the centres themselves")
    iterations: int = Field(80, ge=0, description="coarsest-level iterations from each candidate")


class BoundsSpec(Params):
    """The search box around the start."""

    max_translation: float | None = Field(None, gt=0, allow_inf_nan=False, description="bound on each translation from "
                                          "the start (default: half the fixed image's smallest extent; at most the two "
                                          "images' largest extents added, beyond which they cannot overlap)")
    max_angle: float = Field(60.0, gt=0, le=180, description="bound on each angle (degrees)")


class SamplingSpec(Params):
    """Which fixed pixels the joint histograms sample."""

    region: Literal["all", "foreground"] = Field("foreground", description="every fixed pixel, or the fixed Otsu "
                                                                          "foreground grown by `margin` (a mask given "
                                                                          "to the API wins)")
    margin: float = Field(16.0, ge=0, allow_inf_nan=False,
                          description="grow the foreground by this distance (physical units), so that the object's "
                                      "outline and a band around it are sampled: a moving image whose only structure "
                                      "is the outline (a silhouette, a label map) has it there")
    jitter: bool = Field(True, description="move each sample by a fixed random offset within its pixel")


class CheckSpec(Params):
    """The self-check: every test is on by a positive threshold (0 / false: off)."""

    search: bool = Field(True, description="coarse search: a better basin found from its best transforms flags the "
                                           "result (and, with retry, replaces it)")
    probes: int = Field(24, ge=4, description="2D: rotations over the full circle of the coarse search")
    angles: list[FiniteFloat] = Field(default_factory=lambda: [-30.0, 30.0],
                                description="3D: rotations of the coarse search about each axis (degrees), besides none")
    grid: int = Field(13, ge=1, description="translations per axis of the coarse search (over the search box)")
    min_content: float = Field(0.2, ge=0, le=1, allow_inf_nan=False,
                               description="flag a result that maps less than this fraction of the fixed image's "
                                           "content (Otsu foreground) onto the moving image's content")
    min_structure: float = Field(0.06, ge=0, allow_inf_nan=False,
                                 description="a pair in which either image has less structure inside its outline "
                                             "than this (interior over outline gradient, structure.py) is "
                                             "outline-only (a mask, a silhouette): registered at "
                                             "metric.outline_alpha with outline_smoothing, flagged by the outline "
                                             "tests below (0: this test is off)")
    min_spread: float = Field(0.05, ge=0, allow_inf_nan=False,
                              description="a pair in which either image's intensities inside its object spread less "
                                          "than this fraction of the object's contrast (q90 - q10 over the "
                                          "object-background median difference, structure.py) is outline-only too: "
                                          "a mask or silhouette whose outline is too intricate for min_structure "
                                          "(0: this test is off)")
    min_residual: float = Field(0.002, ge=0, le=1, allow_inf_nan=False,
                                description="where neither test above can judge an image (its object fills the grid: "
                                            "a tight field of view), a pair in which the larger variance of its two "
                                            "Otsu classes is less than this fraction of their contrast squared is "
                                            "outline-only too: a mask or silhouette, noisy or soft (structure.py; "
                                            "0: this test is off)")
    outline_gap: float = Field(6.0, ge=0, allow_inf_nan=False,
                               description="such a pair is flagged when the two outlines lie farther apart than this "
                                           "(physical units, mean, compared within 4 fixed pixels of the fixed "
                                           "outline) at the result: outlines that do not correspond at all "
                                           "(the validation corpus's correct outline-only results: at most 5.8); "
                                           "0 flags every such pair")
    min_outline_view: float = Field(0.5, ge=0, le=1, allow_inf_nan=False, description="such a pair is flagged when "
                                    "less than this fraction of the outline-only image's object boundary is outline "
                                    "inside the grid, the rest cut by a border (structure.outline_in_view; 0: off; 3D: 0.45)")
    outline_flat: float = Field(0.02, ge=0, le=1, allow_inf_nan=False, description="such a pair with less than 1.2 "
                                "times min_outline_view of its outline in view is flagged when the measure one unit from "
                                "the result is within this fraction of it: nothing pins it to a unit (0: off; 3D: off)")
    outline_view_partner: bool = Field(True, description="the outline in view counts only what the other image "
                                       "sees at the result (a cropped partner's border cuts it too)")
    outline_drop: float = Field(0.003, ge=0, le=1, allow_inf_nan=False,
                                description="such a pair is flagged when a coarser level's measure is lower at the "
                                            "result than at its own end by more than this fraction, and lower on "
                                            "average over 8 other samples: its finer levels left the optimum it found")
    min_prominence: float = Field(6.0, ge=0, allow_inf_nan=False,
                                  description="flag a result less than this many median absolute deviations above "
                                              "the coarse search's median")
    outline_prominence: bool = Field(True, description="the prominence test judges outline-only pairs too (3D: no)")
    search_region: bool = Field(False, description="the coarse search is scaled to the fixed sampling region and "
                                "samples only it (thirty-ninth round; 3D: yes)")
    min_flatness: float = Field(0.1, ge=0, le=1, allow_inf_nan=False,
                                description="flag a result from which the measure, on a copy of the images scaled to "
                                            "their content, falls in its flattest direction less than this fraction "
                                            "of its fall in the steepest: a parameter the images do not determine")
    overlap_bound: bool = Field(True, description="flag a result whose measure keeps rising where the images overlap "
                                                  "less than min_overlap")
    chance: float = Field(0.0, ge=0, description="flag a result whose measure is below this multiple of its chance "
                                                 "level (the same samples with the fixed intensities paired at random)")
    consistency: float = Field(0.014, ge=0, le=1, allow_inf_nan=False,
                               description="flag a result at which a coarser level's measure is lower than at that "
                                           "level's own end by more than this fraction of it: a finer level walked "
                                           "away from the basin the coarser one found")
    stability: float = Field(0.0, ge=0, allow_inf_nan=False,
                             description="flag a result from which the finest level, run again on another sample of "
                                         "the images, ends farther than this (physical units; 0: off)")
    agreement: float = Field(1.0, ge=0, allow_inf_nan=False,
                             description="flag a result farther than this (physical units) from the optimum of the "
                                         "thesis's measure (JT, alpha 2, histogram weights) climbed from it at the "
                                         "finest level: a measure whose own optimum is biased (0: off; no effect "
                                         "with that measure)")
    mi_agreement: float = Field(1.0, ge=0, allow_inf_nan=False, description="with JT (alpha 2, histogram weights): "
                                "flag a result farther than this (physical units) from MI's climb from it (0: off)")
    label: float = Field(2.0, ge=0, allow_inf_nan=False, description="flag a result farther than this (physical "
                         "units) from the registration of the pair with each label map (plateau share >= "
                         "label_plateau, three values or more) replaced by its object (0: off)")
    label_plateau: float = Field(0.2, gt=0, le=1, description="an image whose object has at least this share of "
                                 "exact plateaus is read as a label map by the label test")
    margin: float = Field(0.005, ge=0, description="relative margin by which a probe must win to flag the result")
    candidates: int = Field(3, ge=1, description="best probes refined and compared with the result")
    shortlist: int = Field(10, ge=0, description="when the candidates find no better basin, the best of this many "
                           "grid transforms by the first level's measure are probed; a winner only flags (0: off)")
    start_search: bool = Field(True, description="when no start search ran (start.steps 0: 2D), the 3D start search's "
                               "end is one more probe of a pair read as an image; a winner only flags")
    refine: int = Field(20, ge=0, description="coarsest-level iterations from each probe before the comparison")
    retry: bool = Field(True, description="when a probe wins, adopt the result of the schedule run from it and check "
                                          "again (once)")
    mirror: float = Field(0.05, ge=0, allow_inf_nan=False, description="a result that the moving image mirrored beats by "
                          "this fraction is flagged: a flipped file (44th round; 3D: 0.1, 45th; 0: off)")
    mirror_refine: bool = Field(True, description="the mirrored pair's two best coarse transforms refined and compared "
                                "with the result at the coarsest level; off (3D): the two coarse searches' best scores")
    on_failure: Literal["flag", "error"] = Field("flag", description="flag a failed registration, or raise an error")


class RegisterParams(Params):
    """Parameters of :func:`~topomatch.stages.registration.register.register` (module docstring); fields left
    out take :data:`DIMENSION_DEFAULTS` for the images' dimension."""

    metric: MetricSpec = Field(default_factory=MetricSpec, description="the measure: name, alpha, weights, tmi_form, min_overlap")
    optimizer: OptimizerSpec = Field(default_factory=OptimizerSpec, description="spsa or powell, and SPSA's gains")
    schedule: list[LevelSpec] = Field(default_factory=list, description="coarse-to-fine levels, LevelSpec's "
                                      "fields (default: the dimension's, docs/registration.md)")
    transform: TransformSpec = Field(default_factory=TransformSpec, description="initialisation of the transform")
    start: StartSpec = Field(default_factory=StartSpec, description="search for the start (3D default: steps 2)")
    bounds: BoundsSpec = Field(default_factory=BoundsSpec, description="search box: max_translation, max_angle")
    sampling: SamplingSpec = Field(default_factory=SamplingSpec, description="region, margin, jitter of the samples")
    check: CheckSpec = Field(default_factory=CheckSpec, description="self-check: search, probes, thresholds, retry, on_failure")
    seed: int = Field(0, ge=0, description="seed of the SPSA perturbations and of the sample subsets")
    outline_smoothing: float = Field(1.0, ge=0, allow_inf_nan=False,
                                     description="on an outline-only or two-level pair, the finest level's "
                                                 "images are smoothed by a Gaussian of this many of its pixels: the "
                                                 "outline's step becomes a ramp that the histogram sees at sub-pixel "
                                                 "shifts (0: the level's own smoothing)")
    label_smoothing: float = Field(1.0, ge=0, allow_inf_nan=False, description="the same on a label map of three "
                                   "labels or more, whose blends fall on other labels' values (3D: 0, 36th round)")
    label_samples: float = Field(1.0, gt=0, le=16, allow_inf_nan=False, description="a label map's finest level takes "
                                 "this many times its samples: unsmoothed, its measure is rough (3D: 4, 37th round)")
    coarse_overlap_power: float = Field(0.0, ge=0, le=4, allow_inf_nan=False,
                                        description="every level but the finest multiplies its measure by the "
                                                    "overlap fraction to this power: a sliver of overlap cannot "
                                                    "outscore the aligned position")

    def method(self) -> str:
        """A short label such as ``spsa/jt(alpha=2 histogram)``."""
        return f"{self.optimizer.name}/{self.metric.label()}"


def _level(spacing, bins, iterations, step, c, interpolation, samples=None, **more) -> dict:
    return dict(spacing=spacing, bins=bins, iterations=iterations, step=step, c=c, interpolation=interpolation,
                samples=samples, **more)


DIMENSION_DEFAULTS: dict[int, dict[str, Any]] = {
    2: {
        # factors 4 and 2, then native pixels (the 2D accuracy sweep of docs/registration.md); 20,000 samples at the
        # finest level; the thresholds of the self-check: the validation corpus's tune split (docs/registration_history.md)
        "schedule": [_level(4.0, 16, 260, 4.0, 8.0, "parzen"), _level(2.0, 24, 40, 1.0, 2.0, "parzen"),
                     _level(0.0, 32, 30, 0.3, 0.5, "parzen", 20000, average=2, gain_alpha=1.0)],
        "optimizer": {"ensemble": 2},  # thirty-first round
    },
    3: {
        # 8, 4 and 2 mm (the 3D tune sets of docs/registration_history.md)
        "schedule": [_level(8.0, 16, 150, 4.0, 4.0, "parzen", 4000), _level(4.0, 24, 60, 1.0, 2.0, "parzen", 8000),
                     _level(2.0, 64, 40, 0.3, 1.0, "parzen", 30000, average=2, gain_alpha=1.0, settle=0.2, reruns=2)],
        "start": {"steps": 2, "iterations": 40}, "optimizer": {"average_finest": 1}, "bounds": {"max_angle": 45.0},
        "coarse_overlap_power": 1.0, "label_smoothing": 0.0, "label_samples": 4.0,  # 36th, 37th rounds
        "check": {"grid": 5, "min_content": 0.0, "min_flatness": 0.0, "overlap_bound": False,
                  "chance": 3.0, "consistency": 0.0, "stability": 0.8, "margin": 0.01, "candidates": 2, "refine": 30,
                  "outline_view_partner": False, "outline_prominence": False, "search_region": True,
                  "min_outline_view": 0.45, "outline_flat": 0.0, "mirror": 0.1, "mirror_refine": False},
    },
}


def for_dimension(params: RegisterParams, dim: int) -> RegisterParams:
    """``params`` with :data:`DIMENSION_DEFAULTS` of ``dim`` for every field the caller did not set."""
    if dim not in DIMENSION_DEFAULTS:
        raise ValueError(f"registration works on 2D and 3D images, got {dim}D")
    given = params.model_dump(exclude_unset=True)
    if not given.get("schedule"):
        given.pop("schedule", None)
    return RegisterParams.model_validate(deep_merge(DIMENSION_DEFAULTS[dim], given))
