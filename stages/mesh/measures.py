"""Geometric measures of a triangle mesh: area, bounding box, edge lengths, counts.

The surface area is computed with libigl (``igl.doublearea``, the reference) and
cross-checked with open3d's ``TriangleMesh.get_surface_area``; both values and
their relative difference are reported. Edge statistics are over the unique
undirected edges (``igl.edges``), so interior edges are not counted twice.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass
from typing import ClassVar

import numpy as np

from topomatch.pipeline.contract import Params, StageResult, stage
from topomatch.stages.mesh.mesh import Mesh


def bbox_diagonal(V: np.ndarray) -> float:
    """Length of the diagonal of the axis-aligned bounding box of the points ``V`` (n, 3); 0 if empty."""
    V = np.asarray(V, dtype=np.float64)
    if V.shape[0] == 0:
        return 0.0
    return float(np.linalg.norm(V.max(axis=0) - V.min(axis=0)))


def mean_edge_length(mesh: Mesh) -> float:
    """Mean length of the unique undirected edges of ``mesh`` (0 if it has no faces)."""
    import igl

    if mesh.n_faces == 0:
        return 0.0
    E = igl.edges(mesh.F)
    return float(np.linalg.norm(mesh.V[E[:, 0]] - mesh.V[E[:, 1]], axis=1).mean())


@dataclass(frozen=True)
class MeshMeasures:
    """Geometric measures of a mesh.

    Attributes
    ----------
    n_vertices, n_faces, n_edges : int
        Counts (``n_edges``: unique undirected edges).
    area : float
        Surface area, sum of ``igl.doublearea / 2``.
    area_open3d : float
        Surface area from ``open3d.geometry.TriangleMesh.get_surface_area``.
    area_rel_diff : float
        ``|area - area_open3d| / area`` (0 when both are 0).
    bbox_min, bbox_max : tuple of 3 floats
        Corners of the axis-aligned bounding box of all vertices.
    bbox_diagonal : float
        ``|bbox_max - bbox_min|``.
    edge_mean, edge_min, edge_max, edge_std : float
        Statistics of the unique edge lengths (population std, ``ddof=0``).
    """

    n_vertices: int
    n_faces: int
    n_edges: int
    area: float
    area_open3d: float
    area_rel_diff: float
    bbox_min: tuple[float, float, float]
    bbox_max: tuple[float, float, float]
    bbox_diagonal: float
    edge_mean: float
    edge_min: float
    edge_max: float
    edge_std: float

    def as_dict(self) -> dict:
        """All fields as a plain dict."""
        return asdict(self)


def mesh_measures(mesh: Mesh) -> MeshMeasures:
    """Measure ``mesh`` (usable outside the pipeline).

    Parameters
    ----------
    mesh : Mesh
        ``V`` (n, 3) float64, ``F`` (m, 3) int64; at least one vertex.

    Returns
    -------
    MeshMeasures
        Counts, areas (libigl and open3d), bounding box and edge-length statistics.
        With no faces the areas and edge statistics are 0.
    """
    import igl

    from topomatch.stages.adapters.open3d_adapter import to_open3d

    V, F = mesh.V, mesh.F
    if V.shape[0] == 0:
        raise ValueError(f"mesh {mesh.name!r} has no vertices")
    lo, hi = V.min(axis=0), V.max(axis=0)
    if F.shape[0] > 0:
        area = float(igl.doublearea(V, F).sum() / 2.0)
        area_o3d = float(to_open3d(mesh).get_surface_area())
        E = igl.edges(F)
        lengths = np.linalg.norm(V[E[:, 0]] - V[E[:, 1]], axis=1)
    else:
        area = area_o3d = 0.0
        E = np.zeros((0, 2), np.int64)
        lengths = np.zeros(1)
    rel = abs(area - area_o3d) / area if area > 0 else float(area_o3d != 0.0)
    return MeshMeasures(
        n_vertices=mesh.n_vertices,
        n_faces=mesh.n_faces,
        n_edges=int(E.shape[0]),
        area=area,
        area_open3d=area_o3d,
        area_rel_diff=float(rel),
        bbox_min=tuple(float(x) for x in lo),
        bbox_max=tuple(float(x) for x in hi),
        bbox_diagonal=float(np.linalg.norm(hi - lo)),
        edge_mean=float(lengths.mean()),
        edge_min=float(lengths.min()),
        edge_max=float(lengths.max()),
        edge_std=float(lengths.std()),
    )


class MeasuresParams(Params):
    """Parameters of :func:`measures` (none)."""


@dataclass(frozen=True, eq=False)
class MeasuresResult(StageResult):
    """The measures of the current mesh (the mesh itself passes through unchanged)."""

    column_labels: ClassVar[dict[str, str]] = {
        "area": "surface area (mesh units²)", "area_open3d": "surface area by open3d (mesh units²)",
        "bbox_diagonal": "bounding-box diagonal (mesh units)", "edge_mean": "mean edge length (mesh units)",
        "edge_min": "shortest edge (mesh units)", "edge_max": "longest edge (mesh units)",
        "vertices": "vertices", "faces": "faces", "edges": "edges"}

    measures: MeshMeasures

    def summary(self) -> dict:
        m = self.measures
        return {
            "vertices": m.n_vertices,
            "faces": m.n_faces,
            "edges": m.n_edges,
            "area": m.area,
            "area_open3d": m.area_open3d,
            "area_rel_diff": m.area_rel_diff,
            "bbox_diagonal": m.bbox_diagonal,
            "edge_mean": m.edge_mean,
            "edge_min": m.edge_min,
            "edge_max": m.edge_max,
            "edge_std": m.edge_std,
        }


@stage("measures", params=MeasuresParams, version=1, consumes=("mesh",), produces=())
def measures(mesh: Mesh, *, params: MeasuresParams) -> MeasuresResult:
    """Measure area (libigl, checked against open3d), bounding box and edge lengths."""
    return MeasuresResult(measures=mesh_measures(mesh))
