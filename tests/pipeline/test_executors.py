"""The dask executor's check of its workers before any work (the cluster itself: test_dask.py)."""

from __future__ import annotations

from topomatch.pipeline import executors
from topomatch.pipeline.executors import environment_problems, worker_environment
from topomatch.pipeline.manifest import package_versions


def test_a_worker_reports_the_modules_it_cannot_import_and_the_paths_it_does_not_see(tmp_path, monkeypatch):
    monkeypatch.setattr(executors, "_SINGLE_THREADED", True)  # this process keeps its BLAS threads (test_dask.py)
    seen = tmp_path / "mesh.off"
    seen.write_text("OFF\n")
    report = worker_environment(["topomatch.pipeline.config", "no_such_stage_module"],
                                [str(seen), str(tmp_path / "elsewhere.off")], str(tmp_path / "cache"))
    assert report["packages"] == package_versions()
    assert report["modules"] == {"no_such_stage_module": "ModuleNotFoundError: No module named 'no_such_stage_module'"}
    assert report["unseen"] == [str(tmp_path / "elsewhere.off"), f"{tmp_path / 'cache'} (the cache: no writable folder "
                                                                 "there)"]
    (tmp_path / "cache").mkdir()
    assert worker_environment([], [str(seen)], str(tmp_path / "cache"))["unseen"] == []


def test_the_problems_name_each_worker_and_what_differs():
    here = {"topomatch": "0.1.0", "numpy": "2.1.0", "open3d": "0.18.0"}
    same = {"packages": dict(here), "modules": {}, "unseen": []}
    other = {"packages": {"topomatch": "0.0.9", "numpy": "2.1.0", "open3d": None},
             "modules": {"mystages": "ModuleNotFoundError: No module named 'mystages'"},
             "unseen": [f"/data/m{i}.off" for i in range(5)]}
    assert environment_problems({"tcp://a:1": same}, here) == []
    assert environment_problems({"tcp://b:2": other, "tcp://a:1": same}, here) == [
        "tcp://b:2: cannot import the stage module mystages (ModuleNotFoundError: No module named 'mystages')",
        "tcp://b:2: other versions: topomatch 0.0.9 (here 0.1.0), open3d not installed (here 0.18.0)",
        "tcp://b:2: does not see /data/m0.off, /data/m1.off, /data/m2.off and 2 more",
    ]


def _chain_items(meshes: list[str]):
    """Items whose results are MBs: a mesh loaded, cleaned and its spectrum (40 eigenpairs), then its HKS descriptor."""
    from tests_paths import BUNDLED_MESHES
    from topomatch.pipeline.config import build_experiment

    return build_experiment({"name": "records", "inputs": {"meshes": [str(BUNDLED_MESHES / m) for m in meshes]},
                             "stages": ["load", {"clean": {"components": "largest"}}, "spectrum", "hks"]}).items()


def test_a_worker_sends_back_a_small_record_and_the_results_stay_in_the_cache(tmp_path):
    """What the pool's workers return for an item whose results are MBs is a few KB: status, timings, keys, the
    table row's summaries and the kept descriptor; the results are read from the cache, equal to the computed
    ones; without a cache, the results come back whole."""
    import pickle  # the size a worker's answer has on the wire (multiprocessing and dask pickle it)

    import numpy as np

    from topomatch.pipeline.config import ExecutorConfig
    from topomatch.pipeline.item import StoredResults, run_items

    items = _chain_items(["odedstein_hand_closed.obj.gz", "odedstein_human_man.obj.gz"])
    cache = str(tmp_path / "cache")
    computed = {r.item_id: r for r in run_items(items, None)}
    records = {r.item_id: r for r in executors.execute(items, cache, ExecutorConfig(workers=2), keep=("descriptor",))}
    assert records.keys() == computed.keys()
    for item_id, record in records.items():
        full = computed[item_id]
        assert len(pickle.dumps(full)) > 2_000_000, len(pickle.dumps(full))
        assert len(pickle.dumps(record)) < 8_000, (len(pickle.dumps(record)), record.results)
        assert isinstance(record.results, StoredResults) and list(record.results.inline) == ["hks"]
        assert record.row() == full.row() and list(record.results) == list(full.results)
        np.testing.assert_array_equal(record.final("mesh").V, full.final("mesh").V)  # read from the cache
        np.testing.assert_array_equal(record.results["spectrum"].spectrum.values,
                                      full.results["spectrum"].spectrum.values)
    uncached = next(executors.execute(items[:1], None, ExecutorConfig(workers=1)))
    assert set(uncached.results.inline) == {"load", "clean", "spectrum", "hks"}
