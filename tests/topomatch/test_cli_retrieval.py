"""``topomatch index / query / evaluate / match`` on bundled meshes."""

from __future__ import annotations

import json
import shutil
import sqlite3

import numpy as np
import pytest

from topomatch.cli import main
from tests_paths import BUNDLED_MESHES

MESHES = ["torus.off", "eight_genus2.off", "odedstein_human_man.obj.gz", "odedstein_human_woman.obj.gz",
          "odedstein_hand_closed.obj.gz", "odedstein_hand_lowres.obj.gz"]
# psbTable leaves classes of at most 2 shapes out of the averages: two classes of three
LABELS = {"torus.off": "handles", "eight_genus2.off": "handles", "odedstein_hand_lowres.obj.gz": "handles",
          "odedstein_human_man.obj.gz": "body", "odedstein_human_woman.obj.gz": "body",
          "odedstein_hand_closed.obj.gz": "body"}


@pytest.fixture
def collection(tmp_path):
    folder = tmp_path / "meshes"
    folder.mkdir()
    for name in MESHES:
        shutil.copy(BUNDLED_MESHES / name, folder / name)
    (folder / "labels.csv").write_text("relative_path,class\n" + "".join(f"{k},{v}\n" for k, v in LABELS.items()))
    return folder


def run(capsys, *args):
    code = main([str(a) for a in args])
    out, err = capsys.readouterr()
    return code, out, err


def test_index_skip_query_evaluate(collection, tmp_path, capsys):
    db = tmp_path / "index.db"
    code, out, _ = run(capsys, "index", collection, "--db", db, "--method", "rgpd", "--labels",
                       collection / "labels.csv", "--workers", "1", "--no-progress")
    assert code == 0 and "6 indexed, 0 failed, 0 unchanged" in out
    code, out, _ = run(capsys, "index", collection, "--db", db, "--method", "rgpd", "--workers", "1", "--no-progress")
    assert "0 indexed, 0 failed, 6 unchanged" in out
    rows = sqlite3.connect(db).execute("SELECT path, label, status, n_endpoints FROM shapes").fetchall()
    assert len(rows) == 6 and all(r[2] == "ok" and r[1] == LABELS[r[0].split("/")[-1]] for r in rows)

    code, out, _ = run(capsys, "query", collection / "odedstein_human_man.obj.gz", "--db", db, "--method", "rgpd",
                       "-k", "3", "--json")
    result = json.loads(out)
    assert code == 0 and result["results"][0]["path"].endswith("odedstein_human_man.obj.gz")
    assert result["results"][0]["dissimilarity"] == 0.0 and len(result["results"]) == 3

    npz = tmp_path / "D.npz"
    code, out, _ = run(capsys, "evaluate", "--db", db, "--method", "rgpd", "--json", "--out", npz)
    metrics = json.loads(out)
    assert code == 0 and metrics["n"] == 6 and 0.0 <= metrics["micro"]["nn"] <= 1.0
    data = np.load(npz)
    assert data["D"].shape == (6, 6) and np.all(np.diag(data["D"]) == 0) and len(data["labels"]) == 6


def test_bad_mesh_is_recorded_and_the_others_indexed(collection, tmp_path, capsys):
    (collection / "broken.off").write_text("OFF\n3 1 0\n0 0 0\n")
    db = tmp_path / "index.db"
    code, out, err = run(capsys, "index", collection, "--db", db, "--method", "d2", "--workers", "1", "--no-progress")
    assert code == 1 and "6 indexed, 1 failed" in out and "broken.off" in err and "malformed OFF" in err
    assert "1 descriptors are missing" in err
    status = dict(sqlite3.connect(db).execute("SELECT path, status FROM shapes").fetchall())
    assert sum(s == "failed" for s in status.values()) == 1
    # a re-run skips the failed mesh, says so, and still exits 1
    code, out, err = run(capsys, "index", collection, "--db", db, "--method", "d2", "--workers", "1", "--no-progress")
    assert code == 1 and "0 indexed, 0 failed, 6 unchanged (skipped), 1 failed before" in out
    assert "broken.off" in err  # the failure the error message points at is listed on this run too


def test_changed_and_deleted_files_leave_no_stale_rows(collection, tmp_path, capsys):
    db = tmp_path / "index.db"
    code, _, _ = run(capsys, "index", collection, "--db", db, "--method", "d2", "--workers", "1", "--no-progress")
    assert code == 0
    torus, changed, gone = collection / "torus.off", collection / "eight_genus2.off", collection / "odedstein_hand_lowres.obj.gz"
    changed.write_bytes(torus.read_bytes())  # eight_genus2.off now holds the torus
    gone.unlink()
    code, out, _ = run(capsys, "index", collection, "--db", db, "--method", "d2", "--workers", "1", "--no-progress")
    assert code == 0 and "1 indexed, 0 failed, 4 unchanged" in out
    assert "1 rows of files no longer in the indexed folders were removed" in out
    paths = [p for (p,) in sqlite3.connect(db).execute("SELECT path FROM shapes WHERE method = 'd2'")]
    assert len(paths) == len(set(paths)) == len(MESHES) - 1 and str(gone.resolve()) not in paths
    code, out, _ = run(capsys, "query", torus, "--db", db, "--method", "d2", "-k", "10", "--json")
    hits = {r["path"]: r["dissimilarity"] for r in json.loads(out)["results"]}
    assert len(hits) == len(MESHES) - 1 and hits[str(changed.resolve())] == 0.0  # the new content, once


def test_interrupted_index_resumes(collection, tmp_path, capsys, monkeypatch):
    import topomatch.pipeline.executors as ex

    db = tmp_path / "index.db"

    original = ex.execute_groups

    def interrupted(groups, cache, config, **kw):  # Ctrl-C after three meshes
        for i, results in enumerate(original(groups, cache, config, **kw)):
            if i == 3:
                raise KeyboardInterrupt
            yield results

    monkeypatch.setattr(ex, "execute_groups", interrupted)
    code, _, err = run(capsys, "index", collection, "--db", db, "--method", "d2", "--workers", "1", "--no-progress")
    assert code == 130
    assert sqlite3.connect(db).execute("SELECT COUNT(*) FROM shapes").fetchone()[0] == 3
    monkeypatch.setattr(ex, "execute_groups", original)
    code, out, _ = run(capsys, "index", collection, "--db", db, "--method", "d2", "--workers", "1", "--no-progress")
    assert "3 indexed, 0 failed, 3 unchanged" in out


def test_match_prints_correspondence(capsys):
    code, out, _ = run(capsys, "match", BUNDLED_MESHES / "odedstein_human_man.obj.gz",
                       BUNDLED_MESHES / "odedstein_human_woman.obj.gz", "--method", "rgpd", "--json")
    result = json.loads(out)
    assert code == 0 and result["n_endpoints_a"] >= 5 and result["n_endpoints_b"] >= 5
    assert len(result["correspondence"]) == min(result["n_endpoints_a"], result["n_endpoints_b"])
    # the method's own unmatched cost (the catalogue's, 0.3 for rgpd) for each endpoint left without a partner
    from topomatch.stages.retrieval.catalogue import get_method

    unmatched = abs(result["n_endpoints_a"] - result["n_endpoints_b"])
    cost = get_method("rgpd").unmatched_cost
    assert cost > 0 and result["dissimilarity"] == pytest.approx(sum(p["cost"] for p in result["correspondence"])
                                                                 + cost * unmatched)


def test_errors(tmp_path, capsys):
    code, _, err = run(capsys, "query", BUNDLED_MESHES / "torus.off", "--db", tmp_path / "none.db")
    assert code == 1 and "none.db: index not found" in err
    code, _, err = run(capsys, "index", tmp_path / "nothing", "--db", tmp_path / "x.db")
    assert code == 1 and "nothing: file not found" in err


def test_fused_topomatch_method(collection, tmp_path, capsys, monkeypatch):
    db = tmp_path / "index.db"
    code, out, _ = run(capsys, "index", collection, "--db", db, "--method", "topomatch", "--labels",
                       collection / "labels.csv", "--workers", "1", "--no-progress")
    assert code == 0
    for part in ("agd", "hks", "shapedna", "d2", "sh"):  # one index run per part of the fusion
        assert f"6 indexed, 0 failed, 0 unchanged (skipped) [{part}," in out
    from topomatch.stages.retrieval import ranking

    with monkeypatch.context() as patched:  # the database's part matrices were saved by index: a query reads them
        patched.setattr(ranking, "dissimilarity_matrix", lambda *a: pytest.fail("part matrix recomputed"))
        code, out, _ = run(capsys, "query", collection / "odedstein_hand_closed.obj.gz", "--db", db,
                           "--method", "topomatch", "-k", "6", "--json")
    result = json.loads(out)
    assert code == 0 and result["results"][0]["path"].endswith("odedstein_hand_closed.obj.gz")
    assert result["results"][0]["dissimilarity"] == 0.0 and len(result["results"]) == 6
    from topomatch.stages.retrieval.catalogue import get_method
    from topomatch.stages.retrieval.fusion import rerank_neighbours

    default = get_method("topomatch").fusion
    assert result["fusion"]["rerank_k"] == rerank_neighbours(default, 6 + 1)  # the query joins the graph
    code, out, _ = run(capsys, "evaluate", "--db", db, "--method", "topomatch", "--json", "--out", tmp_path / "D.npz")
    D = np.load(tmp_path / "D.npz")["D"]
    assert code == 0 and D.shape == (6, 6) and np.allclose(D, D.T) and np.allclose(np.diag(D), D.min(axis=1))
    fusion = json.loads(out)["fusion"]  # what the screening did, with each part's agreement
    assert sorted(fusion["kept"] + fusion["dropped"]) == sorted(("agd", "hks", "shapedna", "d2", "sh"))
    assert max(fusion["agreement"].values()) <= 1 and fusion["rerank_k"] == rerank_neighbours(default, 6)
    code, out, _ = run(capsys, "evaluate", "--db", db, "--method", "topomatch-equal", "--out", tmp_path / "E.npz")
    assert code == 0 and "fusion: kept agd, hks, shapedna, d2, sh; part agreement not measured" in out
    # a fusion needs an index: match does not offer it (usage error, 2)
    with pytest.raises(SystemExit) as usage:
        run(capsys, "match", collection / "torus.off", collection / "torus.off", "--method", "topomatch")
    assert usage.value.code == 2 and "invalid choice: 'topomatch'" in capsys.readouterr().err
    # a shape that is not in the index is not at 0 from its first match (the values say how far, not only the rank)
    code, out, _ = run(capsys, "query", BUNDLED_MESHES / "odedstein_cat-low-resolution.obj.gz", "--db", db, "--json")
    first = json.loads(out)["results"][0]
    assert code == 0 and 0.0 < first["dissimilarity"] < 1.0


def test_index_reports_open_and_multi_component_meshes(tmp_path, capsys):
    import igl
    from shapes import disjoint_union, icosphere

    def write(name, V, F):
        igl.write_triangle_mesh(str(folder / name), np.asarray(V, float), np.asarray(F, np.int64))

    folder = tmp_path / "meshes"
    folder.mkdir()
    sphere = icosphere(3)
    write("closed.off", sphere.V, sphere.F)
    used = sphere.F[sphere.V[sphere.F].mean(axis=1)[:, 2] < 0.8]  # a sphere with a hole at the top
    kept = np.unique(used)
    write("open.off", sphere.V[kept], np.searchsorted(kept, used))
    two = disjoint_union(sphere, icosphere(2))
    write("two.off", two.V, two.F)
    code, out, _ = run(capsys, "index", folder, "--db", tmp_path / "i.db", "--method", "shapedna", "--no-progress")
    assert code == 0 and "3 indexed, 0 failed" in out
    assert "1 mesh is open (with boundaries; " in out and "open.off): " in out and "holes were capped" in out
    assert "1 mesh has several components (" in out and "two.off): the largest was indexed" in out


def test_shortlisted_query_ranks_as_the_exact_fusion_without_re_ranking(collection, tmp_path, capsys):
    """With the shortlist longer than the index, the shortlisted query is the exact fused ranking
    (scales and screening from the whole index, no manifold ranking)."""
    from dataclasses import replace

    from topomatch.retrieval import open_index
    from topomatch.stages.retrieval.catalogue import get_method
    from topomatch.stages.retrieval.fusion import fused_query

    db = tmp_path / "index.db"
    assert run(capsys, "index", collection, "--db", db, "--workers", "1", "--no-progress")[0] == 0
    index = open_index(db)
    query = collection / "odedstein_human_woman.obj.gz"
    result = index.query(query, k=6, shortlist=True)
    assert result.fusion["shortlist"] == 6 and result.fusion["rerank_k"] is None
    assert (tmp_path / "index.db.ann").is_file() and (tmp_path / "index.db.ann.json").is_file()
    rows, descriptors = index.parts("topomatch")
    mats = index.part_matrices("topomatch", descriptors)
    i = next(j for j, r in enumerate(rows) if r.path.endswith("odedstein_human_woman.obj.gz"))
    exact = fused_query([M[i] for M in mats], mats, replace(get_method("topomatch").fusion, rerank_k=None))
    assert [r["path"] for r in result.results] == [rows[j].path for j in np.argsort(exact, kind="stable")]
    assert len(index.shortlist()) == 6

    def exact_order():
        rows, descriptors = index.parts("topomatch")
        mats = index.part_matrices("topomatch", descriptors)
        i = next(j for j, r in enumerate(rows) if r.path.endswith("odedstein_human_woman.obj.gz"))
        exact = fused_query([M[i] for M in mats], mats, replace(get_method("topomatch").fusion, rerank_k=None))
        return [rows[j].path for j in np.argsort(exact, kind="stable")]

    # what an index killed between its row commits and its graph save leaves: rows whose vectors are not the
    # graph's (here two shapes' hks descriptors swapped in the database); the graph is brought up to date
    import sqlite3
    con = sqlite3.connect(db)
    (a, da), (b, dbl) = con.execute("SELECT id, descriptor FROM shapes WHERE method = 'hks' ORDER BY id LIMIT 2")
    con.execute("UPDATE shapes SET descriptor = ? WHERE id = ?", (dbl, a))
    con.execute("UPDATE shapes SET descriptor = ? WHERE id = ?", (da, b))
    con.commit()
    con.close()
    assert [r["path"] for r in index.query(query, k=6, shortlist=True).results] == exact_order()
    # a graph of another dimension (a foreign or older file) is ignored with a warning, and rebuilt
    from topomatch.stages.retrieval.shortlist import Shortlist, shape_key
    keys = np.array([shape_key(r.path) for r in rows], dtype=np.uint64)
    foreign = Shortlist.build(keys, {"x": np.ones((len(keys), 3))}, {"x": 1.0})
    foreign.save(tmp_path / "index.db.ann")
    with pytest.warns(UserWarning, match="index.db.ann: it embeds parts"):
        result = index.query(query, k=6, shortlist=True)
    assert [r["path"] for r in result.results] == exact_order()


def test_labels_belong_to_files_and_unmatched_label_rows_are_reported(collection, tmp_path, capsys):
    db = tmp_path / "index.db"
    labels = collection / "labels.csv"
    labels.write_text(labels.read_text() + "missing.off,body\n")
    code, out, err = run(capsys, "index", collection, "--db", db, "--method", "d2", "--labels", labels,
                         "--workers", "1", "--no-progress")
    assert code == 0 and "1 labelled path is no mesh file of this run" in err and "missing.off" in err
    code, _, err = run(capsys, "index", collection, "--db", db, "--method", "d2", "--labels", labels, "--workers", "1",
                       "--no-progress", "-q")
    assert code == 0 and err == ""  # -q: no warnings (without it the second run warns again: below)
    code, _, err = run(capsys, "index", collection, "--db", db, "--method", "d2", "--labels", labels, "--workers", "1",
                       "--no-progress")
    assert "1 labelled path is no mesh file of this run" in err
    # a second method indexed without --labels takes the files' labels
    code, _, _ = run(capsys, "index", collection, "--db", db, "--method", "sh", "--workers", "1", "--no-progress")
    code, out, _ = run(capsys, "evaluate", "--db", db, "--method", "sh", "--json", "--out", tmp_path / "S.npz")
    assert code == 0 and json.loads(out)["n"] == len(MESHES)


def test_matching_options_on_a_method_without_endpoints_are_flagged(collection, tmp_path, capsys):
    db = tmp_path / "index.db"
    run(capsys, "index", collection, "--db", db, "--method", "d2", "--workers", "1", "--no-progress")
    code, _, err = run(capsys, "query", collection / "torus.off", "--db", db, "--method", "d2", "--unmatched-cost", "1")
    assert code == 0 and "--unmatched-cost apply to skeleton-endpoint matching; d2 has no endpoint part" in err


def test_shapes_without_endpoints_are_flagged_by_the_endpoint_methods(capsys):
    # the torus and the double torus have skeletons without endpoints: srg puts them at 0 from each other,
    # and says why instead of printing a 0 that reads as "the same shape"
    code, out, err = run(capsys, "match", BUNDLED_MESHES / "torus.off", BUNDLED_MESHES / "eight_genus2.off",
                         "--method", "srg")
    assert code == 0 and "dissimilarity (srg): 0" in out
    assert err.count("skeleton has no endpoints") == 2 and "torus.off" in err and "eight_genus2.off" in err
    code, _, err = run(capsys, "-q", "match", BUNDLED_MESHES / "torus.off", BUNDLED_MESHES / "eight_genus2.off",
                       "--method", "srg")
    assert code == 0 and err == ""


def test_index_of_another_method_and_small_classes_are_explained(collection, tmp_path, capsys):
    db = tmp_path / "d2.db"
    labels = tmp_path / "labels.csv"  # three shapes in one class, one alone: PSB evaluates three queries
    labels.write_text("relative_path,class\nmeshes/torus.off,a\nmeshes/eight_genus2.off,a\n"
                      "meshes/odedstein_hand_lowres.obj.gz,a\nmeshes/odedstein_human_man.obj.gz,b\n")
    files = [collection / n for n in ("torus.off", "eight_genus2.off", "odedstein_hand_lowres.obj.gz",
                                      "odedstein_human_man.obj.gz")]
    code, _, _ = run(capsys, "index", *files, "--db", db, "--method", "d2", "--labels", labels, "--no-progress")
    assert code == 0
    code, _, err = run(capsys, "query", files[0], "--db", db)  # the default method, which this index does not hold
    assert code == 2 and "no shapes indexed for method 'topomatch'" in err and "pass --method d2" in err
    code, out, _ = run(capsys, "evaluate", "--db", db, "--method", "d2", "--out", tmp_path / "D.npz")
    assert code == 0 and "3 of the 4 shapes are evaluated as queries" in out


def test_an_output_folder_that_cannot_be_written_is_refused_before_the_work(collection, tmp_path, capsys, monkeypatch):
    from topomatch.retrieval import Collection

    db = tmp_path / "d2.db"
    run(capsys, "index", collection, "--db", db, "--method", "d2", "--labels", collection / "labels.csv",
        "--no-progress")
    # nothing is created before the work: a skeleton whose input fails leaves no output folder behind
    code, _, err = run(capsys, "skeleton", tmp_path / "missing.off", "--out", tmp_path / "new" / "sk")
    assert code == 1 and "missing.off: file not found" in err and not (tmp_path / "new").exists()
    blocker = tmp_path / "a_file"
    blocker.write_text("not a folder")
    monkeypatch.setattr(Collection, "part_matrices", lambda *a, **k: pytest.fail("computed before the check"))
    code, _, err = run(capsys, "evaluate", "--db", db, "--method", "d2", "--out", blocker / "D.npz")
    assert code == 1 and "a_file: not a folder to write into" in err
    code, _, err = run(capsys, "evaluate", "--db", db, "--method", "d2", "--out", tmp_path / "nowhere" / "D.npz")
    assert code == 1 and "nowhere: no such folder to write into" in err  # evaluate's folder must exist
    from topomatch import skeletons

    monkeypatch.setattr(skeletons, "skeleton_with", lambda *a, **k: pytest.fail("computed before the check"))
    code, _, err = run(capsys, "skeleton", collection / "torus.off", "--out", blocker / "sk")
    assert code == 1 and "sk: not a folder to write into (a file is in the way: " in err
