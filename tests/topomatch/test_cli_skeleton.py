"""``topomatch skeleton``: JSON fields, outputs, and documented behaviour on bad meshes."""

from __future__ import annotations

import json

import igl
import networkx as nx
import numpy as np
import pytest

from topomatch.cli import main
from tests_paths import BUNDLED_MESHES

REQUIRED = {"n_vertices", "n_faces", "genus", "n_nodes", "n_edges", "n_endpoints", "cycle_rank", "lambda2", "seconds"}


def skeleton_json(capsys, *args):
    code = main(["skeleton", *map(str, args), "--json"])
    out, err = capsys.readouterr()
    return code, (json.loads(out) if code == 0 else None), err


@pytest.mark.parametrize("name,genus", [("torus.off", 1), ("eight_genus2.off", 2)])
def test_json_fields(capsys, name, genus):
    code, out, _ = skeleton_json(capsys, BUNDLED_MESHES / name, "--function", "mixture", "--levels", "40")
    assert code == 0 and REQUIRED <= set(out)
    assert out["genus"] == genus and out["cycle_rank"] == genus and out["n_boundary_loops"] == 0
    assert set(out["seconds"]) == {"load", "clean", "morse", "level_sets", "reeb_graph", "prune"}
    assert out["lambda2"] is None


def test_outputs_written(capsys, tmp_path):
    import open3d as o3d

    code, out, _ = skeleton_json(capsys, BUNDLED_MESHES / "odedstein_fish_low_resolution.obj.gz",
                                 "--function", "mixture", "--out", tmp_path, "--format", "ply,graphml")
    assert code == 0
    assert sorted(p.rsplit("/", 1)[-1] for p in out["files"]) == sorted(
        ["skeleton.ply", "reeb.ply", "skeleton.graphml", "reeb.graphml", "skeleton.png"])
    ls = o3d.io.read_line_set(str(tmp_path / "skeleton.ply"))
    assert (len(ls.points), len(ls.lines)) == (out["n_nodes"], out["n_edges"])
    G = nx.read_graphml(tmp_path / "skeleton.graphml", force_multigraph=True)
    assert G.number_of_nodes() == out["n_nodes"]
    ends = [v for v in G if v != "root" and G.degree(v) == 1]
    assert len(ends) == out["n_endpoints"]
    assert (tmp_path / "skeleton.png").stat().st_size > 10_000


def test_default_output_is_a_ply_polyline_and_bad_formats_are_usage_errors(capsys, tmp_path):
    code, out, _ = skeleton_json(capsys, BUNDLED_MESHES / "torus.off", "--function", "mixture", "--out", tmp_path)
    assert code == 0 and sorted(p.rsplit("/", 1)[-1] for p in out["files"]) == ["reeb.ply", "skeleton.ply", "skeleton.png"]
    with pytest.raises(SystemExit) as exc:
        main(["skeleton", str(BUNDLED_MESHES / "torus.off"), "--format", "stl"])
    assert exc.value.code == 2 and "expected formats among ply, obj, graphml, json, got 'stl'" in capsys.readouterr().err


def _write(tmp_path, name, V, F):
    path = tmp_path / name
    igl.write_triangle_mesh(str(path), np.asarray(V, float), np.asarray(F, np.int64))
    return path


def _icosphere():
    V, F = igl.icosahedron()
    V, F = igl.upsample(V, F, number_of_subdivs=2)
    return V / np.linalg.norm(V, axis=1, keepdims=True) * [1.0, 1.5, 2.0], F


def test_multi_component_mesh_uses_the_largest(capsys, tmp_path):
    V, F = _icosphere()
    small = 0.3 * V + [5, 0, 0]
    path = _write(tmp_path, "two.off", np.vstack([V, small]), np.vstack([F, F + len(V)]))
    code, out, _ = skeleton_json(capsys, path, "--function", "mixture")
    assert code == 0 and out["n_vertices"] == len(V) and out["cycle_rank"] == 0


def test_open_mesh_works(capsys):
    import igl

    from topomatch.meshes import read_mesh

    path = BUNDLED_MESHES / "odedstein_hand_lowres.obj.gz"
    code, out, _ = skeleton_json(capsys, path, "--function", "height")
    assert code == 0 and out["genus"] == 0 and out["n_endpoints"] >= 2
    loops = igl.boundary_loop_all(np.asarray(read_mesh(path).F))  # libigl's count of the open mesh's boundary loops
    assert out["n_boundary_loops"] == len(loops) >= 1


def test_degenerate_faces_are_cleaned(capsys, tmp_path):
    V, F = _icosphere()
    F = np.vstack([F, [[0, 0, 1], [2, 2, 2]]])  # repeated indices
    code, out, _ = skeleton_json(capsys, _write(tmp_path, "degenerate.off", V, F), "--function", "mixture")
    assert code == 0 and out["n_faces"] == len(F) - 2


def test_non_manifold_mesh_works(capsys, tmp_path):
    V, F = _icosphere()
    extra = np.array([[V[F[0, 0]], V[F[0, 1]], [3.0, 3.0, 3.0]]]).reshape(3, 3)
    V2 = np.vstack([V, extra[2:]])
    F2 = np.vstack([F, [[F[0, 0], F[0, 1], len(V)]]])  # a fin on an existing edge: 3 faces at one edge
    code, out, _ = skeleton_json(capsys, _write(tmp_path, "fin.off", V2, F2), "--function", "mixture")
    assert code == 0 and out["genus"] is None  # genus is undefined for a non-manifold surface


def test_tiny_mesh_works(capsys, tmp_path):
    V = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1.0]])
    F = np.array([[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]])
    code, out, _ = skeleton_json(capsys, _write(tmp_path, "tet.off", V, F), "--function", "mixture", "--levels", "4")
    assert code == 0 and out["n_vertices"] == 4 and out["cycle_rank"] == 0


def test_flat_mesh_fails_clearly(capsys, tmp_path):
    V = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 1, 0.0]])
    F = np.array([[0, 1, 2], [1, 3, 2]])
    code, _, err = skeleton_json(capsys, _write(tmp_path, "flat.off", V, F), "--function", "mixture")
    assert code == 1 and "flat.off" in err and "plane" in err


def test_missing_and_malformed(capsys, tmp_path):
    code, _, err = skeleton_json(capsys, tmp_path / "none.off")
    assert code == 1 and "none.off: file not found" in err
    bad = tmp_path / "bad.off"
    bad.write_text("OFF\n3 1 0\n0 0 0\n")
    code, _, err = skeleton_json(capsys, bad, "--function", "mixture")
    assert code == 1 and "bad.off" in err and "malformed OFF" in err
