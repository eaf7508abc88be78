"""Client memory of ``topomatch index`` on a local two-worker dask cluster (issue 27).

Usage::

    TOPOMATCH_DATA_ROOT=../shared/data .venv/bin/python benchmarks/cluster_index_memory.py --n 400 --local
    # the same 40 meshes with another checkout's code (e.g. main before the change), for a before/after:
    .venv/bin/python benchmarks/cluster_index_memory.py --n 40 --code /path/to/other/checkout --tag before

It starts a scheduler and ``--workers`` worker processes on localhost (``dask scheduler`` / ``dask worker
--nthreads 1``, each a process of its own, in a scratch folder), then runs the client as a user would, a new
process: ``topomatch index MESHES --db D --labels L --method M --executor dask --address A --json``, and
reports the client process's peak resident memory (``ru_maxrss`` of that process, from ``os.wait4``: the
high-water mark, nothing sampled), its wall time and the scheduler's and workers' peaks beside it. The meshes
are the first ``--n / 20`` of each SHREC'07 Watertight class (``{data_root}/meshes/shrec07_watertight``,
labels.csv order), read in place: nothing is copied. Every index starts cold (a fresh database and stage
cache in the scratch folder, removed at the end).

``--local`` also indexes the same meshes with the local executor (``--executor local --workers 2``) into a
second database with a cache of its own (computed again, not read from the first), compares the two databases
row by row (path, method, status, descriptor bytes) and evaluates both (``topomatch evaluate --json``: NN,
mAP ...), which must be identical. The numbers go to ``benchmarks/results/cluster_index_memory.json`` under
``<tag>-<n>`` (``--tag``: default ``after``).

``--config PATH`` measures a config ``run`` instead of ``index`` (the issue's other case: "the client peaked
at 379 MB for 40 meshes"): the config (e.g. ``configs/retrieval/watertight.yaml``, its reports included) with
``inputs`` replaced by the chosen meshes, run by ``topomatch run CONFIG --executor dask --address A --json``;
``--local`` runs it again with the local executor into a second run folder with a cache of its own and compares
the two ``results.csv`` tables (every column but the timings and the per-item cache flags) and the report
tables. The record is ``<tag>-run-<config stem>-<n>``.

``--sqlite ROWS`` measures instead how fast the index's rows can be written (the choice of docs/cluster.md):
one writer on the client committing each row as it arrives (``ShapeIndex.put``, as ``topomatch index`` did
before), the same committing at most once a second (as it does now: ``put(commit=False)``, ``commit()``), and
per-worker shards (``--workers`` processes each
writing its share into a database of its own, then merged into the index by the client with ``ATTACH`` and
one ``INSERT ... SELECT``); descriptors of the default method's sizes (agd 8 x 11 endpoints, hks 256, shapedna
30, d2 64, sh 544 values), into a fresh index in the scratch folder.
"""

from __future__ import annotations

import argparse
import csv
import json
import os
import platform
import shutil
import signal
import sqlite3
import subprocess
import sys
import tempfile
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
RESULTS = HERE / "results" / "cluster_index_memory.json"


def watertight() -> Path:
    root = os.environ.get("TOPOMATCH_DATA_ROOT")
    folder = Path(root or "") / "meshes" / "shrec07_watertight"
    if not root or not (folder / "labels.csv").is_file():
        sys.exit("set TOPOMATCH_DATA_ROOT to the data root holding meshes/shrec07_watertight (README: Data)")
    return folder


def choose_meshes(folder: Path, n: int) -> list[Path]:
    """The first ``ceil(n / 20)`` meshes of each class (labels.csv order), ``n`` in all."""
    with open(folder / "labels.csv", newline="") as fh:
        rows = list(csv.DictReader(fh))
    classes: dict[str, list[Path]] = {}
    for row in rows:
        classes.setdefault(row["class"], []).append(folder / row["relative_path"])
    per_class = -(-n // len(classes))
    chosen = [path for paths in classes.values() for path in paths[:per_class]]
    return chosen[:n]


class Cluster:
    """A scheduler and ``n`` single-threaded workers on localhost, each a process group of its own."""

    def __init__(self, folder: Path, n: int, env: dict[str, str]):
        self.folder, self.env, self.procs = folder, env, []
        info = folder / "scheduler.json"
        self._start("scheduler", ["distributed.cli.dask_scheduler", "--host", "127.0.0.1", "--port", "0",
                                  "--no-dashboard", "--scheduler-file", str(info)])
        deadline = time.time() + 120
        while True:
            try:
                self.address = json.loads(info.read_text())["address"]
                break
            except (OSError, ValueError, KeyError):
                if time.time() > deadline or self.procs[0].poll() is not None:
                    self.stop()
                    sys.exit(f"the scheduler did not start: see {folder / 'scheduler.log'}")
                time.sleep(0.2)
        for i in range(n):
            self._start(f"worker{i}", ["distributed.cli.dask_worker", self.address, "--nthreads", "1",
                                       "--no-dashboard", "--no-nanny"])
        from distributed import Client

        with Client(self.address, timeout=120) as client:
            client.wait_for_workers(n, timeout=120)

    def _start(self, name: str, argv: list[str]) -> None:
        with open(self.folder / f"{name}.log", "ab") as log:
            self.procs.append(subprocess.Popen([sys.executable, "-m", *argv], cwd=self.folder, env=self.env,
                                               stdout=log, stderr=log, start_new_session=True))

    def peaks_mb(self) -> list[float]:
        """Peak resident memory (MB) of the scheduler and each worker so far (VmHWM)."""
        out = []
        for proc in self.procs:
            try:
                status = Path(f"/proc/{proc.pid}/status").read_text()
                out.append(int(next(l for l in status.splitlines() if l.startswith("VmHWM:")).split()[1]) / 1024)
            except (OSError, StopIteration):
                out.append(float("nan"))
        return out

    def stop(self) -> None:
        for proc in self.procs:
            try:
                os.killpg(proc.pid, signal.SIGKILL)
            except ProcessLookupError:
                pass
            proc.wait()


def run_config(config: Path, meshes: list[Path], scratch: Path) -> Path:
    """``config`` with its inputs replaced by ``meshes`` (absolute paths), written into ``scratch``."""
    import yaml

    data = yaml.safe_load(config.read_text())
    data["inputs"] = {"meshes": [str(m) for m in meshes]}
    path = scratch / config.name
    path.write_text(yaml.safe_dump(data, sort_keys=False))
    return path


#: results.csv columns that differ between two runs of the same science: timings and cache flags.
_RUN_DEPENDENT = ("seconds", "cached", "time", "worker")


def same_run_tables(a: Path, b: Path) -> dict:
    """Compare two run folders' tables (``tables/*.csv``): every column but the timings and cache flags."""
    out = {}
    for table in sorted((a / "tables").glob("*.csv")):
        other = b / "tables" / table.name
        if not other.is_file():
            out[table.name] = "missing in the second run"
            continue
        rows = []
        for path in (table, other):
            with open(path, newline="") as fh:
                rows.append([{k: v for k, v in row.items() if not any(w in k for w in _RUN_DEPENDENT)}
                             for row in csv.DictReader(fh)])
        out[table.name] = rows[0] == rows[1]
    return out


def client_run(argv: list[str], env: dict[str, str], cwd: Path) -> dict:
    """Run ``python -m topomatch ARGV`` as a new process; its exit status, JSON object, wall time and peak
    resident memory (MB, ``ru_maxrss`` of that process alone)."""
    out, err = cwd / "client.out", cwd / "client.err"
    t0 = time.perf_counter()
    with open(out, "wb") as fo, open(err, "wb") as fe:
        proc = subprocess.Popen([sys.executable, "-m", "topomatch", *argv], cwd=cwd, env=env, stdout=fo, stderr=fe)
        _, status, usage = os.wait4(proc.pid, 0)
        proc.returncode = os.waitstatus_to_exitcode(status)
    seconds = time.perf_counter() - t0
    text = out.read_text()
    try:
        document = json.loads(text)
    except ValueError:
        document = {"stdout": text[-2000:], "stderr": err.read_text()[-2000:]}
    return {"rc": proc.returncode, "json": document, "seconds": round(seconds, 1),
            "client_peak_mb": round(usage.ru_maxrss / 1024, 1)}


def rows_of(db: Path) -> list[tuple]:
    with sqlite3.connect(db) as con:
        return con.execute("SELECT path, method, params_hash, status, label, n_endpoints, kind, descriptor FROM shapes "
                           "ORDER BY path, method").fetchall()


PART_SIZES = {"agd": (8, 11), "hks": (256,), "shapedna": (30,), "d2": (64,), "sh": (544,)}


def _rows(first: int, n_meshes: int):
    import numpy as np

    rng = np.random.default_rng(first)
    for m in range(first, first + n_meshes):
        for part, shape in PART_SIZES.items():
            yield dict(content_hash=f"{m:064x}", path=f"/shared/meshes/{m}.off", label=None, method=part,
                       params_hash="0" * 16, params={"stages": []}, status="ok", reason=None,
                       n_endpoints=shape[0] if len(shape) == 2 else None,
                       kind="endpoints" if len(shape) == 2 else "vector", descriptor=rng.random(shape), seconds=0.1)


def _write_shard(path: str, first: int, n_meshes: int) -> None:
    """One worker's shard: its meshes' rows, one commit per row (as a worker would, each mesh when it is done)."""
    from topomatch.shape_index import ShapeIndex

    with ShapeIndex(path) as shard:
        for row in _rows(first, n_meshes):
            shard.put(**row)


def sqlite_writers(n_rows: int, workers: int, scratch: Path) -> dict:
    """Seconds to write ``n_rows`` index rows: one client writer (per row, per mesh), per-worker shards merged."""
    import multiprocessing

    from topomatch.shape_index import COMMIT_SECONDS, ShapeIndex

    n_meshes = n_rows // len(PART_SIZES)
    out: dict = {"rows": n_meshes * len(PART_SIZES), "meshes": n_meshes}
    t = time.perf_counter()
    with ShapeIndex(scratch / "one.db") as db:
        for row in _rows(0, n_meshes):
            db.put(**row)
    out["one_writer_commit_per_row_s"] = round(time.perf_counter() - t, 3)
    t = time.perf_counter()
    with ShapeIndex(scratch / "per_second.db") as db:  # what topomatch index does
        committed = time.monotonic()
        for row in _rows(0, n_meshes):
            db.put(**row, commit=False)
            if time.monotonic() - committed >= COMMIT_SECONDS:
                db.commit()
                committed = time.monotonic()
        db.commit()
    out["one_writer_commit_per_second_s"] = round(time.perf_counter() - t, 3)
    share = -(-n_meshes // workers)
    ctx = multiprocessing.get_context("forkserver")
    t = time.perf_counter()
    procs = [ctx.Process(target=_write_shard, args=(str(scratch / f"shard{w}.db"), w * share,
                                                    min(share, n_meshes - w * share))) for w in range(workers)]
    for proc in procs:
        proc.start()
    for proc in procs:
        proc.join()
    out["shards_written_s"] = round(time.perf_counter() - t, 3)
    t = time.perf_counter()
    with ShapeIndex(scratch / "merged.db") as db:
        columns = ("content_hash, path, label, method, params_hash, params, status, reason, n_endpoints, kind, "
                   "descriptor, seconds, created")
        for w in range(workers):
            db.db.execute("ATTACH DATABASE ? AS shard", (str(scratch / f"shard{w}.db"),))
            db.db.execute(f"INSERT OR REPLACE INTO shapes ({columns}) SELECT {columns} FROM shard.shapes")
            db.db.commit()
            db.db.execute("DETACH DATABASE shard")
    out["shards_merged_s"] = round(time.perf_counter() - t, 3)
    out["one_writer_rows_per_s"] = {"commit_per_row": round(out["rows"] / out["one_writer_commit_per_row_s"]),
                                     "commit_per_second": round(out["rows"] / out["one_writer_commit_per_second_s"])}
    return out


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--n", type=int, default=400, help="meshes (default all 400)")
    p.add_argument("--method", default="topomatch")
    p.add_argument("--workers", type=int, default=2)
    p.add_argument("--code", type=Path, default=HERE.parent, help="the checkout whose topomatch every process runs")
    p.add_argument("--tag", default="after", help="the record's name in the results (with -<n>)")
    p.add_argument("--local", action="store_true", help="also index with the local executor and compare")
    p.add_argument("--keep", action="store_true", help="keep the scratch folder")
    p.add_argument("--sqlite", type=int, metavar="ROWS", help="only measure the index writers (see above)")
    p.add_argument("--config", type=Path, help="measure `topomatch run CONFIG` on the chosen meshes (see above)")
    args = p.parse_args()
    if args.sqlite:
        with tempfile.TemporaryDirectory(prefix="cluster-index-sqlite-") as scratch:
            record = {**sqlite_writers(args.sqlite, args.workers, Path(scratch)), "load": os.getloadavg()[0]}
        results = json.loads(RESULTS.read_text()) if RESULTS.exists() else {}
        results[f"sqlite-{record['rows']}"] = record
        RESULTS.write_text(json.dumps(results, indent=2) + "\n")
        print(json.dumps(record, indent=2))
        return

    folder = watertight()
    meshes = choose_meshes(folder, args.n)
    scratch = Path(tempfile.mkdtemp(prefix="cluster-index-memory-"))
    code = args.code.resolve()
    env = {**os.environ, "PYTHONPATH": str(code), "OMP_NUM_THREADS": "1"}
    env.pop("DASK_SCHEDULER_ADDRESS", None)
    if args.config:
        common = ["run", str(run_config(args.config.resolve(), meshes, scratch)), "--json", "--no-progress", "-q"]
        target = {"dask": ["--out", str(scratch / "dask-runs")], "local": ["--out", str(scratch / "local-runs")]}
    else:
        common = ["index", *map(str, meshes), "--labels", str(folder / "labels.csv"), "--method", args.method,
                  "--json", "--no-progress", "-q"]
        target = {"dask": ["--db", str(scratch / "dask.db")], "local": ["--db", str(scratch / "local.db")]}
    record: dict = {"n": len(meshes), "method": args.method, "config": args.config and str(args.config),
                    "workers": args.workers, "code": str(code),
                    "commit": _commit(code), "python": platform.python_version(),
                    "load_before": os.getloadavg()[0]}
    try:
        (scratch / "cluster").mkdir()
        cluster = Cluster(scratch / "cluster", args.workers, env)
        try:
            run = client_run([*common, *target["dask"], "--executor", "dask", "--address", cluster.address], env,
                             scratch)
            peaks = cluster.peaks_mb()
        finally:
            cluster.stop()
        record["dask"] = {**{k: v for k, v in run.items() if k != "json"}, "scheduler_peak_mb": round(peaks[0], 1),
                          "worker_peaks_mb": [round(x, 1) for x in peaks[1:]],
                          "indexed": [part.get("indexed") for part in run["json"].get("parts", [])],
                          "failed": run["json"].get("n_failed", run["json"].get("error")),
                          "summary": {k: run["json"].get(k) for k in ("n_items", "n_failed", "report_errors")}}
        print(f"dask: client peak {run['client_peak_mb']} MB, {run['seconds']} s, rc {run['rc']}", flush=True)
        if args.local:
            local = client_run([*common, *target["local"], "--workers", str(args.workers)], env, scratch)
            record["local"] = {k: v for k, v in local.items() if k != "json"}
            print(f"local: client peak {local['client_peak_mb']} MB, {local['seconds']} s", flush=True)
        if args.local and args.config:
            record["identical"] = same_run_tables(Path(run["json"]["run_dir"]), Path(local["json"]["run_dir"]))
            print(f"tables identical: {record['identical']}", flush=True)
        elif args.local:
            a, b = rows_of(scratch / "dask.db"), rows_of(scratch / "local.db")
            record["rows"] = len(a)
            record["rows_identical"] = a == b
            evaluations = {}
            for kind in ("dask", "local"):
                ev = client_run(["evaluate", "--db", str(scratch / f"{kind}.db"), "--method", args.method, "--json"],
                                env, scratch)
                evaluations[kind] = {"n": ev["json"].get("n"), "micro": ev["json"].get("micro"),
                                     "macro": ev["json"].get("macro")}
            record["evaluation"] = evaluations
            record["evaluation_identical"] = evaluations["dask"] == evaluations["local"]
            print(f"rows identical: {record['rows_identical']} ({len(a)} rows); evaluation {evaluations['dask']}; "
                  f"identical: {record['evaluation_identical']}", flush=True)
    finally:
        if args.keep:
            print(f"kept {scratch}")
        else:
            shutil.rmtree(scratch, ignore_errors=True)
    record["load_after"] = os.getloadavg()[0]
    results = json.loads(RESULTS.read_text()) if RESULTS.exists() else {}
    results[f"{args.tag}-run-{args.config.stem}-{len(meshes)}" if args.config else f"{args.tag}-{len(meshes)}"] = record
    RESULTS.parent.mkdir(parents=True, exist_ok=True)
    RESULTS.write_text(json.dumps(results, indent=2) + "\n")
    print(json.dumps(record, indent=2))


def _commit(code: Path) -> str | None:
    try:
        return subprocess.run(["git", "-C", str(code), "rev-parse", "--short", "HEAD"], capture_output=True, text=True,
                              check=True).stdout.strip()
    except (OSError, subprocess.CalledProcessError):
        return None


if __name__ == "__main__":
    main()
