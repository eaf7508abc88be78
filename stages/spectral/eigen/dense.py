"""``scipy.linalg.eigh`` on the dense matrices: small problems, and the last fallback."""

from __future__ import annotations

import numpy as np
import scipy.linalg as la

from topomatch.stages.spectral.eigen.problem import NotConverged, Problem, Raw

#: Largest n for the dense method (and the dense fallback).
DENSE_MAX = 3000


def dense_pairs(prob: Problem, nev: int) -> Raw:
    if prob.n > DENSE_MAX:
        raise NotConverged(f"n = {prob.n} is above the dense limit {DENSE_MAX}")
    Qd, Kd = prob.Q.toarray(), prob.K.toarray()
    w, X = la.eigh(Qd, Kd, subset_by_index=[0, nev])
    X = prob.deflate(X[:, 1:])
    X = prob.k_orthonormalize(X)
    # k_orthonormalize may rotate within the block: Rayleigh–Ritz back to eigenvectors
    H = X.T @ (prob.Q @ X)
    w, S = np.linalg.eigh((H + H.T) / 2)
    return Raw(w, X @ S, 1, 0, 0.0)



def solve(prob: Problem, nev: int, opts, V: np.ndarray | None, F: np.ndarray | None) -> Raw:
    """The ``dense`` method."""
    return dense_pairs(prob, nev)
