"""Geodesic distance from the vertex nearest the centroid (libigl's heat method)."""

from __future__ import annotations

import numpy as np

from topomatch.pipeline.contract import StageError
from topomatch.stages.morse.centroid import CENTROIDS
from topomatch.stages.morse.function import MorseFunction, normalized


def geodesic_from_centroid(V: np.ndarray, F: np.ndarray, *, centroid: str = "vertices") -> MorseFunction:
    """Heat-method geodesic distance (Crane et al. 2013, ``igl.heat_geodesics_*``) from the
    vertex closest to the centroid, normalised to [0, 1]. Time step: libigl's default
    (squared mean edge length)."""
    import igl

    c = CENTROIDS[centroid](V, F)
    source = int(np.argmin(((V - c) ** 2).sum(axis=1)))
    data = igl.HeatGeodesicsData()
    try:
        igl.heat_geodesics_precompute(V, F, data)
        d = igl.heat_geodesics_solve(data, np.array([source], dtype=np.int64))
    except RuntimeError as exc:
        raise StageError(f"libigl's heat geodesics failed ({exc})") from None
    if not np.all(np.isfinite(d)):
        raise StageError("heat geodesic distances are not finite (several connected components?)")
    return MorseFunction(normalized(d), "geodesic", root=c, info={"source_vertex": source})
