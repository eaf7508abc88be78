"""``--json``: every command's output validates against the shipped schema (topomatch/cli/schema.json,
docs/cli_json.md); errors are one JSON object on stdout with the exit status; ``-v``/``-q``."""

from __future__ import annotations

import json

import pytest
import yaml

from topomatch.cli import main
from cli_schema import SCHEMA, check
from tests_paths import BUNDLED_MESHES, ITK_DIR


def run_json(capsys, *args):
    code = main([*map(str, args), "--json"])
    out, err = capsys.readouterr()
    lines = [line for line in out.splitlines() if line.strip()]
    document = json.loads(out)  # exactly one JSON object (it may span lines: stages indents)
    return code, document, err, lines


def test_the_schema_is_a_valid_json_schema():
    jsonschema = pytest.importorskip("jsonschema")
    jsonschema.Draft202012Validator.check_schema(SCHEMA)
    assert SCHEMA["x-schema-version"] == 1


@pytest.fixture(scope="module")
def labelled_db(tmp_path_factory):
    db = tmp_path_factory.mktemp("db") / "shapes.db"
    assert main(["-q", "index", str(BUNDLED_MESHES), "--db", str(db), "--method", "d2",
                 "--labels", str(BUNDLED_MESHES / "labels.csv")]) == 0
    return db


def test_every_command_output_validates(capsys, tmp_path, labelled_db):
    torus, eight = BUNDLED_MESHES / "torus.off", BUNDLED_MESHES / "eight_genus2.off"
    hand = BUNDLED_MESHES / "odedstein_hand_lowres.obj.gz"
    cases = {
        "skeleton": ["skeleton", hand, "--function", "mixture", "--out", tmp_path / "sk"],
        "match": ["match", hand, BUNDLED_MESHES / "odedstein_hand_closed.obj.gz", "--method", "srg"],
        "index": ["index", torus, eight, "--db", tmp_path / "i.db", "--method", "d2", "--no-progress"],
        "query": ["query", torus, "--db", labelled_db, "--method", "d2", "-k", "3"],
        "evaluate": ["evaluate", "--db", labelled_db, "--method", "d2", "--out", tmp_path / "D.npz"],
        "register": ["register", ITK_DIR / "BrainProtonDensitySliceBorder20.png",
                     ITK_DIR / "BrainProtonDensitySliceShifted13x17y.png"],
        "validate": ["validate", BUNDLED_MESHES.parent.parent / "configs" / "demo.yaml"],
        "stages": ["stages"],
    }
    for definition, args in cases.items():
        code, document, _, _ = run_json(capsys, *args)
        assert code == 0, (definition, document)
        check(document, definition)
    # the same counts under the same names: a skeleton's endpoints and a match's
    code, sk, _, _ = run_json(capsys, "skeleton", hand, "--function", "mixture")
    assert sk["n_endpoints"] >= 2
    code, m, _, _ = run_json(capsys, *cases["match"])
    assert m["n_endpoints_a"] >= 2 and "endpoints_a" not in m
    code, q, _, _ = run_json(capsys, *cases["query"])
    assert q["results"][0]["path"].endswith("torus.off") and q["results"][0]["dissimilarity"] == 0.0


def test_run_json(capsys, tmp_path):
    config = tmp_path / "c.yaml"
    config.write_text(yaml.safe_dump({"name": "j", "inputs": {"meshes": [str(BUNDLED_MESHES / "torus.off")]},
                                      "stages": ["load", "measures"],
                                      "reports": [{"table": {"name": "t"}}, "accuracy_summary"]}))
    code, document, err, _ = run_json(capsys, "run", config, "--out", tmp_path / "runs", "--no-progress")
    assert code == 0
    check(document, "run")
    assert document["n_items"] == 1 and document["outputs"]["table"] == ["tables/t.csv", "tables/t.json"]
    # a report's notes are not files
    assert document["outputs"]["accuracy_summary"] == [] and document["report_errors"] == []
    assert document["report_notes"] == {"accuracy_summary": ["no evaluate results"]}
    assert (tmp_path / "runs" / document["run_dir"].rsplit("/", 1)[-1] / "index.html").is_file()


@pytest.mark.parametrize("args,status,kind,file", [
    (["skeleton", "{tmp}/none.off"], 1, "input", "{tmp}/none.off"),
    (["skeleton", str(BUNDLED_MESHES / "torus.off"), "--levels", "1"], 2, "config", None),
    (["skeleton", str(BUNDLED_MESHES / "torus.off"), "--format", "stl"], 2, "usage", None),
    (["query", str(BUNDLED_MESHES / "torus.off"), "--db", "{tmp}/missing.db"], 1, "input", "{tmp}/missing.db"),
    (["register", "{tmp}/none.png", str(ITK_DIR / "BrainProtonDensitySlice.png")], 1, "input", "{tmp}/none.png"),
    (["run", "{tmp}/none.yaml"], 1, "input", "{tmp}/none.yaml"),
])
def test_errors_are_one_json_object_with_the_exit_status(capsys, tmp_path, args, status, kind, file):
    args = [a.replace("{tmp}", str(tmp_path)) for a in args]
    if kind == "usage":
        with pytest.raises(SystemExit) as exc:
            main([*args, "--json"])
        code = exc.value.code
        out, err = capsys.readouterr()
        document = json.loads(out)
    else:
        code, document, err, _ = run_json(capsys, *args)
    check(document, "error")
    assert code == status == document["status"] and document["kind"] == kind
    assert document["file"] == (file.replace("{tmp}", str(tmp_path)) if file else None)
    assert "error:" in err  # the one-line message still goes to stderr


def test_quiet_hides_warnings_and_verbose_lists_outputs(capsys, tmp_path):
    import numpy as np

    from topomatch.stages.mesh.export import mesh_text

    V = np.array([[1, 0, 0], [-1, 0, 0], [0, 1, 0], [0, -1, 0], [0, 0, 1], [0, 0, -1]], float)
    F = np.array([[0, 2, 4], [2, 1, 4], [1, 3, 4], [3, 0, 4], [2, 0, 5], [1, 2, 5], [3, 1, 5], [0, 3, 5]])
    pinched = tmp_path / "pinched.off"  # two octahedra sharing a vertex: non-manifold, so a warning
    pinched.write_text(mesh_text(np.vstack([V, V + [2, 0, 0]]), np.vstack([F, np.where(F == 1, 0, F + 6)]), "off"))
    assert main(["skeleton", str(pinched), "--function", "mixture"]) == 0
    assert "warning" in capsys.readouterr().err
    assert main(["-q", "skeleton", str(pinched), "--function", "mixture"]) == 0
    assert capsys.readouterr().err == ""
    assert main(["skeleton", str(pinched), "--function", "mixture", "--quiet"]) == 0  # after the command too
    assert capsys.readouterr().err == ""
    config = tmp_path / "c.yaml"
    config.write_text(yaml.safe_dump({"name": "v", "inputs": {"meshes": [str(BUNDLED_MESHES / "torus.off")]},
                                      "stages": ["load"], "reports": [{"table": {"name": "t"}}]}))
    assert main(["run", str(config), "--out", str(tmp_path / "r"), "-v", "--no-progress"]) == 0
    assert "table: tables/t.csv" in capsys.readouterr().err
    assert main(["run", str(config), "--out", str(tmp_path / "r"), "--no-progress"]) == 0
    assert "table: tables/t.csv" not in capsys.readouterr().err
