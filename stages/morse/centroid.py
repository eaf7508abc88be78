"""Centres of a mesh: vertex mean, area-weighted surface centroid, minimal enclosing sphere.

The thesis calls the point c of the mixture distance "the mesh centroid" in one
place and "the centre of the minimal enclosing sphere of the vertices" in
another. topomatch defaults to the vertex mean, because the centred vertex matrix
V_c used for the affine term is centred at it; the other two are options.
"""

from __future__ import annotations

import numpy as np


def vertex_mean(V: np.ndarray) -> np.ndarray:
    """Mean of the vertices, (3,)."""
    return np.asarray(V, dtype=np.float64).mean(axis=0)


def surface_centroid(V: np.ndarray, F: np.ndarray) -> np.ndarray:
    """Area-weighted centroid of the surface, (3,) (independent of the sampling density)."""
    P = V[F]
    area = 0.5 * np.linalg.norm(np.cross(P[:, 1] - P[:, 0], P[:, 2] - P[:, 0]), axis=1)
    total = area.sum()
    if total <= 0:
        return vertex_mean(V)
    return (area[:, None] * P.mean(axis=1)).sum(axis=0) / total


def enclosing_sphere_center(V: np.ndarray, *, tol: float = 1e-9, max_iter: int = 10000) -> np.ndarray:
    """Centre of the minimal enclosing sphere of the vertices, (3,).

    Bădoiu–Clarkson iteration started from the bounding-box centre: move the
    centre towards the farthest point by 1/(k+1) of the gap; it converges to the
    exact centre, with radius error O(1/k). Stops when the step is below ``tol``
    times the bounding-box diagonal. (No maintained Python package offers this;
    Welzl's algorithm would be exact but is recursive and slower in numpy.)
    """
    V = np.asarray(V, dtype=np.float64)
    c = (V.min(axis=0) + V.max(axis=0)) / 2
    scale = float(np.linalg.norm(V.max(axis=0) - V.min(axis=0))) or 1.0
    for k in range(1, max_iter + 1):
        far = V[np.argmax(((V - c) ** 2).sum(axis=1))]
        step = (far - c) / (k + 1)
        c = c + step
        if np.linalg.norm(step) < tol * scale and k > 50:
            break
    return c


CENTROIDS = {
    "vertices": lambda V, F: vertex_mean(V),
    "area": surface_centroid,
    "enclosing_sphere": lambda V, F: enclosing_sphere_center(V),
}
