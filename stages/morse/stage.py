"""The ``morse`` stage: compute a Morse function on the mesh vertices."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

import numpy as np
from pydantic import Field

from topomatch.pipeline.contract import Params, StageResult, stage
from topomatch.stages.mesh.mesh import Mesh
from topomatch.stages.morse.function import MorseFunction


class MorseParams(Params):
    """Parameters of :func:`morse`."""

    function: Literal["fiedler", "mixture", "euclidean", "affine", "height", "geodesic", "agd"] = Field(
        "fiedler", description="the Fiedler vector (thesis ch. 4, the default: intrinsic, and the better thesis "
                               "method on SHREC'07), the mixture distance (ch. 3), its Euclidean or affine part, "
                               "principal-axis height, heat geodesic distance from the centroid, or average "
                               "geodesic distance (Hilaga 2001, intrinsic)")
    centroid: Literal["vertices", "area", "enclosing_sphere"] = Field(
        "vertices", description="centre c of the distance functions: vertex mean, area centroid, or centre of "
                                "the minimal enclosing sphere")
    lam: float | None = Field(None, gt=0, lt=1, description="fixed mixture weight lambda; none = data-dependent")
    euclidean_scale: Literal["mean_squared_radius", "none"] = Field(
        "mean_squared_radius", description="divide the Euclidean term by its mean (scale invariant) or not (literal)")
    mass: Literal["full", "voronoi"] = Field("full", description="Fiedler: FEM mass matrix type")
    sources: int = Field(64, ge=1, description="agd: number of Dijkstra sources")
    sampling: Literal["random", "farthest"] = Field(
        "farthest", description="agd: sources drawn by area (Monte-Carlo mean) or by farthest-point sampling, each "
                              "weighted by its geodesic Voronoi area (Hilaga 2001's base vertices)")


@dataclass(frozen=True, eq=False)
class MorseResult(StageResult):
    function: MorseFunction

    def summary(self) -> dict:
        out = {"kind": self.function.kind}
        out.update({k: v for k, v in self.function.info.items() if np.isscalar(v)})
        return out


def morse_function(mesh: Mesh, params: MorseParams) -> MorseFunction:
    """Compute the function selected by ``params.function`` on ``mesh``."""
    if params.function in ("mixture", "euclidean", "affine"):
        from topomatch.stages.morse.mixture import mixture_distance

        return mixture_distance(mesh.V, mesh.F, kind=params.function, centroid=params.centroid, lam=params.lam,
                                euclidean_scale=params.euclidean_scale)
    if params.function == "height":
        from topomatch.stages.morse.height import principal_height

        return principal_height(mesh.V)
    if params.function == "agd":
        from topomatch.stages.morse.agd import average_geodesic_distance

        return average_geodesic_distance(mesh.V, mesh.F, sources=params.sources, sampling=params.sampling)
    if params.function == "geodesic":
        from topomatch.stages.morse.geodesic import geodesic_from_centroid

        return geodesic_from_centroid(mesh.V, mesh.F, centroid=params.centroid)
    from topomatch.stages.morse.fiedler import fiedler_function

    return fiedler_function(mesh, mass=params.mass)


@stage("morse", params=MorseParams, version=2, consumes=("mesh",), produces=("function",))
def morse(mesh: Mesh, *, params: MorseParams) -> MorseResult:
    """A Morse function on the vertices (mixture distance, Fiedler vector, height, geodesic, AGD)."""
    return MorseResult(morse_function(mesh, params))
