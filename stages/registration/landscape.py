"""Objective landscapes (thesis Figs. 2.9-2.15): the measure as each parameter varies alone, 2D and 3D.

Around a centre ``theta_0`` (the transform's parameters in SimpleITK's order, angles in degrees), each parameter in turn
is moved over a range while the others stay at ``theta_0``; the joint histogram is computed once per point and every
order ``alpha`` of :attr:`LandscapeParams.alphas` is evaluated on it."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Literal

import numpy as np
from pydantic import Field

from topomatch.pipeline.contract import Params, StageResult, stage
from topomatch.stages.registration.divergence import similarity
from topomatch.stages.registration.histogram import Binning, JointHistogram
from topomatch.stages.registration.image import Image
from topomatch.stages.registration.transform import NAMES, n_angles


class LandscapeParams(Params):
    """Parameters of :func:`landscape`."""

    metric: Literal["jt", "jr", "mi", "tmi"] = Field("jt", description="measure (see register.metric.name)")
    weights: Literal["histogram", "uniform"] = Field("histogram", description="Jensen weights")
    alphas: list[float] = Field(default_factory=lambda: [0.5, 1.0, 2.0, 3.0], min_length=1,
                                description="entropy orders to evaluate (jt, jr, tmi; one curve each)")
    bins: int = Field(32, ge=2, le=1024, description="histogram bins")
    interpolation: Literal["linear", "parzen", "pv"] = Field("pv", description="binning (see register.schedule)")
    spacing: float = Field(0.0, ge=0, allow_inf_nan=False, description="pyramid level of both images (0: native)")
    center: list[float] | None = Field(None, description="theta_0 the scans pass through, SimpleITK's order, angles "
                                                         "in degrees (default: the identity)")
    translation_range: float = Field(20.0, gt=0, description="translations vary over theta_0 +- this")
    angle_range: float = Field(30.0, gt=0, description="angles vary over theta_0 +- this (degrees)")
    points: int = Field(81, ge=3, le=2001, description="points per scan")


@dataclass(frozen=True, eq=False)
class LandscapeResult(StageResult):
    """One scan per parameter: per parameter name the ``offsets`` from ``center`` (points,; degrees for angles)
    and the measure's ``values`` (len(alphas), points); ``center``: theta_0 (angles in degrees); ``label``: e.g.
    ``'jt, histogram weights'``."""

    offsets: dict[str, np.ndarray]
    values: dict[str, np.ndarray]
    alphas: tuple[float, ...]
    center: tuple[float, ...]
    label: str
    metric: str = ""
    weights: str = ""
    extra: dict = field(default_factory=dict)

    def summary(self) -> dict:
        out = {f"peak_{name}": float(self.offsets[name][int(np.nanargmax(v[-1]))]) for name, v in self.values.items()}
        first = next(iter(self.values))
        out["value_at_center"] = float(self.values[first][-1][len(self.offsets[first]) // 2])
        return out


def scan(fixed: Image, moving: Image, params: LandscapeParams) -> LandscapeResult:
    """The measure along each parameter around ``params.center`` (see the module docstring)."""
    names, k = NAMES[fixed.dim], n_angles(fixed.dim)
    center = np.asarray(params.center if params.center is not None else [0.0] * len(names), dtype=np.float64)
    if len(center) != len(names):
        raise ValueError(f"landscape.center needs {len(names)} values ({', '.join(names)}), got {len(center)}")
    jh = JointHistogram(fixed.shrink_to(params.spacing), moving.shrink_to(params.spacing),
                        Binning.of(fixed.data, params.bins), Binning.of(moving.data, params.bins), center=fixed.center,
                        mode=params.interpolation)
    alphas = tuple(params.alphas) if params.metric != "mi" else (1.0,)
    offsets, values = {}, {}
    for j, name in enumerate(names):
        d = np.linspace(-1.0, 1.0, params.points) * (params.angle_range if j < k else params.translation_range)
        out = np.full((len(alphas), len(d)), np.nan)
        for i, di in enumerate(d):
            theta = center.copy()
            theta[j] += di
            theta[:k] = np.radians(theta[:k])
            h, n_inside = jh(theta)
            if n_inside:
                out[:, i] = [similarity(h, params.metric, alpha=a, weights=params.weights) for a in alphas]
        offsets[name], values[name] = d, out
    label = params.metric + (f", {params.weights} weights" if params.metric in ("jt", "jr") else "")
    return LandscapeResult(offsets, values, alphas, tuple(center), label, params.metric, params.weights)


@stage("landscape", params=LandscapeParams, version=2, consumes=("fixed", "moving"))
def landscape(fixed: Image, moving: Image, *, params: LandscapeParams) -> LandscapeResult:
    """The measure as each parameter varies alone, for several entropy orders (Figs. 2.9-2.15)."""
    return scan(fixed, moving, params)
