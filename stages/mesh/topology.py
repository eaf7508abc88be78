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

libigl quirks avoided here: ``igl.euler_characteristic(F)`` counts
``F.max() + 1`` vertices (unreferenced vertices in the middle of ``V`` shift it),
``igl.vertex_components`` and ``igl.is_vertex_manifold`` label unreferenced
vertices too, and ``igl.boundary_loop_all`` assumes a consistently oriented
manifold (it splits the boundary of a Möbius strip into single vertices). So the
faces are re-indexed to the referenced vertices first and boundary loops are
counted from edge incidences.

Cost: every count comes from one sort of the 3m half-edges (:class:`HalfEdges`; on a broken mesh a
second, small one of the faces around its non-manifold places): edges and their incidences, boundary and
non-manifold edges, the fans around each vertex, and the orientation (an edge-manifold mesh whose two
half-edges per interior edge run opposite ways is consistently oriented, hence orientable; only a mesh
that is not is searched further, with ``igl.bfs_orient``). Components are connected components of the
edge graph (scipy). On the 48k-vertex horse the report takes about 25 ms, under one ``igl.cotmatrix``
(``benchmarks/commands.py`` times the command).
"""

from __future__ import annotations

from dataclasses import asdict, dataclass
from functools import cached_property

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


def _argsort_with_keys(key: np.ndarray, key_bound: int) -> tuple[np.ndarray, np.ndarray]:
    """(order, key[order]) of non-negative int64 keys below ``key_bound``, equal keys in index order.

    When a key and its index fit in 63 bits together, one ``np.sort`` of ``key << b | index``
    (numpy's vectorised sort: about 4x faster than ``argsort`` on 4 M keys) gives both."""
    bits = max(int(key.size - 1).bit_length(), 1)
    if key_bound <= 1 << (63 - bits):
        packed = np.sort((key << bits) | np.arange(key.size, dtype=np.int64))
        return packed & ((1 << bits) - 1), packed >> bits
    order = np.argsort(key, kind="stable")
    return order, key[order]


class HalfEdges:
    """The 3m half-edges of the triangles ``F`` (m, 3), sorted by their undirected edge, once.

    Half-edge ``3 f + k`` runs from corner ``k`` of face ``f`` to corner ``k + 1``. Attributes:
    ``forward`` (3m,) whether it runs from the edge's smaller vertex to its larger one; ``counts``
    (e,) incident faces per edge; ``E`` (e, 2) the unique edges, sorted lexicographically;
    ``pair_a``, ``pair_b`` consecutive half-edges of one edge in the sorted order (the two faces of an
    interior edge of a manifold). A mesh whose every edge has exactly two half-edges (closed and
    edge-manifold, the usual input) skips the run-length pass: its runs are the sorted pairs.
    """

    def __init__(self, F: np.ndarray, n_vertices: int):
        F = np.asarray(F, dtype=np.int64)
        self.F, self.n_vertices = F, n_vertices
        u, w = F.ravel(), F[:, [1, 2, 0]].ravel()
        self.forward = u < w  # the half-edge runs from lo to hi
        lo, hi = np.minimum(u, w), np.maximum(u, w)
        bits = max(int(max(n_vertices, 1) - 1).bit_length(), 1)
        wide = 2 * bits > 62  # over 2^31 vertices a shifted key would overflow: a product instead
        key = lo * n_vertices + hi if wide else (lo << bits) | hi  # the edges follow from the keys
        order, sorted_key = _argsort_with_keys(key, n_vertices ** 2 if wide else 1 << (2 * bits))
        if key.size % 2 == 0 and np.array_equal(sorted_key[0::2], sorted_key[1::2]) and not np.any(
                sorted_key[2::2] == sorted_key[1:-1:2]):  # every edge twice: closed, edge-manifold
            heads = sorted_key[0::2]
            self.counts = np.full(heads.size, 2, dtype=np.int64)
            self.pair_a, self.pair_b = order[0::2], order[1::2]
        else:
            starts = np.flatnonzero(np.r_[True, sorted_key[1:] != sorted_key[:-1]])
            heads = sorted_key[starts]
            self.counts = np.diff(np.r_[starts, key.size]).astype(np.int64)
            # consecutive half-edges of one edge: the faces around it, in sorted order
            same = sorted_key[1:] == sorted_key[:-1]
            self.pair_a, self.pair_b = order[:-1][same], order[1:][same]
        self.E = np.empty((heads.size, 2), dtype=np.int64)
        mask = (1 << bits) - 1
        self.E[:, 0], self.E[:, 1] = np.divmod(heads, n_vertices) if wide else (heads >> bits, heads & mask)

    @cached_property
    def twin(self) -> np.ndarray:
        """(3m,) the other half-edge of each half-edge's edge, -1 on the boundary (an edge of one face).
        Meaningful for edge-manifold edges; a half-edge of an edge with three faces or more has some other
        half-edge of it (never -1)."""
        twin = np.full(3 * self.F.shape[0], -1, dtype=np.int64)
        twin[self.pair_a], twin[self.pair_b] = self.pair_b, self.pair_a
        return twin

    def ends(self, h: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(start, end) vertices of the half-edges ``h``: half-edge ``3 f + k`` runs from corner ``k`` of
        face ``f`` to corner ``k + 1``."""
        corners = self.F.ravel()
        return corners[h], corners[h - h % 3 + (h + 1) % 3]

    @cached_property
    def disagreeing(self) -> np.ndarray:
        """(len(pair_a),) bool: the two faces of the pair traverse their edge in the same direction (their
        orientations disagree). Computed once: the fan test and the orientability test both ask."""
        return self.forward[self.pair_a] == self.forward[self.pair_b]

    @property
    def consistently_oriented(self) -> bool:
        """Whether every edge shared by two faces is traversed in opposite directions by them (the
        faces' orientations agree). Meaningful for edge-manifold meshes."""
        return not self.disagreeing.any()

    @cached_property
    def components(self) -> tuple[int, np.ndarray]:
        """(count, (n_vertices,) labels) of the connected components of the edge graph
        (:func:`edge_graph_components` of ``E``); computed once for the report and ``clean``."""
        return edge_graph_components(self.E, self.n_vertices)


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
    he = HalfEdges(F, int(F.max()) + 1)
    return he.E, he.counts


def _compact_faces(F: np.ndarray, n_vertices: int) -> tuple[np.ndarray, int]:
    """``F`` re-indexed to its referenced vertices 0..r-1 (order kept), and r; ``F`` itself when every
    vertex is referenced."""
    used = np.bincount(F.ravel(), minlength=n_vertices) > 0
    n_ref = int(used.sum())
    if n_ref == n_vertices:
        return F, n_ref
    new_index = np.cumsum(used) - 1
    return new_index[F], n_ref


def edge_graph_components(E: np.ndarray, n_vertices: int) -> tuple[int, np.ndarray]:
    """Connected components of the graph of the edges ``E`` (k, 2) on ``n_vertices`` vertices: (count, labels).

    Edges sorted by their first vertex (as :class:`HalfEdges` gives them) become a CSR matrix directly;
    others go through scipy's COO conversion (a sort).
    """
    from scipy.sparse import coo_matrix, csr_matrix
    from scipy.sparse.csgraph import connected_components

    E = np.asarray(E, dtype=np.int64)
    if len(E) and (E.min() < 0 or E.max() >= n_vertices):  # the CSR path below would not check it
        raise ValueError(f"edge vertex indices must lie in 0..{n_vertices - 1}, got {E.min()}..{E.max()}")
    if len(E) and np.all(E[1:, 0] >= E[:-1, 0]):
        indptr = np.zeros(n_vertices + 1, dtype=np.int64)
        np.cumsum(np.bincount(E[:, 0], minlength=n_vertices), out=indptr[1:])
        A = csr_matrix((np.ones(len(E)), E[:, 1], indptr), shape=(n_vertices, n_vertices))
    else:
        A = coo_matrix((np.ones(len(E), dtype=bool), (E[:, 0], E[:, 1])), shape=(n_vertices, n_vertices))
    count, labels = connected_components(A, directed=False)
    return int(count), labels


def boundary_loops(E_boundary: np.ndarray) -> tuple[int, np.ndarray, np.ndarray]:
    """Connected components of the graph of the boundary edges ``E_boundary`` (k, 2), on their own vertices:
    (count, (v,) the vertices, (v,) the loop of each). On a manifold mesh these are the boundary cycles."""
    if len(E_boundary) == 0:
        return 0, np.zeros(0, np.int64), np.zeros(0, np.int64)
    vertices, local = np.unique(E_boundary, return_inverse=True)
    count, labels = edge_graph_components(local.reshape(-1, 2), len(vertices))
    return count, vertices, np.asarray(labels, dtype=np.int64)


def nonmanifold_vertices(F: np.ndarray, n_vertices: int, half_edges: HalfEdges | None = None) -> np.ndarray:
    """(n_vertices,) bool: vertices whose incident faces do not form one edge-connected fan.

    The same test as ``igl.is_vertex_manifold`` (faces around a vertex must form exactly one
    connected component through shared edges; vertices on non-manifold edges are not flagged
    for that reason alone), vectorised: the corners of the faces are linked across every
    shared edge, and a vertex's fans are the connected components among its corners.
    ``half_edges``: the sorted half-edges of ``F``, if already computed.

    Vertices whose edges are all manifold (two faces at most) and consistently oriented, and whose
    faces repeat no index -- every vertex of the usual input -- take :func:`_walk_fans`, a walk
    around every vertex at once; the others (a few on a broken mesh) the connected components of the
    corner graph of the faces around them.
    """
    F = np.asarray(F, dtype=np.int64)
    he = half_edges or HalfEdges(F, n_vertices)
    if not F.shape[0]:
        return np.zeros(n_vertices, dtype=bool)
    hard = np.zeros(n_vertices, dtype=bool)  # vertices the walk cannot go around
    hard[he.E[he.counts > 2].ravel()] = True
    disagree = he.pair_a[he.disagreeing]  # a half-edge of each edge whose two faces disagree in orientation
    if disagree.size:
        for end in he.ends(disagree):
            hard[end] = True
    hard[F[(F[:, 0] == F[:, 1]) | (F[:, 1] == F[:, 2]) | (F[:, 2] == F[:, 0])].ravel()] = True
    bad = _walk_fans(F, n_vertices, he, ~hard)
    if hard.any():
        around = np.flatnonzero(hard[F[:, 0]] | hard[F[:, 1]] | hard[F[:, 2]])  # every face at a hard vertex
        bad[hard] = _corner_graph_fans(F[around], n_vertices, HalfEdges(F[around], n_vertices))[hard]
    return bad


def _walk_fans(F: np.ndarray, n_vertices: int, he: HalfEdges, walk: np.ndarray) -> np.ndarray:
    """:func:`nonmanifold_vertices` of the vertices ``walk`` (n_vertices,) bool whose edges are all manifold
    and consistently oriented and whose faces repeat no index (False for the others), in O(m): the
    corners of a vertex are ordered around it by ``sigma`` (half-edge ``h`` leaves the vertex at its
    corner; ``sigma(h)`` is the twin of the half-edge entering that corner, which leaves the same vertex
    in the next face), so every fan is a cycle or a path of ``sigma``. A vertex has one fan iff it has
    at most one path start (a corner whose half-edge has no twin) and the walk from it (or from any
    corner) first ends -- back at its start, or off the path's end -- after exactly as many steps as the
    vertex has corners. The walks run for all vertices at once, one step per corner of the vertex with
    most corners (or until every walk left has ended early); with the vertices sorted by corner count,
    those still walking at step k are a prefix, so a step is a slice, not a selection."""
    m = F.shape[0]
    twin = he.twin
    sigma = np.empty(3 * m + 1, dtype=np.int64)  # sigma[-1] = -1: a walk off a path's end stays off
    sigma[-1] = -1
    for k in range(3):  # the twin of the previous half-edge of the face, 3 f + (k + 2) % 3; -1 on the boundary
        sigma[k:3 * m:3] = twin[(k + 2) % 3::3]
    vertex = F.ravel()
    corners = np.bincount(vertex, minlength=n_vertices)
    open_start = twin < 0  # a corner no sigma step reaches: a path (open fan) starts there
    starts = np.bincount(vertex[open_start], minlength=n_vertices)
    first = np.full(n_vertices, -1, dtype=np.int64)
    first[vertex] = np.arange(3 * m, dtype=np.int64)  # some corner of each vertex (any one starts a cycle)
    first[vertex[open_start]] = np.flatnonzero(open_start)
    bad = (starts > 1) & walk
    todo = np.flatnonzero((corners > 0) & walk & ~bad)
    count = corners[todo]
    most = int(count.max(initial=0))
    # most corners first; a stable sort of 16-bit keys is numpy's radix sort
    todo = todo[np.argsort((most - count).astype(np.uint16 if most < 1 << 16 else np.int64), kind="stable")]
    count = corners[todo]
    origin = first[todo]
    current = origin.copy()
    ended = np.zeros(todo.size, dtype=bool)  # the walk ended before its vertex's last corner
    steps = int(count[0]) if count.size else 0
    walking = np.searchsorted(-count, -np.arange(1, steps + 2), side="right")  # [k - 1]: vertices with >= k corners
    for k in range(1, steps + 1):
        now, later = walking[k - 1], walking[k]  # walking at step k; still walking after it
        step = sigma[current[:now]]
        current[:now] = step
        stop = (step < 0) | (step == origin[:now])
        ended[:later] |= stop[:later]
        bad[todo[later:now]] = ended[later:now] | ~stop[later:now]  # vertices with exactly k corners
        if later and ended[:later].all():  # every walk left has ended before its last corner: not one fan
            bad[todo[:later]] = True
            break
    return bad


def _corner_graph_fans(F: np.ndarray, n_vertices: int, he: HalfEdges) -> np.ndarray:
    """:func:`nonmanifold_vertices` of any mesh: connected components of the corner graph (scipy)."""
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components

    m = F.shape[0]
    # half-edge h = 3 f + k runs from corner h to corner 3 f + (k + 1) % 3; the corner at lo / hi:
    nxt = (np.arange(3 * m, dtype=np.int64).reshape(m, 3)[:, [1, 2, 0]]).ravel()
    h = np.arange(3 * m, dtype=np.int64)
    c_lo = np.where(he.forward, h, nxt)
    c_hi = np.where(he.forward, nxt, h)
    a, b = he.pair_a, he.pair_b  # consecutive faces around one edge
    rows = np.concatenate([c_lo[a], c_hi[a]])
    cols = np.concatenate([c_lo[b], c_hi[b]])
    graph = coo_matrix((np.ones(rows.size, dtype=bool), (rows, cols)), shape=(3 * m, 3 * m))
    n_fans, label = connected_components(graph, directed=False)
    fan_vertex = np.empty(n_fans, dtype=np.int64)
    fan_vertex[label] = F.ravel()  # every link joins two corners of one vertex: a fan is one vertex's
    return np.bincount(fan_vertex, minlength=n_vertices) > 1


def _is_orientable(F: np.ndarray, half_edges: HalfEdges) -> bool:
    """Whether an edge-manifold triangle mesh can be oriented consistently.

    A consistently oriented mesh is; otherwise ``igl.bfs_orient`` flips faces to agree with their
    neighbours patch by patch, and the result is consistent (no directed edge used twice) iff the
    mesh is orientable.
    """
    if half_edges.consistently_oriented:
        return True
    import igl

    FF, _ = igl.bfs_orient(F)
    directed = np.asarray(FF, dtype=np.int64)[:, [0, 1, 1, 2, 2, 0]].reshape(-1, 2)
    keys = directed[:, 0] * (int(directed.max()) + 1) + directed[:, 1]
    return bool(np.unique(keys).size == keys.size)


def topology_report(mesh: Mesh, half_edges: HalfEdges | None = None) -> TopologyReport:
    """Count the topological invariants of ``mesh``.

    Parameters
    ----------
    mesh : Mesh
        ``V`` (n, 3) float64, ``F`` (m, 3) int64. Any mesh is accepted (non-manifold,
        several components, unreferenced vertices, no faces).
    half_edges : HalfEdges, optional
        ``HalfEdges(mesh.F, mesh.n_vertices)`` if the caller has it (used only when every vertex is
        referenced).

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
    F = mesh.F
    n_vertices = mesh.n_vertices
    if F.shape[0] == 0:
        return TopologyReport(
            n_vertices=n_vertices, n_unreferenced_vertices=n_vertices, n_faces=0, n_edges=0,
            n_components=0, n_boundary_loops=0, n_boundary_edges=0, n_nonmanifold_edges=0,
            n_nonmanifold_vertices=0, euler_characteristic=0, genus=None, is_closed=False,
            is_manifold=True, is_orientable=None,
        )
    Fc, n_ref = _compact_faces(F, n_vertices)
    he = half_edges if half_edges is not None and Fc is F else HalfEdges(Fc, n_ref)
    E, counts = he.E, he.counts
    n_edges = int(E.shape[0])
    boundary = counts == 1
    n_boundary_edges = int(boundary.sum())
    n_nonmanifold_edges = int((counts > 2).sum())
    n_nonmanifold_vertices = int(nonmanifold_vertices(Fc, n_ref, he).sum())
    n_components = he.components[0]
    n_boundary_loops = boundary_loops(E[boundary])[0]
    chi = n_ref - n_edges + int(Fc.shape[0])
    is_manifold = n_nonmanifold_edges == 0 and n_nonmanifold_vertices == 0
    is_orientable = _is_orientable(Fc, he) if is_manifold else None
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
