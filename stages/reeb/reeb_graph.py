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
(:mod:`stages.reeb.band_geometry`): exact ``area``, ``pos`` (area centroid) and
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

from pipeline.params import Params
from pipeline.registry import stage
from pipeline.result import StageResult

from stages.reeb.band_geometry import below
from stages.reeb.level_sets import band_index

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


def _components(n: int, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    graph = coo_matrix((np.ones(len(a), dtype=np.int8), (a, b)), shape=(n, n))
    return connected_components(graph, directed=False)[1]


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
    t0, t1, t2 = vb[F[:, 0]], vb[F[:, 1]], vb[F[:, 2]]
    b0 = np.minimum(np.minimum(t0, t1), t2)
    b2 = np.maximum(np.maximum(t0, t1), t2)
    b1 = t0 + t1 + t2 - b0 - b2  # the middle band
    # extra pieces: bands strictly between the sorted vertex bands of a triangle
    r1, k1 = _expand(b0 + 1, b1 - 1)
    r2, k2 = _expand(b1 + 1, b2 - 1)
    x_face, x_band = np.concatenate([r1, r2]), np.concatenate([k1, k2])
    x_key = x_face * (n_bands + 1) + x_band
    order = np.argsort(x_key, kind="stable")
    x_face, x_band, x_key = x_face[order], x_band[order], x_key[order]

    def piece_id(face, band):
        """Graph id of the piece (face, band): one of its vertices, or n + extra index."""
        Ff = F[face]
        match = vb[Ff] == band[:, None]
        vert = Ff[np.arange(len(face)), match.argmax(axis=1)]
        extra = n + np.searchsorted(x_key, face * (n_bands + 1) + band)
        return np.where(match.any(axis=1), vert, extra)

    # connectivity: edges inside one band, and extra pieces across edges spanning 3+ bands. A triangle
    # inside one band needs only two of its edges; half-edges across bands come from crossing triangles.
    whole = b0 == b2
    Fw = F[whole]
    crossing = np.flatnonzero(~whole)
    Fc = F[crossing]
    u, w = Fc.ravel(), Fc[:, [1, 2, 0]].ravel()
    face = np.repeat(crossing, 3)
    same = vb[u] == vb[w]
    f1, f2, eu, ew = _face_pairs(u[~same], w[~same], face[~same], n)
    e_lo, e_hi = np.minimum(vb[eu], vb[ew]), np.maximum(vb[eu], vb[ew])
    rows, k = _expand(e_lo + 1, e_hi - 1)
    label = _components(n + len(x_face),
                        np.concatenate([Fw[:, 0], Fw[:, 0], u[same], piece_id(f1[rows], k)]),
                        np.concatenate([Fw[:, 1], Fw[:, 2], w[same], piece_id(f2[rows], k)]))
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

        whole_owner = vertex_node[Fw[:, 0]]
        verts = (count(vertex_node[referenced]) + count(node_of(f1[rows_c], kc - 1)) + count(node_of(f1[rows_c], kc)))
        rows_s, ks = _expand(e_lo, e_hi)
        same_half_edges = 3 * count(whole_owner) + count(vertex_node[u[same]])  # each edge twice (closed)
        edges = (same_half_edges // 2 + count(node_of(f1[rows_s], ks))
                 + count(node_of(c_face, c_level - 1)) + count(node_of(c_face, c_level)))
        p_rows, p_band = _expand(b0[crossing], b2[crossing])
        faces = count(whole_owner) + count(node_of(crossing[p_rows], p_band))
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
        Level values (see :func:`stages.reeb.level_sets.level_values`).
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

    # triangles inside one band: whole-triangle measures
    whole = part.t_lo == part.t_hi
    area_t = 0.5 * igl.doublearea(V, F).ravel()
    Fw = F[whole]
    owner = part.vertex_node[Fw[:, 0]]
    aw = area_t[whole]
    cw = (V[Fw[:, 0]] + V[Fw[:, 1]] + V[Fw[:, 2]]) / 3.0
    area = per_node(owner, aw)
    moment = np.stack([per_node(owner, aw * cw[:, j]) for j in range(3)], 1)
    integral = per_node(owner, aw * (f[Fw[:, 0]] + f[Fw[:, 1]] + f[Fw[:, 2]]) / 3.0)

    # triangles across bands: closed-form measures of each piece
    crossing = np.flatnonzero(~whole)
    rows, piece_band = _expand(part.t_lo[crossing], part.t_hi[crossing])
    piece_face = crossing[rows]
    piece_node = part.node_of(piece_face, piece_band)
    order = np.argsort(f[F[piece_face]], axis=1, kind="stable")
    Fs = np.take_along_axis(F[piece_face], order, axis=1)
    fs = f[Fs]
    Pa, Pb, Pc = V[Fs[:, 0]], V[Fs[:, 1]], V[Fs[:, 2]]
    tri_area = area_t[piece_face]
    lower = np.where(piece_band == 0, -np.inf, levels[piece_band])
    upper = np.where(piece_band == n_bands - 1, np.inf, levels[np.minimum(piece_band + 1, n_bands)])
    A1, M1, I1 = below(Pa, Pb, Pc, fs[:, 0], fs[:, 1], fs[:, 2], tri_area, upper)
    A0, M0, I0 = below(Pa, Pb, Pc, fs[:, 0], fs[:, 1], fs[:, 2], tri_area, lower)
    area += per_node(piece_node, A1 - A0)
    moment += np.stack([per_node(piece_node, (M1 - M0)[:, j]) for j in range(3)], 1)
    integral += per_node(piece_node, I1 - I0)
    has_area = area > 1e-300
    pos = moment / np.where(has_area, area, 1)[:, None]
    if not has_area.all():  # a band met only at a vertex or an edge: mean centroid of its triangles
        owners = np.concatenate([owner, piece_node])
        centres = np.concatenate([cw, (Pa + Pb + Pc) / 3])
        touched = per_node(owners, np.ones(len(owners)))
        fallback = np.stack([per_node(owners, centres[:, j]) for j in range(3)], 1) / np.maximum(touched, 1)[:, None]
        pos[~has_area] = fallback[~has_area]
    node_band = part.node_band
    mid = (levels[node_band] + levels[np.minimum(node_band + 1, n_bands)]) / 2
    value = np.where(has_area, integral / np.where(has_area, area, 1), mid)

    vertex_node = part.vertex_node
    referenced = np.flatnonzero(vertex_node >= 0)
    by_node = referenced[np.argsort(vertex_node[referenced], kind="stable")]
    members = np.split(by_node, np.cumsum(np.bincount(vertex_node[referenced], minlength=n_nodes))[:-1])
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
                                 root_mode=params.root_mode, split_handle_bands=params.split_handle_bands))
