"""The default solver: shift-invert block Krylov-Rayleigh-Ritz with locking and thick restarts
(ARPACK on the same factorisation when it does not converge)."""

from __future__ import annotations

from typing import Callable

import numpy as np
import scipy.linalg as la

from topomatch.stages.spectral.eigen.arpack import arpack_fallback
from topomatch.stages.spectral.eigen.factorization import ShiftInvert
from topomatch.stages.spectral.eigen.problem import NotConverged, Problem, Raw, auto_shift, axis_functions, start_block


def _svqb(prob: Problem, B: np.ndarray, KB: np.ndarray, floor: np.ndarray) -> tuple[np.ndarray, np.ndarray, float]:
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


def _orthonormalize_against(prob: Problem, Z: np.ndarray, KZ: np.ndarray, B: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
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


def block_krylov(prob: Problem, solve: Callable[[np.ndarray], np.ndarray], X0: np.ndarray, nev: int,
                  tol: float, maxiter: int, max_basis: int) -> tuple[np.ndarray, np.ndarray, int, int]:
    """Block Krylov–Rayleigh–Ritz with ``W = S^{-1} K``, locking and thick restarts.

    The basis ``Z`` is K-orthonormal; its column 0 is the exact constant ``c`` (so the
    orthogonalisation deflates it, with ``Q c = 0``), and the Rayleigh–Ritz problem is
    ``H = Z[:, 1:]^T Q Z[:, 1:]``. Each step adds ``W x`` for the wanted Ritz vectors ``x`` whose
    residual is above ``tol`` (converged ones are locked: they stay in the basis but are
    no longer expanded). When the basis is full it is restarted on the current Ritz
    vectors (thick restart).

    Returns the nev smallest Ritz values, their K-normalised Ritz vectors, the number of
    block steps and of single-vector solves. Raises :class:`NotConverged`.
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
            raise NotConverged("the Krylov space stopped growing (breakdown)")
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
    raise NotConverged(f"no convergence in {maxiter} block steps (residuals {np.array2string(res, precision=2)}, "
                        f"tol {tol:g})")


def shift_invert_pairs(prob: Problem, nev: int, *, tol: float, maxiter: int, V: np.ndarray | None, seed: int,
                  sigma: float | None, backend: str, X0: np.ndarray | None = None, threads: int = 1) -> Raw:
    p = nev + 1  # one more start vector than wanted pairs
    axis = None if V is None else axis_functions(prob, V, p)
    sigma = auto_shift(prob, V, axis) if sigma is None else float(sigma)
    try:
        fac = ShiftInvert(prob.Q, prob.K, sigma, backend=backend, threads=threads)
    except (RuntimeError, ValueError) as exc:  # singular factor, ...
        raise NotConverged(f"factorisation of Q - sigma K failed ({exc})") from None
    if X0 is None:
        X0 = start_block(prob, p, V, seed, axis=axis)
    max_basis = int(min(prob.n - 1, max(6 * p, 40)))
    with fac:
        try:
            values, vectors, steps, n_solves = block_krylov(prob, fac.solve, X0, nev, tol, maxiter, max_basis)
            return Raw(values, vectors, steps, n_solves, sigma)
        except NotConverged as first:
            arpack = arpack_fallback(prob, fac, nev, tol, V, seed)
            if arpack is None:
                raise first
            return arpack



def solve(prob: Problem, nev: int, opts, V: np.ndarray | None, F: np.ndarray | None) -> Raw:
    """The ``shift_invert`` method (module docstring of :mod:`topomatch.stages.spectral.eigen`)."""
    return shift_invert_pairs(prob, nev, tol=opts.tol, maxiter=opts.maxiter, V=V, seed=opts.seed, sigma=opts.sigma,
                              backend=opts.backend, threads=opts.threads)
