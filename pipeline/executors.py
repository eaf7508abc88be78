"""Executors: where the items of a run are computed.

``local`` runs items in a process pool (``forkserver`` start method: no fork of a
threaded parent) with one worker per core by default, or inline when there is
one worker or one item. ``dask`` submits items to a dask.distributed cluster: a
new ``LocalCluster`` (processes, one thread each) or an existing scheduler at
``address``. Both yield results as they complete; the runner orders them.

Each pool worker limits its BLAS/OpenMP thread pools to one thread: the items are the
parallelism, and BLAS threads on top of one process per core oversubscribe the cores
(measured: ARPACK in ShapeDNA ran 2-3x slower with two workers each using two BLAS threads).
"""

from __future__ import annotations

import logging
import multiprocessing
import os
import sys
from contextlib import contextmanager
from concurrent.futures import ProcessPoolExecutor, as_completed
from typing import Iterator, Sequence

from topomatch.pipeline.config import ExecutorConfig, Item
from topomatch.pipeline.errors import ConfigError
from topomatch.pipeline.item import ItemResult, run_items


def default_workers() -> int:
    return max(1, len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count() or 1)


def execute(items: Sequence[Item], cache_root: str | None, config: ExecutorConfig) -> Iterator[ItemResult]:
    """Run every item; yield results in completion order."""
    for results in execute_groups([[item] for item in items], cache_root, config):
        yield from results


def execute_groups(groups: Sequence[Sequence[Item]], cache_root: str | None,
                   config: ExecutorConfig) -> Iterator[list[ItemResult]]:
    """Run every group of items in one worker (:func:`~topomatch.pipeline.item.run_items`: a stage result
    shared by items of a group is computed once and kept in memory); yield each group's results in
    completion order. The unit of parallelism is the group (e.g. one mesh and every part method)."""
    if config.kind == "dask":
        yield from _dask(groups, cache_root, config)
    else:
        yield from _local(groups, cache_root, config.workers or default_workers())


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


def _local(groups: Sequence[Sequence[Item]], cache_root: str | None, workers: int) -> Iterator[list[ItemResult]]:
    """Run the groups in a process pool. A worker that dies (killed, out of memory, a crash in
    native code) breaks the whole pool: the groups it left unfinished run again, each in a pool
    of its own, so that only the group that kills its worker fails (as an error naming the
    worker's death), and every other result is kept."""
    workers = min(workers, len(groups))
    if workers <= 1:
        for group in groups:
            yield run_items(group, cache_root)
        return
    unfinished: list[int] = []
    yield from _pool_run(groups, range(len(groups)), cache_root, workers, unfinished)
    for i in unfinished:  # after a worker died: isolate the culprit
        lost: list[int] = []
        yield from _pool_run(groups, [i], cache_root, 1, lost)
        if lost:
            yield [_worker_died(item) for item in groups[i]]


def _pool_run(groups: Sequence[Sequence[Item]], which: Sequence[int], cache_root: str | None, workers: int,
              unfinished: list[int]) -> Iterator[list[ItemResult]]:
    """Run ``groups[i]`` for ``i`` in ``which`` in one pool; on a broken pool, append the indices it
    did not finish to ``unfinished`` and return."""
    from concurrent.futures.process import BrokenProcessPool

    ctx = multiprocessing.get_context("forkserver")
    ctx.set_forkserver_preload(["topomatch.pipeline.item"])
    done: set[int] = set()
    with ProcessPoolExecutor(max_workers=workers, mp_context=ctx, initializer=_worker_init,
                             initargs=(os.getpid(),)) as pool:
        with _main_script_hidden([item for i in which for item in groups[i]]):
            futures = {pool.submit(run_items, groups[i], cache_root): i for i in which}  # starts the workers
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
    every worker's own run and crash. The workers run only the engine's ``run_items``, so they need
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


def _dask(groups: Sequence[Sequence[Item]], cache_root: str | None,
          config: ExecutorConfig) -> Iterator[list[ItemResult]]:
    try:
        from dask.distributed import Client, LocalCluster, as_completed as dask_completed
    except ImportError as exc:  # pragma: no cover - dask is a dependency
        raise ConfigError(f"executor.kind=dask needs dask[distributed] ({exc})") from None
    # distributed sets its loggers to INFO when imported: they follow the process's level instead (the CLI's
    # -q / default / -v), so a quiet run stays quiet
    logging.getLogger("distributed").setLevel(logging.getLogger().getEffectiveLevel())
    cluster = None
    if config.address:
        try:
            client = Client(config.address, timeout="10s")
        except (OSError, ValueError, TypeError) as exc:  # unreachable; malformed address (ValueError, TypeError)
            raise ConfigError(f"executor.address: cannot reach the dask scheduler at {config.address!r} ({exc})") from None
    else:
        cluster = LocalCluster(
            n_workers=config.workers or default_workers(),
            threads_per_worker=1,
            processes=True,
            dashboard_address=None,
        )
        client = Client(cluster)
        client.run(_single_threaded)
    try:
        futures = [client.submit(run_items, list(group), cache_root, pure=False) for group in groups]
        for future in dask_completed(futures):
            yield future.result()
    finally:
        client.close()
        if cluster is not None:
            cluster.close()

