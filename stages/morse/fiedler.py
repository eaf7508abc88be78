"""The Fiedler vector ``phi2`` of the Laplace–Beltrami operator as a Morse function (thesis ch. 4).

``phi2`` is the eigenvector of the second smallest eigenvalue of ``Q phi = lambda K phi``
(:mod:`topomatch.stages.spectral.laplacian`, :mod:`topomatch.stages.spectral.eigen`): K-normalised
(``phi2^T K phi2 = 1``), sign fixed by the eigensolver's sign rule (default: positive
K-weighted skewness). It is invariant under rotations and translations; under a uniform
scale ``s`` it becomes ``phi2 / s`` (and ``lambda -> lambda / s^2``), so its level sets do
not change. This module only wires the stage; the numerical work is in the two modules
above.

The stage consumes the mesh (not a ``laplacian`` state entry), so that a config can say
``- fiedler`` (or ``- morse: {function: fiedler}``) without a ``laplacian`` stage before it;
assembling the Laplacian costs about 10% of the solve.
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from typing import Literal

import numpy as np
from pydantic import Field
from topomatch.pipeline.contract import InputError, Params, StageResult, stage
from topomatch.stages.mesh.mesh import Mesh
from topomatch.stages.morse.function import MorseFunction
from topomatch.stages.spectral.eigen import (
    Eigenpairs,
    relative_gap,
    smallest_eigenpairs,
)
from topomatch.stages.spectral.laplacian import MassType, laplacian


class FiedlerParams(Params):
    """Parameters of :func:`fiedler`."""

    mass: MassType = Field("full", description="mass matrix: 'full' (consistent FEM area matrix, thesis) or "
                                               "'voronoi' (libigl diagonal mixed-Voronoi)")
    method: Literal["auto", "shift_invert", "multilevel", "lobpcg", "dense"] = Field(
        "auto", description="eigensolver: auto (dense for tiny meshes, else shift_invert), shift_invert "
                            "(sparse LDL^T + block Krylov), multilevel (decimate, solve, prolong, LOBPCG+AMG), "
                            "lobpcg (LOBPCG + AMG, no factorisation), dense")
    n_eigenpairs: int = Field(3, ge=2, le=50, description="eigenpairs to compute, the constant phi1 included "
                                                          "(3 gives lambda3 and the gap lambda3 - lambda2)")
    sign_rule: Literal["skewness", "max_abs"] = Field(
        "skewness", description="sign of phi2: positive K-weighted third moment (skewness) or positive "
                                "largest-magnitude entry")
    tol: float = Field(1e-6, ge=1e-10, le=1e-2, allow_inf_nan=False,
                       description="relative residual ||Q x - lambda K x||_{D^-1} / lambda at convergence")


@dataclass(frozen=True, eq=False)
class FiedlerResult(StageResult):
    """The Fiedler vector of a mesh.

    Attributes
    ----------
    function : MorseFunction
        ``values`` = ``phi2`` (n,) float64 (K-normalised, sign-fixed), ``kind='fiedler'``,
        no root; ``info`` holds the scalars of :meth:`summary`.
    eigenpairs : Eigenpairs
        All computed pairs (``values`` (k,), ``vectors`` (n, k), method, residuals, ...).
    seconds : float
        Wall time of Laplacian assembly and eigensolve.
    """

    function: MorseFunction
    eigenpairs: Eigenpairs
    seconds: float

    @property
    def values(self) -> np.ndarray:
        """``phi2`` on the vertices, (n,) float64."""
        return self.function.values

    @property
    def eigenvalues(self) -> np.ndarray:
        """The computed eigenvalues, ascending, (k,) float64 (``eigenvalues[0] = 0``)."""
        return self.eigenpairs.values

    def summary(self) -> dict:
        return dict(self.function.info)


def fiedler_result(mesh: Mesh, *, mass: MassType = "full", method: str = "auto", n_eigenpairs: int = 3,
                   sign_rule: str = "skewness", tol: float = 1e-6) -> FiedlerResult:
    """Laplacian of ``mesh``, its smallest eigenpairs, and ``phi2`` as a :class:`MorseFunction`.

    Parameters are those of :class:`FiedlerParams`.

    Raises
    ------
    InputError
        The mesh cannot carry a Laplacian (empty, degenerate, several components, ...).
    StageError
        No eigensolver converged.
    """
    start = time.perf_counter()
    if mesh.n_vertices <= n_eigenpairs:
        raise InputError(mesh.name, f"the mesh has {mesh.n_vertices} vertices and {mesh.n_faces} faces: too few for "
                                    f"{n_eigenpairs} Laplace-Beltrami eigenpairs (a closed surface has at least 4 "
                                    f"vertices)")
    lap = laplacian(mesh, mass)
    pairs = smallest_eigenpairs(lap.Q, lap.K, n_eigenpairs, method=method, tol=tol, V=mesh.V, F=mesh.F,
                                sign_rule=sign_rule)
    seconds = time.perf_counter() - start
    info = {
        "lambda2": float(pairs.values[1]),
        "lambda3": float(pairs.values[2]) if pairs.k > 2 else float("nan"),
        "lambda2_area": float(pairs.values[1] * lap.area),
        "gap23": relative_gap(pairs.values) if pairs.k > 2 else float("nan"),
        "skewness2": float(pairs.skewness[1]),
        "residual": float(pairs.residuals.max()),
        "method": pairs.method,
        "fallbacks": len(pairs.attempts),
        "n_solves": pairs.n_solves,
        "mass": mass,
        "seconds": seconds,
    }
    function = MorseFunction(pairs.fiedler.copy(), "fiedler", root=None, info=info)
    return FiedlerResult(function=function, eigenpairs=pairs, seconds=seconds)


def fiedler_function(mesh: Mesh, *, mass: MassType = "full", method: str = "auto", n_eigenpairs: int = 3,
                     sign_rule: str = "skewness", tol: float = 1e-6) -> MorseFunction:
    """``phi2`` of ``mesh`` as a :class:`MorseFunction` (used by the ``morse`` stage); see :func:`fiedler_result`."""
    return fiedler_result(mesh, mass=mass, method=method, n_eigenpairs=n_eigenpairs, sign_rule=sign_rule,
                          tol=tol).function


@stage("fiedler", params=FiedlerParams, version=1, consumes=("mesh",), produces=("function",))
def fiedler(mesh: Mesh, *, params: FiedlerParams) -> FiedlerResult:
    """Fiedler vector phi2 of the FEM Laplace-Beltrami operator, as a Morse function."""
    return fiedler_result(mesh, mass=params.mass, method=params.method, n_eigenpairs=params.n_eigenpairs,
                          sign_rule=params.sign_rule, tol=params.tol)
