"""The dask executor on a real cluster on localhost: a scheduler and workers started as separate processes
(``dask scheduler`` / ``dask worker``, in a working folder of their own), driven through the command line as a
user would: a task that kills its workers fails alone, a lost scheduler and a scheduler without workers end
the run within a bounded time with a message naming the scheduler, ``--json`` always prints its object, the
address given on the command line wins over ``$DASK_SCHEDULER_ADDRESS``, and no process outlives a test."""

from __future__ import annotations

import csv
import json
import os
import signal
import socket
import sqlite3
import subprocess
import sys
import threading
import time
import uuid
from pathlib import Path

import pytest
import yaml

import dask_stages  # noqa: F401  (registers test_worker_exit here; the workers import it by name)
from cli_schema import check
from processes import TAG_ENV, tagged_processes
from tests_paths import BUNDLED_MESHES, REPO_ROOT

from topomatch.cli import main

pytestmark = [pytest.mark.slow, pytest.mark.timeout(120),
              pytest.mark.skipif(not Path("/proc/self/environ").exists(), reason="needs /proc")]

MESHES = ["torus.off", "eight_genus2.off", "odedstein_hand_lowres.obj.gz", "odedstein_spot_low_resolution.obj.gz"]


class Cluster:
    """A scheduler and ``n_workers`` single-threaded workers (with nannies unless ``nanny`` is False), each a
    process of its own working in ``folder`` (not the client's), all tagged; :meth:`stop` kills them and checks
    that none is left."""

    def __init__(self, folder: Path, n_workers: int, *, allowed_failures: int = 3,
                 test_stages_on: tuple[str, ...] = ("scheduler", "workers"), nanny: bool = True):
        self.folder, self.tag, self.test_stages_on, self.nanny = folder, uuid.uuid4().hex, test_stages_on, nanny
        folder.mkdir(parents=True, exist_ok=True)
        self.env = {**os.environ, TAG_ENV: self.tag,
                    "DASK_DISTRIBUTED__SCHEDULER__ALLOWED_FAILURES": str(allowed_failures)}
        self.env.pop("DASK_SCHEDULER_ADDRESS", None)
        self.procs: list[subprocess.Popen] = []
        info = folder / "scheduler.json"
        self._start("scheduler", ["distributed.cli.dask_scheduler", "--host", "127.0.0.1", "--port", "0",
                                  "--no-dashboard", "--scheduler-file", str(info)])
        deadline = time.time() + 60
        self.address = None
        while self.address is None:
            assert time.time() < deadline and self.procs[0].poll() is None, self.log("scheduler")
            try:
                self.address = json.loads(info.read_text())["address"]
            except (OSError, ValueError, KeyError):
                time.sleep(0.1)
        self.add_workers(n_workers)
        if n_workers:  # registered before a test runs with short timeouts, also on a loaded machine
            from distributed import Client

            with Client(self.address, timeout=60) as client:
                client.wait_for_workers(n_workers, timeout=60)

    def _start(self, name: str, argv: list[str]) -> None:
        # this checkout's topomatch, and the tests' stage module (dask_stages) where test_stages_on says
        paths = [str(REPO_ROOT), *([str(REPO_ROOT / "tests")] if name in self.test_stages_on else [])]
        env = {**self.env, "PYTHONPATH": os.pathsep.join([*paths, os.environ.get("PYTHONPATH", "")])}
        log = open(self.folder / f"{name}.log", "ab")
        self.procs.append(subprocess.Popen([sys.executable, "-m", *argv], cwd=self.folder, env=env,
                                           stdout=log, stderr=log, start_new_session=True))
        log.close()

    def add_workers(self, n: int) -> None:
        """``n`` workers, each its own ``dask worker`` command (a nanny and its worker process, or without
        ``nanny`` the worker alone, which then has as many BLAS threads as cores unless topomatch limits them)."""
        for _ in range(n):
            self._start("workers", ["distributed.cli.dask_worker", self.address, "--nthreads", "1", "--no-dashboard",
                                    *([] if self.nanny else ["--no-nanny"])])

    def kill_scheduler(self) -> None:
        os.killpg(self.procs[0].pid, signal.SIGKILL)
        self.procs[0].wait()

    def kill_workers(self, n: int | None = None) -> None:
        """The first ``n`` workers (default: all), each with its nanny (which would restart it)."""
        for proc in self.procs[1:][:n]:
            os.killpg(proc.pid, signal.SIGKILL)
            proc.wait()

    def log(self, name: str) -> str:
        path = self.folder / f"{name}.log"
        return path.read_text(errors="replace") if path.exists() else ""

    def stop(self) -> None:
        for proc in self.procs:
            try:
                os.killpg(proc.pid, signal.SIGKILL)  # the process group of each command started here
            except ProcessLookupError:
                pass
            proc.wait()
        deadline = time.time() + 10
        while tagged_processes(self.tag) and time.time() < deadline:
            time.sleep(0.2)
        assert tagged_processes(self.tag) == [], "cluster processes outlived the test"


@pytest.fixture
def cluster_factory(tmp_path):
    started: list[Cluster] = []

    def start(n_workers: int, **kw) -> Cluster:
        started.append(Cluster(tmp_path / f"cluster{len(started)}", n_workers, **kw))
        return started[-1]

    yield start
    for cluster in started:
        cluster.stop()


def _cli(argv: list[str], capfd, schema: str) -> tuple[int, dict, str]:
    """Run the command in this process: exit status, its one JSON object on stdout (checked against the
    ``schema`` definition of the shipped --json schema), stderr."""
    status = main(argv)
    out, err = capfd.readouterr()
    lines = [line for line in out.splitlines() if line.strip()]
    assert len(lines) == 1, f"stdout holds {len(lines)} lines, expected one JSON object:\n{out}\n{err}"
    document = json.loads(lines[0])
    check(document, schema)
    return status, document, err


def _config(folder: Path, name: str, stage: dict) -> Path:
    path = folder / f"{name}.yaml"
    path.write_text(yaml.safe_dump({"name": name, "inputs": {"meshes": [str(BUNDLED_MESHES / m) for m in MESHES]},
                                    "stages": ["load", {"test_worker_exit": stage}]}))
    return path


def test_a_task_that_kills_its_workers_fails_alone_and_paths_are_the_clients(cluster_factory, tmp_path, monkeypatch,
                                                                            capfd):
    """Dask gives up on the task (KilledWorker): that item fails with the reason, the others are kept and
    results.csv is written; the relative --out is the client's: the workers, in another folder, wrote the
    cache under it."""
    cluster = cluster_factory(2, allowed_failures=0)
    client = tmp_path / "client"
    client.mkdir()
    monkeypatch.chdir(client)
    _config(client, "killer", {"exit_on": "eight_genus2"})
    status, out, err = _cli(["run", "killer.yaml", "--executor", "dask", "--address", cluster.address,
                             "--out", "runs", "--json", "--no-progress"], capfd, "run")
    assert status == 1 and out["n_items"] == 4 and out["n_failed"] == 1, (out, err)
    (failure,) = out["failures"]
    assert "eight_genus2.off: the dask workers computing this item died" in failure
    assert "also when it ran again alone: Dask gave up on it (KilledWorker: 1 worker death, the last on tcp://" in failure
    with open(Path(out["run_dir"]) / "tables" / "results.csv") as f:
        status_of = {row["item"]: row["status"] for row in csv.DictReader(f)}
    assert status_of == {"torus.off": "ok", "eight_genus2.off": "failed", "odedstein_hand_lowres.obj.gz": "ok",
                         "odedstein_spot_low_resolution.obj.gz": "ok"}
    assert "1 of 4 items failed" in err and "Traceback" not in err
    assert out["run_dir"].startswith("runs/")
    assert len(list((client / "runs" / ".cache").rglob("*.npz"))) >= 6  # load x 4 and the stage x 3, by the workers
    assert not (cluster.folder / "runs").exists()


def test_workers_without_a_stage_module_are_refused_before_any_work(cluster_factory, tmp_path, capfd):
    """A worker that cannot import a stage's module would close when it receives its first task (Dask): the check
    of the workers' environment names the module and the worker instead, before anything is computed."""
    cluster = cluster_factory(1, test_stages_on=("scheduler",))
    out_dir = tmp_path / "runs"
    status, out, err = _cli(["run", str(_config(tmp_path, "nomodule", {})), "--executor", "dask", "--address",
                             cluster.address, "--out", str(out_dir), "--json", "--no-progress"], capfd, "error")
    assert status == 1 and out["kind"] == "executor", (out, err)
    assert out["error"].startswith(f"the dask workers of the scheduler at {cluster.address} (executor.address) cannot "
                                   "compute as this client would; nothing was computed:\n  tcp://127.0.0.1:")
    assert ": cannot import the stage module dask_stages (ModuleNotFoundError: No module named 'dask_stages')" in \
        out["error"]
    assert not list((out_dir / ".cache").rglob("*.npz")) and "Traceback" not in err


def test_index_on_a_cluster_is_the_local_index_computed_with_one_blas_thread(cluster_factory, tmp_path, capfd):
    """The default (fused) method's index through the cluster equals the local one, row for row; what a worker
    sends back for a mesh is a record of a few KB (its descriptor kept), the results staying in the cache."""
    import pickle  # the size of a worker's answer on the wire (dask pickles it)

    cluster = cluster_factory(2, nanny=False)
    folder = tmp_path / "meshes"
    folder.mkdir()
    for name in MESHES:
        (folder / name).symlink_to(BUNDLED_MESHES / name)
    rows, reports = {}, {}
    for kind, options in (("local", ["--workers", "1"]), ("dask", ["--executor", "dask", "--address", cluster.address])):
        db = tmp_path / f"{kind}.db"
        status, out, err = _cli(["index", str(folder), "--db", str(db), "--json", "--no-progress", *options], capfd,
                                "index")
        assert status == 0 and [part["indexed"] for part in out["parts"]] == [4] * 5, err
        rows[kind] = sqlite3.connect(db).execute("SELECT path, method, status, n_endpoints, kind, descriptor FROM shapes "
                                                 "ORDER BY path, method").fetchall()
        reports[kind] = {k: v for k, v in out.items() if k not in ("db", "seconds", "parts")}
    assert rows["dask"] == rows["local"] and len(rows["local"]) == 4 * 5
    assert reports["dask"] == reports["local"]
    from distributed import Client

    from topomatch.pipeline.executors import _dask_task
    from topomatch.retrieval import method_experiment

    with Client(cluster.address) as client:  # workers started without a nanny (no thread settings) compute with one
        threads = client.run(dask_stages.blas_threads)
        items = method_experiment("hks", [BUNDLED_MESHES / "odedstein_hand_closed.obj.gz"]).items()  # results: MBs
        (record,) = client.submit(_dask_task, items, str(tmp_path / "records"), ("descriptor",), pure=False).result()
    assert len(threads) == 2 and all(counts and set(counts) == {1} for counts in threads.values()), threads
    assert record.ok and len(pickle.dumps(record)) < 8_000 and list(record.results.inline) == ["hks"]
    assert record.final("spectrum").values.shape == (41,)  # read from the cache the worker wrote


class _KillAfterTheFirstItem(threading.Thread):
    """Call ``kill`` once the first item's two stages (load, test_worker_exit) are in ``cache``, unless the run
    ended before (:meth:`stop`)."""

    def __init__(self, cache: Path, kill):
        super().__init__()
        self.cache, self.kill, self.ended = cache, kill, threading.Event()
        self.start()

    def run(self) -> None:
        while len(list(self.cache.rglob("*.npz"))) < 2:
            if self.ended.wait(0.05):
                return
        self.kill()

    def stop(self) -> None:
        self.ended.set()
        self.join()


def test_a_lost_scheduler_ends_the_run_naming_it_and_the_run_resumes(cluster_factory, tmp_path, capfd):
    cluster = cluster_factory(1)
    config = _config(tmp_path, "lost", {"sleep": 0.5})
    out_dir = tmp_path / "runs"
    killer = _KillAfterTheFirstItem(out_dir / ".cache", cluster.kill_scheduler)
    t0 = time.perf_counter()
    status, out, err = _cli(["run", str(config), "--executor", "dask", "--address", cluster.address, "--out",
                             str(out_dir), "--json", "--no-progress"], capfd, "error")
    killer.stop()
    assert status == 1 and out["kind"] == "executor" and out["status"] == 1, (out, err)
    assert out["error"].startswith(f"lost the dask scheduler at {cluster.address} (executor.address): the "
                                   "connection broke (")
    assert out["error"].endswith("finished and are kept (their stage results are cached): run the same command "
                                 "again to resume")
    assert "Traceback" not in err and time.perf_counter() - t0 < 60
    (run_dir,) = out_dir.glob("lost-*")
    assert (run_dir / "INCOMPLETE").is_file()

    status, again, err = _cli(["run", str(config), "--executor", "local", "--workers", "1", "--out", str(out_dir),
                               "--json", "--no-progress"], capfd, "run")
    assert status == 0 and again["run_dir"] == str(run_dir), err
    assert again["cache"]["hits"] >= 2  # at least the first item's two stages, computed before the scheduler was lost
    assert not (run_dir / "INCOMPLETE").exists()


def test_a_worker_killed_mid_run_is_replaced_by_the_others(cluster_factory, tmp_path, capfd):
    """A worker killed by something other than its task (its nanny too: it does not come back): the scheduler
    computes its tasks on the other worker, and the run completes."""
    cluster = cluster_factory(2)
    out_dir = tmp_path / "runs"
    killer = _KillAfterTheFirstItem(out_dir / ".cache", lambda: cluster.kill_workers(1))
    status, out, err = _cli(["run", str(_config(tmp_path, "one", {"sleep": 0.5})), "--executor", "dask", "--address",
                             cluster.address, "--out", str(out_dir), "--json", "--no-progress"], capfd, "run")
    killer.stop()
    assert status == 0 and out["n_items"] == 4 and out["n_failed"] == 0, (out, err)
    assert cluster.procs[1].poll() is not None and cluster.procs[2].poll() is None  # one killed, one kept working


def test_workers_that_all_leave_end_the_run_in_bounded_time(cluster_factory, tmp_path, capfd):
    cluster = cluster_factory(1)
    out_dir = tmp_path / "runs"
    killer = _KillAfterTheFirstItem(out_dir / ".cache", cluster.kill_workers)
    t0 = time.perf_counter()
    status, out, err = _cli(["run", str(_config(tmp_path, "left", {"sleep": 0.5})), "--executor", "dask", "--address",
                             cluster.address, "--dask-timeout", "1", "--out", str(out_dir), "--json", "--no-progress"],
                            capfd, "error")
    killer.stop()
    assert status == 1 and out["kind"] == "executor" and time.perf_counter() - t0 < 30, (out, err)
    assert out["error"].startswith(f"the dask scheduler at {cluster.address} (executor.address) has no workers: "
                                   "every worker left and none joined in 1 s")
    assert "finished and are kept" in out["error"] and "Traceback" not in err


def _closed_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def test_a_scheduler_without_workers_fails_in_bounded_time_and_the_command_lines_address_wins(
        cluster_factory, tmp_path, monkeypatch, capfd):
    cluster = cluster_factory(0)
    mesh = str(BUNDLED_MESHES / "torus.off")
    index = ["index", mesh, "--db", str(tmp_path / "x.db"), "--method", "d2", "--json", "--no-progress"]
    t0 = time.perf_counter()
    status, out, err = _cli([*index, "--executor", "dask", "--address", cluster.address, "--dask-timeout", "1"], capfd, "error")
    assert status == 1 and out["kind"] == "executor" and time.perf_counter() - t0 < 20, (out, err)
    assert out["error"].startswith(f"the dask scheduler at {cluster.address} (executor.address) has no workers: no "
                                   "worker joined in 1 s")

    monkeypatch.setenv("DASK_SCHEDULER_ADDRESS", cluster.address)  # what --executor dask uses without an address
    config = _config(tmp_path, "env", {})
    status, out, err = _cli(["run", str(config), "--executor", "dask", "--dask-timeout", "1", "--out",
                             str(tmp_path / "runs"), "--json", "--no-progress"], capfd, "error")
    assert status == 1 and out["error"].startswith(f"the dask scheduler at {cluster.address} "
                                                   "($DASK_SCHEDULER_ADDRESS) has no workers"), (out, err)

    other = f"tcp://127.0.0.1:{_closed_port()}"  # the command line's address wins over the environment's
    status, out, err = _cli([*index, "--executor", "dask", "--address", other, "--dask-timeout", "1"], capfd, "error")
    assert status == 2 and out["kind"] == "config", (out, err)
    assert out["error"].startswith(f"executor.address: cannot reach the dask scheduler at '{other}' within 1 s")
    assert "Traceback" not in err
