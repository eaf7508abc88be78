"""Similarity transform of a mesh: rotation about an axis, uniform scale, translation.

    p' = s R (p - c) + c + t

``R`` rotates by ``angle_deg`` degrees about the unit vector along ``axis``
(right-hand rule; Rodrigues' formula via ``scipy.spatial.transform.Rotation``),
``s`` is the uniform scale, ``t`` the translation and ``c`` the centre about which
rotation and scale act: the origin or the vertex centroid (mean of the vertex
positions, computed on the input). The result carries the equivalent 4x4
homogeneous matrix, so ``[p', 1] = M [p, 1]``.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Annotated, Literal

import numpy as np
from pydantic import Field, model_validator

from topomatch.pipeline.contract import Params, StageResult, stage
from topomatch.stages.mesh.mesh import Mesh

FiniteFloat = Annotated[float, Field(allow_inf_nan=False)]


class TransformParams(Params):
    """Parameters of :func:`transform`."""

    axis: tuple[FiniteFloat, FiniteFloat, FiniteFloat] = Field(
        (0.0, 0.0, 1.0), description="rotation axis (any non-zero length; normalised)")
    angle_deg: FiniteFloat = Field(0.0, title="rotation angle (degrees)", description="rotation angle in degrees (right-hand rule about axis)")
    scale: float = Field(1.0, gt=0, allow_inf_nan=False, description="uniform scale factor s > 0")
    translation: tuple[FiniteFloat, FiniteFloat, FiniteFloat] = Field(
        (0.0, 0.0, 0.0), description="translation t added after rotation and scale")
    center: Literal["origin", "centroid"] = Field(
        "origin", description="centre c of rotation and scale: the origin or the mean of the vertices")

    @model_validator(mode="after")
    def _axis_nonzero(self) -> "TransformParams":
        if not np.linalg.norm(self.axis) > 0:
            raise ValueError("axis must be a non-zero vector")
        return self


@dataclass(frozen=True, eq=False)
class TransformResult(StageResult):
    """A transformed mesh.

    Attributes
    ----------
    mesh : Mesh
        Same faces and name, transformed vertices.
    matrix : (4, 4) float64
        Homogeneous matrix with ``[p', 1] = matrix @ [p, 1]``.
    """

    mesh: Mesh
    matrix: np.ndarray

    def summary(self) -> dict:
        return {"det": float(np.linalg.det(self.matrix[:3, :3])),
                "translation_norm": float(np.linalg.norm(self.matrix[:3, 3]))}


def similarity_matrix(axis, angle_deg: float, scale: float, translation, center) -> np.ndarray:
    """The 4x4 matrix of ``p -> s R (p - c) + c + t``.

    Parameters
    ----------
    axis : (3,) float
        Rotation axis, non-zero.
    angle_deg : float
        Rotation angle in degrees.
    scale : float
        Uniform scale ``s``.
    translation, center : (3,) float
        ``t`` and ``c``.

    Returns
    -------
    (4, 4) float64
    """
    from scipy.spatial.transform import Rotation

    axis = np.asarray(axis, dtype=np.float64)
    R = Rotation.from_rotvec(np.deg2rad(angle_deg) * axis / np.linalg.norm(axis)).as_matrix()
    c = np.asarray(center, dtype=np.float64)
    M = np.eye(4)
    M[:3, :3] = scale * R
    M[:3, 3] = c + np.asarray(translation, dtype=np.float64) - scale * R @ c
    return M


@stage("transform", params=TransformParams, version=1, consumes=("mesh",), produces=("mesh",))
def transform(mesh: Mesh, *, params: TransformParams) -> TransformResult:
    """Rotate about an axis, scale uniformly and translate (p' = s R (p - c) + c + t)."""
    c = mesh.V.mean(axis=0) if params.center == "centroid" and mesh.n_vertices else np.zeros(3)
    M = similarity_matrix(params.axis, params.angle_deg, params.scale, params.translation, c)
    V = mesh.V @ M[:3, :3].T + M[:3, 3]
    return TransformResult(mesh=mesh.with_vertices(V), matrix=M)
