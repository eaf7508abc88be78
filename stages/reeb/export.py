"""Writing skeletons: GraphML, JSON (networkx node-link) and PLY / OBJ polylines.

Node ids are written as strings ("0", "1", ..., "root"); ``pos`` becomes
``x, y, z``; ``members`` (vertex ids) becomes a space-separated string in
GraphML and a list in JSON.
"""

from __future__ import annotations

import json
from pathlib import Path

import networkx as nx
import numpy as np

from topomatch.pipeline.contract import atomic_write_text


def _flat_graph(G: nx.MultiGraph, *, members_as_text: bool) -> nx.MultiGraph:
    H = nx.MultiGraph()
    for v, d in G.nodes(data=True):
        x, y, z = (float(c) for c in d["pos"])
        members = [int(i) for i in d.get("members", [])]
        H.add_node(str(v), x=x, y=y, z=z, band=int(d["band"]), value=float(d["value"]), area=float(d["area"]),
                   members=" ".join(map(str, members)) if members_as_text else members)
    for a, b, d in G.edges(data=True):
        H.add_edge(str(a), str(b), level=int(d["level"]), length=float(d["length"]))
    return H


def write_graphml(G: nx.MultiGraph, path: str | Path) -> None:
    """GraphML with scalar node attributes (readable by networkx, Gephi, yEd)."""
    text = "\n".join(nx.generate_graphml(_flat_graph(G, members_as_text=True)))
    atomic_write_text(path, text + "\n")


def graph_to_json(G: nx.MultiGraph) -> dict:
    """networkx node-link data (``edges="edges"``) of the flattened graph."""
    return nx.node_link_data(_flat_graph(G, members_as_text=False), edges="edges")


def write_json(G: nx.MultiGraph, path: str | Path) -> None:
    atomic_write_text(path, json.dumps(graph_to_json(G)))


def polyline(G: nx.MultiGraph) -> tuple[np.ndarray, np.ndarray, list]:
    """Node positions (k, 3), edges (e, 2) as row indices, and the node order."""
    nodes = list(G.nodes)
    index = {v: i for i, v in enumerate(nodes)}
    P = np.array([G.nodes[v]["pos"] for v in nodes], dtype=np.float64).reshape(-1, 3)
    E = np.array([(index[a], index[b]) for a, b in G.edges()], dtype=np.int64).reshape(-1, 2)
    return P, E, nodes


def write_polyline(G: nx.MultiGraph, path: str | Path) -> None:
    """The skeleton as an OBJ (``v`` + ``l`` lines) or ASCII PLY (vertex + edge elements)."""
    path = Path(path)
    P, E, _ = polyline(G)
    if path.suffix.lower() == ".obj":
        lines = [f"v {x:.17g} {y:.17g} {z:.17g}" for x, y, z in P]
        lines += [f"l {a + 1} {b + 1}" for a, b in E]
    elif path.suffix.lower() == ".ply":
        lines = ["ply", "format ascii 1.0", f"element vertex {len(P)}", "property double x", "property double y",
                 "property double z", f"element edge {len(E)}", "property int vertex1", "property int vertex2",
                 "end_header"]
        lines += [f"{x:.17g} {y:.17g} {z:.17g}" for x, y, z in P]
        lines += [f"{a} {b}" for a, b in E]
    else:
        raise ValueError(f"{path}: polyline format must be .obj or .ply")
    atomic_write_text(path, "\n".join(lines) + "\n")
