"""Height along the principal axis of the vertices (a cheap, rotation-invariant Morse function)."""

from __future__ import annotations

import numpy as np

from topomatch.stages.morse.function import MorseFunction, normalized


def principal_height(V: np.ndarray) -> MorseFunction:
    """Coordinate of each vertex along the first principal axis, normalised to [0, 1].

    Sign rule: the axis is oriented so that the third central moment of the
    heights is positive (the longer tail points to larger values); invariant to
    rotation, translation and uniform scale. For a shape symmetric about its
    middle plane the sign is arbitrary.
    """
    V = np.asarray(V, dtype=np.float64)
    Q = V - V.mean(axis=0)
    _, vecs = np.linalg.eigh(Q.T @ Q)
    h = Q @ vecs[:, -1]
    if np.mean(h**3) < 0:
        h = -h
    return MorseFunction(normalized(h), "height", root=V.mean(axis=0))
