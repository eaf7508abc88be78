"""Runner: run folder contents, cache hits and misses, resume after interruption, executors agree."""

from __future__ import annotations

import dataclasses
import json
import os
import signal
import sys

import numpy as np
import pytest
from pydantic import Field

from topomatch.pipeline.config import build_experiment
from topomatch.pipeline.contract import Params, ReportOutput, StageResult, report, stage
from topomatch.pipeline.registry import STAGES, discover, register_module
from topomatch.pipeline import reports
from topomatch.pipeline.runner import run_experiment


def _run(config: dict, tmp_path, **kw):
    return run_experiment(build_experiment(config), out_root=tmp_path / "runs", progress=False, **kw)


def _stage_hits(outcome) -> dict[str, dict[str, bool]]:
    return {r.item_id: dict(r.cache_hits) for r in outcome.items}


def test_run_folder_has_config_manifest_tables_index(small_config, tmp_path):
    small_config["reports"] = [{"table": {"name": "areas", "columns": ["item", "measures.area*"]}}]
    outcome = _run(small_config, tmp_path)
    d = outcome.run_dir
    for name in ("config.yaml", "manifest.json", "index.html", "tables/results.csv", "tables/areas.csv"):
        assert (d / name).is_file(), name
    manifest = json.loads((d / "manifest.json").read_text())
    assert manifest["n_items"] == 4 and manifest["n_failed"] == 0
    assert manifest["packages"]["numpy"] == np.__version__
    assert manifest["seeds"] == {"noise.seed": 3}
    assert all(set(item["seconds"]) == {"load", "clean", "noise", "measures"} for item in manifest["items"])
    rows = json.loads((d / "tables" / "areas.json").read_text())
    assert len(rows) == 4 and all(row["measures.area"] > 0 for row in rows)


def test_second_run_is_all_cache_hits_with_identical_results(small_config, tmp_path):
    first = _run(small_config, tmp_path)
    second = _run(small_config, tmp_path)
    for item in first.items:  # sweep points of one mesh share load and clean, computed once
        shared = item.sweep["noise.sigma"] != 0.0
        assert item.cache_hits == {"load": shared, "clean": shared, "noise": False, "measures": False}
    assert all(h for hits in _stage_hits(second).values() for h in hits.values())
    for a, b in zip(first.items, second.items):
        np.testing.assert_array_equal(a.final("mesh").V, b.final("mesh").V)


def test_a_second_run_reuses_unchanged_reports_and_redraws_changed_ones(small_config, tmp_path, monkeypatch):
    small_config["reports"] = [{"table": {"name": "areas", "columns": ["item", "measures.area*"]}},
                               {"table": {"name": "names", "columns": ["item"]}}]
    first = _run(small_config, tmp_path)
    areas = first.run_dir / "tables" / "areas.json"
    stamp = areas.stat().st_mtime_ns
    second = _run(small_config, tmp_path)
    assert second.manifest["reports_reused"] == ["table", "table#1"] and areas.stat().st_mtime_ns == stamp
    assert second.manifest["outputs"] == first.manifest["outputs"]
    areas.unlink()  # a report whose files are gone is drawn again
    third = _run(small_config, tmp_path)
    assert third.manifest["reports_reused"] == ["table#1"] and areas.is_file()
    monkeypatch.setattr(reports, "_FINGERPRINT", "another version of the code")  # a code change: all drawn again
    assert _run(small_config, tmp_path).manifest["reports_reused"] == []
    monkeypatch.undo()
    small_config["stages"][2] = {"noise": {"sigma": 0.0, "relative_to": "bbox_diagonal", "seed": 4}}
    fourth = _run(small_config, tmp_path)  # another config is another run folder: nothing to reuse
    assert fourth.manifest["reports_reused"] == []


def test_a_run_folder_of_the_previous_release_is_read(small_config, tmp_path):
    """Its manifest listed a report's notes and error among the paths (``"NOTE: ..."``, ``"ERROR: ..."``): a
    complete report is reused, a failed one drawn again, and the manifest is rewritten with typed records."""
    small_config["reports"] = [{"table": {"name": "areas", "columns": ["item", "measures.area*"]}},
                               {"table": {"name": "names", "columns": ["item"]}}]
    first = _run(small_config, tmp_path)
    assert first.manifest["outputs"]["table"] == {"files": ["tables/areas.csv", "tables/areas.json"], "notes": [],
                                                  "error": None}
    path = first.run_dir / "manifest.json"
    old = json.loads(path.read_text())
    old["outputs"] = {"table": ["tables/areas.csv", "tables/areas.json", "NOTE: drawn by 0.1.0"],
                      "table#1": ["ERROR: report table#1 failed: ValueError: no"]}
    path.write_text(json.dumps(old))
    second = _run(small_config, tmp_path)
    assert second.manifest["reports_reused"] == ["table"]
    assert second.manifest["outputs"] == {
        "table": {"files": ["tables/areas.csv", "tables/areas.json"], "notes": ["drawn by 0.1.0"], "error": None},
        "table#1": {"files": ["tables/names.csv", "tables/names.json"], "notes": [], "error": None}}
    page = (second.run_dir / "index.html").read_text()
    assert "<p>drawn by 0.1.0</p>" in page and "all 4 items ok</span></dd>" in page


def test_figures_drawn_when_written_are_closed_and_one_that_fails_is_the_reports_error(small_config, tmp_path):
    """A report may give a figure as a function: it is drawn when the engine writes it, then closed; one that
    fails to draw is recorded as the report's error and its other outputs are written (the run goes on)."""
    import matplotlib.pyplot as plt

    small_config["reports"] = ["test_lazy_figures", {"table": {"name": "names", "columns": ["item"]}}]
    DRAWN.clear()
    open_before = plt.get_fignums()  # figures other tests left open
    outcome = _run(small_config, tmp_path)
    record = outcome.manifest["outputs"]["test_lazy_figures"]
    assert DRAWN == ["first", "broken"]
    assert record["files"] == ["tables/lazy.csv", "tables/lazy.json", "figures/first.png", "figures/eager.png"]
    assert record["error"] == ("report test_lazy_figures failed to draw broken: ValueError: no data to draw")
    assert all((outcome.run_dir / f).is_file() for f in record["files"])
    assert outcome.manifest["outputs"]["table"]["error"] is None and plt.get_fignums() == open_before


def test_changed_param_recomputes_only_downstream(small_config, tmp_path):
    _run(small_config, tmp_path)
    small_config["stages"][2] = {"noise": {"sigma": 0.0, "relative_to": "bbox_diagonal", "seed": 4}}
    again = _run(small_config, tmp_path)
    for item in again.items:
        assert item.cache_hits["load"] and item.cache_hits["clean"]
        if item.sweep["noise.sigma"] > 0:
            assert not item.cache_hits["noise"] and not item.cache_hits["measures"]
        else:
            # sigma = 0 with another seed is another cache key too: the key is the params, not the output
            assert not item.cache_hits["noise"]


def test_stage_version_bump_is_a_miss(small_config, tmp_path, monkeypatch):
    before = _run(small_config, tmp_path)
    discover()
    monkeypatch.setitem(STAGES, "clean", dataclasses.replace(STAGES["clean"], version=STAGES["clean"].version + 1))
    again = _run(small_config, tmp_path)
    for old, item in zip(before.items, again.items):
        assert item.cache_hits["load"] and item.keys["load"] == old.keys["load"]
        assert item.keys["clean"] != old.keys["clean"] and item.keys["noise"] != old.keys["noise"]
        if item.sweep["noise.sigma"] == 0.0:  # the first item of each mesh recomputes clean
            assert not item.cache_hits["clean"] and not item.cache_hits["noise"]


class _BoomParams(Params):
    fail_on: str = Field("", description="interrupt when the mesh has this name")


@dataclasses.dataclass(frozen=True)
class _BoomResult(StageResult):
    name: str


CALLS: list[str] = []


@stage("test_interrupt", params=_BoomParams, version=1, consumes=("mesh",), produces=())
def _interrupting_stage(mesh, *, params):
    """Test stage: simulates a crash (Ctrl-C) on one mesh."""
    CALLS.append(mesh.name)
    if mesh.name == params.fail_on:
        raise KeyboardInterrupt
    return _BoomResult(mesh.name)


@stage("test_sigkill", params=_BoomParams, version=1, consumes=("mesh",), produces=())
def _killing_stage(mesh, *, params):
    """Test stage: the worker process dies (SIGKILL, as an out-of-memory kill) on one mesh."""
    if mesh.name == params.fail_on:
        os.kill(os.getpid(), signal.SIGKILL)
    return _BoomResult(mesh.name)


DRAWN: list[str] = []


@report("test_lazy_figures", params=Params)
def _lazy_figures_report(experiment, results, params):
    """Test report: two figures drawn when written (one fails), one made at once, a table."""
    import matplotlib.pyplot as plt

    def draw(name):
        DRAWN.append(name)
        if name == "broken":
            raise ValueError("no data to draw")
        fig, ax = plt.subplots()
        ax.plot([0, 1], [0, len(results)])
        return fig

    eager, _ = plt.subplots()
    return ReportOutput(tables={"lazy": [{"n": len(results)}]},
                        figures={"first": lambda: draw("first"), "broken": lambda: draw("broken"), "eager": eager})


register_module(sys.modules[__name__])


def test_interrupted_run_resumes_without_recomputing(small_config, tmp_path):
    small_config["sweep"] = {}
    small_config["stages"] = ["load", {"clean": {}}, {"test_interrupt": {"fail_on": "eight_genus2"}}]
    CALLS.clear()
    with pytest.raises(KeyboardInterrupt):
        _run(small_config, tmp_path)
    assert CALLS == ["torus", "eight_genus2"]
    small_config["stages"][2] = {"test_interrupt": {"fail_on": "nothing"}}
    CALLS.clear()
    outcome = _run(small_config, tmp_path)
    hits = _stage_hits(outcome)
    assert hits["torus.off"]["load"] and hits["torus.off"]["clean"]
    assert hits["eight_genus2.off"]["load"] and hits["eight_genus2.off"]["clean"], "finished stages are kept"
    assert CALLS == ["torus", "eight_genus2"]  # the params changed, so this stage reruns


def test_failed_item_does_not_stop_the_others(small_config, tmp_path):
    bad = tmp_path / "broken.off"
    bad.write_text("OFF\n3 1 0\n0 0 0\n1 0\n")
    small_config["inputs"]["meshes"].insert(0, str(bad))
    small_config["sweep"] = {}
    outcome = _run(small_config, tmp_path)
    assert [r.ok for r in outcome.items] == [False, True, True]
    assert "broken.off" in outcome.items[0].error and "malformed OFF" in outcome.items[0].error
    rows = json.loads((outcome.run_dir / "tables" / "results.json").read_text())
    assert [row["status"] for row in rows] == ["failed", "ok", "ok"]


def test_a_dying_worker_fails_only_its_item(small_config, tmp_path):
    """A worker killed mid-item breaks the process pool; the command neither crashes nor loses the
    other items: they run again in pools of their own and only the killing item fails."""
    small_config["sweep"] = {}
    small_config["stages"] = ["load", {"test_sigkill": {"fail_on": "eight_genus2"}}]
    small_config["executor"] = {"kind": "local", "workers": 2}
    outcome = _run(small_config, tmp_path, use_cache=False)
    status = {r.item_id: r.ok for r in outcome.items}
    assert status == {"torus.off": True, "eight_genus2.off": False}
    failed = next(r for r in outcome.items if not r.ok)
    assert "worker process computing this item died" in failed.error


def _finals(outcome):
    return {r.item_id: (r.final("mesh").V, r.row()) for r in outcome.items}


@pytest.mark.slow
def test_executors_give_identical_results(small_config, tmp_path):
    inline = _run(small_config, tmp_path / "a", use_cache=False)
    small_config["executor"] = {"kind": "local", "workers": 2}
    pool = _run(small_config, tmp_path / "b", use_cache=False)
    small_config["executor"] = {"kind": "dask", "workers": 2}
    dask = _run(small_config, tmp_path / "c", use_cache=False)
    ref = _finals(inline)
    for other in (_finals(pool), _finals(dask)):
        assert other.keys() == ref.keys()
        for key, (V, row) in ref.items():
            np.testing.assert_array_equal(other[key][0], V)
            assert {k: v for k, v in other[key][1].items() if "seconds" not in k} == \
                   {k: v for k, v in row.items() if "seconds" not in k}


@pytest.mark.slow
def test_dask_executor_connects_to_an_existing_scheduler(small_config, tmp_path):
    from dask.distributed import LocalCluster

    with LocalCluster(n_workers=1, threads_per_worker=1, processes=True, dashboard_address=None) as cluster:
        small_config["executor"] = {"kind": "dask", "address": cluster.scheduler_address}
        outcome = _run(small_config, tmp_path)
    assert len(outcome.items) == 4 and not outcome.failed


def test_pool_workers_use_one_blas_thread():
    # numpy's and scipy's OpenBLAS both limited in a worker process (no oversubscription)
    import multiprocessing

    from topomatch.pipeline.executors import _single_threaded

    ctx = multiprocessing.get_context("forkserver")
    with ctx.Pool(1, initializer=_single_threaded) as pool:
        threads = pool.apply(_blas_threads_in_worker)
    assert threads and all(n == 1 for n in threads)


def _blas_threads_in_worker():
    import scipy.sparse.linalg  # noqa: F401  (what the stages use: scipy's own OpenBLAS)
    from threadpoolctl import threadpool_info

    return [i["num_threads"] for i in threadpool_info() if i["user_api"] == "blas"]


def test_items_run_together_compute_their_shared_stages_once(small_config):
    """run_items: two chains on one mesh that share load -> clean -> test_interrupt compute that
    prefix once, in memory, even without a cache."""
    from topomatch.pipeline.item import run_items

    small_config["sweep"] = {}
    small_config["inputs"]["meshes"] = small_config["inputs"]["meshes"][:1]
    small_config["stages"] = ["load", {"clean": {}}, {"test_interrupt": {"fail_on": "nothing"}}, "measures"]
    (a,) = build_experiment(small_config).items()
    small_config["stages"][3] = {"noise": {"sigma": 0.01, "seed": 1}}
    (b,) = build_experiment(small_config).items()
    CALLS.clear()
    first, second = run_items([a, b], None)
    assert CALLS == ["torus"]  # the shared stage ran once
    assert second.cache_hits["load"] and second.cache_hits["test_interrupt"] and not second.cache_hits["noise"]
    assert second.results["clean"] is first.results["clean"]


def test_an_interrupted_run_folder_is_marked_incomplete(small_config, tmp_path):
    from topomatch.pipeline.runner import INCOMPLETE

    small_config["sweep"] = {}
    small_config["stages"] = ["load", {"clean": {}}, {"test_interrupt": {"fail_on": "eight_genus2"}}]
    with pytest.raises(KeyboardInterrupt):
        _run(small_config, tmp_path)
    (folder,) = (tmp_path / "runs").glob("small-*")
    assert "has not finished" in (folder / INCOMPLETE).read_text()
    small_config["stages"][2] = {"test_interrupt": {"fail_on": "nothing"}}
    outcome = _run(small_config, tmp_path)
    assert not (outcome.run_dir / INCOMPLETE).exists()
