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


def _edge_face_pairs(F: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, bool]:
    """Pairs of faces sharing an edge: (face1, face2, u, w, closed_manifold).

    Faces around a non-manifold edge are chained (f1-f2, f2-f3, ...);
    ``closed_manifold`` is True when every edge has exactly two faces.
    """
    m = len(F)
    u = F[:, [0, 1, 2]].ravel()
    w = F[:, [1, 2, 0]].ravel()
    face = np.repeat(np.arange(m), 3)
    lo, hi = np.minimum(u, w), np.maximum(u, w)
    key = lo * (int(F.max()) + 1) + hi
    order = np.argsort(key, kind="stable")
    key, face, lo, hi = key[order], face[order], lo[order], hi[order]
    same = key[1:] == key[:-1]
    closed_manifold = bool(len(key) % 2 == 0 and np.all(same[0::2]) and not np.any(same[1::2]))
    return face[:-1][same], face[1:][same], lo[:-1][same], hi[:-1][same], closed_manifold


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
    """Band components of the pieces and the contours between them (internal)."""

    piece_face: np.ndarray   # (p,) triangle of each piece
    piece_band: np.ndarray   # (p,) band of each piece
    piece_node: np.ndarray   # (p,) node of each piece
    vertex_node: np.ndarray  # (n,) node of each vertex, -1 when unreferenced
    node_band: np.ndarray    # (k,)
    below_node: np.ndarray   # (c,) per contour component: node below and above, and the level index
    above_node: np.ndarray
    contour_level: np.ndarray
    genus: np.ndarray | None  # (k,) genus of each band component (closed manifold meshes only)


def _partition(F: np.ndarray, f: np.ndarray, levels: np.ndarray, pairs) -> _Partition:
    n, m = len(f), len(F)
    f1, f2, eu, ew, closed = pairs
    vb = band_index(f, levels)
    tb = vb[F]
    t_lo, t_hi = tb.min(axis=1), tb.max(axis=1)
    span = t_hi - t_lo + 1
    offset = np.cumsum(span) - span

    def piece(face, band):
        return offset[face] + band - t_lo[face]

    piece_face, piece_band = _expand(t_lo, t_hi)
    n_pieces = len(piece_face)
    # same-band connectivity: shared edges meeting the band, and shared vertices in the band
    e_lo, e_hi = np.minimum(vb[eu], vb[ew]), np.maximum(vb[eu], vb[ew])
    rows, k = _expand(e_lo, e_hi)
    corner_face = np.repeat(np.arange(m), 3)
    corner_piece = piece(corner_face, vb[F.ravel()])
    comp_of = _components(n_pieces + n, np.concatenate([piece(f1[rows], k), corner_piece]),
                          np.concatenate([piece(f2[rows], k), n_pieces + F.ravel()]))
    used, piece_node = np.unique(comp_of[:n_pieces], return_inverse=True)
    n_nodes = len(used)
    hub_comp = comp_of[n_pieces:]
    vertex_node = np.minimum(np.searchsorted(used, hub_comp), n_nodes - 1)
    vertex_node[used[vertex_node] != hub_comp] = -1  # unreferenced vertices belong to no node
    node_band = np.zeros(n_nodes, dtype=np.int64)
    node_band[piece_node] = piece_band

    # contours: (triangle, level) crossings joined through edges crossing the level
    c_face, c_level = _expand(t_lo + 1, t_hi)
    c_offset = np.cumsum(span - 1) - (span - 1)
    rows_c, kc = _expand(e_lo + 1, e_hi)
    contour = _components(len(c_face), c_offset[f1[rows_c]] + kc - t_lo[f1[rows_c]] - 1,
                          c_offset[f2[rows_c]] + kc - t_lo[f2[rows_c]] - 1) if len(c_face) else np.zeros(0, np.int64)
    _, first = np.unique(contour, return_index=True)
    rep_face, rep_level = c_face[first], c_level[first]
    below_node = piece_node[piece(rep_face, rep_level - 1)]
    above_node = piece_node[piece(rep_face, rep_level)]

    genus = None
    if closed:
        # Euler characteristic of each closed band component from the mesh cut along the levels:
        # vertices (mesh vertices + edge crossings on both bounding levels), edges (mesh-edge
        # segments + contour segments on both bounding levels), faces (pieces).
        count = lambda idx: np.bincount(idx, minlength=n_nodes)  # noqa: E731
        rows_x, jx = rows_c, kc
        verts = (count(vertex_node[vertex_node >= 0]) + count(piece_node[piece(f1[rows_x], jx - 1)])
                 + count(piece_node[piece(f1[rows_x], jx)]))
        edges = (count(piece_node[piece(f1[rows], k)]) + count(piece_node[piece(c_face, c_level - 1)])
                 + count(piece_node[piece(c_face, c_level)]))
        chi = verts - edges + count(piece_node)
        degree = count(below_node) + count(above_node)
        genus = (2 - chi - degree) // 2
    return _Partition(piece_face, piece_band, piece_node, vertex_node, node_band, below_node, above_node,
                      rep_level, genus)


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
    """
    V = np.asarray(V, dtype=np.float64)
    F = np.asarray(F, dtype=np.int64)
    f = np.asarray(f, dtype=np.float64)
    levels = np.asarray(levels, dtype=np.float64)
    pairs = _edge_face_pairs(F)
    part = _partition(F, f, levels, pairs)
    for _ in range(MAX_SPLIT_ROUNDS):
        if not split_handle_bands or part.genus is None or not np.any(part.genus > 0):
            break
        bands = np.unique(part.node_band[part.genus > 0])
        levels = np.union1d(levels, (levels[bands] + levels[bands + 1]) / 2)
        part = _partition(F, f, levels, pairs)
    return _assemble(V, F, f, levels, part, root, root_mode)


def _assemble(V, F, f, levels, part: _Partition, root, root_mode) -> ReebGraph:
    """Measure the nodes exactly and build the networkx graph."""
    n_bands = len(levels) - 1
    piece_face, piece_band, piece_node = part.piece_face, part.piece_band, part.piece_node
    n_nodes = len(part.node_band)
    order = np.argsort(f[F], axis=1, kind="stable")
    Fs = np.take_along_axis(F, order, axis=1)[piece_face]
    fs = np.take_along_axis(f[F], order, axis=1)[piece_face]
    Pa, Pb, Pc = V[Fs[:, 0]], V[Fs[:, 1]], V[Fs[:, 2]]
    tri_area = 0.5 * np.linalg.norm(np.cross(Pb - Pa, Pc - Pa), axis=1)
    lower = np.where(piece_band == 0, -np.inf, levels[piece_band])
    upper = np.where(piece_band == n_bands - 1, np.inf, levels[np.minimum(piece_band + 1, n_bands)])
    A1, M1, I1 = below(Pa, Pb, Pc, fs[:, 0], fs[:, 1], fs[:, 2], tri_area, upper)
    A0, M0, I0 = below(Pa, Pb, Pc, fs[:, 0], fs[:, 1], fs[:, 2], tri_area, lower)

    def per_node(weights):
        return np.bincount(piece_node, weights=weights, minlength=n_nodes)

    area = per_node(A1 - A0)
    moment = np.stack([per_node((M1 - M0)[:, j]) for j in range(3)], 1)
    integral = per_node(I1 - I0)
    # fallback for zero-area nodes (a band touched only at vertices): mean of the touching triangles
    fallback = np.stack([per_node((Pa + Pb + Pc)[:, j] / 3) for j in range(3)], 1)
    fallback /= np.maximum(per_node(np.ones(len(piece_node))), 1)[:, None]
    has_area = area > 1e-300
    pos = np.where(has_area[:, None], moment / np.where(has_area, area, 1)[:, None], fallback)
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
