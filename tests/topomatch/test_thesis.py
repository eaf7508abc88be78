"""``topomatch thesis``: the catalogue covers the thesis's figures and tables with existing configs; a
selection runs, measures its verdicts from the run's tables and writes the page; a config that needs
the missing data root is reported as not run."""

from __future__ import annotations

import json


from cli_schema import check
from topomatch.cli import main
from topomatch.experiments import CONFIGS_DIR
from topomatch.thesis import CATALOGUE, _matches


def test_catalogue_covers_the_thesis_with_existing_configs():
    ids = " ".join(i.id for i in CATALOGUE)
    for wanted in ("2.2", "2.3", "2.4", "2.6", "2.9", "2.11", "2.13", "3.1", "3.2", "3.3", "3.5", "3.7", "3.8",
                   "3.9", "3.10", "3.11", "3.12", "3.13", "4.3", "4.4", "4.5", "4.7", "4.8", "4.9", "4.10"):
        assert any(_matches(i, wanted) for i in CATALOGUE), wanted
    for table in ("Table 3.1", "Table 3.2", "Table 3.3", "Table 4.1", "Table 4.2", "Table 4.3"):
        assert table in ids
    for item in CATALOGUE:
        assert (CONFIGS_DIR / f"{item.config}.yaml").is_file(), item.config
        assert item.caption and item.claim


def test_thesis_runs_a_selection_and_writes_the_page(capsys, tmp_path, monkeypatch):
    monkeypatch.delenv("TOPOMATCH_DATA_ROOT", raising=False)
    code = main(["-q", "thesis", "--out", str(tmp_path), "--only", "3.2", "--only", "3.5", "--only", "Table 3.1",
                 "--json"])
    out = json.loads(capsys.readouterr().out)
    assert code == 1  # Table 3.1, asked for by name, needs the data root: the others ran and the page was written
    check(out, "thesis")
    by = {i["id"]: i for i in out["items"]}
    assert set(by) == {"Fig. 3.2", "Figs. 3.4-3.6", "Table 3.1"}
    assert by["Fig. 3.2"]["verdict"] == "reproduced" and "genus 2" in by["Fig. 3.2"]["measured"]
    assert by["Figs. 3.4-3.6"]["verdict"] == "reproduced" and "Σ dc_i = 1" in by["Figs. 3.4-3.6"]["measured"]
    assert by["Table 3.1"]["verdict"] == "not run" and "data root" in by["Table 3.1"]["measured"]
    page = (tmp_path / "thesis.html").read_text()
    assert "Fig. 3.2: Reeb graph extraction at several steps" in page and "configs/figures/reeb_steps.yaml" in page
    for f in by["Fig. 3.2"]["files"]:
        assert (tmp_path / by["Fig. 3.2"]["run_dir"].split(str(tmp_path) + "/")[-1] / f).is_file()
    assert json.loads((tmp_path / "thesis.json").read_text())[0]["id"] == "Fig. 3.2"


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
