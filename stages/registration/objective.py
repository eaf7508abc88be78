"""The registration objective: a similarity measure of the joint histogram as a function of the transform parameters.

``Objective(theta)`` with ``theta`` the rigid transform's parameters (:mod:`~topomatch.stages.registration.transform`,
rotation first) returns the measure of :mod:`topomatch.stages.registration.divergence` on the joint histogram of
``(fixed(x), moving(T(x)))`` over the fixed samples whose ``T(x)`` lies inside the moving image. If fewer than
``min_overlap`` of the fixed samples land inside, it returns ``-inf`` (an invalid transform, as in DIPY: the optimisers
treat it as "do not go there") instead of a measure computed on a sliver of the images."""

from __future__ import annotations

import math
from typing import Literal

from topomatch.stages.registration.divergence import Metric, Weights, similarity
from topomatch.stages.registration.histogram import JointHistogram


class Objective:
    """Similarity of fixed and transformed moving image at one resolution (callable on theta).

    ``histogram``: anything with ``histogram(theta) -> (h, n_inside)``, ``n_samples`` and ``overlap(theta)``; ``alpha``:
    the entropies' order (jt, jr, tmi); ``weights``: the Jensen divergences' (jt, jr). The measure is multiplied by
    (fraction of fixed samples inside) ** ``overlap_power`` (0: not): samples that leave the moving image count as
    carrying no information, so a sliver of overlap whose few samples happen to agree cannot outscore a wide one (coarse
    levels)."""

    def __init__(self, histogram: JointHistogram, metric: Metric = "jt", *, alpha: float = 2.0,
                 weights: Weights = "histogram", tmi_form: Literal["additive", "relative"] = "additive",
                 min_overlap: float = 0.25, overlap_power: float = 0.0):
        self.histogram = histogram
        self.metric, self.alpha, self.weights, self.tmi_form = metric, float(alpha), weights, tmi_form
        self.min_overlap, self.overlap_power = float(min_overlap), float(overlap_power)
        self.n_evals = 0

    def on(self, histogram, *, min_overlap: float | None = None) -> "Objective":
        """The same measure (and overlap settings, unless ``min_overlap`` is given) on another histogram."""
        return Objective(histogram, self.metric, alpha=self.alpha, weights=self.weights, tmi_form=self.tmi_form,
                         min_overlap=self.min_overlap if min_overlap is None else min_overlap,
                         overlap_power=self.overlap_power)

    def overlap(self, theta) -> float:
        """Fraction of fixed samples whose ``T(x)`` lies inside the moving image."""
        return self.histogram.overlap(theta)

    def __call__(self, theta) -> float:
        self.n_evals += 1
        h, n_inside = self.histogram(theta)
        if n_inside < self.min_overlap * self.histogram.n_samples or n_inside == 0:
            return -math.inf
        value = similarity(h, self.metric, alpha=self.alpha, weights=self.weights, tmi_form=self.tmi_form)
        if self.overlap_power:
            value *= (n_inside / self.histogram.n_samples) ** self.overlap_power
        return value if math.isfinite(value) else -math.inf
