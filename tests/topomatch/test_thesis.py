"""``topomatch thesis``: the catalogue has a row for every figure and table of the thesis's lists; a selection
runs, measures its verdicts from the run's tables and replaces only its rows of an existing page; a config
that needs the missing data root is reported as not run; ``--list`` runs nothing; the page loads in a browser
with every image and no script error."""

from __future__ import annotations

import json

import pytest
from browser import dump_dom, needs_chromium, screenshot
from cli_schema import check
from topomatch.cli import main
from topomatch.experiments import CONFIGS_DIR
from topomatch.thesis import CATALOGUE, VERDICTS, _matches

#: The thesis's list of figures (chapter: count) and its tables.
FIGURES = {1: 9, 2: 15, 3: 13, 4: 10}
TABLES = ("Table 3.1", "Table 3.2", "Table 3.3", "Table 4.1", "Table 4.2", "Table 4.3")


def test_every_figure_and_table_of_the_thesis_is_exactly_one_row():
    for chapter, count in FIGURES.items():
        for k in range(1, count + 1):
            rows = [i.id for i in CATALOGUE if _matches(i, f"{chapter}.{k}")]
            assert len(rows) == 1, (f"{chapter}.{k}", rows)
    ids = [i.id for i in CATALOGUE]
    assert len(ids) == len(set(ids)) and all(t in ids for t in TABLES)
    for item in CATALOGUE:
        assert all((CONFIGS_DIR / f"{c}.yaml").is_file() for c in item.configs), item.configs
        assert item.caption and item.claim
        if not item.configs:  # a drawing: its row says so without running anything
            verdict, reason = item.check({})
            assert verdict == "illustration" and reason


def test_list_prints_the_catalogue_without_running(capsys, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    assert main(["thesis", "--list", "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    check(out, "thesis_list")
    assert [r["id"] for r in out["items"]] == [i.id for i in CATALOGUE] and not any(tmp_path.iterdir())
    noise = next(r for r in out["items"] if r["id"] == "Fig. 3.9")
    assert noise["command"] == 'topomatch thesis --only "Fig. 3.9" --out thesis'
    assert any("limit the project chose" in d for d in noise["departures"])
    table = next(r for r in out["items"] if r["id"] == "Table 3.1")
    assert table["command"].endswith("--data-root DIR")  # its config needs the external data root


def test_a_selection_runs_and_replaces_only_its_rows(capsys, tmp_path, monkeypatch):
    monkeypatch.delenv("TOPOMATCH_DATA_ROOT", raising=False)
    code = main(["-q", "thesis", "--out", str(tmp_path), "--only", "3.2", "--only", "3.5", "--only", "Table 3.1",
                 "--json"])
    out = json.loads(capsys.readouterr().out)
    assert code == 1  # Table 3.1, asked for by name, needs the data root: the others ran and the page was written
    check(out, "thesis")
    by = {i["id"]: i for i in out["items"]}
    assert set(by) == {"Fig. 3.2", "Figs. 3.4-3.6", "Table 3.1"}
    # cycles = genus is enforced by the band splitting: the steps are drawn, not a test
    assert by["Fig. 3.2"]["verdict"] == "illustration" and "genus 2" in by["Fig. 3.2"]["measured"]
    # the features' normalisation holds by definition: an illustration, not a reproduction
    assert by["Figs. 3.4-3.6"]["verdict"] == "illustration" and "by the definition" in by["Figs. 3.4-3.6"]["measured"]
    assert by["Table 3.1"]["verdict"] == "not run" and "data root" in by["Table 3.1"]["measured"]
    assert all(i["verdict"] in VERDICTS for i in out["items"])
    page = (tmp_path / "thesis.html").read_text()
    assert "Fig. 3.2: Reeb graph extraction at several steps" in page and "configs/figures/reeb_steps.yaml" in page
    assert 'topomatch thesis --only &quot;Fig. 3.2&quot;' in page
    saved = {r["id"]: r for r in json.loads((tmp_path / "thesis.json").read_text())}
    for f in saved["Fig. 3.2"]["files"]:
        assert (tmp_path / f).is_file() and f.startswith(saved["Fig. 3.2"]["run_dir"] + "/")
    # a second selection keeps the first one's rows, in the catalogue's order
    assert main(["-q", "thesis", "--out", str(tmp_path), "--only", "2.2", "--json"]) == 0
    capsys.readouterr()
    rows = json.loads((tmp_path / "thesis.json").read_text())
    assert [r["id"] for r in rows] == ["Fig. 2.2", "Fig. 3.2", "Figs. 3.4-3.6", "Table 3.1"]
    assert rows[1] == saved["Fig. 3.2"]
    html = (tmp_path / "thesis.html").read_text()
    assert html.count("<section") == 4 and "Fig. 3.2: Reeb graph extraction" in html


def test_unknown_selection_is_an_error(capsys, tmp_path):
    assert main(["thesis", "--out", str(tmp_path), "--only", "9.9"]) == 2  # a usage error (README's exit codes)
    assert "no thesis figure or table matches 9.9" in capsys.readouterr().err
    # beside an id that exists, too: nothing runs
    assert main(["thesis", "--out", str(tmp_path), "--only", "3.2", "--only", "9.9"]) == 2
    assert "no thesis figure or table matches 9.9;" in capsys.readouterr().err and not (tmp_path / "runs").exists()


def test_items_asked_for_that_cannot_run_fail_the_command(capsys, tmp_path):
    # without its data (a data root that does not exist) the tooth figures cannot run: asked for by name, that
    # is exit 1, with the page still written
    code = main(["thesis", "--out", str(tmp_path), "--only", "figures/spectral_tooth", "--data-root",
                 str(tmp_path / "nowhere")])
    out, err = capsys.readouterr()
    assert code == 1 and "not run" in out and "did not run or could not be measured (Fig. 4.3, Fig. 4.4)" in err
    assert (tmp_path / "thesis.html").is_file()


@needs_chromium
def test_the_page_loads_every_image_without_script_errors(capsys, tmp_path, monkeypatch):
    monkeypatch.delenv("TOPOMATCH_DATA_ROOT", raising=False)
    assert main(["-q", "thesis", "--out", str(tmp_path), "--only", "2.2", "--only", "2.4", "--only", "3.2"]) == 0
    capsys.readouterr()
    dom = dump_dom(tmp_path / "thesis.html")
    root = dom[dom.index("<html"):dom.index(">", dom.index("<html"))]  # the attributes the page's scripts set
    assert "data-js-errors" not in root
    assert 'data-broken-images=""' in root and 'data-images="' in root and 'data-images="0"' not in root
    shot = screenshot(tmp_path / "thesis.html", "thesis_page.png", tmp_path)
    assert shot.is_file() and shot.stat().st_size > 10_000


def test_a_damaged_page_record_loses_only_its_bad_rows(capsys, tmp_path, monkeypatch):
    monkeypatch.delenv("TOPOMATCH_DATA_ROOT", raising=False)
    assert main(["-q", "thesis", "--out", str(tmp_path), "--only", "3.2"]) == 0
    rows = json.loads((tmp_path / "thesis.json").read_text())
    rows[0]["files"].append("runs/gone/tables/missing.csv")  # a run folder deleted since
    (tmp_path / "thesis.json").write_text(json.dumps(rows + [{"id": "Fig. 2.3"}, 5, {"id": "Fig. 9.9"}]))
    with pytest.warns(UserWarning, match="3 earlier row.s. are not rows this version wrote"):
        assert main(["thesis", "--out", str(tmp_path), "--only", "2.2"]) == 0
    capsys.readouterr()
    kept = [r["id"] for r in json.loads((tmp_path / "thesis.json").read_text())]
    assert kept == ["Fig. 2.2", "Fig. 3.2"] and "cannot be read" in (tmp_path / "thesis.html").read_text()
    (tmp_path / "page").write_text("a file where the page's folder should be")
    assert main(["thesis", "--out", str(tmp_path / "page"), "--only", "2.2"]) == 1
    assert "a file is in the way" in capsys.readouterr().err and not (tmp_path / "page.runs").exists()
