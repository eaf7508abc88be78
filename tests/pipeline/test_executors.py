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
