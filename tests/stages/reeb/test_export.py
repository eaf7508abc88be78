"""Export: GraphML and JSON round trips, OBJ/PLY polylines."""

from __future__ import annotations

import json

import networkx as nx
import numpy as np
import pytest

from topomatch.stages.morse.mixture import mixture_distance
from topomatch.stages.reeb.export import write_graphml, write_json, write_polyline
from topomatch.stages.reeb.level_sets import level_values
from topomatch.stages.reeb.reeb_graph import reeb_graph


@pytest.fixture
def graph(bundled_mesh):
    m = bundled_mesh("eight_genus2.off")
    mf = mixture_distance(m.V, m.F)
    return reeb_graph(m.V, m.F, mf.values, level_values(mf.values, 22), root=mf.root).graph


def test_graphml_round_trip(graph, tmp_path):
    write_graphml(graph, tmp_path / "g.graphml")
    H = nx.read_graphml(tmp_path / "g.graphml", force_multigraph=True)
    assert H.number_of_nodes() == graph.number_of_nodes() and H.number_of_edges() == graph.number_of_edges()
    for v, d in graph.nodes(data=True):
        h = H.nodes[str(v)]
        np.testing.assert_allclose([h["x"], h["y"], h["z"]], d["pos"], rtol=1e-15)
        assert h["area"] == d["area"] and [int(i) for i in h["members"].split()] == list(d["members"])


def test_json_round_trip(graph, tmp_path):
    write_json(graph, tmp_path / "g.json")
    H = nx.node_link_graph(json.loads((tmp_path / "g.json").read_text()), edges="edges")
    assert nx.is_isomorphic(H, nx.MultiGraph(nx.relabel_nodes(graph, str)))


@pytest.mark.parametrize("suffix", [".obj", ".ply"])
def test_polyline(graph, tmp_path, suffix):
    import open3d as o3d

    path = tmp_path / f"skeleton{suffix}"
    write_polyline(graph, path)
    text = path.read_text()
    if suffix == ".obj":
        assert text.count("\nl ") + text.startswith("l ") == graph.number_of_edges()
        assert sum(1 for line in text.splitlines() if line.startswith("v ")) == graph.number_of_nodes()
    else:
        ls = o3d.io.read_line_set(str(path))
        assert len(ls.points) == graph.number_of_nodes() and len(ls.lines) == graph.number_of_edges()
