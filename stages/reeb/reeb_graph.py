"""Reeb graph of a piecewise-linear function on a triangle mesh (thesis Algorithms 1 and 4).

The thesis builds one node per connected component of each band of vertices
(d(k-1) < d <= d(k)), placed at its centroid, and joins components of
consecutive bands that touch. topomatch computes the same graph on the
*surface* rather than on the vertices, which makes it exact for any number of
levels and any triangle size:

- a **piece** is the part of one triangle inside one band (a convex polygon; a
  triangle whose values span several bands gives several pieces);
- pieces of the same band are joined through the mesh edges whose value range
  meets the band and through shared vertices of the band, so a **node** is a
  connected component of f^{-1}(band) -- even a band thinner than the edges
  gives connected components instead of isolated vertices;
- each connected **contour** f^{-1}(l_k) (triangles crossing l_k, joined through
  edges crossing it) separates exactly one node below from one node above and
  gives one **edge** between them. Parallel edges are kept (``nx.MultiGraph``):
  a handle contained in two bands is a double edge, still one cycle.

For a closed orientable surface of genus g and levels fine enough that no band
contains a whole handle, the graph has exactly g independent cycles
(``cycle_rank = E - V + C``). Node attributes come from closed forms
(:mod:`topomatch.stages.reeb.band_geometry`): exact ``area``, ``pos`` (area centroid) and
``value`` (mean of f) of the band component, plus ``band`` and ``members``
(the vertices whose value lies in the band).

The mixture-distance skeleton (Algorithm 1) adds a ``root`` node at the centre
c, joined to every node of the first band (``root_mode="first_band"``, the
thesis) or only to the node nearest c (``"nearest"``). The root is not part of
the surface, so ``cycle_rank`` is counted without it.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

import networkx as nx
import numpy as np
from scipy.sparse import coo_matrix
from pydantic import Field
from scipy.sparse.csgraph import connected_components

from topomatch.pipeline.contract import Params, StageResult, stage

from topomatch.stages.mesh.geometry import min_max3
from topomatch.stages.reeb.band_geometry import below
from topomatch.stages.reeb.level_sets import band_index

ROOT = "root"


@dataclass(frozen=True, eq=False)
class ReebGraph:
    """A Reeb graph and its counts.

    Attributes
    ----------
    graph : networkx.MultiGraph
        Nodes 0..n-1 (and ``"root"`` when rooted) with attributes ``pos`` (3,),
        ``band``, ``value``, ``area``, ``members`` (vertex ids); edges with ``level``
        (the level index crossed; -1 for root edges) and ``length`` (distance of the
        node positions).
    levels : (N+1,) float64
        Level values.
    cycle_rank : int
        Independent cycles of the graph without the root: E - V + C.
    """

    graph: nx.MultiGraph
    levels: np.ndarray
    cycle_rank: int

    @property
    def n_nodes(self) -> int:
        return self.graph.number_of_nodes()

    @property
    def n_edges(self) -> int:
        return self.graph.number_of_edges()


def _half_edges(F: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(u, w, face) of the 3 m directed half-edges u -> w of the triangles."""
    return F.ravel(), F[:, [1, 2, 0]].ravel(), np.repeat(np.arange(len(F)), 3)


def is_closed_manifold(F: np.ndarray) -> bool:
    """True when every edge has exactly two faces (a closed, edge-manifold surface)."""
    u, w, _ = _half_edges(F)
    key = np.sort(np.minimum(u, w) * (int(F.max()) + 1) + np.maximum(u, w))
    same = key[1:] == key[:-1]
    return bool(len(key) % 2 == 0 and np.all(same[0::2]) and not np.any(same[1::2]))


def _face_pairs(u, w, face, n_vertices: int):
    """Pairs of faces sharing an edge among the given half-edges: (face1, face2, u, w).

    Faces around a non-manifold edge are chained (f1-f2, f2-f3, ...)."""
    lo, hi = np.minimum(u, w), np.maximum(u, w)
    key = lo * n_vertices + hi
    order = np.argsort(key, kind="stable")
    key, face, lo, hi = key[order], face[order], lo[order], hi[order]
    same = key[1:] == key[:-1]
    return face[:-1][same], face[1:][same], lo[:-1][same], hi[:-1][same]


def _expand(start: np.ndarray, stop: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """For rows i and integers k in [start_i, stop_i]: (row index, k) arrays."""
    count = np.maximum(stop - start + 1, 0)
    rows = np.repeat(np.arange(len(start)), count)
    offset = np.arange(count.sum()) - np.repeat(np.cumsum(count) - count, count)
    return rows, np.repeat(start, count) + offset


def _index_dtype(n: int):
    return np.int32 if n < 2**31 - 1 else np.int64


def _components(n: int, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Connected components of the graph on 0..n-1 with the edges a_i - b_i.

    Labels are numbered in the order of the smallest node of each component."""
    graph = coo_matrix((np.ones(len(a)), (a, b)), shape=(n, n))
    return connected_components(graph, directed=False)[1]


def _roots(parent: np.ndarray) -> np.ndarray:
    """Pointer jumping on a forest whose pointers go to smaller nodes: the root of every node."""
    while True:
        grand = parent[parent]
        if np.array_equal(grand, parent):
            return parent
        parent = grand


#: Hooking rounds on the roots in :func:`_row_components` before the sparse-graph step.
HOOK_ROUNDS = 8


def _row_components(n: int, rows: np.ndarray, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Connected components of the nodes 0..n-1 joined by the rows of ``rows`` (3, r) (each row joins its
    three nodes) and by the edges a_i - b_i; labels numbered by the smallest node of each component
    (as :func:`scipy.sparse.csgraph.connected_components` numbers them).

    Min-hooking instead of a sparse graph of all ~2 r edges: every node points to the smallest node
    of its rows (a forest, since pointers go to smaller nodes) and pointer jumping gives the roots;
    then, on the roots only (a fifth of the nodes on a mesh with a spatially coherent vertex order),
    every root joined to a smaller root points to the smallest one, repeatedly, while the edges
    between different roots shrink (2.5x, 9x, 20x in the first rounds on a 1.3 M-face mesh). The
    smallest node of a component always stays a root, so the final roots number the components in
    order. This costs about 0.6x scipy's connected components of the same edges."""
    idx = rows.dtype
    parent = np.arange(n, dtype=idx)
    low = np.minimum(np.minimum(rows[0], rows[1]), rows[2])
    for k in range(3):
        np.minimum.at(parent, rows[k], low)
    np.minimum.at(parent, a, np.minimum(a, b))
    np.minimum.at(parent, b, np.minimum(a, b))
    parent = _roots(parent)
    is_root = parent == np.arange(n, dtype=idx)
    rank = np.cumsum(is_root, dtype=idx) - 1  # roots renumbered 0..n_roots-1, in order
    n_roots = int(rank[-1]) + 1 if n else 0
    node_root = rank[parent]
    r0, r1, r2, ra, rb = (node_root[x] for x in (rows[0], rows[1], rows[2], a, b))
    # edges between different roots: r0 - r1, and r1 - r2 unless r2 is r0 or r1 (no repeat within a row)
    d01, d12 = r0 != r1, (r1 != r2) & (r2 != r0)
    dx = ra != rb
    ea = np.concatenate([r0[d01], r1[d12], ra[dx]])
    eb = np.concatenate([r1[d01], r2[d12], rb[dx]])
    top = np.arange(n_roots, dtype=idx)
    for _ in range(HOOK_ROUNDS):
        if not len(ea):
            break
        low = np.minimum(ea, eb)
        np.minimum.at(top, ea, low)
        np.minimum.at(top, eb, low)
        top = _roots(top)
        ea, eb = top[ea], top[eb]
        keep = ea != eb
        ea, eb = ea[keep], eb[keep]
    if len(ea):  # not done after HOOK_ROUNDS: finish on the remaining edges between roots
        top = _components(n_roots, ea, eb)[top]
    used = np.zeros(n_roots, dtype=bool)
    used[top] = True
    return (np.cumsum(used) - 1)[top][node_root]


@dataclass
class _Partition:
    """Band components and the contours between them (internal).

    Pieces (triangle, band) are not stored: a piece that contains a vertex belongs
    to that vertex's node; the rare pieces without a vertex (a band thinner than a
    triangle) are the "extra" pieces. ``node_of(face, band)`` maps pieces to nodes.
    """

    vb: np.ndarray           # (n,) band of each vertex
    t_lo: np.ndarray         # (m,) lowest and highest band of each triangle
    t_hi: np.ndarray
    vertex_node: np.ndarray  # (n,) node of each vertex, -1 when unreferenced
    node_band: np.ndarray    # (k,)
    node_of: object          # callable (face, band) -> node
    below_node: np.ndarray   # (c,) per contour component: node below, node above, level index
    above_node: np.ndarray
    contour_level: np.ndarray
    genus: np.ndarray | None  # (k,) genus of each band component (closed manifold meshes only)


def _partition(F: np.ndarray, f: np.ndarray, levels: np.ndarray, closed: bool) -> _Partition:
    n, m = len(f), len(F)
    n_bands = len(levels) - 1
    vb = band_index(f, levels)
    t0, t1, t2 = vb[F.T]
    b0, b2 = min_max3(t0, t1, t2)
    # extra pieces: bands strictly between the sorted vertex bands of a triangle (spanning 3+ bands)
    wide = np.flatnonzero(b2 - b0 >= 2)
    b1 = t0[wide] + t1[wide] + t2[wide] - b0[wide] - b2[wide]  # the middle band
    r1, k1 = _expand(b0[wide] + 1, b1 - 1)
    r2, k2 = _expand(b1 + 1, b2[wide] - 1)
    x_face, x_band = wide[np.concatenate([r1, r2])], np.concatenate([k1, k2])
    x_key = x_face * (n_bands + 1) + x_band
    order = np.argsort(x_key, kind="stable")
    x_face, x_band, x_key = x_face[order], x_band[order], x_key[order]

    def piece_id(face, band):
        """Graph id of the piece (face, band): its first vertex in the band, or n + extra index."""
        in0, in1 = t0[face] == band, t1[face] == band
        vert = np.where(in0, F[face, 0], np.where(in1, F[face, 1], F[face, 2]))
        if not len(x_key):  # every piece has a vertex
            return vert
        extra = n + np.searchsorted(x_key, face * (n_bands + 1) + band)
        return np.where(in0 | in1 | (t2[face] == band), vert, extra)

    # connectivity: the vertices of a triangle that lie in one band (all three for a triangle inside one
    # band, two for a triangle with one edge inside a band), and extra pieces across edges spanning 3+ bands.
    # Half-edges across bands come from the crossing triangles.
    whole = b0 == b2
    crossing = np.flatnonzero(~whole)
    Fc = F[crossing]
    u, w = Fc.ravel(), Fc[:, [1, 2, 0]].ravel()
    face = np.repeat(crossing, 3)
    same = vb[u] == vb[w]
    f1, f2, eu, ew = _face_pairs(u[~same], w[~same], face[~same], n)
    e_lo, e_hi = np.minimum(vb[eu], vb[ew]), np.maximum(vb[eu], vb[ew])
    rows, k = _expand(e_lo + 1, e_hi - 1)
    idx = _index_dtype(n + len(x_face))
    e01, e12, e20 = t0 == t1, t1 == t2, t2 == t0
    # per triangle, three nodes joined: (v0, v1, v2) inside one band; (v0, v1, v1), (v1, v1, v2),
    # (v0, v0, v2) with one edge inside a band; (v0, v0, v0) (nothing) otherwise
    joined = np.empty((3, m), dtype=idx)
    np.copyto(joined[0], F[:, 0])
    np.copyto(joined[0], F[:, 1], where=e12 & ~e01)
    np.copyto(joined[1], np.where(e01 | e12, F[:, 1], F[:, 0]))
    np.copyto(joined[2], np.where(e12 | e20, F[:, 2], joined[1]))
    label = _row_components(n + len(x_face), joined, piece_id(f1[rows], k).astype(idx),
                            piece_id(f2[rows], k).astype(idx))
    referenced = np.zeros(n, dtype=bool)
    referenced[F.ravel()] = True
    ids = np.concatenate([np.flatnonzero(referenced), n + np.arange(len(x_face))])
    used = np.zeros(int(label.max(initial=-1)) + 1, dtype=bool)
    used[label[ids]] = True  # components that hold a referenced vertex or an extra piece, renumbered
    node = np.full(n + len(x_face), -1, dtype=np.int64)
    node[ids] = (np.cumsum(used) - 1)[label[ids]]
    n_nodes = int(used.sum())
    vertex_node = node[:n]
    node_band = np.zeros(n_nodes, dtype=np.int64)
    node_band[vertex_node[referenced]] = vb[referenced]
    node_band[node[n:]] = x_band

    def node_of(face, band):
        return node[piece_id(face, band)]

    # contours: (triangle, level) crossings joined through edges crossing the level
    span1 = b2[crossing] - b0[crossing]
    rows_cf, c_level = _expand(b0[crossing] + 1, b2[crossing])
    c_face = crossing[rows_cf]
    c_offset = np.zeros(m, dtype=np.int64)
    c_offset[crossing] = np.cumsum(span1) - span1
    rows_c, kc = _expand(e_lo + 1, e_hi)
    if len(c_face):
        contour = _components(len(c_face), c_offset[f1[rows_c]] + kc - b0[f1[rows_c]] - 1,
                              c_offset[f2[rows_c]] + kc - b0[f2[rows_c]] - 1)
    else:
        contour = np.zeros(0, np.int64)
    _, first = np.unique(contour, return_index=True)
    rep_face, rep_level = c_face[first], c_level[first]
    below_node = node_of(rep_face, rep_level - 1)
    above_node = node_of(rep_face, rep_level)

    genus = None
    if closed:
        # Euler characteristic of each closed band component, from the mesh cut along the levels:
        # vertices (mesh vertices + edge crossings on both bounding levels), edges (mesh-edge
        # segments + contour segments on both bounding levels), faces (pieces).
        def count(idx):
            return np.bincount(idx, minlength=n_nodes)

        whole_faces = count(vertex_node[F[:, 0]][whole])
        verts = (count(vertex_node[referenced]) + count(node_of(f1[rows_c], kc - 1)) + count(node_of(f1[rows_c], kc)))
        rows_s, ks = _expand(e_lo, e_hi)
        same_half_edges = 3 * whole_faces + count(vertex_node[u[same]])  # each edge twice (closed)
        edges = (same_half_edges // 2 + count(node_of(f1[rows_s], ks))
                 + count(node_of(c_face, c_level - 1)) + count(node_of(c_face, c_level)))
        p_rows, p_band = _expand(b0[crossing], b2[crossing])
        faces = whole_faces + count(node_of(crossing[p_rows], p_band))
        genus = (2 - verts + edges - faces - count(below_node) - count(above_node)) // 2
    return _Partition(vb, b0, b2, vertex_node, node_band, node_of, below_node, above_node, rep_level, genus)


#: Upper bound on the rounds of band splitting in :func:`reeb_graph`.
MAX_SPLIT_ROUNDS = 30


def reeb_graph(
    V: np.ndarray,
    F: np.ndarray,
    f: np.ndarray,
    levels: np.ndarray,
    *,
    root: np.ndarray | None = None,
    root_mode: Literal["first_band", "nearest", "none"] = "first_band",
    split_handle_bands: bool = True,
    closed: bool | None = None,
) -> ReebGraph:
    """Reeb graph of the vertex function ``f`` with the bands of ``levels``.

    Parameters
    ----------
    V : (n, 3) float64
    F : (m, 3) int64
    f : (n,) float64
        Vertex values (linear on each triangle).
    levels : (N+1,) float64
        Level values (see :func:`topomatch.stages.reeb.level_sets.level_values`).
    root : (3,) float64, optional
        Position of a root node (the mixture distance's centre).
    root_mode : {'first_band', 'nearest', 'none'}
        How the root joins the graph (ignored without ``root``).
    split_handle_bands : bool
        On a closed manifold mesh, split (halve, repeatedly) every band that has a
        component of positive genus, i.e. a band that contains a whole handle and
        would hide its cycle. The thesis's uniform levels are kept everywhere else.
        ``ReebGraph.levels`` holds the levels actually used.
    closed : bool, optional
        Whether the mesh is a closed manifold, if known (e.g. from ``clean``);
        computed when None and ``split_handle_bands`` is on.
    """
    V = np.asarray(V, dtype=np.float64)
    F = np.asarray(F, dtype=np.int64)
    f = np.asarray(f, dtype=np.float64)
    levels = np.asarray(levels, dtype=np.float64)
    if split_handle_bands and closed is None:
        closed = is_closed_manifold(F)
    split = bool(split_handle_bands and closed)
    part = _partition(F, f, levels, split)
    for _ in range(MAX_SPLIT_ROUNDS):
        if not split or not np.any(part.genus > 0):
            break
        bands = np.unique(part.node_band[part.genus > 0])
        levels = np.union1d(levels, (levels[bands] + levels[bands + 1]) / 2)
        part = _partition(F, f, levels, split)
    return _assemble(V, F, f, levels, part, root, root_mode)


def _assemble(V, F, f, levels, part: _Partition, root, root_mode) -> ReebGraph:
    """Measure the nodes exactly and build the networkx graph."""
    import igl

    n_bands = len(levels) - 1
    n_nodes = len(part.node_band)

    def per_node(index, weights):
        return np.bincount(index, weights=weights, minlength=n_nodes).astype(np.float64, copy=False)

    # triangles inside one band: whole-triangle measures, gathered per vertex (a third of each triangle's
    # area to each of its vertices, which lie in the triangle's node): area, first moment and integral of f
    whole = part.t_lo == part.t_hi
    area_t = 0.5 * igl.doublearea(V, F).ravel()
    third = np.where(whole, area_t / 3.0, 0.0)
    vertex_weight = np.bincount(F.ravel(), weights=np.repeat(third, 3), minlength=len(V))
    vertex_node = part.vertex_node
    referenced = np.flatnonzero(vertex_node >= 0)
    vnode, vweight = vertex_node[referenced], vertex_weight[referenced]
    area = per_node(vnode, vweight)
    moment = np.stack([per_node(vnode, vweight * V[referenced, j]) for j in range(3)], 1)
    integral = per_node(vnode, vweight * f[referenced])

    # triangles across bands: closed-form measures of each piece, from the measures below each level the
    # triangle crosses (lo + 1 .. hi), padded with 0 below its lowest band and the whole triangle above
    # its highest: piece (band b) = pad[b - lo + 1] - pad[b - lo]
    crossing = np.flatnonzero(~whole)
    lo, hi = part.t_lo[crossing], part.t_hi[crossing]
    order = np.argsort(f[F[crossing]], axis=1, kind="stable")
    Fs = np.take_along_axis(F[crossing], order, axis=1)
    fa, fb, fc = f[Fs].T
    Pa, Pb, Pc = V[Fs[:, 0]], V[Fs[:, 1]], V[Fs[:, 2]]
    tri_area = area_t[crossing]
    c_rows, c_level = _expand(lo + 1, hi)
    cut = below(Pa[c_rows], Pb[c_rows], Pc[c_rows], fa[c_rows], fb[c_rows], fc[c_rows], tri_area[c_rows],
                levels[c_level])
    start = np.cumsum(hi - lo + 2) - (hi - lo + 2)
    top = start + hi - lo + 1
    slot = start[c_rows] + c_level - lo[c_rows]
    n_pad = int(top[-1]) + 1 if len(top) else 0
    pad_A, pad_M, pad_I = np.zeros(n_pad), np.zeros((n_pad, 3)), np.zeros(n_pad)
    # the whole triangle exactly as below() gives it for a value above fc
    pad_A[top], pad_M[top], pad_I[top] = tri_area, tri_area[:, None] * (Pa + Pb + Pc) / 3.0, \
        tri_area * (fa + fb + fc) / 3.0
    pad_A[slot], pad_M[slot], pad_I[slot] = cut
    rows, piece_band = _expand(lo, hi)
    piece_node = part.node_of(crossing[rows], piece_band)
    p0 = start[rows] + piece_band - lo[rows]
    area += per_node(piece_node, pad_A[p0 + 1] - pad_A[p0])
    dM = pad_M[p0 + 1] - pad_M[p0]
    moment += np.stack([per_node(piece_node, dM[:, j]) for j in range(3)], 1)
    integral += per_node(piece_node, pad_I[p0 + 1] - pad_I[p0])
    has_area = area > 1e-300
    pos = moment / np.where(has_area, area, 1)[:, None]
    if not has_area.all():  # a band met only at a vertex or an edge: mean centroid of its triangles
        Fw = F[whole]
        owners = np.concatenate([vertex_node[Fw[:, 0]], piece_node])
        centres = np.concatenate([(V[Fw[:, 0]] + V[Fw[:, 1]] + V[Fw[:, 2]]) / 3.0, ((Pa + Pb + Pc) / 3)[rows]])
        touched = per_node(owners, np.ones(len(owners)))
        fallback = np.stack([per_node(owners, centres[:, j]) for j in range(3)], 1) / np.maximum(touched, 1)[:, None]
        pos[~has_area] = fallback[~has_area]
    node_band = part.node_band
    mid = (levels[node_band] + levels[np.minimum(node_band + 1, n_bands)]) / 2
    value = np.where(has_area, integral / np.where(has_area, area, 1), mid)

    # a stable sort of small integers is a radix sort
    key = vnode.astype(np.uint16) if n_nodes <= 2**16 else vnode
    by_node = referenced[np.argsort(key, kind="stable")]
    members = np.split(by_node, np.cumsum(np.bincount(vnode, minlength=n_nodes))[:-1])
    G = nx.MultiGraph()
    for i in range(n_nodes):
        G.add_node(i, pos=pos[i], band=int(node_band[i]), value=float(value[i]), area=float(area[i]),
                   members=members[i])
    for a, b, lvl in zip(part.below_node.tolist(), part.above_node.tolist(), part.contour_level.tolist()):
        G.add_edge(a, b, level=int(lvl), length=float(np.linalg.norm(pos[a] - pos[b])))
    cycle_rank = G.number_of_edges() - n_nodes + (nx.number_connected_components(G) if n_nodes else 0)
    if root is not None and root_mode != "none" and n_nodes:
        root = np.asarray(root, dtype=np.float64)
        G.add_node(ROOT, pos=root, band=-1, value=float(levels[0]), area=0.0, members=np.zeros(0, np.int64))
        if root_mode == "first_band":
            targets = [i for i in range(n_nodes) if node_band[i] == 0]
        else:
            targets = [int(np.argmin(np.linalg.norm(pos - root, axis=1)))]
        for t in targets:
            G.add_edge(ROOT, t, level=-1, length=float(np.linalg.norm(pos[t] - root)))
    return ReebGraph(G, levels, int(cycle_rank))


# --------------------------------------------------------------------------- stage


class ReebParams(Params):
    """Parameters of the ``reeb_graph`` stage."""

    root_mode: Literal["first_band", "nearest", "none"] = Field(
        "first_band", description="how the root (the centre of the mixture distance) joins the graph: every "
                                  "first-band node (thesis Algorithm 1), the nearest node, or no root")
    split_handle_bands: bool = Field(True, description="closed meshes: halve every band that contains a whole "
                                     "handle, so that no cycle is hidden (false: the thesis's uniform bands only)")


@dataclass(frozen=True, eq=False)
class ReebResult(StageResult):
    reeb: ReebGraph

    def summary(self) -> dict:
        G = self.reeb.graph
        return {"nodes": self.reeb.n_nodes, "edges": self.reeb.n_edges, "cycle_rank": self.reeb.cycle_rank,
                "levels_used": len(self.reeb.levels) - 1,
                "components": nx.number_connected_components(G) if len(G) else 0}


@stage("reeb_graph", params=ReebParams, version=1, consumes=("mesh", "function", "level_sets"), produces=("reeb",))
def reeb_graph_stage(mesh, function, level_sets, *, params: ReebParams) -> ReebResult:
    """Reeb graph: one node per connected component of each band, edges across contours."""
    return ReebResult(reeb_graph(mesh.V, mesh.F, function.values, level_sets.values, root=function.root,
                                 root_mode=params.root_mode, split_handle_bands=params.split_handle_bands,
                                 closed=mesh.closed_manifold))
