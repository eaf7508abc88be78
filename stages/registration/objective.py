"""The registration objective: a similarity measure of the joint histogram as a function of the
transform parameters, at one or several resolutions.

``Objective(theta)`` with ``theta = (tx, ty, angle)`` (ITK convention, full-resolution pixels and
degrees) returns the measure of :mod:`topomatch.stages.registration.divergence` on the joint histogram of
``(fixed(x), moving(T(x)))`` over the fixed samples whose ``T(x)`` lies inside the moving image.
If fewer than ``min_overlap`` of the fixed samples land inside, it returns ``-inf`` (an invalid
transform, as in DIPY: the optimisers treat it as "do not go there") instead of a measure computed
on a sliver of the images.

:func:`build_pyramid` makes one :class:`Objective` per pyramid level (block-averaged images,
factor f), all in full-resolution parameter units.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Literal

import numpy as np

from topomatch.stages.registration.divergence import Metric, Weights, similarity
from topomatch.stages.registration.histogram import Binning, Interpolation, JointHistogram
from topomatch.stages.registration.image import Image
from topomatch.stages.registration.interpolation import downsample


class Objective:
    """Similarity of fixed and transformed moving image at one resolution (callable on theta).

    Parameters
    ----------
    histogram : JointHistogram or VolumeHistogram
        Anything with ``histogram(theta) -> (h, n_inside)``, ``n_samples``, ``overlap(theta)`` and
        ``factor``: the 2D images' histogram, or the 3D volumes' of
        :mod:`~topomatch.stages.registration.histogram3d` (theta = 3 Euler angles and a translation in mm).
    metric : {'jt', 'jr', 'mi', 'tmi'}
    alpha : float
        Order of the Tsallis / Renyi entropies (jt, jr, tmi).
    weights : {'histogram', 'uniform'}
        Weights of the Jensen divergences (jt, jr).
    tmi_form : {'additive', 'relative'}
    min_overlap : float
        Smallest accepted fraction of fixed samples inside the moving image.
    overlap_power : float
        The measure is multiplied by (fraction of fixed samples inside) ** ``overlap_power`` (0: not):
        samples that leave the moving image count as carrying no information, so a sliver of overlap
        whose few samples happen to agree cannot outscore a wide one (3D coarse levels).
    """

    def __init__(self, histogram: JointHistogram, metric: Metric = "jt", *, alpha: float = 2.0,
                 weights: Weights = "histogram", tmi_form: Literal["additive", "relative"] = "additive",
                 min_overlap: float = 0.25, overlap_power: float = 0.0):
        self.histogram = histogram
        self.metric, self.alpha, self.weights, self.tmi_form = metric, float(alpha), weights, tmi_form
        self.min_overlap, self.overlap_power = float(min_overlap), float(overlap_power)
        self.n_evals = 0

    def with_min_overlap(self, min_overlap: float) -> "Objective":
        """The same measure on the same histogram with another overlap bound."""
        return self.on(self.histogram, min_overlap=min_overlap)

    def on(self, histogram, *, min_overlap: float | None = None) -> "Objective":
        """The same measure (and overlap settings, unless ``min_overlap`` is given) on another histogram."""
        return Objective(histogram, self.metric, alpha=self.alpha, weights=self.weights, tmi_form=self.tmi_form,
                         min_overlap=self.min_overlap if min_overlap is None else min_overlap,
                         overlap_power=self.overlap_power)

    @property
    def factor(self) -> int:
        return self.histogram.factor

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


@dataclass(frozen=True)
class Level:
    """One pyramid level: its factor, bin count, and objective."""

    factor: int
    bins: int
    objective: Objective


def build_pyramid(fixed: Image, moving: Image, *, factors: list[int], bins: list[int], metric: Metric = "jt",
                  alpha: float = 2.0, weights: Weights = "histogram",
                  tmi_form: Literal["additive", "relative"] = "additive",
                  interpolation: Interpolation | list[Interpolation] = "bilinear",
                  samples: int | None | list[int | None] = None, min_overlap: float = 0.25,
                  seed: int = 0) -> list[Level]:
    """One objective per pyramid factor (coarse to fine, as given), with ``bins[i]`` bins each
    and interpolation ``interpolation[i]`` (or one for all).

    The binning covers each full-resolution image's intensity range at every level; the
    rotation centre is the full-resolution fixed image's centre; ``samples`` (one value or one
    per level) caps the fixed samples per level (random subset drawn with ``seed + level``).
    """
    if len(bins) != len(factors):
        raise ValueError(f"need one bin count per level: {len(factors)} levels, {len(bins)} bin counts")
    interps = [interpolation] * len(factors) if isinstance(interpolation, str) else list(interpolation)
    if len(interps) != len(factors):
        raise ValueError(f"need one interpolation per level: {len(factors)} levels, {len(interps)} given")
    caps = list(samples) if isinstance(samples, (list, tuple)) else [samples] * len(factors)
    levels = []
    for i, (f, b, interp, cap) in enumerate(zip(factors, bins, interps, caps)):
        jh = JointHistogram(downsample(fixed.data, f), downsample(moving.data, f), Binning.of(fixed.data, b),
                            Binning.of(moving.data, b), factor=f, center=fixed.center, interpolation=interp,
                            samples=cap, seed=seed + i)
        levels.append(Level(f, b, Objective(jh, metric, alpha=alpha, weights=weights, tmi_form=tmi_form,
                                            min_overlap=min_overlap)))
    return levels


def rms_radius(shape: tuple[int, int]) -> float:
    """Root-mean-square distance of the pixel centres of a (H, W) grid from its centre (pixels).

    A rotation by ``d`` radians moves the pixels by ``d * rms_radius`` on average (RMS), which
    is how the optimisers put angles and translations on one scale.
    """
    H, W = shape
    return math.sqrt((W * W - 1) / 12.0 + (H * H - 1) / 12.0)


def intensity_centroid(image: Image) -> np.ndarray:
    """Centre of mass ``(col, row)`` of ``data - min(data)`` (pixels)."""
    w = image.data - image.data.min()
    total = w.sum()
    H, W = image.shape
    return np.array([w.sum(axis=0) @ np.arange(W), w.sum(axis=1) @ np.arange(H)]) / total
