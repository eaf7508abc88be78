"""Uniform random points on a triangle mesh surface, and exact area moments.

Shared by the D2 and spherical-harmonic baselines. Sampling follows Osada et al. (2002),
sec. 4.1: a triangle is chosen with probability proportional to its area (here: the counts
per triangle are one multinomial draw, which is the same law), then a point uniformly
inside it,

    p = (1 - sqrt(r1)) A + sqrt(r1) (1 - r2) B + sqrt(r1) r2 C,    r1, r2 ~ U[0, 1).

With the same generator state the points of a rigidly moved or uniformly scaled mesh are the
moved / scaled points (the face choice depends only on the area *ratios*), up to round-off.
"""

from __future__ import annotations

import numpy as np

from topomatch.pipeline.contract import InputError
from topomatch.stages.mesh.mesh import Mesh


def triangle_areas(V: np.ndarray, F: np.ndarray) -> np.ndarray:
    """Areas (m,) float64 of the triangles ``F`` (m, 3) of the vertices ``V`` (n, 3)."""
    P = V[F]
    return 0.5 * np.linalg.norm(np.cross(P[:, 1] - P[:, 0], P[:, 2] - P[:, 0]), axis=1)


def checked_areas(mesh: Mesh) -> np.ndarray:
    """Triangle areas of ``mesh``, after checking that it can be sampled.

    Raises
    ------
    InputError
        Naming the mesh: no faces, face indices out of range, non-finite coordinates, or a
        zero total area.
    """
    if mesh.n_faces == 0 or mesh.n_vertices == 0:
        raise InputError(mesh.name, f"empty mesh ({mesh.n_vertices} vertices, {mesh.n_faces} faces): "
                                    "a surface descriptor needs triangles")
    lo, hi = int(mesh.F.min()), int(mesh.F.max())
    if lo < 0 or hi >= mesh.n_vertices:
        raise InputError(mesh.name, f"face indices must be in [0, {mesh.n_vertices - 1}], got range [{lo}, {hi}]")
    if not np.isfinite(mesh.V).all():
        raise InputError(mesh.name, f"{int((~np.isfinite(mesh.V)).any(axis=1).sum())} vertices have non-finite "
                                    "coordinates; run `clean` first")
    areas = triangle_areas(mesh.V, mesh.F)
    if not areas.sum() > 0:
        raise InputError(mesh.name, "the surface has zero area (all triangles degenerate)")
    return areas


def sample_surface(V: np.ndarray, F: np.ndarray, n: int, rng: np.random.Generator,
                   areas: np.ndarray | None = None, *, shuffle: bool = False) -> np.ndarray:
    """``n`` points uniformly distributed (by area) on the triangles ``F`` of ``V``.

    The number of points of each triangle is one multinomial draw with the area fractions
    as probabilities (the same law as ``n`` independent area-weighted triangle choices, and
    ~10x faster than inverting the cumulative areas point by point); each point is then
    placed uniformly in its triangle with Osada et al.'s square-root formula.

    Parameters
    ----------
    V : (nv, 3) float64
        Vertex positions.
    F : (m, 3) int64
        Triangles; at least one with positive area.
    n : int
        Number of points.
    rng : numpy.random.Generator
        Source of randomness.
    areas : (m,) float64, optional
        Precomputed triangle areas.
    shuffle : bool
        Return the points in random order. Without it they are grouped by triangle (in the
        order of ``F``), which is fine for densities but not for pairing points.

    Returns
    -------
    (n, 3) float64
    """
    if areas is None:
        areas = triangle_areas(V, F)
    counts = rng.multinomial(n, areas / areas.sum())
    face = np.repeat(np.arange(F.shape[0]), counts)
    r = rng.random((2, n))
    if shuffle:  # the same points as shuffling them afterwards, with smaller gathers
        order = rng.permutation(n)
        face, r = face[order], r[:, order]
    s = np.sqrt(r[0])
    corners = V[F][face]  # (n, 3, 3): one gather of whole triangles instead of three of vertices
    return ((1.0 - s)[:, None] * corners[:, 0] + (s * (1.0 - r[1]))[:, None] * corners[:, 1]
            + (s * r[1])[:, None] * corners[:, 2])


def area_centroid_and_rms_radius(V: np.ndarray, F: np.ndarray, areas: np.ndarray | None = None
                                 ) -> tuple[np.ndarray, float]:
    """Exact area-weighted centroid (3,) and RMS radius of the surface about it.

    Uses the exact triangle moments: ``int_T x dA = A (a + b + c) / 3`` and
    ``int_T |x|^2 dA = A (|a|^2 + |b|^2 + |c|^2 + |a + b + c|^2) / 12``, so the RMS radius
    ``sqrt(int |x - c|^2 dA / A_total)`` rotates, translates and scales exactly with the mesh
    (no sampling).
    """
    if areas is None:
        areas = triangle_areas(V, F)
    total = areas.sum()
    T = V[F]
    centroid = (areas[:, None] * T.sum(axis=1)).sum(axis=0) / (3.0 * total)
    X = T - centroid
    s = X.sum(axis=1)
    second = (areas * ((X * X).sum(axis=(1, 2)) + (s * s).sum(axis=1))).sum() / 12.0
    return centroid, float(np.sqrt(max(second / total, 0.0)))
