"""Endpoint features of a skeleton (thesis §3.3).

For the endpoints v_1..v_n of a skeleton (degree-1 nodes), the root c and the
shortest-path distance ``dist`` along the skeleton (edge length = distance of
the node positions; Dijkstra):

- a_i, relative node area: area of the endpoint's band component / total area;
- dv_i, relative node path: sum_k dist(v_i, v_k) / sum_k dist(c, v_k);
- dc_i, relative centroid path: dist(c, v_i) / sum_k dist(c, v_k).

All three are ratios, so they are invariant to rotation, translation and uniform
scale. The root is the ``root`` node of a mixture-distance skeleton; a skeleton
without one (the Fiedler vector) uses the node nearest the surface centroid,
which is the area-weighted mean of the node positions (thesis ch. 4).
"""

from __future__ import annotations

from dataclasses import dataclass

import networkx as nx
import numpy as np
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import dijkstra

from topomatch.stages.reeb.prune import endpoints as graph_endpoints
from topomatch.stages.reeb.reeb_graph import ROOT


@dataclass(frozen=True, eq=False)
class EndpointFeatures:
    """Features of the endpoints of one skeleton.

    Attributes
    ----------
    features : (n, 3) float64
        Rows (a_i, dv_i, dc_i), one per endpoint.
    endpoints : list
        Node ids of the endpoints, in row order.
    root : node id
        The node used as root c.
    """

    features: np.ndarray
    endpoints: list
    root: object

    @property
    def n(self) -> int:
        return int(self.features.shape[0])


def skeleton_root(G: nx.Graph):
    """The ``root`` node if present, else the node nearest the area-weighted mean of the node positions."""
    if ROOT in G:
        return ROOT
    nodes = list(G.nodes)
    pos = np.array([G.nodes[v]["pos"] for v in nodes], dtype=float)
    area = np.array([G.nodes[v]["area"] for v in nodes], dtype=float)
    centre = (area[:, None] * pos).sum(0) / area.sum() if area.sum() > 0 else pos.mean(0)
    return nodes[int(np.argmin(np.linalg.norm(pos - centre, axis=1)))]


def shortest_paths(G: nx.Graph, sources: list) -> tuple[np.ndarray, dict]:
    """Dijkstra distances (len(sources), |V|) along edges weighted by ``length``, and the node index."""
    index = {v: i for i, v in enumerate(G.nodes)}
    a, b, w = [], [], []
    for u, v, d in G.edges(data=True):
        a.append(index[u])
        b.append(index[v])
        w.append(max(float(d.get("length", 1.0)), 1e-300))  # zero lengths would vanish from the sparse matrix
    n = len(index)
    a, b, w = np.asarray(a, dtype=np.int64), np.asarray(b, dtype=np.int64), np.asarray(w, dtype=float)
    lo, hi = np.minimum(a, b), np.maximum(a, b)
    order = np.lexsort((w, hi, lo))  # parallel edges: keep the shortest
    lo, hi, w = lo[order], hi[order], w[order]
    first = np.ones(len(lo), dtype=bool)
    first[1:] = (lo[1:] != lo[:-1]) | (hi[1:] != hi[:-1])
    W = coo_matrix((w[first], (lo[first], hi[first])), shape=(n, n)).tocsr()
    D = dijkstra(W, directed=False, indices=[index[s] for s in sources])
    return np.atleast_2d(D), index


def endpoint_features(G: nx.Graph) -> EndpointFeatures:
    """The (a, dv, dc) features of every endpoint of the skeleton graph ``G``."""
    ends = graph_endpoints(G)
    root = skeleton_root(G)
    if not ends:
        return EndpointFeatures(np.zeros((0, 3)), [], root)
    D, index = shortest_paths(G, [root] + ends)
    cols = [index[v] for v in ends]
    d_root = D[0, cols]
    d_ends = D[1:, cols]
    finite = np.isfinite(d_root)
    d_root = np.where(finite, d_root, 0.0)  # endpoints in another component than the root
    d_ends = np.where(np.isfinite(d_ends), d_ends, 0.0)
    total_area = sum(d["area"] for _, d in G.nodes(data=True)) or 1.0
    s = d_root.sum() or 1.0
    a = np.array([G.nodes[v]["area"] for v in ends]) / total_area
    return EndpointFeatures(np.column_stack([a, d_ends.sum(axis=1) / s, d_root / s]), ends, root)


def endpoint_signatures(G: nx.Graph, ends: list, signature: np.ndarray, mass: np.ndarray) -> np.ndarray:
    """(len(ends), s) area-weighted mean of a vertex signature (n, s) over each endpoint node's vertices.

    Describes what each protrusion tip looks like (e.g. the heat kernel signature: thin or
    thick, long or short), which the three skeleton ratios cannot tell apart.
    """
    out = np.zeros((len(ends), signature.shape[1]))
    for row, v in enumerate(ends):
        members = np.asarray(G.nodes[v]["members"], dtype=np.int64)
        w = mass[members]
        if w.sum() > 0:
            out[row] = w @ signature[members] / w.sum()
    return out
