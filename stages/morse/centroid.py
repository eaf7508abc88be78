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


def _circumcenter(A: np.ndarray) -> np.ndarray:
    """Centre of the smallest sphere through the 1-4 points A (k, 3) (circumcentre in their affine hull)."""
    if len(A) == 1:
        return A[0].copy()
    D = A[1:] - A[0]
    G = D @ D.T
    rhs = 0.5 * np.einsum("ij,ij->i", D, D)
    coef = np.linalg.lstsq(G, rhs, rcond=None)[0]
    return A[0] + coef @ D


def enclosing_sphere_center(V: np.ndarray, *, seed: int = 0) -> np.ndarray:
    """Centre of the minimal enclosing sphere of the vertices, (3,).

    Welzl's algorithm (1991) in its iterative move-to-front-free form with
    nested loops (expected linear time in random order) over the convex-hull
    vertices (``scipy.spatial.ConvexHull``); exact up to rounding, so the centre
    moves exactly with a rotated, scaled or translated mesh. Written here because
    no maintained Python package provides it for 3D points.
    """
    from scipy.spatial import ConvexHull, QhullError

    V = np.asarray(V, dtype=np.float64)
    lo, hi = V.min(axis=0), V.max(axis=0)
    mid, scale = (lo + hi) / 2, float(np.linalg.norm(hi - lo)) or 1.0
    P = (V - mid) / scale
    try:
        P = P[ConvexHull(P).vertices]
    except (QhullError, ValueError):  # flat or tiny point sets: use all points
        pass
    P = P[np.random.default_rng(seed).permutation(len(P))]
    eps = 1e-12

    def outside(p, c, r2):
        return float(((p - c) ** 2).sum()) > r2 * (1 + eps) + eps

    def ball(points):
        c = _circumcenter(np.asarray(points))
        return c, float(((points[0] - c) ** 2).sum())

    c, r2 = ball([P[0]])
    for i in range(1, len(P)):
        if not outside(P[i], c, r2):
            continue
        c, r2 = ball([P[i]])
        for j in range(i):
            if not outside(P[j], c, r2):
                continue
            c, r2 = ball([P[i], P[j]])
            for k in range(j):
                if not outside(P[k], c, r2):
                    continue
                c, r2 = ball([P[i], P[j], P[k]])
                for m in range(k):
                    if outside(P[m], c, r2):
                        c, r2 = ball([P[i], P[j], P[k], P[m]])
    return mid + scale * c


CENTROIDS = {
    "vertices": lambda V, F: vertex_mean(V),
    "area": surface_centroid,
    "enclosing_sphere": lambda V, F: enclosing_sphere_center(V),
}
