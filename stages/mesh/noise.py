"""Gaussian vertex noise, the perturbation model of the thesis' robustness experiments.

Every coordinate of every vertex moves independently::

    p' = p + sigma * N(0, 1)

with ``sigma`` given in units of the mean edge length, of the bounding-box
diagonal, or absolute. The connectivity is unchanged. The generator is
``numpy.random.default_rng(seed)``, so a seed gives the same mesh on every run
and machine (for the same numpy bit generator, PCG64).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

import numpy as np
from pydantic import Field

from topomatch.pipeline.contract import Params, StageResult, stage
from topomatch.stages.mesh.measures import bbox_diagonal, mean_edge_length
from topomatch.stages.mesh.mesh import Mesh


class NoiseParams(Params):
    """Parameters of :func:`noise`."""

    sigma: float = Field(0.0, ge=0, allow_inf_nan=False,
                         description="standard deviation of the displacement per coordinate, in units of relative_to")
    relative_to: Literal["mean_edge", "bbox_diagonal", "absolute"] = Field(
        "bbox_diagonal", description="unit of sigma: mean edge length, bounding-box diagonal, or absolute")
    seed: int = Field(0, ge=0, description="seed of numpy.random.default_rng")

    def axis_label(self, name: str) -> str | None:
        if name == "sigma":
            unit = {"mean_edge": "× mean edge length", "bbox_diagonal": "× bounding-box diagonal",
                    "absolute": "mesh units"}[self.relative_to]
            return f"vertex noise σ ({unit})"
        return super().axis_label(name)


@dataclass(frozen=True, eq=False)
class NoiseResult(StageResult):
    """A perturbed mesh.

    Attributes
    ----------
    mesh : Mesh
        Same faces and name, perturbed vertices.
    sigma_absolute : float
        The standard deviation per coordinate in the mesh's units.
    rms_displacement : float
        ``sqrt(mean |p' - p|^2)`` over the vertices; about ``sqrt(3) * sigma_absolute``.
    """

    mesh: Mesh
    sigma_absolute: float
    rms_displacement: float

    def summary(self) -> dict:
        return {"sigma_absolute": self.sigma_absolute, "rms_displacement": self.rms_displacement}


def noise_scale(mesh: Mesh, relative_to: str) -> float:
    """The length that ``sigma`` is measured in: mean edge length, bbox diagonal or 1."""
    if relative_to == "mean_edge":
        return mean_edge_length(mesh)
    if relative_to == "bbox_diagonal":
        return bbox_diagonal(mesh.V)
    if relative_to == "absolute":
        return 1.0
    raise ValueError(f"relative_to must be 'mean_edge', 'bbox_diagonal' or 'absolute', got {relative_to!r}")


@stage("noise", params=NoiseParams, version=1, consumes=("mesh",), produces=("mesh",))
def noise(mesh: Mesh, *, params: NoiseParams) -> NoiseResult:
    """Add Gaussian noise to every vertex coordinate (p' = p + sigma N(0, 1))."""
    sigma = params.sigma * noise_scale(mesh, params.relative_to)
    rng = np.random.default_rng(params.seed)
    D = sigma * rng.standard_normal(mesh.V.shape)
    rms = float(np.sqrt(np.mean(np.sum(D * D, axis=1)))) if D.size else 0.0
    return NoiseResult(mesh=mesh.with_vertices(mesh.V + D), sigma_absolute=float(sigma), rms_displacement=rms)
