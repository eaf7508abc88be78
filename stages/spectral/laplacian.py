"""The FEM Laplace–Beltrami operator of a triangle mesh: cotangent stiffness ``Q`` and mass ``K``.

Conventions (thesis ch. 4, written once here):

- ``Q`` is the cotangent *stiffness* matrix, positive semidefinite:
  ``Q_ij = -1/2 (cot alpha_ij + cot beta_ij)`` for an edge ij (the angles opposite it),
  ``Q_ii = -sum_{j != i} Q_ij``. It equals ``-igl.cotmatrix(V, F)`` (libigl's matrix is
  negative semidefinite); rows sum to zero, so constants are in its kernel.
- ``K`` is the mass matrix. ``mass="full"`` (default) is the consistent P1 FEM mass
  matrix, the thesis's "area matrix": ``K_ij = (1/12) sum of the areas of the triangles at
  edge ij``, ``K_ii = (1/6) sum of the areas of the triangles at i``, i.e.
  ``igl.massmatrix(V, F, igl.MASSMATRIX_TYPE_FULL)``. ``mass="voronoi"`` is libigl's
  diagonal mixed-Voronoi lumped mass (``MASSMATRIX_TYPE_VORONOI``). Both sum to the
  surface area: ``1^T K 1 = area``.
- The eigenproblem is ``Q phi = lambda K phi`` (see :mod:`topomatch.stages.spectral.eigen`).

Assembly. ``Q`` and the full ``K`` are assembled here with vectorised numpy (same
formulas as libigl: squared edge lengths, Kahan's stable Heron formula for the double
area, ``cot = (l_a^2 + l_b^2 - l_c^2) / (4 A)``) into one shared CSR sparsity pattern; on
the 48k-vertex horse this takes about 30 ms against about 90 ms for ``igl.cotmatrix`` +
``igl.massmatrix``, and matches them to ~1e-13 relative (tested). The Voronoi mass
comes from ``igl.massmatrix``.

Validation (:func:`check_mesh`), before anything is solved, with an
:class:`~topomatch.pipeline.errors.InputError` naming the mesh:

- no vertices or no faces; non-finite coordinates; face indices out of range;
- vertices used by no face (their row of ``K`` is zero, so ``K`` is singular);
- degenerate triangles (repeated index or zero area): infinite cotangents, and a
  singular ``K`` at vertices with only such triangles;
- several connected components (when ``require_connected``): the eigenvalue 0 then has
  one eigenvector per component, so ``lambda2 = 0`` and the "Fiedler vector" is just an
  arbitrary mix of component indicators, meaningless as a Morse function. Keep the
  largest component with ``clean: {components: largest}`` first.

Each of these problems is repaired by the ``clean`` stage, which the messages name.
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from typing import Literal

import numpy as np
import scipy.sparse as sp
from pydantic import Field

from topomatch.pipeline.contract import InputError, Params, StageResult, stage
from topomatch.stages.mesh.geometry import double_areas_and_sq_lengths
from topomatch.stages.mesh.mesh import Mesh

MassType = Literal["full", "voronoi"]


@dataclass(frozen=True, eq=False)
class Laplacian:
    """The FEM Laplace–Beltrami pair of a mesh.

    Attributes
    ----------
    Q : (n, n) scipy.sparse.csr_matrix, float64
        Cotangent stiffness matrix, symmetric positive semidefinite, ``-igl.cotmatrix(V, F)``.
    K : (n, n) scipy.sparse.csr_matrix, float64
        Mass matrix, symmetric positive definite (``mass`` says which one).
    mass : {'full', 'voronoi'}
        Consistent FEM mass matrix or libigl's diagonal mixed-Voronoi mass.
    area : float
        Surface area, ``1^T K 1``.
    """

    Q: sp.csr_matrix
    K: sp.csr_matrix
    mass: str
    area: float

    @property
    def n(self) -> int:
        """Number of vertices."""
        return int(self.Q.shape[0])

    def lumped_mass(self) -> np.ndarray:
        """Row sums of ``K``, (n,) float64 (the lumped, barycentric vertex areas for ``mass='full'``)."""
        return np.asarray(self.K.sum(axis=1)).ravel()




def cotangent_and_full_mass(V: np.ndarray, F: np.ndarray) -> tuple[sp.csr_matrix, sp.csr_matrix]:
    """Vectorised assembly of ``Q = -igl.cotmatrix(V, F)`` and ``K = igl.massmatrix(V, F, FULL)``.

    Parameters
    ----------
    V : (n, 3) float64
        Vertex positions.
    F : (m, 3) int64
        Triangles; every triangle must have a positive area (see :func:`check_mesh`).

    Returns
    -------
    Q, K : (n, n) scipy.sparse.csr_matrix
        Stiffness and consistent mass matrix, with the same sparsity pattern (the
        vertex adjacency plus the diagonal), sorted indices, no duplicates.
    """
    V = np.asarray(V, dtype=np.float64)
    F = np.asarray(F, dtype=np.int64)
    return _assemble(V.shape[0], F, *double_areas_and_sq_lengths(V, F))


def _assemble(n: int, F: np.ndarray, s: np.ndarray, dbl: np.ndarray) -> tuple[sp.csr_matrix, sp.csr_matrix]:
    """:func:`cotangent_and_full_mass` from squared edge lengths ``s`` (m, 3) and double areas ``dbl`` (m,)."""
    with np.errstate(divide="ignore", invalid="ignore"):
        # half the cotangent of the angle at corner k: (s_a + s_b - s_k) / (4 * double area)
        C = (s[:, [1, 2, 0]] + s[:, [2, 0, 1]] - s) / (4.0 * dbl[:, None])
    C0, C1, C2 = C[:, 0], C[:, 1], C[:, 2]
    m = F.shape[0]
    idx = np.int32 if n < 2**31 - 1 else np.int64
    Fi = F.astype(idx)
    i0, i1, i2 = Fi[:, 0], Fi[:, 1], Fi[:, 2]
    # COO entries: 6 per triangle (its three edges, both directions), then the diagonal
    rows = np.empty(6 * m + n, dtype=idx)
    cols = np.empty(6 * m + n, dtype=idx)
    rows[:6 * m].reshape(6, m)[:] = (i1, i2, i2, i0, i0, i1)
    cols[:6 * m].reshape(6, m)[:] = (i2, i1, i0, i2, i1, i0)
    rows[6 * m:] = cols[6 * m:] = np.arange(n, dtype=idx)
    # One COO -> CSR conversion (duplicates summed) for both matrices: Q in the real part,
    # K in the imaginary part of a complex matrix, so they share one sorted pattern.
    data = np.empty(6 * m + n, dtype=np.complex128)
    off = data[:6 * m].reshape(6, m)
    off.real[:] = (-C0, -C0, -C1, -C1, -C2, -C2)
    off.imag[:] = dbl / 24.0
    data.real[6 * m:] = np.bincount(Fi.ravel(), (C[:, [1, 2, 0]] + C[:, [2, 0, 1]]).ravel(), n)
    data.imag[6 * m:] = np.bincount(Fi.ravel(), np.repeat(dbl, 3), n) / 12.0
    Z = sp.coo_matrix((data, (rows, cols)), shape=(n, n)).tocsr()
    Z.sum_duplicates()
    Q = sp.csr_matrix((np.ascontiguousarray(Z.data.real), Z.indices, Z.indptr), shape=(n, n))
    K = sp.csr_matrix((np.ascontiguousarray(Z.data.imag), Z.indices.copy(), Z.indptr.copy()), shape=(n, n))
    return Q, K


def _components(Q: sp.csr_matrix) -> tuple[int, np.ndarray]:
    """Connected components of the vertex graph given by the pattern of ``Q`` (count, labels)."""
    from scipy.sparse.csgraph import connected_components

    return connected_components(Q, directed=False)


def check_mesh(mesh: Mesh) -> None:
    """Reject meshes on which the Laplacian is undefined or singular (before any assembly).

    Raises
    ------
    InputError
        Naming ``mesh.name``: empty mesh, non-finite coordinates, face indices out of
        range, vertices used by no face, degenerate (repeated-index) triangles. Zero-area
        triangles with distinct indices and several components are detected during
        assembly (:func:`laplacian`).
    """
    n, m = mesh.n_vertices, mesh.n_faces
    if n == 0 or m == 0:
        raise InputError(mesh.name, f"empty mesh ({n} vertices, {m} faces): the Laplacian needs triangles")
    if not np.isfinite(mesh.V).all():
        bad = int((~np.isfinite(mesh.V)).any(axis=1).sum())
        raise InputError(mesh.name, f"{bad} vertices have non-finite coordinates (NaN or inf)")
    F = mesh.F
    lo, hi = int(F.min()), int(F.max())
    if lo < 0 or hi >= n:
        raise InputError(mesh.name, f"face indices must be in [0, {n - 1}], got range [{lo}, {hi}]")
    repeated = (F[:, 0] == F[:, 1]) | (F[:, 1] == F[:, 2]) | (F[:, 2] == F[:, 0])
    if repeated.any():
        raise InputError(mesh.name, f"{int(repeated.sum())} degenerate triangles (a repeated vertex index): "
                                    "their cotangents are undefined; run `clean` (drop_degenerate: true) first")
    used = np.zeros(n, dtype=bool)
    used[F.ravel()] = True
    if not used.all():
        raise InputError(mesh.name, f"{int(n - used.sum())} vertices are used by no face, which makes the mass "
                                    "matrix singular; run `clean` first (it drops unreferenced vertices)")


def laplacian(mesh: Mesh, mass: MassType = "full", *, require_connected: bool = True) -> Laplacian:
    """Assemble the cotangent stiffness ``Q`` and the mass matrix ``K`` of ``mesh``.

    Parameters
    ----------
    mesh : Mesh
        ``V`` (n, 3) float64, ``F`` (m, 3) int64; see :func:`check_mesh` for what is rejected.
    mass : {'full', 'voronoi'}
        ``'full'``: consistent FEM mass matrix (thesis "area matrix", libigl
        ``MASSMATRIX_TYPE_FULL``); ``'voronoi'``: libigl's diagonal mixed-Voronoi mass.
    require_connected : bool
        Raise if the mesh has several connected components (the default: the Fiedler
        vector of a disconnected mesh is meaningless).

    Returns
    -------
    Laplacian
        ``Q`` (n, n) PSD and ``K`` (n, n) SPD, CSR, float64.

    Raises
    ------
    InputError
        Empty or degenerate mesh, zero-area triangles, unreferenced vertices, several
        components (with ``require_connected``); the message names the mesh and the fix.
    """
    if mass not in ("full", "voronoi"):
        raise ValueError(f"mass must be 'full' or 'voronoi', got {mass!r}")
    check_mesh(mesh)
    V, F = mesh.V, mesh.F
    sq, dbl = double_areas_and_sq_lengths(V, F)
    zero = ~(dbl > 0)
    if zero.any():
        raise InputError(mesh.name, f"{int(zero.sum())} triangles have zero area (collinear vertices): infinite "
                                    "cotangent weights and a possibly singular mass matrix; run `clean` "
                                    "(drop_degenerate: true) first")
    Q, K = _assemble(mesh.n_vertices, F, sq, dbl)
    if not (np.isfinite(Q.data).all() and np.isfinite(K.data).all()):
        raise InputError(mesh.name, "the cotangent or mass matrix has non-finite entries (nearly degenerate "
                                    "triangles); run `clean` first")
    if require_connected:
        count, labels = _components(Q)
        if count > 1:
            sizes = np.sort(np.bincount(labels))[::-1]
            shown = ", ".join(str(int(s)) for s in sizes[:5]) + (", ..." if count > 5 else "")
            raise InputError(mesh.name, f"mesh has {count} connected components (vertices: {shown}); the "
                                        "Laplacian then has eigenvalue 0 once per component, so lambda2 = 0 and "
                                        "the Fiedler vector is meaningless; add `clean: {components: largest}` "
                                        "before this stage")
    if mass == "voronoi":
        import igl

        K = sp.csr_matrix(igl.massmatrix(V, F, igl.MASSMATRIX_TYPE_VORONOI))
        if not (np.isfinite(K.data).all() and (K.diagonal() > 0).all()):
            raise InputError(mesh.name, "the Voronoi mass matrix has zero or non-finite vertex areas; "
                                        "run `clean` first or use mass: full")
    area = float(dbl.sum() / 2.0)
    return Laplacian(Q=Q, K=K, mass=mass, area=area)


class LaplacianParams(Params):
    """Parameters of :func:`laplacian_stage`."""

    mass: MassType = Field("full", description="mass matrix: 'full' (consistent FEM area matrix, thesis) "
                                               "or 'voronoi' (libigl diagonal mixed-Voronoi)")
    require_connected: bool = Field(True, description="fail on a mesh with several connected components "
                                                      "(lambda2 = 0 there); use clean.components: largest")


@dataclass(frozen=True, eq=False)
class LaplacianResult(StageResult):
    """The ``laplacian`` stage's result.

    Attributes
    ----------
    laplacian : Laplacian
        ``Q``, ``K``, mass type and area.
    seconds : float
        Wall time of the assembly (validation included).
    """

    laplacian: Laplacian
    seconds: float

    def summary(self) -> dict:
        lap = self.laplacian
        return {"vertices": lap.n, "nnz_Q": int(lap.Q.nnz), "nnz_K": int(lap.K.nnz), "mass": lap.mass,
                "area": lap.area, "seconds": self.seconds}


@stage("laplacian", params=LaplacianParams, version=1, consumes=("mesh",), produces=("laplacian",))
def laplacian_stage(mesh: Mesh, *, params: LaplacianParams) -> LaplacianResult:
    """FEM Laplace–Beltrami matrices: cotangent stiffness Q (PSD) and mass K."""
    start = time.perf_counter()
    lap = laplacian(mesh, params.mass, require_connected=params.require_connected)
    return LaplacianResult(lap, time.perf_counter() - start)
