"""The skeleton reports of a config run: the ``export`` report's files read back by open3d and
networkx with the counts of the run's own results."""

from __future__ import annotations

import json

import networkx as nx
import pytest

from topomatch.pipeline.config import build_experiment
from topomatch.pipeline.runner import run_experiment
from tests_paths import BUNDLED_MESHES


@pytest.fixture(scope="module")
def skeleton_run(tmp_path_factory):
    config = {
        "name": "skeleton-reports",
        "inputs": {"meshes": [str(BUNDLED_MESHES / "torus.off"), str(BUNDLED_MESHES / "eight_genus2.off")]},
        "stages": ["load", {"clean": {"components": "largest"}}, {"decimate": {"ratio": 0.5}},
                   {"morse": {"function": "mixture"}}, "level_sets", "reeb_graph", "prune"],
        "reports": [{"export": {"meshes": ["clean", "decimate"], "graph_formats": ["ply", "graphml", "json"]}}],
        "figure_format": ["png", "svg"],
    }
    out = tmp_path_factory.mktemp("runs")
    return run_experiment(build_experiment(config), out_root=out, progress=False)


def test_export_writes_meshes_and_skeletons_that_read_back(skeleton_run):
    import open3d as o3d

    d = skeleton_run.run_dir
    rows = json.loads((d / "tables" / "exports.json").read_text())
    assert len(rows) == 2 * (2 + 3)  # two items x (two meshes + three skeleton files)
    for r in skeleton_run.items:
        stem = r.input_path.split("/")[-1].split(".")[0]
        clean, decimated, skel = r.results["clean"].mesh, r.results["decimate"].mesh, r.final("skeleton")
        for which, mesh in (("clean", clean), ("decimate", decimated)):
            m = o3d.io.read_triangle_mesh(str(d / "exports" / stem / f"mesh_{which}.ply"))
            assert (len(m.vertices), len(m.triangles)) == (mesh.n_vertices, mesh.n_faces)
        assert decimated.n_faces < clean.n_faces
        ls = o3d.io.read_line_set(str(d / "exports" / stem / "skeleton.ply"))
        assert (len(ls.points), len(ls.lines)) == (skel.graph.number_of_nodes(), skel.graph.number_of_edges())
        G = nx.read_graphml(d / "exports" / stem / "skeleton.graphml", force_multigraph=True)
        assert nx.is_isomorphic(G, nx.MultiGraph(nx.relabel_nodes(skel.graph, str)))
        assert sum(1 for v in G if v != "root" and G.degree(v) == 1) == len(skel.endpoints)


def test_export_refuses_a_stage_that_makes_no_mesh(tmp_path):
    config = {"name": "bad-export", "inputs": {"meshes": [str(BUNDLED_MESHES / "torus.off")]},
              "stages": ["load", {"morse": {"function": "mixture"}}],
              "reports": [{"export": {"meshes": ["morse"]}}]}
    outcome = run_experiment(build_experiment(config), out_root=tmp_path, progress=False)
    assert outcome.manifest["outputs"]["export"] == [
        "ERROR: report export failed: ConfigError: export: stage 'morse' produces no mesh; choose among ['load']"]
