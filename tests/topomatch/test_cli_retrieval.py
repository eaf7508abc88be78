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
    code, out, _ = run(capsys, "index", collection, "--db", db, "--method", "d2", "--workers", "1", "--no-progress")
    assert code == 1 and "0 indexed, 0 failed, 7 unchanged (skipped), 1 failed before" in out


def test_interrupted_index_resumes(collection, tmp_path, capsys, monkeypatch):
    import topomatch.pipeline.executors as ex

    db = tmp_path / "index.db"

    original = ex.execute_groups

    def interrupted(groups, cache, config):  # Ctrl-C after three meshes
        for i, results in enumerate(original(groups, cache, config)):
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
    # the method's own unmatched cost (0.2 for rgpd) for each endpoint left without a partner
    unmatched = abs(result["n_endpoints_a"] - result["n_endpoints_b"])
    assert result["dissimilarity"] == pytest.approx(sum(p["cost"] for p in result["correspondence"]) + 0.2 * unmatched)


def test_errors(tmp_path, capsys):
    code, _, err = run(capsys, "query", BUNDLED_MESHES / "torus.off", "--db", tmp_path / "none.db")
    assert code == 1 and "none.db: index not found" in err
    code, _, err = run(capsys, "index", tmp_path / "nothing", "--db", tmp_path / "x.db")
    assert code == 1 and "nothing: file not found" in err


def test_fused_topomatch_method(collection, tmp_path, capsys):
    db = tmp_path / "index.db"
    code, out, _ = run(capsys, "index", collection, "--db", db, "--method", "topomatch", "--labels",
                       collection / "labels.csv", "--workers", "1", "--no-progress")
    assert code == 0
    for part in ("agd", "hks", "shapedna", "d2", "sh"):  # one index run per part of the fusion
        assert f"6 indexed, 0 failed, 0 unchanged (skipped) [{part}," in out
    code, out, _ = run(capsys, "query", collection / "odedstein_hand_closed.obj.gz", "--db", db,
                       "--method", "topomatch", "-k", "6", "--json")
    result = json.loads(out)
    assert code == 0 and result["results"][0]["path"].endswith("odedstein_hand_closed.obj.gz")
    assert result["results"][0]["dissimilarity"] == 0.0 and len(result["results"]) == 6
    code, out, _ = run(capsys, "evaluate", "--db", db, "--method", "topomatch", "--json", "--out", tmp_path / "D.npz")
    D = np.load(tmp_path / "D.npz")["D"]
    assert code == 0 and D.shape == (6, 6) and np.allclose(D, D.T) and np.allclose(np.diag(D), D.min(axis=1))
    # a fusion needs an index: match explains and exits 2
    code, _, err = run(capsys, "match", collection / "torus.off", collection / "torus.off", "--method", "topomatch")
    assert code == 2 and "fused method" in err and "agd" in err
