"""Objective landscapes (thesis Figs. 2.9-2.15): the measure as each parameter varies alone.

Around a centre ``theta_0 = (tx, ty, angle)`` (ITK convention), each parameter in turn is
moved over a range while the other two stay at ``theta_0``; the joint histogram is computed once
per point and every order ``alpha`` of :attr:`LandscapeParams.alphas` is evaluated on it.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Literal

import numpy as np
from pydantic import Field

from topomatch.pipeline.contract import Params, StageResult, stage
from topomatch.stages.registration.divergence import similarity
from topomatch.stages.registration.histogram import Binning, JointHistogram
from topomatch.stages.registration.image import Image
from topomatch.stages.registration.interpolation import downsample

PARAMETERS = ("tx", "ty", "angle")


class LandscapeParams(Params):
    """Parameters of :func:`landscape`."""

    metric: Literal["jt", "jr", "mi", "tmi"] = Field("jt", description="measure (see register.metric.name)")
    weights: Literal["histogram", "uniform"] = Field("histogram", description="Jensen weights")
    alphas: list[float] = Field(default_factory=lambda: [0.5, 1.0, 2.0, 3.0], min_length=1,
                                description="entropy orders to evaluate (jt, jr, tmi; one curve each)")
    bins: int = Field(32, ge=2, le=1024, description="histogram bins")
    interpolation: Literal["bilinear", "pv"] = Field("pv", description="bilinear or partial volume")
    factor: int = Field(1, ge=1, description="pyramid factor (block averaging) of both images")
    center: tuple[float, float, float] = Field((0.0, 0.0, 0.0), description="theta_0 = (tx, ty, angle) the scans pass through")
    translation_range: float = Field(20.0, gt=0, description="tx and ty vary over theta_0 +- this (pixels)")
    angle_range: float = Field(30.0, gt=0, description="angle varies over theta_0 +- this (degrees)")
    points: int = Field(81, ge=3, le=2001, description="points per scan")


@dataclass(frozen=True, eq=False)
class LandscapeResult(StageResult):
    """One scan per parameter.

    Attributes
    ----------
    offsets : dict of ndarray
        Per parameter name: the offsets from ``center`` (points,).
    values : dict of ndarray
        Per parameter name: the measure, shape (len(alphas), points).
    alphas : tuple of float
    center : tuple of float
    label : str
        E.g. ``'jt, histogram weights'``.
    """

    offsets: dict[str, np.ndarray]
    values: dict[str, np.ndarray]
    alphas: tuple[float, ...]
    center: tuple[float, float, float]
    label: str
    metric: str = ""
    weights: str = ""
    extra: dict = field(default_factory=dict)

    def summary(self) -> dict:
        out = {}
        for name in PARAMETERS:
            v = self.values[name][-1]
            out[f"peak_{name}"] = float(self.offsets[name][int(np.nanargmax(v))])
        out["value_at_center"] = float(self.values["tx"][-1][len(self.offsets["tx"]) // 2])
        return out


def scan(fixed: Image, moving: Image, params: LandscapeParams) -> LandscapeResult:
    """The measure along each parameter around ``params.center`` (see the module docstring)."""
    f = params.factor
    jh = JointHistogram(downsample(fixed.data, f), downsample(moving.data, f), Binning.of(fixed.data, params.bins),
                        Binning.of(moving.data, params.bins), factor=f, center=fixed.center,
                        interpolation=params.interpolation)
    alphas = tuple(params.alphas) if params.metric != "mi" else (1.0,)
    offsets, values = {}, {}
    for j, name in enumerate(PARAMETERS):
        span = params.angle_range if name == "angle" else params.translation_range
        d = np.linspace(-span, span, params.points)
        out = np.full((len(alphas), len(d)), np.nan)
        for i, di in enumerate(d):
            theta = np.array(params.center, dtype=float)
            theta[j] += di
            h, n_inside = jh(theta)
            if n_inside == 0:
                continue
            for a, alpha in enumerate(alphas):
                out[a, i] = similarity(h, params.metric, alpha=alpha, weights=params.weights)
        offsets[name], values[name] = d, out
    label = params.metric + (f", {params.weights} weights" if params.metric in ("jt", "jr") else "")
    return LandscapeResult(offsets, values, alphas, tuple(params.center), label, params.metric, params.weights)


@stage("landscape", params=LandscapeParams, version=1, consumes=("fixed", "moving"))
def landscape(fixed: Image, moving: Image, *, params: LandscapeParams) -> LandscapeResult:
    """The measure as tx, ty and angle vary one at a time, for several entropy orders (Figs. 2.9-2.15)."""
    return scan(fixed, moving, params)
