"""Export: GraphML and JSON round trips, PLY polylines read back with their edges by open3d and
trimesh, meshes read back by libigl and open3d, and the ``export`` report of a config run."""

from __future__ import annotations

import json

import networkx as nx
import numpy as np
import pytest

from topomatch.stages.morse.mixture import mixture_distance
from topomatch.stages.mesh.export import MESH_FORMATS, mesh_text
from topomatch.stages.reeb.export import SKELETON_FORMATS, write_graphml, write_json, write_polyline, write_skeleton
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


def test_ply_polyline_keeps_its_edges_in_open3d_and_trimesh(graph, tmp_path):
    import open3d as o3d

    path = tmp_path / "skeleton.ply"
    write_skeleton(graph, path)
    ls = o3d.io.read_line_set(str(path))
    assert len(ls.points) == graph.number_of_nodes() and len(ls.lines) == graph.number_of_edges()
    ends = {tuple(sorted(e)) for e in np.asarray(ls.lines).tolist()}
    nodes = list(graph.nodes)
    assert ends == {tuple(sorted((nodes.index(a), nodes.index(b)))) for a, b in graph.edges()}
    np.testing.assert_allclose(np.asarray(ls.points), [graph.nodes[v]["pos"] for v in nodes], rtol=1e-15)
    trimesh = pytest.importorskip("trimesh")
    path3d = trimesh.load(str(path))
    assert isinstance(path3d, trimesh.path.Path3D)
    segments = sum(len(e.points) - 1 for e in path3d.entities)
    assert segments == graph.number_of_edges() and len(path3d.vertices) == graph.number_of_nodes()


def test_graphml_and_json_through_networkx_keep_degrees(graph, tmp_path):
    write_skeleton(graph, tmp_path / "s.graphml")
    write_skeleton(graph, tmp_path / "s.json")
    H = nx.read_graphml(tmp_path / "s.graphml", force_multigraph=True)
    J = nx.node_link_graph(json.loads((tmp_path / "s.json").read_text()), edges="edges")
    for G in (H, J):
        assert sorted(d for _, d in G.degree()) == sorted(d for _, d in graph.degree())


def test_unknown_format_is_refused(graph, tmp_path):
    with pytest.raises(ValueError, match=r"skeleton\.stl: a skeleton file must end in one of \.ply"):
        write_skeleton(graph, tmp_path / "skeleton.stl")
    assert SKELETON_FORMATS[0] == "ply"


@pytest.mark.parametrize("fmt", MESH_FORMATS)
def test_mesh_text_reads_back_exactly(bundled_mesh, tmp_path, fmt):
    import igl
    import open3d as o3d

    m = bundled_mesh("torus.off")
    path = tmp_path / f"m.{fmt}"
    path.write_text(mesh_text(m.V, m.F, fmt))
    V, F = igl.read_triangle_mesh(str(path))
    np.testing.assert_array_equal(V, m.V)
    np.testing.assert_array_equal(F, m.F)
    o3 = o3d.io.read_triangle_mesh(str(path))
    assert len(o3.vertices) == m.n_vertices and len(o3.triangles) == m.n_faces


def test_exported_graphs_carry_the_cycle_rank_of_the_surface(graph, tmp_path):
    # the mixture skeleton's root joins the first band's nodes and closes loops the genus-2 surface does not have:
    # the files say the surface's cycle rank (2) and which node is the root, so a reader can drop it
    write_graphml(graph, tmp_path / "g.graphml")
    write_json(graph, tmp_path / "g.json")
    write_polyline(graph, tmp_path / "g.ply")
    H = nx.read_graphml(tmp_path / "g.graphml", force_multigraph=True)
    J = json.loads((tmp_path / "g.json").read_text())["graph"]
    assert H.graph["cycle_rank"] == J["cycle_rank"] == 2 and H.graph["root"] == J["root"] == "root"
    assert H.number_of_edges() - H.number_of_nodes() + 1 > 2  # with the root, the graph itself has more loops
    H.remove_node(H.graph["root"])
    assert H.number_of_edges() - H.number_of_nodes() + nx.number_connected_components(H) == 2
    assert "comment cycle_rank 2 (without the root node)" in (tmp_path / "g.ply").read_text()
