"""Cleaning and validating a triangle mesh before the science stages.

The repairs, in this order:

1. drop unreferenced (isolated) vertices (``igl.remove_unreferenced``);
2. merge duplicated vertices (``igl.remove_duplicate_vertices``). libigl snaps the
   coordinates to a grid of spacing ``eps = merge_tolerance * bbox_diagonal`` and
   merges vertices in the same cell, so two points closer than ``eps`` usually, but
   not always, merge (they may straddle a cell border); with ``merge_tolerance=0``
   only exactly equal positions merge. The vertex order is kept (libigl sorts
   it; see :func:`merge_duplicate_vertices`). The default 1e-9 merges the copies of a
   vertex that OBJ/STL writers duplicate per face and nothing a modeller meant
   to keep apart;
3. drop degenerate faces: faces with a repeated vertex index (often created by
   step 2) or an area of exactly 0.0 in floating point. Removing a zero-area face
   with three distinct (collinear) vertices can open a hole, which the
   topology report after cleaning then shows;
4. drop duplicated faces: faces with the same three vertices in any order or
   orientation; the first occurrence is kept;
5. handle several connected components (``components``): keep them all, keep the
   one with the most faces (ties: the lowest component id), or fail;
6. drop the vertices orphaned by steps 3–5.

The topology of the mesh before and after (:func:`~topomatch.stages.mesh.topology.topology_report`)
is part of the result, so a run's table shows genus, components, Euler
characteristic and manifoldness of every input.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

import numpy as np
from pydantic import Field

from topomatch.pipeline.contract import InputError, Params, StageResult, stage
from topomatch.stages.mesh.geometry import double_areas_and_sq_lengths, min_max3
from topomatch.stages.mesh.mesh import Mesh
from topomatch.stages.mesh.topology import HalfEdges, TopologyReport, topology_report


class CleanParams(Params):
    """Parameters of :func:`clean`."""

    merge_tolerance: float = Field(
        1e-9, ge=0, allow_inf_nan=False,
        description="merge vertices closer than merge_tolerance * bounding-box diagonal "
                    "(libigl grid snapping, coordinate-wise); 0 merges exact duplicates only",
    )
    drop_degenerate: bool = Field(True, description="drop faces with a repeated vertex index or zero area")
    drop_duplicate_faces: bool = Field(True, description="drop faces with the same three vertices as an earlier face (any order)")
    components: Literal["keep_all", "largest", "fail"] = Field(
        "keep_all", description="several connected components: keep all, keep the one with most faces, or fail")
    fail_on_nonmanifold: bool = Field(False, description="fail if non-manifold edges or vertices remain after cleaning")


@dataclass(frozen=True, eq=False)
class CleanResult(StageResult):
    """A cleaned mesh, its topology before and after, and what was removed.

    Attributes
    ----------
    mesh : Mesh
        The cleaned mesh (same name as the input).
    before, after : TopologyReport
        Topology of the input and of the cleaned mesh.
    merged_vertices : int
        Vertices removed by merging duplicates.
    unreferenced_vertices : int
        Isolated vertices of the input plus vertices orphaned by dropping
        degenerate or duplicated faces.
    degenerate_faces, duplicate_faces : int
        Faces dropped as degenerate / as duplicates.
    dropped_components : int
        Components dropped by ``components='largest'``.
    dropped_component_faces, dropped_component_vertices : int
        Faces and vertices of those components.
    """

    mesh: Mesh
    before: TopologyReport
    after: TopologyReport
    merged_vertices: int
    unreferenced_vertices: int
    degenerate_faces: int
    duplicate_faces: int
    dropped_components: int
    dropped_component_faces: int
    dropped_component_vertices: int

    def summary(self) -> dict:
        a = self.after
        return {
            "vertices": self.mesh.n_vertices,
            "faces": self.mesh.n_faces,
            "merged_vertices": self.merged_vertices,
            "unreferenced_vertices": self.unreferenced_vertices,
            "degenerate_faces": self.degenerate_faces,
            "duplicate_faces": self.duplicate_faces,
            "dropped_components": self.dropped_components,
            "components": a.n_components,
            "genus": a.genus,
            "euler": a.euler_characteristic,
            "boundary_loops": a.n_boundary_loops,
            "closed": a.is_closed,
            "manifold": a.is_manifold,
            "nonmanifold_edges": a.n_nonmanifold_edges,
            "nonmanifold_vertices": a.n_nonmanifold_vertices,
        }


def _remove_unreferenced(V: np.ndarray, F: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    import igl

    NV, NF, _, _ = igl.remove_unreferenced(V, F)
    return np.ascontiguousarray(NV, dtype=np.float64), np.ascontiguousarray(NF, dtype=np.int64).reshape(-1, 3)


def _igl_merge_grid(V: np.ndarray, eps: float) -> np.ndarray:
    """The rows ``igl.remove_duplicate_vertices`` compares, (n, 3) float64: ``round(V / eps)`` with libigl's
    rounding (half away from zero) for ``eps > 0``, else ``V``; ``-0.0`` made ``+0.0`` (libigl compares with ``<``,
    for which they are equal)."""
    if eps > 0:
        X = V / eps  # finite: merge_duplicate_vertices uses eps = 0 when the grid would overflow
        X = np.where(X < 0, np.ceil(X - 0.5), np.floor(X + 0.5))
    else:
        X = np.array(V, dtype=np.float64)
    X += 0.0
    return X


def _row_hashes(X: np.ndarray) -> np.ndarray:
    """(n,) uint64 hash of each row of ``X`` (n, 3) float64: equal rows have equal hashes."""
    bits = np.ascontiguousarray(X).view(np.uint64)
    h = bits[:, 0] * np.uint64(0x9E3779B97F4A7C15)
    h ^= (h >> np.uint64(29)) + bits[:, 1] * np.uint64(0xBF58476D1CE4E5B9)
    h ^= (h >> np.uint64(31)) + bits[:, 2] * np.uint64(0x94D049BB133111EB)
    return h


def _repeated(x: np.ndarray) -> np.ndarray:
    """(n,) bool: the elements of ``x`` (n,) whose value another element has. One sort; the lookup only
    when some value repeats (the usual mesh has none)."""
    s = np.sort(x)
    values = np.unique(s[1:][s[1:] == s[:-1]])
    if not values.size:
        return np.zeros(x.size, dtype=bool)
    return values[np.minimum(np.searchsorted(values, x), values.size - 1)] == x


def merge_duplicate_vertices(V: np.ndarray, F: np.ndarray, eps: float) -> tuple[np.ndarray, np.ndarray]:
    """Merge vertices that ``igl.remove_duplicate_vertices`` finds equal up to ``eps``, keeping the vertex order.

    libigl snaps each vertex to its grid cell (:func:`_igl_merge_grid`) and merges equal cells; only
    vertices whose cell's hash another vertex shares can merge, so libigl runs on those alone (a mesh
    whose cells are all distinct comes back at once, after one sort of the hashes). Each merged group is
    represented by its first vertex, which keeps its place, so a mesh without duplicates comes back
    unchanged.

    Parameters
    ----------
    V : (n, 3) float64
    F : (m, 3) int64
    eps : float
        Absolute grid spacing of libigl's snapping (0: exact duplicates only). A spacing so small that
        ``V / eps`` overflows merges exact duplicates only (libigl would put whole octants in one cell).

    Returns
    -------
    V : (k, 3) float64
        ``k <= n`` vertices, in the order of their first occurrence in the input.
    F : (m, 3) int64
        The faces re-indexed (faces may now repeat an index).
    """
    import igl

    with np.errstate(over="ignore"):
        if eps > 0 and V.size and not np.isfinite(float(np.abs(V).max()) / eps):
            eps = 0.0
    candidates = np.flatnonzero(_repeated(_row_hashes(_igl_merge_grid(V, eps))))
    if not candidates.size:  # libigl would merge nothing
        return V, F
    _, _, group = igl.remove_duplicate_vertices(np.ascontiguousarray(V[candidates]), eps)
    first = np.full(int(group.max()) + 1, V.shape[0], dtype=np.int64)
    np.minimum.at(first, group, candidates)  # the first vertex of each merged group
    representative = np.arange(V.shape[0], dtype=np.int64)
    representative[candidates] = first[group]
    keep = representative == np.arange(V.shape[0])
    if keep.all():  # nothing merged (equal hashes of distinct cells)
        return V, F
    new_index = np.cumsum(keep) - 1
    return np.ascontiguousarray(V[keep]), np.ascontiguousarray(new_index[representative][F])


#: A face whose cross-product double area exceeds this times its longest squared edge has a positive
#: Heron area for certain (see :func:`degenerate_faces`); only the others are measured with Heron.
CERTAINLY_NOT_DEGENERATE = 1e-6


def degenerate_faces(V: np.ndarray, F: np.ndarray) -> np.ndarray:
    """Mask of degenerate faces.

    Parameters
    ----------
    V : (n, 3) float64
    F : (m, 3) int64

    Returns
    -------
    (m,) bool
        True for faces with a repeated vertex index or a zero area, computed with the
        stable Heron formula the Laplacian uses (:func:`topomatch.stages.mesh.geometry.double_areas_and_sq_lengths`),
        so that every face the Laplacian would reject as degenerate is dropped here.

    Notes
    -----
    Heron's formula is measured only on the faces libigl's cross-product areas (``igl.doublearea``,
    ``igl.squared_edge_lengths``: ~5x cheaper) cannot clear: a face with double area ``D >= t a^2``
    (``a`` its longest edge, ``t`` = :data:`CERTAINLY_NOT_DEGENERATE`) has, with sides a >= b >= c,
    ``b + c - a >= D^2 / (3 a^3) >= t^2 a / 3 = 3.3e-13 a``, over 100 times the rounding error of the
    computed lengths (~12 eps a = 2.7e-15 a), so the radicand is positive; faces with ``a`` below 1e-50
    are measured too (the radicand could underflow). The mask equals Heron's on the meshes ``clean``
    accepts (extents up to 1e50, tests); beyond ~1e77 Heron's squares overflow to NaN (a face flagged
    degenerate) while libigl's areas are infinite (a face kept).
    """
    repeated = (F[:, 0] == F[:, 1]) | (F[:, 1] == F[:, 2]) | (F[:, 2] == F[:, 0])
    if F.shape[0] == 0:
        return repeated
    import igl

    double_area = np.asarray(igl.doublearea(V, F)).ravel()
    sq = np.asarray(igl.squared_edge_lengths(V, F))
    longest = min_max3(sq[:, 0], sq[:, 1], sq[:, 2])[1]
    unsure = np.flatnonzero(~((double_area > CERTAINLY_NOT_DEGENERATE * longest) & (longest > 1e-100)) & ~repeated)
    bad = repeated
    if unsure.size:
        bad[unsure] = ~(double_areas_and_sq_lengths(V, F[unsure])[1] > 0)
    return bad


def duplicate_faces(F: np.ndarray) -> np.ndarray:
    """Mask of faces (m, 3) whose vertex set equals that of an earlier face (any order or orientation)."""
    if F.shape[0] == 0:
        return np.zeros(0, dtype=bool)
    a, b, c = F[:, 0], F[:, 1], F[:, 2]
    lo, hi = min_max3(a, b, c)
    mid = a + b + c - lo - hi  # the sorted triple, without a per-row sort
    n = int(hi.max()) + 1
    if n ** 3 < 2 ** 63:  # one int64 key per face
        key = (lo * n + mid) * n + hi
        shared = np.flatnonzero(_repeated(key))  # the faces whose key another face has
        dup = np.zeros(F.shape[0], dtype=bool)
        if not shared.size:  # the usual case
            return dup
        order = shared[np.argsort(key[shared], kind="stable")]  # the first of equal faces first
        dup[order[1:][key[order][1:] == key[order][:-1]]] = True
        return dup
    _, first = np.unique(np.column_stack([lo, mid, hi]), axis=0, return_index=True)
    dup = np.ones(F.shape[0], dtype=bool)
    dup[first] = False
    return dup


def _face_components(F: np.ndarray, half_edges: HalfEdges) -> tuple[int, np.ndarray]:
    """(number of connected components, (m,) component of each face) of a mesh without unreferenced
    vertices, from its half-edges; components are numbered by their smallest vertex, as
    ``igl.vertex_components`` numbers them."""
    count, labels = half_edges.components
    return count, np.asarray(labels, dtype=np.int64)[F[:, 0]]


EXTENT_RANGE = (1e-50, 1e50)
"""Supported extents: squared areas (Heron's formula, ~ extent^4) stay normal double-precision numbers."""


def _check_extent(name: str, V: np.ndarray) -> float:
    """Refuse a mesh whose size makes squared lengths overflow or underflow (areas, cotangents); return the
    diagonal of its bounding box."""
    lo, hi = EXTENT_RANGE
    with np.errstate(over="ignore", invalid="ignore"):
        sides = np.array([V[:, k].max() - V[:, k].min() for k in range(3)]) if len(V) else np.zeros(3)
        extent = float(np.max(np.abs(sides)))
    if extent == 0.0:
        raise InputError(name, "all vertices are at one point")
    if not lo <= extent <= hi:
        what = "overflow" if not extent < hi else "underflow"
        raise InputError(name, f"the mesh is {extent:.3g} units across: squared lengths and areas {what} double "
                               f"precision (supported: {lo:g} to {hi:g}); rescale it, e.g. to unit size")
    return float(np.linalg.norm(sides))


def clean_mesh(mesh: Mesh, params: CleanParams | None = None) -> CleanResult:
    """Repair and validate ``mesh`` (see the module docstring for the steps).

    Parameters
    ----------
    mesh : Mesh
        ``V`` (n, 3) float64, ``F`` (m, 3) int64.
    params : CleanParams, optional
        Defaults when omitted.

    Returns
    -------
    CleanResult

    Raises
    ------
    InputError
        Named after ``mesh.name``: no faces (before or after cleaning), several
        components with ``components='fail'``, non-manifold elements with
        ``fail_on_nonmanifold=True``.
    """
    params = params or CleanParams()
    before = topology_report(mesh)
    if mesh.n_faces == 0:
        raise InputError(mesh.name, "mesh has no faces")

    V, F = mesh.V, mesh.F
    if before.n_unreferenced_vertices:
        V, F = _remove_unreferenced(V, F)
    unreferenced = mesh.n_vertices - V.shape[0]
    diagonal = _check_extent(mesh.name, V)

    n_before = V.shape[0]
    V, F = merge_duplicate_vertices(V, F, params.merge_tolerance * diagonal)
    merged = n_before - V.shape[0]

    n_degenerate = n_duplicate = 0
    if params.drop_degenerate:
        bad = degenerate_faces(V, F)
        n_degenerate = int(bad.sum())
        if n_degenerate:
            F = F[~bad]
    if params.drop_duplicate_faces:
        dup = duplicate_faces(F)
        n_duplicate = int(dup.sum())
        if n_duplicate:
            F = F[~dup]
    if F.shape[0] == 0:
        raise InputError(mesh.name, f"no faces left after cleaning ({n_degenerate} degenerate and "
                                    f"{n_duplicate} duplicated faces of {mesh.n_faces} were dropped)")
    if n_degenerate or n_duplicate:
        n_before = V.shape[0]
        V, F = _remove_unreferenced(V, F)
        unreferenced += n_before - V.shape[0]

    unchanged = V is mesh.V and F is mesh.F  # nothing was repaired: the topology is the one measured
    half_edges = None if unchanged else HalfEdges(F, V.shape[0])  # of the repaired mesh, shared with its report
    n_components, face_label = ((before.n_components, None) if unchanged
                                else _face_components(F, half_edges))
    dropped_components = dropped_faces = dropped_vertices = 0
    if n_components > 1 and params.components == "fail":
        raise InputError(mesh.name, f"mesh has {n_components} connected components; "
                                    "pass clean.components=largest or clean.components=keep_all")
    if n_components > 1 and params.components == "largest":
        if face_label is None:
            half_edges = HalfEdges(F, V.shape[0])
            _, face_label = _face_components(F, half_edges)
        keep = int(np.argmax(np.bincount(face_label, minlength=n_components)))
        mask = face_label == keep
        dropped_components = n_components - 1
        dropped_faces = int((~mask).sum())
        n_before = V.shape[0]
        V, F = _remove_unreferenced(V, F[mask])
        dropped_vertices = n_before - V.shape[0]
        unchanged, half_edges = False, None

    after = before if unchanged else topology_report(Mesh(V, F, name=mesh.name), half_edges)
    cleaned = Mesh(V, F, name=mesh.name, closed_manifold=after.is_closed and after.n_nonmanifold_edges == 0)
    if params.fail_on_nonmanifold and not after.is_manifold:
        raise InputError(mesh.name, f"mesh has {after.n_nonmanifold_edges} non-manifold edges and "
                                    f"{after.n_nonmanifold_vertices} non-manifold vertices after cleaning; "
                                    "repair it (e.g. in MeshLab) or pass clean.fail_on_nonmanifold=false")
    return CleanResult(
        mesh=cleaned,
        before=before,
        after=after,
        merged_vertices=int(merged),
        unreferenced_vertices=int(unreferenced),
        degenerate_faces=n_degenerate,
        duplicate_faces=n_duplicate,
        dropped_components=dropped_components,
        dropped_component_faces=dropped_faces,
        dropped_component_vertices=dropped_vertices,
    )


@stage("clean", params=CleanParams, version=2, consumes=("mesh",), produces=("mesh",))
def clean(mesh: Mesh, *, params: CleanParams) -> CleanResult:
    """Merge duplicate vertices, drop unreferenced vertices, degenerate and duplicated faces; report topology."""
    return clean_mesh(mesh, params)
