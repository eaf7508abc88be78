"""ShapeDNA: the normalised beginning of the Laplace-Beltrami spectrum (Reuter, Wolter, Peinecke 2006).

M. Reuter, F.-E. Wolter, N. Peinecke, "Laplace-Beltrami spectra as 'Shape-DNA' of surfaces and
solids", Computer-Aided Design 38(4), 2006. The spectrum is an isometry invariant: it does
not change under rotations, translations, and bendings that preserve lengths.

Definition used here
--------------------
1. **Operator.** The linear FEM discretisation ``Q phi = lambda K phi`` with the cotangent
   stiffness ``Q = -igl.cotmatrix`` (PSD) and the mass ``K``: the consistent FEM mass matrix
   (``mass='full'``, ``igl.massmatrix(..., FULL)``, default; Reuter et al. use FEM mass
   matrices, of cubic elements) or libigl's lumped Voronoi mass (``mass='voronoi'``). The
   matrices come from :func:`topomatch.stages.spectral.laplacian.laplacian`, which validates the mesh
   (degenerate triangles, unreferenced vertices -> :class:`~topomatch.pipeline.errors.InputError` that
   names the ``clean`` fix). Linear elements with the full mass over-estimate the eigenvalues
   by O(h^2) (0.02 % for ``l = 1``, 0.7 % for ``l = 4`` on a 2,562-vertex icosphere).
2. **Eigenvalues.** The ``k`` [30] smallest **non-zero** eigenvalues. Each connected component
   contributes one zero eigenvalue and its own spectrum; the components are solved separately
   (see :func:`eigenvalues` for why) and merged. On each, the ``k + 1`` smallest are computed by
   ``scipy.sparse.linalg.eigsh`` (ARPACK, ``tol = 1e-10``) in shift-invert mode around
   ``sigma = -0.01 * 4 pi / A`` (slightly negative, so ``Q - sigma K`` is positive definite;
   ``4 pi / A`` is the Weyl-law spacing of the spectrum of a surface of area ``A``, so the
   shift scales with the shape), with a fixed start vector (deterministic), and the zero is
   dropped; components of at most 400 vertices are solved densely. This is the ``arpack`` method
   of :func:`~topomatch.stages.spectral.eigen.smallest_eigenpairs` (``Q - sigma K`` factorised once
   by qdldl's sparse LDL^T, ~1.7x faster than eigsh's own SuperLU).
3. **Scale normalisation** (``normalization``): ``'area_index'`` [default] multiplies by the
   surface area and divides by the index, ``lambda_i * A / i`` (i = 1..k); ``'area'`` only
   multiplies by the area, ``lambda_i * A`` (Reuter et al.'s area normalisation; eigenvalues
   scale as ``1 / length^2``); ``'none'`` keeps the raw eigenvalues (not scale invariant). By
   Weyl's law ``lambda_i ~ 4 pi i / A``, so ``'area_index'`` flattens the sequence towards
   ``4 pi`` and gives every eigenvalue a similar weight in the distance, whereas with
   ``'area'`` the largest eigenvalues (growing like ``4 pi i``) dominate it. The default was
   chosen by measurement: on SHREC'07 Watertight (``benchmarks/baselines.py --watertight
   --variants``, k = 30) ``'area_index'`` gives NN 0.850 / mAP 0.561 against 0.750 / 0.435 for
   ``'area'``.
4. **Distance: L2** (Euclidean) of the normalised sequences.

Analytic check: the unit sphere has ``lambda = l (l + 1)`` with multiplicity ``2 l + 1``, so
``lambda * A = 4 pi l (l + 1)``: 3 x 8 pi, 5 x 24 pi, 7 x 48 pi, ... (tested on an icosphere).

Cost: one sparse factorisation plus ARPACK, about 0.1 s for ``k = 30`` on 8k vertices
(``benchmarks/baselines.py``).
"""

from __future__ import annotations

from typing import Literal

import numpy as np
from pydantic import Field

from topomatch.pipeline.contract import Params, StageError, stage
from topomatch.stages.mesh.mesh import Mesh
from topomatch.stages.retrieval.baselines.vectors import l2, pairwise
from topomatch.stages.retrieval.descriptor import Descriptor, DescriptorResult

Normalization = Literal["area", "area_index", "none"]


class ShapeDNAParams(Params):
    """Parameters of ShapeDNA (:func:`descriptor`)."""

    k: int = Field(30, ge=1, le=1000, description="number of non-zero Laplace-Beltrami eigenvalues kept")
    mass: Literal["full", "voronoi"] = Field("full", description="mass matrix: consistent FEM ('full') or "
                                                                 "libigl's lumped mixed-Voronoi ('voronoi')")
    normalization: Normalization = Field("area_index", description="'area_index': lambda_i * A / i (Weyl-flattened, "
                                                                   "retrieves best); 'area': lambda_i * A; "
                                                                   "'none': raw eigenvalues")


def _component_nonzero_eigenvalues(Q, K, want: int, sigma: float, name: str) -> np.ndarray:
    """The ``want`` smallest eigenvalues of one connected component, its zero dropped (ascending).

    Fewer are returned when the component has fewer than ``want + 1`` vertices (all of them, densely).
    """
    from topomatch.stages.spectral.eigen import smallest_eigenpairs

    n = Q.shape[0]
    if n < 2:
        return np.zeros(0)
    k = min(want + 1, n)
    try:
        pairs = smallest_eigenpairs(Q, K, k, method="arpack", sigma=sigma)
    except StageError as exc:
        raise StageError(f"{name}: {k} eigenvalues of a {n}-vertex component: {exc}") from None
    return pairs.values[1:]


def eigenvalues(mesh: Mesh, k: int, mass: Literal["full", "voronoi"] = "full") -> tuple[np.ndarray, float]:
    """The ``k`` smallest non-zero eigenvalues of ``Q phi = lambda K phi`` and the surface area.

    The spectrum of a mesh with several connected components is the union of the spectra
    of the components, each with its own zero. Each component is therefore solved on its
    own (its ``k + 1`` smallest, the zero dropped) and the results are merged: one ARPACK
    run on the whole matrix would find only one vector of an eigenvalue shared exactly by
    several components (a Krylov space holds one direction per eigenspace; e.g. it misses
    one of the six copies of ``lambda_1`` of two identical spheres). Components of at most
    400 vertices are solved densely. Within one connected component ARPACK
    recovers exactly repeated eigenvalues (symmetric shapes) through round-off; the
    unit-sphere test (exact 3- and 5-fold multiplicities on the icosphere) checks that.

    Parameters
    ----------
    mesh : Mesh
        ``V`` (n, 3) float64, ``F`` (m, 3) int64; no degenerate triangles or unreferenced
        vertices (run ``clean`` first); several components are allowed.
    k : int
        Number of non-zero eigenvalues; the mesh needs ``n - components >= k``.
    mass : {'full', 'voronoi'}
        Mass matrix.

    Returns
    -------
    values : (k,) float64
        Ascending.
    area : float
        Surface area ``1^T K 1``.

    Raises
    ------
    InputError
        Mesh rejected by :func:`topomatch.stages.spectral.laplacian.laplacian` (names the mesh).
    StageError
        Fewer than ``k`` non-zero eigenvalues exist (too few vertices), or ARPACK failed.
    """
    import scipy.sparse as sp
    from scipy.sparse.csgraph import connected_components

    from topomatch.stages.spectral.laplacian import laplacian

    lap = laplacian(mesh, mass, require_connected=False)
    n = lap.n
    count, comp = connected_components(lap.Q, directed=False)
    if n - count < k:
        raise StageError(f"{mesh.name}: ShapeDNA needs k = {k} non-zero eigenvalues but the mesh has only "
                         f"{n - count} ({n} vertices, {count} components); lower shapedna.k")
    sigma = -0.01 * 4.0 * np.pi / lap.area
    if count == 1:
        vals = _component_nonzero_eigenvalues(lap.Q, lap.K, k, sigma, mesh.name)
    else:
        parts = []
        Q, K = sp.csr_matrix(lap.Q), sp.csr_matrix(lap.K)
        for c in range(count):
            idx = np.flatnonzero(comp == c)
            parts.append(_component_nonzero_eigenvalues(Q[idx][:, idx], K[idx][:, idx], k, sigma, mesh.name))
        vals = np.sort(np.concatenate(parts))
    return vals[:k].astype(np.float64), float(lap.area)


def normalize(values: np.ndarray, area: float, normalization: Normalization = "area_index") -> np.ndarray:
    """Scale-normalise eigenvalues (k,): ``lambda_i A``, ``lambda_i A / i`` (i = 1..k) or unchanged."""
    values = np.asarray(values, dtype=np.float64)
    if normalization == "area":
        return values * area
    if normalization == "area_index":
        return values * area / np.arange(1, values.shape[0] + 1)
    if normalization == "none":
        return values.copy()
    raise ValueError(f"normalization must be 'area', 'area_index' or 'none', got {normalization!r}")


def descriptor(mesh: Mesh, params: ShapeDNAParams | None = None) -> np.ndarray:
    """ShapeDNA of ``mesh``: the normalised ``k`` smallest non-zero eigenvalues, (k,) float64, ascending.

    Parameters
    ----------
    mesh : Mesh
        ``V`` (n, 3) float64, ``F`` (m, 3) int64 (see :func:`eigenvalues` for the requirements).
    params : ShapeDNAParams, optional
        Defaults: k = 30, full FEM mass, ``lambda_i * A / i``.

    Raises
    ------
    InputError, StageError
        See :func:`eigenvalues`.
    """
    params = ShapeDNAParams() if params is None else params
    values, area = eigenvalues(mesh, params.k, params.mass)
    return normalize(values, area, params.normalization)


def distance(a: np.ndarray, b: np.ndarray) -> float:
    """L2 (Euclidean) distance of two ShapeDNA sequences of the same length."""
    return l2(a, b, "ShapeDNA")


def distance_matrix(X: np.ndarray, Y: np.ndarray | None = None) -> np.ndarray:
    """All pairwise L2 distances: ``X`` (n, k), ``Y`` (m, k) (default ``X``) -> (n, m) float64."""
    return pairwise(X, Y, metric="euclidean")


@stage("shapedna", params=ShapeDNAParams, version=3, consumes=("mesh",), produces=("descriptor",))
def shapedna_stage(mesh: Mesh, *, params: ShapeDNAParams) -> DescriptorResult:
    """ShapeDNA (Reuter et al. 2006): normalised leading Laplace-Beltrami eigenvalues."""
    return DescriptorResult(Descriptor("vector", descriptor(mesh, params)))


class SpectrumShapeDNAParams(Params):
    """Parameters of ShapeDNA read from a computed spectrum (:func:`from_spectrum`)."""

    k: int = Field(30, ge=1, le=500, description="number of non-zero eigenvalues kept (the spectrum needs at least k)")
    normalization: Normalization = Field("area_index", description="as ShapeDNAParams.normalization")


def from_spectrum(spectrum, k: int = 30, normalization: Normalization = "area_index") -> np.ndarray:
    """ShapeDNA (k,) from a :class:`~topomatch.stages.spectral.spectrum.Spectrum` of a connected mesh:
    its eigenvalues 1..k (index 0 is the zero of the constant vector), normalised like :func:`descriptor`.

    No eigen-solve of its own: the intrinsic retrieval methods already compute this spectrum (on the
    decimated copy, with the lumped mass), so the fusion gets ShapeDNA for free."""
    values = np.asarray(spectrum.values, dtype=np.float64)
    if values.shape[0] < k + 1:
        raise StageError(f"ShapeDNA of a spectrum needs k + 1 = {k + 1} eigenvalues, the spectrum has "
                         f"{values.shape[0]}; raise spectrum.k")
    return normalize(values[1:k + 1], spectrum.area, normalization)


@stage("shapedna_of_spectrum", params=SpectrumShapeDNAParams, version=1, consumes=("spectrum",),
       produces=("descriptor",))
def shapedna_of_spectrum_stage(spectrum, *, params: SpectrumShapeDNAParams) -> DescriptorResult:
    """ShapeDNA read from the shared spectrum (no eigen-solve of its own)."""
    return DescriptorResult(Descriptor("vector", from_spectrum(spectrum, params.k, params.normalization)))
