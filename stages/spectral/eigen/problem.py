"""The eigenproblem ``Q phi = lambda K phi`` and what every solver shares: the lumped mass, the exact
constant, K-orthonormalisation, start blocks, the shift, and the unnormalised result."""

from __future__ import annotations

import os
from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp


class NotConverged(Exception):
    """A solver that did not reach the tolerance (the next solver of the chain is tried)."""


@dataclass
class Raw:
    """Unnormalised output of a method: the nev non-constant pairs."""

    values: np.ndarray
    vectors: np.ndarray
    iterations: int
    n_solves: int
    shift: float


class Problem:
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


def axis_functions(prob: Problem, V: np.ndarray, p: int) -> np.ndarray:
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


def start_block(prob: Problem, p: int, V: np.ndarray | None, seed: int, noise: float = 0.05,
                 axis: np.ndarray | None = None) -> np.ndarray:
    """A start block (n, p): :func:`axis_functions` of ``V`` plus ``noise`` times seeded Gaussian vectors.

    Without ``V``, Gaussian vectors only. The noise keeps every eigenvector present in
    the start (on a symmetric mesh the coordinate functions can all be odd under a
    symmetry under which the Fiedler vector is even, and a Krylov space grown from them
    would never contain it); the first inverse iteration damps its high frequencies.
    """
    G = np.random.default_rng(seed).standard_normal((prob.n, p))
    if V is None:
        return G
    return (axis_functions(prob, V, p) if axis is None else axis) + noise * G


def rayleigh_estimate(prob: Problem, X: np.ndarray) -> float:
    """Smallest Rayleigh quotient among the (deflated) columns of ``X``: an upper bound of lambda2."""
    X = prob.deflate(X)
    num = np.einsum("ij,ij->j", X, prob.Q @ X)
    den = np.einsum("ij,ij->j", X, prob.K @ X)
    ok = den > 0
    return float(np.min(num[ok] / den[ok])) if ok.any() else 1.0


def auto_shift(prob: Problem, V: np.ndarray | None, axis: np.ndarray | None = None) -> float:
    """sigma = -0.01 * (Rayleigh quotient of the first principal-axis coordinate), an upper bound of lambda2.

    ``axis`` (n, >= 1) are precomputed :func:`axis_functions`. Without ``V``:
    ``-1e-8 * median(diag Q / diag K)`` (``diag Q / diag K`` ~ lambda_max ~ n lambda2 on a surface mesh).
    """
    if V is not None:
        axis = axis_functions(prob, V, 1) if axis is None else axis
        est = rayleigh_estimate(prob, axis[:, :1])
        if np.isfinite(est) and est > 0:
            return -0.01 * est
    ratio = np.median(prob.Q.diagonal() / prob.K.diagonal())
    return -1e-8 * float(ratio) if ratio > 0 else -1e-8


def available_cpus() -> int:
    """CPUs this process may run on, at most 2 (the Fiedler blocks have 2 columns)."""
    try:
        n = len(os.sched_getaffinity(0))
    except (AttributeError, OSError):
        n = os.cpu_count() or 1
    return max(1, min(2, n))

