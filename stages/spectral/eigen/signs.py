"""The sign rule of the eigenvectors (module docstring of :mod:`topomatch.stages.spectral.eigen`)."""

from __future__ import annotations

from typing import Literal

import numpy as np

SignRule = Literal["skewness", "max_abs"]

#: Dimensionless skewness below which the 'skewness' sign rule defers to 'max_abs'.
SKEWNESS_TIE = 1e-6



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

