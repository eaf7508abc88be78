"""The leading Laplace-Beltrami eigenpairs of a mesh, kept for signatures (``spectrum`` stage).

``Q phi = lambda K phi`` with the cotangent stiffness ``Q = -igl.cotmatrix`` and the mass ``K``
(:func:`topomatch.stages.spectral.laplacian.laplacian`), the ``k + 1`` smallest eigenpairs (the constant
``phi_0``, ``lambda_0 = 0`` included), K-orthonormal, by
:func:`~topomatch.stages.spectral.eigen.smallest_eigenpairs` with the ``arpack`` method: ARPACK
(``eigsh``) in shift-invert mode around a slightly negative shift (1 % of the Weyl spacing
``4 pi / A``), ``Q - sigma K`` factorised once by qdldl (LDL^T: faster solves than the LL^T the
Fiedler solver prefers, which matters for ARPACK's ~100 solves). The Fiedler stage uses the block
solver tuned for 2-3 eigenpairs; for tens of eigenpairs ARPACK is the better tool. As every
result of ``smallest_eigenpairs``: ``values[0] = 0`` and ``vectors[:, 0]`` the exact constant.

Reference: M. Reuter, F.-E. Wolter, N. Peinecke, "Laplace-Beltrami spectra as 'Shape-DNA' of
surfaces and solids", CAD 38(4), 2006 (the discretisation and the shift).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

import numpy as np
from pydantic import Field

from topomatch.pipeline.contract import Params, StageError, StageResult, stage
from topomatch.stages.mesh.mesh import Mesh

@dataclass(frozen=True, eq=False)
class Spectrum:
    """Leading eigenpairs of one connected mesh.

    Attributes
    ----------
    values : (k + 1,) float64
        Ascending, ``values[0]`` ~ 0.
    vectors : (n, k + 1) float64
        K-orthonormal eigenvectors.
    mass : (n,) float64
        Lumped vertex areas (row sums of K); they sum to ``area``.
    area : float
    """

    values: np.ndarray
    vectors: np.ndarray
    mass: np.ndarray
    area: float


def mesh_spectrum(mesh: Mesh, k: int, mass: Literal["full", "voronoi"] = "voronoi") -> Spectrum:
    """The ``k + 1`` smallest eigenpairs of a connected mesh (see the module docstring).

    Raises
    ------
    InputError
        Mesh rejected by the Laplacian (degenerate, several components: run ``clean`` first).
    StageError
        Fewer than ``k + 1`` vertices, or ARPACK failed.
    """
    from topomatch.stages.spectral.laplacian import laplacian

    from topomatch.stages.spectral.eigen import smallest_eigenpairs

    lap = laplacian(mesh, mass)
    if lap.n < k + 2:
        raise StageError(f"{mesh.name}: spectrum needs k + 1 = {k + 1} eigenpairs but the mesh has {lap.n} "
                         "vertices: too small for the spectral descriptors (in a config: lower spectrum.k)")
    try:
        pairs = smallest_eigenpairs(lap.Q, lap.K, k + 1, method="arpack")
    except StageError as exc:
        raise StageError(f"{mesh.name}: {k + 1} eigenpairs of a {lap.n}-vertex mesh: {exc}") from None
    return Spectrum(pairs.values, pairs.vectors, np.asarray(lap.K.sum(axis=1)).ravel(), float(lap.area))


class SpectrumParams(Params):
    """Parameters of the ``spectrum`` stage."""

    k: int = Field(60, ge=1, le=500, description="number of non-constant eigenpairs")
    mass: Literal["full", "voronoi"] = Field("voronoi", description="mass matrix: libigl's lumped mixed-Voronoi "
                                                                    "or the consistent FEM ('full')")


@dataclass(frozen=True, eq=False)
class SpectrumResult(StageResult):
    spectrum: Spectrum

    def summary(self) -> dict:
        s = self.spectrum
        return {"k": len(s.values) - 1, "lambda1_area": float(s.values[1] * s.area),
                "lambdak_area": float(s.values[-1] * s.area)}


@stage("spectrum", params=SpectrumParams, version=2, consumes=("mesh",), produces=("spectrum",))
def spectrum_stage(mesh: Mesh, *, params: SpectrumParams) -> SpectrumResult:
    """Leading Laplace-Beltrami eigenpairs (for heat-kernel signatures)."""
    return SpectrumResult(mesh_spectrum(mesh, params.k, params.mass))
