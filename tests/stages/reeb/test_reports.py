"""The skeleton reports of a config run: the ``export`` report's files read back by open3d and
networkx with the counts of the run's own results; the gallery's keys; the interactive 3D view
loaded in headless Chromium (no JavaScript error, one WebGL canvas per shape, a screenshot kept in
``$TOPOMATCH_ARTEFACTS`` when set)."""

from __future__ import annotations

import json
import re

import networkx as nx
import numpy as np
import pytest

from topomatch.pipeline.config import build_experiment
from topomatch.pipeline.runner import run_experiment
from browser import dump_dom, needs_chromium, screenshot
from tests_paths import BUNDLED_MESHES


@pytest.fixture(scope="module")
def skeleton_run(tmp_path_factory):
    config = {
        "name": "skeleton-reports",
        "inputs": {"meshes": [str(BUNDLED_MESHES / "torus.off"), str(BUNDLED_MESHES / "eight_genus2.off")]},
        "stages": ["load", {"clean": {"components": "largest"}}, {"decimate": {"ratio": 0.5}},
                   {"morse": {"function": "mixture"}}, "level_sets", "reeb_graph", "prune"],
        "reports": [{"export": {"meshes": ["clean", "decimate"], "graph_formats": ["ply", "graphml", "json"]}},
                    {"skeleton_gallery": {"name": "gallery", "up": "z"}},
                    {"skeleton_3d": {"name": "view", "up": "z"}}],
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


def test_inputs_that_share_a_file_name_export_apart_and_a_repeated_input_counts_once(tmp_path):
    import igl
    import open3d as o3d

    V, F = igl.read_triangle_mesh(str(BUNDLED_MESHES / "torus.off"))
    (tmp_path / "alt").mkdir()
    igl.write_triangle_mesh(str(tmp_path / "alt" / "torus.off"), 2.0 * V, F)  # another torus.off, twice as large
    config = {"name": "same-names", "inputs": {"meshes": [str(BUNDLED_MESHES / "torus.off"), str(tmp_path / "alt" / "*.off"),
                                                          str(BUNDLED_MESHES / "torus.off")]},
              "stages": ["load"], "reports": [{"export": {"meshes": ["load"]}}]}
    outcome = run_experiment(build_experiment(config), out_root=tmp_path / "runs", progress=False)
    rows = json.loads((outcome.run_dir / "tables" / "exports.json").read_text())
    assert len(outcome.items) == 2 and len({r["file"] for r in rows}) == 2  # two inputs, two folders
    sizes = sorted(np.ptp(np.asarray(o3d.io.read_triangle_mesh(str(outcome.run_dir / r["file"])).vertices), axis=0).max()
                   for r in rows)
    assert sizes[1] == pytest.approx(2 * sizes[0])  # neither overwrote the other


def test_export_refuses_a_stage_that_makes_no_mesh(tmp_path):
    config = {"name": "bad-export", "inputs": {"meshes": [str(BUNDLED_MESHES / "torus.off")]},
              "stages": ["load", {"morse": {"function": "mixture"}}],
              "reports": [{"export": {"meshes": ["morse"]}}]}
    outcome = run_experiment(build_experiment(config), out_root=tmp_path, progress=False)
    assert outcome.manifest["outputs"]["export"] == {"files": [], "notes": [], "error":
        "report export failed: ConfigError: export: stage 'morse' produces no mesh; choose among ['load']"}
    # the page's status says so next to the items' (it said "all 1 items ok" in green and nothing else)
    page = (outcome.run_dir / "index.html").read_text()
    assert "all 1 items ok" in page and "1 of 1 reports failed</span> (export: the error is in their section)" in page


def test_gallery_has_keys_and_every_format(skeleton_run):
    d = skeleton_run.run_dir
    assert (d / "figures" / "gallery.png").stat().st_size > 20_000
    svg = (d / "figures" / "gallery.svg").read_text()
    for text in ("endpoint (degree 1)", "root", "skeleton edge", "Mixture distance", "its minimum to its maximum"):
        assert text in svg, text
    page = (d / "index.html").read_text()
    assert "<h2 id='r2'>Gallery" in page and "figures/gallery.svg" in page


def test_depth_sorted_drawing_hides_a_far_branch_behind_the_near_surface():
    """A segment behind an opaque square is covered; in front of it, it is drawn on top."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from topomatch.stages.reeb.render import draw_scene

    square_V = np.array([[-1, -1, 0], [1, -1, 0], [1, 1, 0], [-1, 1, 0]], float)
    square_F = np.array([[0, 1, 2], [0, 2, 3]])
    colours = {}
    for depth in (-0.5, 0.5):  # the view looks down the z axis (elev 90): larger z is nearer
        g = nx.MultiGraph()
        g.add_node("a", pos=np.array([-0.9, 0.0, depth]))
        g.add_node("b", pos=np.array([0.9, 0.0, depth]))
        g.add_edge("a", "b")
        fig, ax = plt.subplots(figsize=(2, 2), dpi=50)
        draw_scene(ax, square_V, square_F, graph=g, elev=90, azim=-90, alpha=1.0, line_width=0.05)
        fig.canvas.draw()
        img = np.asarray(fig.canvas.buffer_rgba())[..., :3].astype(int)
        plt.close(fig)
        colours[depth] = img[img.shape[0] // 2, img.shape[1] // 2]
    assert colours[0.5].max() < 60  # the near segment: black over the surface
    assert colours[-0.5].min() > 120  # the far one: hidden, the grey-blue surface shows


@needs_chromium
def test_run_page_loads_in_chromium_with_its_3d_view(skeleton_run, tmp_path):
    d = skeleton_run.run_dir
    assert (d / "assets" / "plotly.min.js").stat().st_size > 1_000_000  # offline: no CDN
    page = (d / "index.html").read_text()
    assert not re.search(r"src=['\"]?https?:", page) and "<script src='assets/plotly.min.js'>" in page
    dom = dump_dom(d / "index.html")
    assert "<html" in dom
    errors = re.search(r'data-js-errors="([^"]*)"', dom)
    assert errors is None, errors.group(1)
    canvases = dom.count("<canvas")
    assert canvases >= 2, "the plotly view drew no WebGL canvas"  # one scene per shape
    assert "view-view" in dom and "torus" in dom
    shot = screenshot(d / "views" / "view.html", "run_page_3d.png", tmp_path)
    assert shot.stat().st_size > 20_000


def test_reports_that_would_draw_nothing_fail_with_what_is_wrong(tmp_path):
    # a misspelt sweep key drew an empty stability figure with exit 0; a gallery whose `where` matched nothing
    # failed inside matplotlib; a table whose columns matched nothing wrote blank lines
    config = {"name": "empty-reports", "inputs": {"meshes": [str(BUNDLED_MESHES / "torus.off")]},
              "sweep": {"level_sets.levels": [10, 12]},
              "stages": ["load", {"morse": {"function": "mixture"}}, "level_sets", "reeb_graph", "prune"],
              "reports": [{"skeleton_stability": {"name": "s", "reference": {"level_sets.levls": 10},
                                                  "x": "level_sets.levels"}},
                          {"skeleton_gallery": {"name": "g", "where": {"level_sets.levels": 99}}},
                          {"table": {"name": "t", "columns": ["nothing.*"]}}]}
    outcome = run_experiment(build_experiment(config), out_root=tmp_path, progress=False)
    errors = {k: v["error"] for k, v in outcome.manifest["outputs"].items()}
    assert "level_sets.levls is not a sweep key of the config (sweep keys: level_sets.levels)" in errors["skeleton_stability"]
    assert "where {'level_sets.levels': 99} matches none of the 2 items" in errors["skeleton_gallery"]
    assert "the columns ['nothing.*'] match no results column" in errors["table"]
