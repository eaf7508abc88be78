"""Pairwise distances between fixed-length descriptors, shared by the baselines."""

from __future__ import annotations

import numpy as np


def rows(X) -> np.ndarray:
    """``X`` as float64 rows: a 1-D descriptor is one row; (n, ...) becomes (n, d)."""
    X = np.asarray(X, dtype=np.float64)
    return X.reshape(1, -1) if X.ndim == 1 else X.reshape(X.shape[0], -1)


def pairwise(X, Y=None, *, metric: str) -> np.ndarray:
    """All distances between the rows of ``X`` (n, ...) and ``Y`` (m, ...) (default ``X``) -> (n, m).

    ``metric`` is a ``scipy.spatial.distance.cdist`` metric ('cityblock' = L1, 'euclidean' = L2).
    """
    from scipy.spatial.distance import cdist

    X = rows(X)
    Y = X if Y is None else rows(Y)
    if X.shape[1] != Y.shape[1]:
        raise ValueError(f"descriptor sizes differ: {X.shape} vs {Y.shape}")
    return cdist(X, Y, metric=metric)


def l2(a, b, what: str) -> float:
    """L2 (Euclidean) distance of two 1-D descriptors of the same length; ``what`` names them in the error."""
    a = np.asarray(a, dtype=np.float64)
    b = np.asarray(b, dtype=np.float64)
    if a.shape != b.shape or a.ndim != 1:
        raise ValueError(f"{what} descriptors must be 1-D of equal length, got {a.shape} and {b.shape}")
    return float(np.linalg.norm(a - b))
