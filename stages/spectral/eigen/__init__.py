"""Smallest generalised eigenpairs ``Q phi = lambda K phi`` of a mesh Laplacian: one entry point,
:func:`smallest_eigenpairs`, in front of one solver per module.

``Q`` symmetric positive semidefinite with the constants as its kernel (a connected
mesh), ``K`` symmetric positive definite (:mod:`topomatch.stages.spectral.laplacian`). Results
(:class:`Eigenpairs`) follow one convention whatever the method:

- ``values`` ascending, ``values[0] = 0`` exactly and ``vectors[:, 0]`` the exact
  constant ``1 / sqrt(area)`` (the constant is deflated analytically, never computed);
- vectors K-orthonormal: ``vectors.T @ K @ vectors = I`` (to round-off);
- the sign of every non-constant vector fixed by the sign rule (below).

Methods
-------
``shift_invert`` (the default for n > 400)
    Factor ``S = Q - sigma K`` once, with ``sigma < 0`` slightly negative (``S`` is then
    SPD: no pivoting, and the kernel of ``Q`` does not make it singular), by a sparse
    Cholesky LL^T (Eigen's simplicial LLT through libigl, AMD ordering; with ``threads > 1``
    a sparse LDL^T, qdldl, AMD ordering), or SuperLU (MMD on A^T + A) when neither is
    available. Then a block Krylov–Rayleigh–Ritz iteration with the operator ``W = S^{-1} K`` (a
    Davidson/Lanczos hybrid, full K-orthogonalisation, locking of converged pairs, thick
    restarts): each step adds ``W x`` for the unconverged wanted Ritz vectors ``x`` (with
    qdldl, which releases the GIL, the columns of a block are solved in two threads).
    The basis holds up to ``max(6 (k - 1 + 1), 40)`` vectors (restarts more often than that
    slow the convergence badly when many pairs are wanted). A block method finds every copy
    of a multiple eigenvalue; ARPACK, kept as the fallback only, needs fewer solves for many
    pairs but can miss copies (measured: one of the 7 l = 3 sphere harmonics, k = 16).
    The start block is built from the principal-axis coordinates of the vertices when
    ``V`` is given (the Fiedler vector follows the elongation of the shape, so this is
    already a good guess) plus a small seeded random part, so that no eigenvector is
    missed by symmetry. If it does not converge, ARPACK (``scipy.sparse.linalg.eigsh``,
    mode 3) is run with the same factorisation.
``lobpcg``
    ``scipy.sparse.linalg.lobpcg`` preconditioned by one V-cycle of a pyamg
    smoothed-aggregation hierarchy of ``S``, the constant as a constraint. No
    factorisation: O(nnz) memory, for meshes too large to factor.
``multilevel``
    Decimate the mesh (fast-simplification, to ``min(coarse_vertices, n / 4)`` vertices), solve the coarse
    problem exactly (``shift_invert``), prolong the coarse eigenvectors to the fine mesh
    by barycentric interpolation on the closest coarse triangle, and refine on the fine
    mesh with LOBPCG + AMG. Needs ``V`` and ``F``.
``arpack``
    ARPACK (``eigsh``, mode 3) on qdldl's factorisation, asked for a window of extra pairs: the
    method for tens of eigenpairs (the spectrum of a shape, ShapeDNA), where it needs fewer
    solves than the block method (:mod:`.arpack`).
``dense``
    ``scipy.linalg.eigh`` on dense matrices (n <= ``DENSE_MAX``).
``auto``
    ``dense`` for n <= 400, else ``shift_invert``; on failure (factorisation error, no
    convergence) falls back to ``lobpcg`` and, for n <= ``DENSE_MAX``, to ``dense``.

An explicit method also falls back along that chain unless ``fallback=False``; the
result names the method that succeeded and the failed attempts. The options of every method
are one :class:`EigenOptions`.

Modules: :mod:`.problem` (the problem and what the solvers share), :mod:`.factorization`
(``Q - sigma K`` factorised once), :mod:`.block_krylov` (``shift_invert``), :mod:`.arpack`,
:mod:`.lobpcg`, :mod:`.multilevel`, :mod:`.dense`, :mod:`.signs` (the sign rule). See
``docs/spectral.md`` for the measurements behind these choices.

Convergence
-----------
A pair ``(theta, x)`` with ``x^T K x = 1`` has converged when the relative residual
``||Q x - theta K x||_{D^-1} / theta <= tol``, with ``D`` the lumped mass (row sums of
``K``). This quantity is invariant under rigid motions and uniform scaling. The
eigenvalue error is then about ``tol^2 * theta / relative gap`` (1e-12 relative for the
default ``tol = 1e-6``) and the eigenvector error about ``tol / relative gap``.

Sign rule
---------
``'skewness'`` (default): each non-constant ``phi`` is oriented so that its K-weighted
third moment ``sum_i d_i phi_i^3`` (``d`` = lumped mass, a quadrature of the integral of
``phi^3`` over the surface) is positive: the long tail of the distribution of ``phi`` points
to positive values. It depends only on the intrinsic geometry, so it is invariant under
rotations, translations and uniform scaling (``phi -> phi / s``, ``d -> s^2 d``). When the
dimensionless skewness ``|gamma| < 1e-6`` (a shape with a symmetry that maps ``phi`` to
``-phi``, e.g. a sphere, a torus, a symmetric dumbbell) no intrinsic rule can decide, and
the rule falls back to ``'max_abs'``, which is then decided by round-off: the reported
``skewness`` tells how reliable the sign is. ``'max_abs'``: the entry of largest magnitude
is positive.

Degenerate eigenvalues (``lambda2 ~ lambda3``, e.g. shapes with rotational symmetry) make
``phi2`` itself arbitrary within the eigenspace; the relative gap
``(lambda3 - lambda2) / lambda2`` (see :func:`relative_gap`) reports it.
"""

from __future__ import annotations

import dataclasses
import time
from contextlib import contextmanager
from dataclasses import dataclass, field
from typing import Callable, Iterator, Literal

import numpy as np
import scipy.sparse as sp

from topomatch.pipeline.contract import StageError
from topomatch.stages.spectral.eigen import arpack, block_krylov, dense, lobpcg, multilevel
from topomatch.stages.spectral.eigen.dense import DENSE_MAX
from topomatch.stages.spectral.eigen.factorization import ShiftInvert
from topomatch.stages.spectral.eigen.problem import NotConverged, Problem, Raw
from topomatch.stages.spectral.eigen.signs import SKEWNESS_TIE, SignRule, fix_signs, skewness

__all__ = ["smallest_eigenpairs", "Eigenpairs", "EigenOptions", "relative_gap", "ShiftInvert", "fix_signs",
           "skewness", "DENSE_MAX", "AUTO_DENSE_MAX", "SKEWNESS_TIE", "SOLVERS"]

Method = Literal["auto", "shift_invert", "multilevel", "lobpcg", "arpack", "dense"]

#: Method name -> ``solve(problem, nev, options, V, F) -> Raw`` (the nev non-constant pairs).
SOLVERS: dict[str, Callable[..., Raw]] = {
    "shift_invert": block_krylov.solve,
    "arpack": arpack.solve,
    "lobpcg": lobpcg.solve,
    "multilevel": multilevel.solve,
    "dense": dense.solve,
}

#: ``auto`` uses the dense method up to this n.
AUTO_DENSE_MAX = 400



@dataclass(frozen=True)
class EigenOptions:
    """How :func:`smallest_eigenpairs` solves (module docstring).

    Attributes
    ----------
    method : {'auto', 'shift_invert', 'multilevel', 'lobpcg', 'arpack', 'dense'}
    tol : float
        Relative residual at which a pair has converged (module docstring).
    maxiter : int
        Outer iterations per method.
    sign_rule : {'skewness', 'max_abs'}
        How the sign of each non-constant vector is fixed.
    sigma : float, optional
        Shift (< 0) of ``Q - sigma K``; default from a Rayleigh quotient (``arpack``: from the area).
    seed : int
        Seed of the random part of the start block (``arpack``: of its start vector).
    coarse_vertices : int
        Target vertex count of the coarse mesh (``multilevel``).
    backend : {'auto', 'igl', 'qdldl', 'superlu'}
        Sparse factorisation (:class:`ShiftInvert`).
    fallback : bool
        On failure, try the other methods.
    threads : int
        Threads for BLAS (limited with threadpoolctl while the solve runs) and for the columns of a
        block solve. Default 1: the pipeline runs one worker process per core, and on a loaded
        machine more threads made the solve 2.5x slower (docs/spectral.md).
    """

    method: Method = "auto"
    tol: float = 1e-6
    maxiter: int = 200
    sign_rule: SignRule = "skewness"
    sigma: float | None = None
    seed: int = 0
    coarse_vertices: int = 3000
    backend: Literal["auto", "igl", "qdldl", "superlu"] = "auto"
    fallback: bool = True
    threads: int = 1

    def __post_init__(self) -> None:
        if self.method not in ("auto", *SOLVERS):
            raise ValueError(f"unknown method {self.method!r}")
        if not self.tol > 0:
            raise ValueError(f"tol must be positive, got {self.tol}")
        if self.threads < 1:
            raise ValueError(f"threads must be >= 1, got {self.threads}")


@dataclass(frozen=True, eq=False)
class Eigenpairs:
    """The k smallest eigenpairs of ``Q phi = lambda K phi``.

    Attributes
    ----------
    values : (k,) float64
        Ascending; ``values[0] = 0``.
    vectors : (n, k) float64
        K-orthonormal; column 0 is the constant ``1 / sqrt(area)``; signs fixed by ``sign_rule``.
    method : str
        The method that produced them ('shift_invert', 'arpack', 'lobpcg', 'multilevel', 'dense').
    iterations : int
        Outer iterations of that method (block steps, LOBPCG iterations; 0 for ARPACK).
    n_solves : int
        Applications of the inverse or of the preconditioner to one vector.
    residuals : (k,) float64
        Relative residuals ``||Q x - lambda K x||_{D^-1} / lambda`` (0 for the constant).
    skewness : (k,) float64
        Dimensionless K-weighted skewness of each vector after the sign rule (0 for the constant).
    shift : float
        The shift sigma (< 0) of ``Q - sigma K`` (0 for the dense method).
    sign_rule : str
        The sign rule applied.
    attempts : tuple of str
        Failed attempts before ``method``, as ``"method: reason"``.
    seconds : float
        Wall time of :func:`smallest_eigenpairs`.
    """

    values: np.ndarray
    vectors: np.ndarray
    method: str
    iterations: int
    n_solves: int
    residuals: np.ndarray
    skewness: np.ndarray
    shift: float
    sign_rule: str
    attempts: tuple[str, ...] = field(default_factory=tuple)
    seconds: float = 0.0

    @property
    def k(self) -> int:
        return int(self.values.shape[0])

    @property
    def fiedler(self) -> np.ndarray:
        """``phi2``, (n,) float64."""
        return self.vectors[:, 1]



def relative_gap(values: np.ndarray) -> float:
    """``(lambda3 - lambda2) / lambda2`` (inf when fewer than three values)."""
    if len(values) < 3 or values[1] <= 0:
        return float("inf")
    return float((values[2] - values[1]) / values[1])



def _chain(method: str, n: int, nev: int, fallback: bool) -> list[str]:
    """The methods to try in turn (module docstring)."""
    if method == "auto":
        chain = ["dense"] if n <= AUTO_DENSE_MAX else ["shift_invert", "lobpcg"]
    elif method == "arpack" and not arpack.fits(n, nev):
        chain = ["dense"]  # too small for ARPACK's window
    else:
        chain = [method]
        if fallback:
            chain += [m for m in ("shift_invert", "lobpcg") if m != method]
    if fallback or method == "auto":
        if n <= DENSE_MAX and "dense" not in chain:
            chain.append("dense")
    return chain


@contextmanager
def _blas_threads(threads: int) -> Iterator[None]:
    """Limit the BLAS thread pool to ``threads`` inside the block (no-op without threadpoolctl)."""
    try:
        from threadpoolctl import threadpool_limits
    except ImportError:
        yield
        return
    with threadpool_limits(limits=max(1, int(threads)), user_api="blas"):
        yield


def _run_chain(prob: Problem, nev: int, opts: EigenOptions, V, F) -> tuple[Raw | None, str, list[str]]:
    """Try the methods of :func:`_chain` in turn: (result or None, method used, failed attempts)."""
    attempts: list[str] = []
    for m in _chain(opts.method, prob.n, nev, opts.fallback):
        try:
            raw = SOLVERS[m](prob, nev, opts, V, F)
            if m == "shift_invert" and raw.iterations == 0:
                m = "arpack"  # the block method fell back to ARPACK on its factorisation
            return raw, m, attempts
        except (NotConverged, np.linalg.LinAlgError, RuntimeError, ImportError) as exc:
            attempts.append(f"{m}: {exc}")
    return None, "", attempts


def smallest_eigenpairs(Q: sp.spmatrix, K: sp.spmatrix, k: int = 3, *, V: np.ndarray | None = None,
                        F: np.ndarray | None = None, options: EigenOptions | None = None,
                        **overrides) -> Eigenpairs:
    """The ``k`` smallest eigenpairs of ``Q phi = lambda K phi`` (constant included).

    Parameters
    ----------
    Q : (n, n) sparse, symmetric PSD
        Stiffness matrix whose kernel is the constants (a connected mesh).
    K : (n, n) sparse, symmetric PD
        Mass matrix.
    k : int
        Number of pairs, 2 <= k < n, the constant pair included (k = 3: phi1, phi2, phi3); k = n
        only with the dense method.
    V, F : arrays, optional
        The mesh: V (n, 3) improves the start block and the shift; ``multilevel`` needs both.
    options : EigenOptions, optional
        How to solve (default: ``EigenOptions()``).
    **overrides
        Fields of :class:`EigenOptions` that replace ``options``' (``method="lobpcg"``, ``tol=1e-8``, ...).

    Returns
    -------
    Eigenpairs

    Raises
    ------
    ValueError
        Bad shapes or arguments.
    StageError
        Every method failed, or lambda2 is 0 (a disconnected mesh).
    """
    start = time.perf_counter()
    opts = dataclasses.replace(options or EigenOptions(), **overrides)
    if Q.shape != K.shape or Q.ndim != 2 or Q.shape[0] != Q.shape[1]:
        raise ValueError(f"Q and K must be square and of the same shape, got {Q.shape} and {K.shape}")
    n = Q.shape[0]
    if not (2 <= k < n or (2 <= k == n and opts.method in ("dense", "arpack"))):
        raise ValueError(f"k must satisfy 2 <= k < n = {n} (k = n: the dense method), got {k}")
    if V is not None and np.shape(V) != (n, 3):
        raise ValueError(f"V must have shape ({n}, 3), got {np.shape(V)}")
    prob = Problem(Q, K)
    if not np.all(prob.d > 0):
        raise ValueError("K has non-positive row sums: it is not a mass matrix of a mesh without isolated vertices")
    nev = k - 1
    with _blas_threads(opts.threads):
        raw, used, attempts = _run_chain(prob, nev, opts, V, F)
    if raw is None:
        raise StageError("no eigensolver converged: " + "; ".join(attempts))
    order = np.argsort(raw.values)
    values, vectors = raw.values[order], raw.vectors[:, order]
    # diag(Q) / diag(K) ~ the largest eigenvalues; a connected mesh has lambda2 / lambda_max ~ 1 / n
    scale = float(np.median(prob.Q.diagonal() / prob.K.diagonal()))
    if values[0] <= 1e-12 * scale:
        raise StageError(f"lambda2 = {values[0]:.3g} is 0 up to round-off: the mesh is disconnected (one zero "
                         "eigenvalue per component); keep one component with `clean: {components: largest}`")
    vectors = fix_signs(vectors, prob.d, opts.sign_rule)
    all_values = np.concatenate([[0.0], values])
    all_vectors = np.column_stack([prob.c, vectors])
    residuals = np.concatenate([[0.0], prob.residuals(vectors, values)])
    skews = np.concatenate([[0.0], skewness(vectors, prob.d)])
    return Eigenpairs(values=all_values, vectors=all_vectors, method=used, iterations=raw.iterations,
                      n_solves=raw.n_solves, residuals=residuals, skewness=skews, shift=raw.shift,
                      sign_rule=opts.sign_rule, attempts=tuple(attempts), seconds=time.perf_counter() - start)
