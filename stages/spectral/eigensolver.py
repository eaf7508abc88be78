"""Smallest generalised eigenpairs ``Q phi = lambda K phi`` of a mesh Laplacian.

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
``dense``
    ``scipy.linalg.eigh`` on dense matrices (n <= ``DENSE_MAX``).
``auto``
    ``dense`` for n <= 400, else ``shift_invert``; on failure (factorisation error, no
    convergence) falls back to ``lobpcg`` and, for n <= ``DENSE_MAX``, to ``dense``.

An explicit method also falls back along that chain unless ``fallback=False``; the
result names the method that succeeded and the failed attempts. See
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

import os
import time
from concurrent.futures import ThreadPoolExecutor
from contextlib import contextmanager
from dataclasses import dataclass, field
from typing import Callable, Iterator, Literal

import numpy as np
import scipy.linalg as la
import scipy.sparse as sp
import scipy.sparse.linalg as sla

from topomatch.pipeline.contract import StageError

Method = Literal["auto", "shift_invert", "multilevel", "lobpcg", "dense"]
SignRule = Literal["skewness", "max_abs"]

#: Largest n for the dense method (and the dense fallback).
DENSE_MAX = 3000
#: ``auto`` uses the dense method up to this n.
AUTO_DENSE_MAX = 400
#: Dimensionless skewness below which the 'skewness' sign rule defers to 'max_abs'.
SKEWNESS_TIE = 1e-6


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


# --------------------------------------------------------------------------- helpers


class _Problem:
    """``Q``, ``K`` and the quantities every method needs (lumped mass, exact constant)."""

    def __init__(self, Q: sp.spmatrix, K: sp.spmatrix):
        self.Q = sp.csr_matrix(Q, dtype=np.float64)
        self.K = sp.csr_matrix(K, dtype=np.float64)
        self.n = self.Q.shape[0]
        self.d = np.asarray(self.K.sum(axis=1)).ravel()
        self.area = float(self.d.sum())
        self.c0 = 1.0 / np.sqrt(self.area)
        self.c = np.full(self.n, self.c0)  # K-normalised constant
        self.Kc = self.d * self.c0  # K @ c
        self.inv_d = 1.0 / self.d

    def deflate(self, X: np.ndarray) -> np.ndarray:
        """``X`` minus its K-projection on the constant."""
        return X - self.c0 * (self.Kc @ X)

    def residuals(self, X: np.ndarray, theta: np.ndarray, QX: np.ndarray | None = None,
                  KX: np.ndarray | None = None) -> np.ndarray:
        """Relative residuals ``||Q x - theta K x||_{D^-1} / theta`` of the columns of ``X``."""
        QX = self.Q @ X if QX is None else QX
        KX = self.K @ X if KX is None else KX
        R = QX - KX * theta
        return np.sqrt(np.einsum("ij,ij,i->j", R, R, self.inv_d)) / np.abs(theta)

    def k_orthonormalize(self, X: np.ndarray, with_kx: bool = False):
        """K-orthonormal basis of span(X) deflated of the constant (columns may be dropped).

        With ``with_kx``, also returns ``K`` times the basis.
        """
        X = self.deflate(X)
        KX = self.K @ X
        G = X.T @ KX
        w, U = np.linalg.eigh((G + G.T) / 2)
        keep = w > 1e-12 * max(w.max(), 0.0)
        T = U[:, keep] / np.sqrt(w[keep])
        return (X @ T, KX @ T) if with_kx else X @ T


def _axis_functions(prob: _Problem, V: np.ndarray, p: int) -> np.ndarray:
    """(n, p) smooth functions of the vertices: principal-axis coordinates, then their products.

    The axes are the eigenvectors of the area-weighted covariance, ordered by decreasing
    variance; every column has unit area-weighted RMS.
    """
    V = np.asarray(V, dtype=np.float64)
    w = prob.d / prob.area
    X = V - w @ V
    C = (X * w[:, None]).T @ X
    _, R = np.linalg.eigh(C)
    X = X @ R[:, ::-1]
    cols = [X[:, 0], X[:, 1], X[:, 2], X[:, 0] ** 2, X[:, 0] * X[:, 1], X[:, 1] ** 2, X[:, 2] ** 2,
            X[:, 0] * X[:, 2], X[:, 1] * X[:, 2]]
    B = np.column_stack([cols[j % len(cols)] for j in range(p)])
    B = prob.deflate(B)
    return B / (np.sqrt(np.einsum("ij,ij,i->j", B, B, w)) + 1e-300)


def _start_block(prob: _Problem, p: int, V: np.ndarray | None, seed: int, noise: float = 0.05,
                 axis: np.ndarray | None = None) -> np.ndarray:
    """A start block (n, p): :func:`_axis_functions` of ``V`` plus ``noise`` times seeded Gaussian vectors.

    Without ``V``, Gaussian vectors only. The noise keeps every eigenvector present in
    the start (on a symmetric mesh the coordinate functions can all be odd under a
    symmetry under which the Fiedler vector is even, and a Krylov space grown from them
    would never contain it); the first inverse iteration damps its high frequencies.
    """
    G = np.random.default_rng(seed).standard_normal((prob.n, p))
    if V is None:
        return G
    return (_axis_functions(prob, V, p) if axis is None else axis) + noise * G


def _rayleigh_estimate(prob: _Problem, X: np.ndarray) -> float:
    """Smallest Rayleigh quotient among the (deflated) columns of ``X``: an upper bound of lambda2."""
    X = prob.deflate(X)
    num = np.einsum("ij,ij->j", X, prob.Q @ X)
    den = np.einsum("ij,ij->j", X, prob.K @ X)
    ok = den > 0
    return float(np.min(num[ok] / den[ok])) if ok.any() else 1.0


def _auto_shift(prob: _Problem, V: np.ndarray | None, axis: np.ndarray | None = None) -> float:
    """sigma = -0.01 * (Rayleigh quotient of the first principal-axis coordinate), an upper bound of lambda2.

    ``axis`` (n, >= 1) are precomputed :func:`_axis_functions`. Without ``V``:
    ``-1e-8 * median(diag Q / diag K)`` (``diag Q / diag K`` ~ lambda_max ~ n lambda2 on a surface mesh).
    """
    if V is not None:
        axis = _axis_functions(prob, V, 1) if axis is None else axis
        est = _rayleigh_estimate(prob, axis[:, :1])
        if np.isfinite(est) and est > 0:
            return -0.01 * est
    ratio = np.median(prob.Q.diagonal() / prob.K.diagonal())
    return -1e-8 * float(ratio) if ratio > 0 else -1e-8


def _available_cpus() -> int:
    """CPUs this process may run on, at most 2 (the Fiedler blocks have 2 columns)."""
    try:
        n = len(os.sched_getaffinity(0))
    except (AttributeError, OSError):
        n = os.cpu_count() or 1
    return max(1, min(2, n))


def _upper_triangle_csc(S: sp.csc_matrix, lower: bool = False) -> sp.csc_matrix:
    """The upper (or lower) triangle, diagonal included, of a CSC matrix with sorted indices, without a
    COO round trip."""
    counts = np.diff(S.indptr)
    cols = np.repeat(np.arange(S.shape[1], dtype=S.indices.dtype), counts)
    keep = S.indices >= cols if lower else S.indices <= cols
    indptr = np.zeros(S.shape[1] + 1, dtype=S.indptr.dtype)
    np.cumsum(np.bincount(cols[keep], minlength=S.shape[1]), out=indptr[1:])
    return sp.csc_matrix((S.data[keep], S.indices[keep], indptr), shape=S.shape)


class ShiftInvert:
    """A factorisation of ``S = Q - sigma K`` (sigma < 0, so S is SPD), solve many times.

    ``backend='auto'`` uses Eigen's simplicial Cholesky LL^T (AMD ordering) through libigl's
    ``min_quad_with_fixed`` with one thread, qdldl (sparse LDL^T, AMD ordering) with more
    threads (it releases the GIL, so the columns of a block can be solved in parallel), else
    SuperLU with the MMD(A^T + A) ordering and no pivoting (S is SPD). On the 48k-vertex horse
    the LL^T factorisation takes ~100 ms against ~130 ms for qdldl's LDL^T; a solve takes
    ~3.4 ms against ~2.9 ms.

    Parameters
    ----------
    Q, K : (n, n) sparse
        Stiffness and mass matrices.
    sigma : float
        The shift, < 0.
    backend : {'auto', 'igl', 'qdldl', 'superlu'}
        Factorisation library.
    threads : int, optional
        Threads for the columns of a block solve (qdldl only, at most the CPUs this process
        may use); default 1. Use as a context manager (or call :meth:`close`) to stop them.
    """

    def __init__(self, Q: sp.spmatrix, K: sp.spmatrix, sigma: float, backend: str = "auto",
                 threads: int | None = None):
        if not sigma < 0:
            raise ValueError(f"sigma must be negative, got {sigma}")
        self.sigma = float(sigma)
        self.threads = 1 if threads is None else max(1, min(int(threads), _available_cpus()))
        self._pool: ThreadPoolExecutor | None = None
        Q, K = sp.csr_matrix(Q), sp.csr_matrix(K)
        if (Q.has_canonical_format and K.has_canonical_format and np.array_equal(Q.indptr, K.indptr)
                and np.array_equal(Q.indices, K.indices)):
            # same pattern (stages.spectral.laplacian assembles them so), and S is symmetric: its
            # CSR arrays are its CSC arrays
            S = sp.csc_matrix((Q.data - self.sigma * K.data, Q.indices, Q.indptr), shape=Q.shape)
        else:
            S = (Q - self.sigma * K).tocsc()
        self.n = S.shape[0]
        self.backend = backend
        if backend == "igl" or (backend == "auto" and self.threads == 1):
            try:
                import igl

                # Eigen's SimplicialLLT reads the lower triangle; min_quad_with_fixed solves S Z = -B
                self._igl = igl.min_quad_with_fixed_data()
                self._igl_solve = igl.min_quad_with_fixed_solve
                igl.min_quad_with_fixed_precompute(_upper_triangle_csc(S, lower=True), np.zeros(0, dtype=np.int64),
                                                   sp.csc_matrix((0, self.n)), True, self._igl)
                self.backend = "igl"
                return
            except ImportError:
                if backend == "igl":
                    raise
        if backend in ("auto", "qdldl"):
            try:
                import qdldl

                self._qdldl = qdldl.Solver(_upper_triangle_csc(S), upper=True)
                self.backend = "qdldl"
                return
            except ImportError:
                if backend == "qdldl":
                    raise
        self._lu = sla.splu(S, permc_spec="MMD_AT_PLUS_A", diag_pivot_thresh=0.0,
                            options={"SymmetricMode": True})
        self.backend = "superlu"

    def solve(self, B: np.ndarray) -> np.ndarray:
        """``S^{-1} B`` for B (n,) or (n, p).

        With qdldl, the columns of a block are solved in up to ``threads`` threads (qdldl
        releases the GIL and its solve allocates its own work arrays, so this is safe).
        """
        if self.backend == "superlu":
            return self._lu.solve(np.asarray(B, dtype=np.float64))
        if self.backend == "igl":
            B2 = np.asarray(B, dtype=np.float64).reshape(self.n, -1)
            empty = np.zeros((0, B2.shape[1]))
            X = self._igl_solve(self._igl, B2, empty, empty)
            np.negative(X, out=X)
            return X.reshape(B.shape)
        if B.ndim == 1:
            return self._qdldl.solve(np.ascontiguousarray(B, dtype=np.float64))
        cols = [np.ascontiguousarray(B[:, j], dtype=np.float64) for j in range(B.shape[1])]
        if self.threads > 1 and len(cols) > 1:
            if self._pool is None:
                self._pool = ThreadPoolExecutor(max_workers=self.threads, thread_name_prefix="shift-invert")
            xs = list(self._pool.map(self._qdldl.solve, cols))
        else:
            xs = [self._qdldl.solve(c) for c in cols]
        return np.column_stack(xs)

    def close(self) -> None:
        """Stop the solve threads (if any were started)."""
        if self._pool is not None:
            self._pool.shutdown(wait=True)
            self._pool = None

    def __enter__(self) -> "ShiftInvert":
        return self

    def __exit__(self, *exc) -> None:
        self.close()


# --------------------------------------------------------------------------- methods


@dataclass
class _Raw:
    """Unnormalised output of a method: the nev non-constant pairs."""

    values: np.ndarray
    vectors: np.ndarray
    iterations: int
    n_solves: int
    shift: float


class _NotConverged(Exception):
    pass


def _svqb(prob: _Problem, B: np.ndarray, KB: np.ndarray, floor: np.ndarray) -> tuple[np.ndarray, np.ndarray, float]:
    """K-orthonormalise the columns of B (SVQB: scaled Gram matrix, eigendecomposition).

    Columns whose K-norm is below ``floor`` are dropped first (numerically in the span of
    what they were orthogonalised against), then directions with a relative eigenvalue
    below 1e-14 of the scaled Gram matrix. Returns B, K B and that matrix's condition number.
    """
    G = B.T @ KB
    norms = np.sqrt(np.maximum(np.diag(G), 0.0))
    ok = norms > floor
    if not ok.all():
        B, KB, G, norms = B[:, ok], KB[:, ok], G[np.ix_(ok, ok)], norms[ok]
    if B.shape[1] == 0:
        return B, KB, 1.0
    Dinv = 1.0 / norms
    w, U = np.linalg.eigh((G + G.T) / 2 * Dinv[:, None] * Dinv[None, :])
    keep = w > 1e-14 * w.max()
    T = (Dinv[:, None] * U[:, keep]) / np.sqrt(w[keep])
    return B @ T, KB @ T, float(w.max() / max(w[keep].min(), 1e-300))


def _orthonormalize_against(prob: _Problem, Z: np.ndarray, KZ: np.ndarray, B: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Columns of B made K-orthonormal and K-orthogonal to the K-orthonormal basis Z (n, m).

    Block classical Gram–Schmidt twice ("twice is enough") then SVQB within the block; when
    the block was ill-conditioned (cond > 1e6) the whole round is repeated once, so that the
    orthogonality lost in the within-block step (~ eps * cond) is restored. Directions that
    keep less than 1e-13 of their norm are dropped.
    """
    before = np.sqrt(np.einsum("ij,ij->j", B, B)) * np.sqrt(prob.d.max())  # bounds the K-norms
    for _ in range(2):
        B = B - Z @ (KZ.T @ B)
    B, KB, cond = _svqb(prob, B, prob.K @ B, 1e-13 * before.max())
    if B.shape[1] > 1 and cond > 1e6:
        B = B - Z @ (KZ.T @ B)
        B, KB, _ = _svqb(prob, B, prob.K @ B, 1e-3)
    return B, KB


def _block_krylov(prob: _Problem, solve: Callable[[np.ndarray], np.ndarray], X0: np.ndarray, nev: int,
                  tol: float, maxiter: int, max_basis: int) -> tuple[np.ndarray, np.ndarray, int, int]:
    """Block Krylov–Rayleigh–Ritz with ``W = S^{-1} K``, locking and thick restarts.

    The basis ``Z`` is K-orthonormal; its column 0 is the exact constant ``c`` (so the
    orthogonalisation deflates it, with ``Q c = 0``), and the Rayleigh–Ritz problem is
    ``H = Z[:, 1:]^T Q Z[:, 1:]``. Each step adds ``W x`` for the wanted Ritz vectors ``x`` whose
    residual is above ``tol`` (converged ones are locked: they stay in the basis but are
    no longer expanded). When the basis is full it is restarted on the current Ritz
    vectors (thick restart).

    Returns the nev smallest Ritz values, their K-normalised Ritz vectors, the number of
    block steps and of single-vector solves. Raises :class:`_NotConverged`.
    """
    n = prob.n
    # column-major, so that the leading columns Z[:, :m] are one contiguous block for BLAS
    Z = np.empty((n, max_basis + 1), order="F")
    QZ = np.empty((n, max_basis + 1), order="F")
    KZ = np.empty((n, max_basis + 1), order="F")
    Z[:, 0], QZ[:, 0], KZ[:, 0] = prob.c, 0.0, prob.Kc
    H = np.zeros((max_basis + 1, max_basis + 1))  # H[0, :] = H[:, 0] = 0 (Q c = 0)
    m = 1
    B = np.asarray(X0, dtype=np.float64)
    n_solves = 0
    res = np.full(nev, np.inf)
    for step in range(1, maxiter + 1):
        B, KB = _orthonormalize_against(prob, Z[:, :m], KZ[:, :m], B)
        if B.shape[1] == 0:
            raise _NotConverged("the Krylov space stopped growing (breakdown)")
        b = B.shape[1]
        if m + b > max_basis + 1:  # thick restart on the current Ritz vectors
            keep_n = min(m - 1, max(2 * nev, max_basis // 2))
            _, S = np.linalg.eigh(H[1:m, 1:m])
            S = S[:, :keep_n]
            Z[:, 1:1 + keep_n] = Z[:, 1:m] @ S
            QZ[:, 1:1 + keep_n] = QZ[:, 1:m] @ S
            KZ[:, 1:1 + keep_n] = KZ[:, 1:m] @ S
            H[1:1 + keep_n, 1:1 + keep_n] = S.T @ H[1:m, 1:m] @ S
            m = 1 + keep_n
            H[m:, :] = 0
            H[:, m:] = 0
            B = B - Z[:, :m] @ (KZ[:, :m].T @ B)  # B was orthogonal to the old span: one pass
            b = min(b, max_basis + 1 - m)
            B, KB = B[:, :b], prob.K @ B[:, :b]
        QB = prob.Q @ B
        Z[:, m:m + b] = B
        QZ[:, m:m + b] = QB
        KZ[:, m:m + b] = KB
        Hn = Z[:, 1:m + b].T @ QB
        H[1:m + b, m:m + b] = Hn
        H[m:m + b, 1:m + b] = Hn.T
        m += b
        r = min(nev, m - 1)
        theta, S = la.eigh(H[1:m, 1:m], subset_by_index=[0, r - 1])
        QX = QZ[:, 1:m] @ S
        KX = KZ[:, 1:m] @ S
        R = QX - KX * theta
        res = np.sqrt(prob.inv_d @ (R * R)) / np.abs(theta)
        if r == nev and np.all(res <= tol):
            return theta, Z[:, 1:m] @ S, step, n_solves
        todo = np.flatnonzero(res > tol) if r == nev else np.arange(r)
        B = solve(KX[:, todo])
        n_solves += len(todo)
    raise _NotConverged(f"no convergence in {maxiter} block steps (residuals {np.array2string(res, precision=2)}, "
                        f"tol {tol:g})")


def _shift_invert(prob: _Problem, nev: int, *, tol: float, maxiter: int, V: np.ndarray | None, seed: int,
                  sigma: float | None, backend: str, X0: np.ndarray | None = None, threads: int = 1) -> _Raw:
    p = nev + 1  # one more start vector than wanted pairs
    axis = None if V is None else _axis_functions(prob, V, p)
    sigma = _auto_shift(prob, V, axis) if sigma is None else float(sigma)
    try:
        fac = ShiftInvert(prob.Q, prob.K, sigma, backend=backend, threads=threads)
    except (RuntimeError, ValueError) as exc:  # singular factor, ...
        raise _NotConverged(f"factorisation of Q - sigma K failed ({exc})") from None
    if X0 is None:
        X0 = _start_block(prob, p, V, seed, axis=axis)
    max_basis = int(min(prob.n - 1, max(6 * p, 40)))
    with fac:
        try:
            values, vectors, steps, n_solves = _block_krylov(prob, fac.solve, X0, nev, tol, maxiter, max_basis)
            return _Raw(values, vectors, steps, n_solves, sigma)
        except _NotConverged as first:
            arpack = _arpack(prob, fac, nev, tol, V, seed)
            if arpack is None:
                raise first
            return arpack


def _arpack(prob: _Problem, fac: ShiftInvert, nev: int, tol: float, V, seed: int) -> _Raw | None:
    """ARPACK (mode 3) with the same factorisation; the constant is among its k = nev + 1 pairs."""
    count = [0]

    def opinv(b):
        count[0] += 1
        return fac.solve(b)

    op = sla.LinearOperator((prob.n, prob.n), matvec=opinv, dtype=np.float64)
    v0 = prob.deflate(_start_block(prob, 1, V, seed))[:, 0]
    try:
        w, X = sla.eigsh(prob.Q, k=nev + 1, M=prob.K, sigma=fac.sigma, OPinv=op, which="LM", v0=v0,
                         tol=tol * 1e-3, maxiter=2000)
    except (sla.ArpackNoConvergence, sla.ArpackError):
        return None
    order = np.argsort(w)
    w, X = w[order][1:], X[:, order][:, 1:]
    X = prob.deflate(X)
    X = X / np.sqrt(np.einsum("ij,ij->j", X, prob.K @ X))
    if np.any(prob.residuals(X, w) > 10 * tol):
        return None
    return _Raw(w, X, 0, count[0], fac.sigma)


def _amg_preconditioner(prob: _Problem, sigma: float) -> sla.LinearOperator:
    import pyamg

    S = (prob.Q - sigma * prob.K).tocsr()
    ml = pyamg.smoothed_aggregation_solver(S, B=np.ones((prob.n, 1)), max_coarse=300)
    return ml.aspreconditioner(cycle="V")


def _lobpcg(prob: _Problem, nev: int, *, tol: float, maxiter: int, V: np.ndarray | None, seed: int,
            sigma: float | None, X0: np.ndarray | None = None) -> _Raw:
    import warnings

    p = nev + 1
    if prob.n < 5 * (p + 1):
        raise _NotConverged(f"n = {prob.n} is too small for LOBPCG with {p} vectors and a constraint")
    sigma = _auto_shift(prob, V) if sigma is None else float(sigma)
    M = _amg_preconditioner(prob, sigma)
    count = [0]

    def precond(X):
        count[0] += X.shape[1] if X.ndim == 2 else 1
        return M @ X

    Mop = sla.LinearOperator((prob.n, prob.n), matvec=precond, matmat=precond, dtype=np.float64)
    X = _start_block(prob, p, V, seed) if X0 is None else X0
    X = prob.k_orthonormalize(X)
    if X.shape[1] < p:
        X = np.column_stack([X, np.random.default_rng(seed).standard_normal((prob.n, p - X.shape[1]))])
    # lobpcg stops on ||r||_2 <= its tol; ours is ||r||_{D^-1} / theta <= tol, and
    # ||r||_{D^-1} <= ||r||_2 / sqrt(min d). Start from a Rayleigh-quotient estimate of theta and
    # restart (from the current vectors, with a tighter tol) while our criterion is not met.
    est = _rayleigh_estimate(prob, X)
    tol2 = tol * est * np.sqrt(prob.d.min())
    iterations = 0
    for _ in range(4):
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            w, Xv, hist = sla.lobpcg(prob.Q, X, B=prob.K, M=Mop, Y=prob.c[:, None], tol=tol2, maxiter=maxiter,
                                     largest=False, retResidualNormsHistory=True)
        iterations += len(hist)
        res_all = prob.residuals(Xv, w)
        order = np.argsort(w)[:nev]
        res = res_all[order]
        if np.all(res <= tol) or iterations >= maxiter:
            break
        X = Xv
        tol2 *= 0.5 * tol / float(res.max())
    w, Xv = w[order], Xv[:, order]
    Xv = prob.deflate(Xv)
    Xv = Xv / np.sqrt(np.einsum("ij,ij->j", Xv, prob.K @ Xv))
    res = prob.residuals(Xv, w)
    if not np.all(res <= 10 * tol):
        raise _NotConverged(f"LOBPCG stopped after {iterations} iterations with residuals "
                            f"{np.array2string(res, precision=2)} (tol {tol:g})")
    return _Raw(w, Xv, iterations, count[0], sigma)


def _barycentric_prolongation(V: np.ndarray, Vc: np.ndarray, Fc: np.ndarray) -> sp.csr_matrix:
    """(n, nc) interpolation: each fine vertex from the closest point on the coarse mesh (barycentric)."""
    import igl

    _, I, C = igl.point_mesh_squared_distance(V, Vc, Fc)
    I = np.asarray(I, dtype=np.int64).ravel()
    T = Fc[I]
    A, B, Cc = Vc[T[:, 0]], Vc[T[:, 1]], Vc[T[:, 2]]
    L = np.asarray(igl.barycentric_coordinates(np.ascontiguousarray(C), np.ascontiguousarray(A),
                                               np.ascontiguousarray(B), np.ascontiguousarray(Cc)))
    L = np.clip(np.nan_to_num(L, nan=1.0 / 3.0), 0.0, None)
    L /= L.sum(axis=1, keepdims=True)
    n = V.shape[0]
    rows = np.repeat(np.arange(n), 3)
    return sp.csr_matrix((L.ravel(), (rows, T.ravel())), shape=(n, Vc.shape[0]))


def _multilevel(prob: _Problem, nev: int, *, tol: float, maxiter: int, V: np.ndarray | None,
                F: np.ndarray | None, seed: int, sigma: float | None, coarse_vertices: int,
                backend: str) -> _Raw:
    if V is None or F is None:
        raise _NotConverged("the multilevel method needs the mesh (V and F)")
    from topomatch.stages.mesh.decimate import simplify_to_target
    from topomatch.stages.mesh.geometry import double_areas_and_sq_lengths
    from topomatch.stages.spectral.laplacian import _assemble, _components

    target = min(coarse_vertices, prob.n // 4)
    if target < 100:
        raise _NotConverged(f"mesh too small for multilevel ({prob.n} vertices; needs >= 400)")
    Vc, Fc, _ = simplify_to_target(V, F, 2 * target)
    s, dbl = double_areas_and_sq_lengths(Vc, Fc)
    keep = dbl > 0
    Fc = Fc[keep]
    Qc, Kc = _assemble(Vc.shape[0], Fc, s[keep], dbl[keep])
    if _components(Qc)[0] != 1 or not np.all(Kc.diagonal() > 0):
        raise _NotConverged("the decimated mesh is disconnected or degenerate")
    coarse = _Problem(Qc, Kc)
    p = nev + 1
    raw = _shift_invert(coarse, p, tol=1e-4, maxiter=maxiter, V=Vc, seed=seed, sigma=None, backend=backend)
    P = _barycentric_prolongation(V, Vc, Fc)
    X0 = P @ raw.vectors
    fine = _lobpcg(prob, nev, tol=tol, maxiter=maxiter, V=V, seed=seed, sigma=sigma, X0=X0)
    return _Raw(fine.values, fine.vectors, fine.iterations, fine.n_solves + raw.n_solves, fine.shift)


def _dense(prob: _Problem, nev: int) -> _Raw:
    if prob.n > DENSE_MAX:
        raise _NotConverged(f"n = {prob.n} is above the dense limit {DENSE_MAX}")
    Qd, Kd = prob.Q.toarray(), prob.K.toarray()
    w, X = la.eigh(Qd, Kd, subset_by_index=[0, nev])
    X = prob.deflate(X[:, 1:])
    X = prob.k_orthonormalize(X)
    # k_orthonormalize may rotate within the block: Rayleigh–Ritz back to eigenvectors
    H = X.T @ (prob.Q @ X)
    w, S = np.linalg.eigh((H + H.T) / 2)
    return _Raw(w, X @ S, 1, 0, 0.0)


# --------------------------------------------------------------------------- sign rule


def skewness(vectors: np.ndarray, d: np.ndarray) -> np.ndarray:
    """Dimensionless K-weighted skewness ``sum d phi^3 sqrt(sum d) / (sum d phi^2)^(3/2)`` per column."""
    vectors = np.asarray(vectors, dtype=np.float64)
    if vectors.ndim == 1:
        vectors = vectors[:, None]
    sq = vectors * vectors
    m2 = d @ sq
    m3 = np.einsum("i,ij,ij->j", d, sq, vectors)
    with np.errstate(divide="ignore", invalid="ignore"):
        g = m3 * np.sqrt(d.sum()) / m2**1.5
    return np.nan_to_num(g)


def fix_signs(vectors: np.ndarray, d: np.ndarray, rule: SignRule = "skewness") -> np.ndarray:
    """Orient each column of ``vectors`` (n, k) by ``rule`` (see the module docstring); returns a copy."""
    if rule not in ("skewness", "max_abs"):
        raise ValueError(f"sign rule must be 'skewness' or 'max_abs', got {rule!r}")
    X = np.array(vectors, dtype=np.float64, copy=True)
    g = skewness(X, d)
    for j in range(X.shape[1]):
        if rule == "skewness" and abs(g[j]) >= SKEWNESS_TIE:
            flip = g[j] < 0
        else:
            flip = X[np.argmax(np.abs(X[:, j])), j] < 0
        if flip:
            X[:, j] = -X[:, j]
    return X


# --------------------------------------------------------------------------- public entry


def _chain(method: str, n: int, fallback: bool) -> list[str]:
    if method == "auto":
        chain = ["dense"] if n <= AUTO_DENSE_MAX else ["shift_invert", "lobpcg"]
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


def _run_chain(prob: _Problem, nev: int, *, method: str, tol: float, maxiter: int, V, F, seed: int,
               sigma: float | None, coarse_vertices: int, backend: str, fallback: bool,
               threads: int) -> tuple[_Raw | None, str, list[str]]:
    """Try the methods of :func:`_chain` in turn: (result or None, method used, failed attempts)."""
    attempts: list[str] = []
    for m in _chain(method, prob.n, fallback):
        try:
            if m == "shift_invert":
                raw = _shift_invert(prob, nev, tol=tol, maxiter=maxiter, V=V, seed=seed, sigma=sigma,
                                    backend=backend, threads=threads)
                if raw.iterations == 0:
                    m = "arpack"
            elif m == "lobpcg":
                raw = _lobpcg(prob, nev, tol=tol, maxiter=maxiter, V=V, seed=seed, sigma=sigma)
            elif m == "multilevel":
                raw = _multilevel(prob, nev, tol=tol, maxiter=maxiter, V=V, F=F, seed=seed, sigma=sigma,
                                  coarse_vertices=coarse_vertices, backend=backend)
            else:
                raw = _dense(prob, nev)
            return raw, m, attempts
        except (_NotConverged, np.linalg.LinAlgError, RuntimeError, ImportError) as exc:
            attempts.append(f"{m}: {exc}")
    return None, "", attempts


def smallest_eigenpairs(
    Q: sp.spmatrix,
    K: sp.spmatrix,
    k: int = 3,
    *,
    method: Method = "auto",
    tol: float = 1e-6,
    maxiter: int = 200,
    V: np.ndarray | None = None,
    F: np.ndarray | None = None,
    sign_rule: SignRule = "skewness",
    sigma: float | None = None,
    seed: int = 0,
    coarse_vertices: int = 3000,
    backend: Literal["auto", "igl", "qdldl", "superlu"] = "auto",
    fallback: bool = True,
    threads: int = 1,
) -> Eigenpairs:
    """The ``k`` smallest eigenpairs of ``Q phi = lambda K phi`` (constant included).

    Parameters
    ----------
    Q : (n, n) sparse, symmetric PSD
        Stiffness matrix whose kernel is the constants (a connected mesh).
    K : (n, n) sparse, symmetric PD
        Mass matrix.
    k : int
        Number of pairs, 2 <= k < n, the constant pair included (k = 3: phi1, phi2, phi3).
    method : {'auto', 'shift_invert', 'multilevel', 'lobpcg', 'dense'}
        See the module docstring.
    tol : float
        Relative residual at which a pair has converged (module docstring).
    maxiter : int
        Outer iterations per method.
    V, F : arrays, optional
        The mesh: V (n, 3) improves the start block and the shift; ``multilevel`` needs both.
    sign_rule : {'skewness', 'max_abs'}
        How the sign of each non-constant vector is fixed.
    sigma : float, optional
        Shift (< 0) of ``Q - sigma K``; default from a Rayleigh quotient (module docstring).
    seed : int
        Seed of the random part of the start block.
    coarse_vertices : int
        Target vertex count of the coarse mesh (``multilevel``).
    backend : {'auto', 'igl', 'qdldl', 'superlu'}
        Sparse factorisation for ``shift_invert`` (:class:`ShiftInvert`).
    fallback : bool
        On failure, try the other methods (module docstring).
    threads : int
        Threads for BLAS (limited with threadpoolctl while this function runs) and for the
        columns of a block solve. Default 1: the pipeline runs one worker process per core,
        and on a loaded machine more threads made the solve 2.5x slower (docs/spectral.md).

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
    if Q.shape != K.shape or Q.ndim != 2 or Q.shape[0] != Q.shape[1]:
        raise ValueError(f"Q and K must be square and of the same shape, got {Q.shape} and {K.shape}")
    n = Q.shape[0]
    if not 2 <= k < n:
        raise ValueError(f"k must satisfy 2 <= k < n = {n}, got {k}")
    if method not in ("auto", "shift_invert", "multilevel", "lobpcg", "dense"):
        raise ValueError(f"unknown method {method!r}")
    if not tol > 0:
        raise ValueError(f"tol must be positive, got {tol}")
    if threads < 1:
        raise ValueError(f"threads must be >= 1, got {threads}")
    if V is not None and np.shape(V) != (n, 3):
        raise ValueError(f"V must have shape ({n}, 3), got {np.shape(V)}")
    prob = _Problem(Q, K)
    if not np.all(prob.d > 0):
        raise ValueError("K has non-positive row sums: it is not a mass matrix of a mesh without isolated vertices")
    nev = k - 1
    with _blas_threads(threads):
        raw, used, attempts = _run_chain(prob, nev, method=method, tol=tol, maxiter=maxiter, V=V, F=F, seed=seed,
                                         sigma=sigma, coarse_vertices=coarse_vertices, backend=backend,
                                         fallback=fallback, threads=threads)
    if raw is None:
        raise StageError("no eigensolver converged: " + "; ".join(attempts))
    order = np.argsort(raw.values)
    values, vectors = raw.values[order], raw.vectors[:, order]
    # diag(Q) / diag(K) ~ the largest eigenvalues; a connected mesh has lambda2 / lambda_max ~ 1 / n
    scale = float(np.median(prob.Q.diagonal() / prob.K.diagonal()))
    if values[0] <= 1e-12 * scale:
        raise StageError(f"lambda2 = {values[0]:.3g} is 0 up to round-off: the mesh is disconnected (one zero "
                         "eigenvalue per component); keep one component with `clean: {components: largest}`")
    vectors = fix_signs(vectors, prob.d, sign_rule)
    all_values = np.concatenate([[0.0], values])
    all_vectors = np.column_stack([prob.c, vectors])
    residuals = np.concatenate([[0.0], prob.residuals(vectors, values)])
    skews = np.concatenate([[0.0], skewness(vectors, prob.d)])
    return Eigenpairs(values=all_values, vectors=all_vectors, method=used, iterations=raw.iterations,
                      n_solves=raw.n_solves, residuals=residuals, skewness=skews, shift=raw.shift,
                      sign_rule=sign_rule, attempts=tuple(attempts), seconds=time.perf_counter() - start)
