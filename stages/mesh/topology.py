"""Topological invariants of a triangle mesh: components, boundary, manifoldness, Euler characteristic, genus.

:func:`topology_report` is a plain function (not a stage) used by ``clean`` and by
any later stage that needs to check its input (e.g. a Reeb graph of a closed
genus-g surface must have g independent cycles).

Conventions
-----------
- Only *referenced* vertices count: isolated vertices are reported separately and
  do not enter the Euler characteristic or the components.
- Edges are unordered vertex pairs. An edge with one incident face is a boundary
  edge; with more than two, a non-manifold edge. A non-manifold vertex is one
  whose incident faces form more than one fan (``igl.is_vertex_manifold``), e.g.
  the tip of a bow tie.
- Boundary loops are the connected components of the graph of boundary edges. On
  a manifold mesh every boundary vertex has exactly two boundary edges, so these
  are exactly the boundary cycles; on non-manifold meshes the number is indicative.
- Faces with repeated indices are counted as given (``clean`` removes them).

libigl quirks handled here: ``igl.euler_characteristic(F)`` counts
``F.max() + 1`` vertices (unreferenced vertices in the middle of ``V`` shift it),
``igl.vertex_components`` and ``igl.is_vertex_manifold`` label unreferenced
vertices too, and ``igl.boundary_loop_all`` assumes a consistently oriented
manifold (it splits the boundary of a Möbius strip into single vertices). So the
faces are re-indexed to the referenced vertices first and boundary loops are
counted from edge incidences.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np

from topomatch.stages.mesh.mesh import Mesh


@dataclass(frozen=True)
class TopologyReport:
    """Topological summary of a triangle mesh (see the module docstring for conventions).

    Attributes
    ----------
    n_vertices : int
        All vertices of the mesh, referenced or not.
    n_unreferenced_vertices : int
        Vertices used by no face.
    n_faces, n_edges : int
        Triangles and unique undirected edges.
    n_components : int
        Connected components (faces connected through shared vertices).
    n_boundary_loops, n_boundary_edges : int
        Boundary cycles and edges with exactly one incident face.
    n_nonmanifold_edges : int
        Edges with three or more incident faces.
    n_nonmanifold_vertices : int
        Referenced vertices whose incident faces form more than one fan.
    euler_characteristic : int
        chi = V - E + F over referenced vertices.
    genus : int or None
        Sum over components of the genus g_i = (2 - chi_i - b_i) / 2, i.e.
        g = (2c - chi - b) / 2 for c components and b boundary loops. Defined only
        for non-empty, manifold, orientable meshes; ``None`` otherwise.
    is_closed : bool
        At least one face and no boundary edge.
    is_manifold : bool
        No non-manifold edge and no non-manifold vertex.
    is_orientable : bool or None
        Whether the faces can be oriented consistently (``None`` when not manifold).
    """

    n_vertices: int
    n_unreferenced_vertices: int
    n_faces: int
    n_edges: int
    n_components: int
    n_boundary_loops: int
    n_boundary_edges: int
    n_nonmanifold_edges: int
    n_nonmanifold_vertices: int
    euler_characteristic: int
    genus: int | None
    is_closed: bool
    is_manifold: bool
    is_orientable: bool | None

    def as_dict(self) -> dict:
        """All fields as a plain dict (for tables)."""
        return asdict(self)


def edge_incidence(F: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Unique undirected edges of the faces ``F`` and the number of faces on each.

    Parameters
    ----------
    F : (m, 3) int
        Triangles.

    Returns
    -------
    E : (k, 2) int64
        Unique edges, each with ``E[:, 0] < E[:, 1]`` (or equal for a face with a
        repeated index), sorted lexicographically.
    counts : (k,) int64
        Incident faces per edge: 1 on the boundary, 2 in the interior of a
        manifold, 3 or more on a non-manifold edge.
    """
    F = np.asarray(F, dtype=np.int64)
    if F.size == 0:
        return np.zeros((0, 2), np.int64), np.zeros(0, np.int64)
    half = np.sort(F[:, [1, 2, 2, 0, 0, 1]].reshape(-1, 2), axis=1)
    n = int(F.max()) + 1
    keys, counts = np.unique(half[:, 0] * n + half[:, 1], return_counts=True)
    E = np.stack([keys // n, keys % n], axis=1)
    return E, counts.astype(np.int64)


def _compact_faces(F: np.ndarray) -> tuple[np.ndarray, int]:
    """``F`` re-indexed to its referenced vertices 0..r-1, and r."""
    used, Fc = np.unique(F, return_inverse=True)
    return Fc.reshape(F.shape).astype(np.int64), int(used.size)


def _count_boundary_loops(E_boundary: np.ndarray, n_vertices: int) -> int:
    """Connected components of the graph formed by the boundary edges (k, 2)."""
    if len(E_boundary) == 0:
        return 0
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components

    on_boundary = np.unique(E_boundary)
    A = coo_matrix((np.ones(len(E_boundary)), (E_boundary[:, 0], E_boundary[:, 1])), shape=(n_vertices, n_vertices))
    _, labels = connected_components(A, directed=False)
    return int(np.unique(labels[on_boundary]).size)


def nonmanifold_vertices(F: np.ndarray, n_vertices: int) -> np.ndarray:
    """(n_vertices,) bool: vertices whose incident faces do not form one edge-connected fan.

    The same test as ``igl.is_vertex_manifold`` (faces around a vertex must form exactly one
    connected component through shared edges; vertices on non-manifold edges are not flagged
    for that reason alone), vectorised: the corners of the faces are linked across every
    shared edge, and a vertex's fans are the connected components among its corners.
    About 3x faster than libigl's loop (36 ms against 103 ms on 55k faces).
    """
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components

    F = np.asarray(F, dtype=np.int64)
    m = F.shape[0]
    corner = np.arange(3 * m, dtype=np.int64).reshape(m, 3)
    u, w = F.ravel(), F[:, [1, 2, 0]].ravel()  # half-edge k of face f runs from corner k to corner k+1
    cu, cw = corner.ravel(), corner[:, [1, 2, 0]].ravel()
    lo, hi = np.minimum(u, w), np.maximum(u, w)
    c_lo, c_hi = np.where(u < w, cu, cw), np.where(u < w, cw, cu)
    order = np.lexsort((hi, lo))
    same = (lo[order][1:] == lo[order][:-1]) & (hi[order][1:] == hi[order][:-1])
    first, second = order[:-1][same], order[1:][same]  # consecutive faces around one edge
    a = np.concatenate([c_lo[first], c_hi[first]])
    b = np.concatenate([c_lo[second], c_hi[second]])
    graph = coo_matrix((np.ones(a.size, dtype=bool), (a, b)), shape=(3 * m, 3 * m))  # bool: repeats stay edges
    _, label = connected_components(graph, directed=False)
    pairs = np.unique(F.ravel() * (3 * m) + label)  # (vertex, fan) pairs
    fans = np.bincount(pairs // (3 * m), minlength=n_vertices)
    return fans > 1


def _is_orientable(F: np.ndarray) -> bool:
    """Whether an edge-manifold triangle mesh can be oriented consistently.

    ``igl.bfs_orient`` flips faces to agree with their neighbours patch by patch;
    the result is consistent (no directed edge used twice) iff the mesh is orientable.
    """
    import igl

    FF, _ = igl.bfs_orient(F)
    directed = np.asarray(FF, dtype=np.int64)[:, [0, 1, 1, 2, 2, 0]].reshape(-1, 2)
    keys = directed[:, 0] * (int(directed.max()) + 1) + directed[:, 1]
    return bool(np.unique(keys).size == keys.size)


def topology_report(mesh: Mesh) -> TopologyReport:
    """Count the topological invariants of ``mesh``.

    Parameters
    ----------
    mesh : Mesh
        ``V`` (n, 3) float64, ``F`` (m, 3) int64. Any mesh is accepted (non-manifold,
        several components, unreferenced vertices, no faces).

    Returns
    -------
    TopologyReport
        See its attributes; ``genus`` is ``None`` unless the mesh is a non-empty
        orientable manifold.

    Examples
    --------
    A torus reports ``euler_characteristic=0, genus=1, is_closed=True``; a disc
    reports ``n_boundary_loops=1, genus=0``.
    """
    import igl

    F = mesh.F
    n_vertices = mesh.n_vertices
    if F.shape[0] == 0:
        return TopologyReport(
            n_vertices=n_vertices, n_unreferenced_vertices=n_vertices, n_faces=0, n_edges=0,
            n_components=0, n_boundary_loops=0, n_boundary_edges=0, n_nonmanifold_edges=0,
            n_nonmanifold_vertices=0, euler_characteristic=0, genus=None, is_closed=False,
            is_manifold=True, is_orientable=None,
        )
    Fc, n_ref = _compact_faces(F)
    E, counts = edge_incidence(Fc)
    n_edges = int(E.shape[0])
    boundary = counts == 1
    n_boundary_edges = int(boundary.sum())
    n_nonmanifold_edges = int((counts > 2).sum())
    n_nonmanifold_vertices = int(nonmanifold_vertices(Fc, n_ref).sum())
    n_components = int(np.unique(igl.vertex_components(Fc)).size)
    n_boundary_loops = _count_boundary_loops(E[boundary], n_ref)
    chi = n_ref - n_edges + int(Fc.shape[0])
    is_manifold = n_nonmanifold_edges == 0 and n_nonmanifold_vertices == 0
    is_orientable = _is_orientable(Fc) if is_manifold else None
    genus = None
    if is_manifold and is_orientable:
        twice = 2 * n_components - chi - n_boundary_loops
        if twice >= 0 and twice % 2 == 0:
            genus = twice // 2
    return TopologyReport(
        n_vertices=n_vertices,
        n_unreferenced_vertices=n_vertices - n_ref,
        n_faces=int(F.shape[0]),
        n_edges=n_edges,
        n_components=n_components,
        n_boundary_loops=n_boundary_loops,
        n_boundary_edges=n_boundary_edges,
        n_nonmanifold_edges=n_nonmanifold_edges,
        n_nonmanifold_vertices=n_nonmanifold_vertices,
        euler_characteristic=chi,
        genus=genus,
        is_closed=n_boundary_edges == 0,
        is_manifold=is_manifold,
        is_orientable=is_orientable,
    )
