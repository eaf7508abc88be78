"""Executors: where the items of a run are computed.

``local`` runs items in a process pool (``forkserver`` start method: no fork of a
threaded parent) with one worker per core by default, or inline when there is
one worker or one item. ``dask`` submits items to a dask.distributed cluster: a
new ``LocalCluster`` (processes, one thread each) or an existing scheduler at
``address``. Both yield results as they complete; the runner orders them.

Every worker (a pool process, a dask worker, or this process when it computes inline) runs
:func:`~topomatch.pipeline.item.run_records`: it writes the stage results to the cache and sends
back a small record per item (status, timings, cache keys, the summaries of the table row, and
only the results the cache cannot hold or the caller asks for with ``keep``), never the results
themselves, so the client's memory does not grow with the collection (docs/cluster.md).

Each pool worker limits its BLAS/OpenMP thread pools to one thread: the items are the
parallelism, and BLAS threads on top of one process per core oversubscribe the cores
(measured: ARPACK in ShapeDNA ran 2-3x slower with two workers each using two BLAS threads).
"""

from __future__ import annotations

import dataclasses
import logging
import multiprocessing
import os
import sys
import time
from contextlib import contextmanager
from concurrent.futures import ProcessPoolExecutor, as_completed
from typing import Any, Collection, Iterator, Sequence

from topomatch.pipeline.experiment import Item
from topomatch.pipeline.schema import DEFAULT_DASK_TIMEOUT, ExecutorConfig
from topomatch.pipeline.errors import ConfigError, ExecutorError
from topomatch.pipeline.item import ItemResult, run_records


def default_workers() -> int:
    return max(1, len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count() or 1)


def execute(items: Sequence[Item], cache_root: str | None, config: ExecutorConfig,
            keep: Collection[str] = ()) -> Iterator[ItemResult]:
    """Run every item; yield its record (see :func:`execute_groups`) in completion order."""
    for results in execute_groups([[item] for item in items], cache_root, config, keep):
        yield from results


def execute_groups(groups: Sequence[Sequence[Item]], cache_root: str | None,
                   config: ExecutorConfig, keep: Collection[str] = ()) -> Iterator[list[ItemResult]]:
    """Run every group of items in one worker (:func:`~topomatch.pipeline.item.run_items`: a stage result
    shared by items of a group is computed once and kept in memory); yield each group's records in
    completion order. The unit of parallelism is the group (e.g. one mesh and every part method).

    A record (:func:`~topomatch.pipeline.item.to_record`) holds the item's status, timings, cache keys and
    summaries; its ``results`` are read from the cache at ``cache_root`` when asked for, except the results
    the cache does not hold (all of them when ``cache_root`` is None) and the last producers of the state
    entries named in ``keep`` (e.g. ``("descriptor",)``), which come back with it.

    Raises
    ------
    ConfigError
        Settings that do not apply to ``config.kind`` (:meth:`ExecutorConfig.check`), before any work.
    ExecutorError
        The dask scheduler was lost or has no workers (what finished was yielded first).
    """
    config.check()
    if not groups:  # nothing to compute (e.g. an index whose meshes are all unchanged): no cluster to reach
        return
    if config.kind == "dask":
        yield from _dask(groups, cache_root, config, tuple(keep))
    else:
        yield from _local(groups, cache_root, config.workers or default_workers(), tuple(keep))


def _worker_init(parent: int) -> None:
    """Pool-worker initializer: leave when the parent dies, and use one BLAS thread."""
    _exit_with_parent(parent)
    _single_threaded()


def _exit_with_parent(parent: int, interval: float = 0.5) -> None:
    """Watch the process that started the pool and end this worker when it is gone.

    A worker started by ``forkserver`` is a child of the fork server, not of the command, so when
    the command is killed (SIGKILL, an OOM kill) nothing tells its workers, and they would stay
    alive with their memory (~100 MB each): a daemon thread polls the command's pid instead.
    """
    import threading
    import time

    def watch() -> None:
        while True:
            time.sleep(interval)
            try:
                os.kill(parent, 0)
            except ProcessLookupError:
                os._exit(1)
            except PermissionError:  # the pid was reused by another user's process: ours is gone
                os._exit(1)

    threading.Thread(target=watch, name="topomatch-parent-watch", daemon=True).start()


def _single_threaded() -> None:
    """One BLAS / OpenMP thread per worker process.

    threadpoolctl only limits the libraries already loaded, and scipy ships its own OpenBLAS
    (besides numpy's), loaded with ``scipy.linalg``: import it first.
    """
    os.environ["OMP_NUM_THREADS"] = "1"  # read by the libraries that start threads of their own later
    try:
        import scipy.linalg  # noqa: F401  (loads scipy's OpenBLAS)
        import scipy.sparse.linalg  # noqa: F401
        from threadpoolctl import threadpool_limits
    except ImportError:  # pragma: no cover - both are dependencies
        return
    threadpool_limits(limits=1)


def _local(groups: Sequence[Sequence[Item]], cache_root: str | None, workers: int,
           keep: tuple[str, ...]) -> Iterator[list[ItemResult]]:
    """Run the groups in a process pool. A worker that dies (killed, out of memory, a crash in
    native code) breaks the whole pool: the groups it left unfinished run again, each in a pool
    of its own, so that only the group that kills its worker fails (as an error naming the
    worker's death), and every other result is kept."""
    workers = min(workers, len(groups))
    if workers <= 1:
        for group in groups:
            yield run_records(group, cache_root, keep)
        return
    unfinished: list[int] = []
    yield from _pool_run(groups, range(len(groups)), cache_root, workers, unfinished, keep)
    for i in unfinished:  # after a worker died: isolate the culprit
        lost: list[int] = []
        yield from _pool_run(groups, [i], cache_root, 1, lost, keep)
        if lost:
            yield [_worker_died(item) for item in groups[i]]


def _pool_run(groups: Sequence[Sequence[Item]], which: Sequence[int], cache_root: str | None, workers: int,
              unfinished: list[int], keep: tuple[str, ...]) -> Iterator[list[ItemResult]]:
    """Run ``groups[i]`` for ``i`` in ``which`` in one pool; on a broken pool, append the indices it
    did not finish to ``unfinished`` and return."""
    from concurrent.futures.process import BrokenProcessPool

    ctx = multiprocessing.get_context("forkserver")
    ctx.set_forkserver_preload(["topomatch.pipeline.item"])
    done: set[int] = set()
    with ProcessPoolExecutor(max_workers=workers, mp_context=ctx, initializer=_worker_init,
                             initargs=(os.getpid(),)) as pool:
        with _main_script_hidden([item for i in which for item in groups[i]]):
            futures = {pool.submit(run_records, groups[i], cache_root, keep): i for i in which}  # starts the workers
        try:
            for future in as_completed(futures):
                try:
                    result = future.result()
                except BrokenProcessPool:
                    unfinished.extend(i for i in which if i not in done)
                    return
                done.add(futures[future])
                yield result
        except BaseException:
            for f in futures:
                f.cancel()
            raise


def _worker_died(item: Item) -> ItemResult:
    return ItemResult(item.item_id, item.input_path, item.sweep, item.input_label,
                      error="the worker process computing this item died (killed, out of memory, or a crash in "
                            "native code); the other items are kept", error_stage="worker")


@contextmanager
def _main_script_hidden(items: Sequence[Item]) -> Iterator[None]:
    """While the workers start, hide the main script's path from multiprocessing.

    A worker started by ``spawn`` or ``forkserver`` runs the parent's main script again before it
    takes work, to find functions defined there; a user's script that calls the API
    (``topomatch.index(...)``) without an ``if __name__ == "__main__":`` guard would then start
    every worker's own run and crash. The workers run only the engine's ``run_records``, so they need
    the script only when a stage was defined in it (``registry.register_module``): then nothing is
    hidden.
    """
    main = sys.modules.get("__main__")
    path = getattr(main, "__file__", None)
    needs_main = any(call.spec.func.__module__ == "__main__" for item in items for call in item.calls)
    if main is None or path is None or needs_main:
        yield
        return
    del main.__file__
    try:
        yield
    finally:
        main.__file__ = path


def _single_threaded_once() -> None:
    """:func:`_single_threaded`, once per process: a dask worker gets the same one BLAS thread as a pool worker,
    whoever started it (a nanny, ``dask worker``, a batch job) and when it joins or restarts mid-run."""
    global _SINGLE_THREADED
    if not _SINGLE_THREADED:
        _single_threaded()
        _SINGLE_THREADED = True


_SINGLE_THREADED = False


def _dask_task(group: list[Item], cache_root: str | None, keep: tuple[str, ...] = ()) -> list[ItemResult]:
    """What a dask worker runs for one group: the records of its items (the results stay in the cache)."""
    _single_threaded_once()
    return run_records(group, cache_root, keep)


def _absolute(item: Item) -> Item:
    """``item`` with its input files as absolute paths of the client (a worker's working folder is not the
    client's; the displayed ``input_path`` is kept)."""
    paths = item.paths or {"path": item.input_path}
    return dataclasses.replace(item, paths={k: os.path.abspath(v) for k, v in paths.items()})


#: How often (seconds) a dask run looks at its scheduler while it waits for results, and how long it sleeps
#: between looks at the finished tasks.
_POLL = 0.5
_STEP = 0.05


def _dask(groups: Sequence[Sequence[Item]], cache_root: str | None,
          config: ExecutorConfig, keep: tuple[str, ...]) -> Iterator[list[ItemResult]]:
    """Run the groups on a dask cluster: the scheduler at ``config.scheduler()``, else a new ``LocalCluster``.

    The local executor's guarantees, on a cluster: a group whose task Dask gives up on (its workers died
    running it: ``KilledWorker``) is tried once more alone, and fails alone if it kills a worker again; a lost
    scheduler, or a scheduler without workers for ``config.timeout`` seconds, ends the run with an
    :class:`ExecutorError` naming the scheduler (what finished is kept: the cache resumes it). Paths (inputs,
    cache) are the client's, made absolute here: workers must see them at the same place (docs/cluster.md).
    """
    try:
        from dask.distributed import Client, LocalCluster
    except ImportError as exc:  # pragma: no cover - dask is a dependency
        raise ConfigError(f"executor.kind=dask needs dask[distributed] ({exc})") from None
    # distributed sets its loggers to INFO when imported: they follow the process's level instead (the CLI's
    # -q / default / -v), so a quiet run stays quiet
    logging.getLogger("distributed").setLevel(logging.getLogger().getEffectiveLevel())
    address, source = config.scheduler()
    timeout = config.timeout or DEFAULT_DASK_TIMEOUT
    if cache_root is not None:  # made here, so that a worker that does not see it is told (_check_workers)
        cache_root = os.path.abspath(cache_root)
        os.makedirs(cache_root, exist_ok=True)
    groups = [[_absolute(item) for item in group] for group in groups]
    cluster = None
    if address:
        try:
            client = Client(address, timeout=timeout)
        except (OSError, ValueError, TypeError) as exc:  # unreachable; malformed address (ValueError, TypeError)
            raise ConfigError(f"{source}: cannot reach the dask scheduler at {address!r} within {timeout:g} s "
                              f"({exc})") from None
    else:
        cluster = LocalCluster(n_workers=config.workers or default_workers(), threads_per_worker=1, processes=True,
                               dashboard_address=None)
        client = Client(cluster)
        address, source = cluster.scheduler_address, "a local cluster"
    run = _DaskRun(client, address, source, timeout, sum(map(len, groups)))
    try:
        yield from run.groups(groups, cache_root, keep)
    finally:
        run.close()
        if cluster is not None:
            cluster.close()


class _DaskRun:
    """One run's groups on one dask client: submitting, collecting, isolating killed tasks, and the
    errors that end the run (naming the scheduler's address and where it came from: ``source``)."""

    def __init__(self, client, address: str, source: str, timeout: float, n_items: int):
        self.client, self.address, self.timeout, self.n_items = client, address, timeout, n_items
        self.where = f"{address} ({source})"
        self.finished = 0  # items whose results came back
        self.lost = False

    def groups(self, groups: list[list[Item]], cache_root: str | None,
               keep: tuple[str, ...] = ()) -> Iterator[list[ItemResult]]:
        self._wait_for_workers()
        self._check_workers(groups, cache_root)
        futures = {self.client.submit(_dask_task, group, cache_root, keep, pure=False): i
                   for i, group in enumerate(groups)}
        killed: list[int] = []
        for i, outcome in self._collect(futures):
            if _is_killed_worker(outcome):
                killed.append(i)  # maybe only a neighbour of the culprit on its worker: tried again alone below
            else:
                yield self._results(groups[i], outcome)
        for i in killed:
            future = self.client.submit(_dask_task, groups[i], cache_root, keep, pure=False)
            for _, outcome in self._collect({future: i}):
                yield self._results(groups[i], outcome)

    def _results(self, group: list[Item], outcome: Any) -> list[ItemResult]:
        self.finished += len(group)
        if not isinstance(outcome, BaseException):
            return outcome
        if _is_killed_worker(outcome):
            deaths = outcome.allowed_failures + 1
            error = (f"the dask workers computing this item died (killed, out of memory, or a crash in native code), "
                     f"also when it ran again alone: Dask gave up on it (KilledWorker: {deaths} worker "
                     f"{'death' if deaths == 1 else 'deaths'}, the last on {outcome.last_worker.address}); the other "
                     "items are kept")
        else:  # e.g. a worker that cannot import a stage's module
            error = f"the dask worker could not run this item: {type(outcome).__name__}: {' '.join(str(outcome).split())}"
        return [ItemResult(item.item_id, item.input_path, item.sweep, item.input_label, error=f"{item.input_path}: "
                           f"{error}", error_stage="worker") for item in group]

    def _collect(self, futures: dict[Any, int]) -> Iterator[tuple[int, Any]]:
        """(index, result or the task's exception) of each future as it completes; an ExecutorError when the
        scheduler is lost or has had no worker for ``timeout`` seconds.

        Streamed with ``distributed.as_completed`` (one watcher per future), each result released once yielded.
        Waiting in steps with ``distributed.wait(pending, timeout, FIRST_COMPLETED)`` instead left one watcher
        per pending future at every step: the client grew by 0.3 MB a task (185 MB after 400 trivial tasks
        against 70 MB; 347 MB after indexing 400 meshes), whatever the tasks returned.
        """
        from distributed import as_completed

        pending = set(futures)
        done = as_completed(list(futures))
        no_workers_since: float | None = None
        checked = time.monotonic()
        while pending:
            batch = done.next_batch(block=False)
            for future in batch:
                if future.status in ("pending", "lost"):  # its worker died with the result: computed again
                    done.add(future)
                    continue
                if future.status == "finished":
                    try:
                        value = future.result(timeout=self.timeout)
                    except TimeoutError:  # its worker died with the result, and no other computed it again yet
                        done.add(future)
                        continue
                    except Exception as exc:  # the scheduler went away between the task's end and this fetch
                        raise self._lost(exc) from None
                elif future.status == "error":
                    value = future.exception()
                else:  # cancelled: the client lost its scheduler (reason scheduler-connection-lost)
                    raise self._lost(_cancel_reason(future))
                pending.discard(future)
                i = futures[future]
                future.release()
                yield i, value
            if not pending:
                break
            if not batch:
                time.sleep(_STEP)
            if time.monotonic() - checked < _POLL:
                continue
            checked = time.monotonic()
            if self.client.status != "running":
                raise self._lost("scheduler-connection-lost" if self.client.status == "connecting"
                                 else f"the client is {self.client.status}")
            workers = self._n_workers()
            if workers:
                no_workers_since = None
            elif no_workers_since is None:
                no_workers_since = time.monotonic()
            elif time.monotonic() - no_workers_since > self.timeout:
                raise self._no_workers(f"every worker left and none joined in {self.timeout:g} s", mid_run=True)

    def _n_workers(self) -> int:
        try:
            return len(self.client.nthreads())
        except Exception as exc:  # OSError, CommClosedError: the scheduler does not answer
            raise self._lost(exc) from None

    def _wait_for_workers(self) -> None:
        try:
            self.client.wait_for_workers(1, timeout=self.timeout)
        except TimeoutError:  # distributed's WorkerStartTimeoutError
            raise self._no_workers(f"no worker joined in {self.timeout:g} s") from None
        except Exception as exc:  # OSError, CommClosedError
            raise self._lost(exc) from None

    def _check_workers(self, groups: list[list[Item]], cache_root: str | None) -> None:
        """Before any work: every worker present has this client's package versions, imports the stage modules
        and sees the inputs and the cache at the client's paths (:func:`worker_environment`)."""
        from topomatch.pipeline.manifest import package_versions

        calls = {call for group in groups for item in group for call in item.calls}
        modules = sorted({call.spec.func.__module__ for call in calls} | {type(call.params).__module__ for call in calls})
        paths = sorted({path for group in groups for item in group for path in item.paths.values()})
        try:
            found = self.client.run(worker_environment, modules, paths, cache_root)
        except Exception as exc:  # a worker without topomatch cannot even run the check
            raise ExecutorError(f"the dask workers of the scheduler at {self.where} cannot run topomatch's check of "
                                f"their environment ({type(exc).__name__}: {' '.join(str(exc).split())}): every worker "
                                "needs this topomatch installation (docs/cluster.md)") from None
        problems = environment_problems(found, package_versions())
        if problems:
            shown = "\n  ".join(problems[:10]) + (f"\n  ... and {len(problems) - 10} more" if len(problems) > 10 else "")
            raise ExecutorError(f"the dask workers of the scheduler at {self.where} cannot compute as this client "
                                f"would; nothing was computed:\n  {shown}\nevery worker needs the same topomatch and "
                                "package versions, the modules of the stages, and the inputs and the cache at the "
                                "client's paths (docs/cluster.md)")

    def _no_workers(self, what: str, *, mid_run: bool = False) -> ExecutorError:
        return ExecutorError(f"the dask scheduler at {self.where} has no workers: {what} (executor.timeout, "
                             f"--dask-timeout); start workers with `dask worker {self.address}`"
                             + (f". {self._kept()}" if mid_run else ", then run the same command again"))

    def _lost(self, reason: BaseException | str) -> ExecutorError:
        """The error for a scheduler that went away; ``reason``: a cancellation's reason or the exception of a
        call to the scheduler (which one comes first is a race: both say the connection broke)."""
        self.lost = True
        if isinstance(reason, BaseException):
            text = " ".join(str(reason).split())
            reason = f"{type(reason).__name__}: {text}" if text else type(reason).__name__
        return ExecutorError(f"lost the dask scheduler at {self.where}: the connection broke ({reason}). "
                             f"{self._kept()}")

    def _kept(self) -> str:
        return (f"{self.finished} of {self.n_items} items finished and are kept (their stage results are cached): "
                "run the same command again to resume")

    def close(self) -> None:
        """Close the client; after a lost scheduler, without the traceback distributed logs when its
        reconnection attempt is cut short."""
        client_log = logging.getLogger("distributed.client")
        level = client_log.level
        if self.lost:
            client_log.setLevel(logging.CRITICAL + 1)
        try:
            self.client.close(timeout=self.timeout)
        except Exception:  # noqa: BLE001 - a client that cannot close cleanly has nothing left to give
            pass
        finally:
            client_log.setLevel(level)


def worker_environment(modules: list[str], paths: list[str], cache_root: str | None) -> dict[str, Any]:
    """Run on each dask worker before any work: limit its BLAS to one thread (its tasks do too, for a worker that
    joins later), and report its package versions (those a manifest records), the ``modules`` it cannot import
    ({name: error}), and the ``paths`` it does not see (with the cache when it is not a writable folder there)."""
    import importlib

    from topomatch.pipeline.manifest import package_versions

    _single_threaded_once()
    failed = {}
    for name in modules:
        try:
            importlib.import_module(name)
        except Exception as exc:  # noqa: BLE001 - any import failure is reported by name
            failed[name] = f"{type(exc).__name__}: {exc}"
    unseen = [path for path in paths if not os.path.exists(path)]
    if cache_root is not None and not (os.path.isdir(cache_root) and os.access(cache_root, os.W_OK | os.X_OK)):
        unseen.append(f"{cache_root} (the cache: no writable folder there)")
    return {"packages": package_versions(), "modules": failed, "unseen": unseen}


def environment_problems(found: dict[str, dict[str, Any]], here: dict[str, str | None]) -> list[str]:
    """One line per problem of the workers' :func:`worker_environment` reports ``found`` ({worker address:
    report}), against this client's package versions ``here``."""
    problems = []
    for worker, report in sorted(found.items()):
        for name, error in report["modules"].items():
            problems.append(f"{worker}: cannot import the stage module {name} ({error})")
        versions = [f"{name} {there or 'not installed'} (here {here.get(name) or 'not installed'})"
                    for name, there in report["packages"].items() if there != here.get(name)]
        if versions:
            problems.append(f"{worker}: other versions: {', '.join(versions)}")
        unseen = report["unseen"]
        if unseen:
            more = f" and {len(unseen) - 3} more" if len(unseen) > 3 else ""
            problems.append(f"{worker}: does not see {', '.join(unseen[:3])}{more}")
    return problems


def _is_killed_worker(outcome: Any) -> bool:
    from distributed.scheduler import KilledWorker

    return isinstance(outcome, KilledWorker)


def _cancel_reason(future: Any) -> str:
    """Why a future was cancelled (dask: ``scheduler-connection-lost``)."""
    try:
        future.result(timeout=0)
    except BaseException as exc:  # noqa: BLE001 - the cancellation itself (FutureCancelledError)
        return str(getattr(exc, "reason", None) or type(exc).__name__)
    return "cancelled"
