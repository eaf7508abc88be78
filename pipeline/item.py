"""Running a stage chain: one item of a run (inside a worker), or any in-memory state (the API).

:func:`run_chain` is the one place where stages are called: it computes each call's cache key
from the stage name, version, canonical params and the keys of the consumed state entries,
reads the result from the cache or computes and stores it, and hands the produced entries on.
A state entry without a key (an in-memory value given by the Python API) makes everything
downstream of it uncached.

What a worker sends back (:func:`run_records`) is a small record, not the results: each item's
:class:`ItemResult` with its scalar summaries (the table row) and its stage results as a
:class:`StoredResults`, which reads a result from the stage cache when it is asked for. Only the
results the cache does not hold (no cache, an uncached chain, a value the codec cannot store) and
the state entries the caller names (``keep``: e.g. the index's ``descriptor``) travel inline. So
the client's memory does not grow with the collection: it holds one record per item (a few KB),
and a report reads the results it draws, one item at a time (docs/cluster.md).
"""

from __future__ import annotations

import dataclasses
import functools
import hashlib
import json
import os
import time
import traceback
import typing
from collections import OrderedDict
from collections.abc import Collection, Iterator, Mapping
from dataclasses import dataclass, field
from typing import Any

from topomatch.pipeline.cache import Cache, hash_file, stage_key
from pathlib import Path

from topomatch.pipeline.chain import StageCall, check_chain, resolve_chain
from topomatch.pipeline.experiment import Item
from topomatch.pipeline.contract import StageSpec
from topomatch.pipeline.errors import InputError, StageError, TopomatchError
from topomatch.pipeline.files import check_readable_file


@dataclass
class ItemResult:
    """What one item produced: stage results by label, timings, cache hits, error."""

    item_id: str
    input_path: str
    sweep: dict[str, Any]
    input_label: str = ""
    results: dict[str, Any] = field(default_factory=dict)
    seconds: dict[str, float] = field(default_factory=dict)
    cache_hits: dict[str, bool] = field(default_factory=dict)
    keys: dict[str, str] = field(default_factory=dict)
    error: str | None = None
    error_stage: str | None = None
    traceback: str | None = None
    stage_produces: dict[str, tuple[str, ...]] = field(default_factory=dict)
    #: ``{label: result.summary()}``, made where the results were computed (a record); None: from ``results``
    summaries: dict[str, dict[str, Any]] | None = None

    @property
    def ok(self) -> bool:
        return self.error is None

    def final_label(self, state_key: str) -> str | None:
        """The label of the last stage that produced the state entry ``state_key`` (None: no stage did)."""
        return next((label for label in reversed(list(self.results))
                     if state_key in self.stage_produces.get(label, ())), None)

    def final(self, state_key: str) -> Any:
        """The last value of a state entry (e.g. ``"mesh"``) that the chain produced (only that stage's result
        is read: a record's others stay in the cache)."""
        label = self.final_label(state_key)
        return None if label is None else getattr(self.results[label], state_key)

    def summary(self, label: str) -> dict[str, Any]:
        """The scalar summary of the stage result ``label`` (its table columns)."""
        if self.summaries is not None:
            return self.summaries.get(label, {})
        result = self.results[label]
        return result.summary() if hasattr(result, "summary") else {}

    def row(self) -> dict[str, Any]:
        """Flat table row: item, input, sweep values, status, then ``label.column`` summaries."""
        row: dict[str, Any] = {"item": self.item_id, "input": self.input_label or self.input_path}
        row.update(self.sweep)
        row["status"] = "ok" if self.ok else "failed"
        row["error"] = self.error or ""
        for label in self.results:
            for column, value in self.summary(label).items():
                row[f"{label}.{column}"] = value
        return row


class StoredResults(Mapping):
    """An item's stage results by label (in chain order), read from the stage cache at ``root`` when one is asked
    for; ``inline`` holds those that travel with the record. Nothing read is kept here (a few recent reads are, per
    process: :data:`RECENT_READS`), so the records of a whole collection stay small.

    Raises (on reading a result)
    ----------------------------
    StageError
        The cache entry is gone or unusable (deleted or overwritten since the worker wrote it).
    """

    def __init__(self, keys: dict[str, str], root: str | None, inline: dict[str, Any]):
        self.keys, self.root, self.inline = dict(keys), root, dict(inline)

    def __len__(self) -> int:
        return len(self.keys)

    def __iter__(self) -> Iterator[str]:
        return iter(self.keys)

    def __contains__(self, label: object) -> bool:
        return label in self.keys

    def __getitem__(self, label: str) -> Any:
        if label in self.inline:
            return self.inline[label]
        key = self.keys[label]  # KeyError for an unknown label, as a dict
        if key in _RECENT:
            _RECENT.move_to_end(key)
            return _RECENT[key]
        hit, value = Cache(self.root).get(key)
        if not hit:
            raise StageError(f"the result of stage {label} is no longer in the stage cache {self.root} (entry {key}): "
                             "it was deleted or damaged after it was computed; run again to recompute it")
        _RECENT[key] = value
        while len(_RECENT) > RECENT_READS:
            _RECENT.popitem(last=False)
        return value

    def __repr__(self) -> str:
        return f"StoredResults({list(self.keys)}, inline={list(self.inline)}, cache={self.root!r})"


#: Results read from the cache most recently, kept per process (a report that asks for an item's mesh, then its
#: function, reads each once).
RECENT_READS = 4
_RECENT: OrderedDict[str, Any] = OrderedDict()


def to_record(result: ItemResult, cache_root: str | None, keep: Collection[str] = ()) -> ItemResult:
    """``result`` as a worker sends it back: its summaries made here, its results left in the cache at ``cache_root``
    (:class:`StoredResults`) except those the cache does not hold and the final producers of the state entries
    ``keep`` (e.g. ``("descriptor",)``), which travel inline."""
    cache = Cache(cache_root)
    kept = {result.final_label(entry) for entry in keep} - {None}
    inline = {label: value for label, value in result.results.items()
              if label in kept or not result.keys.get(label) or result.keys[label] not in cache}
    summaries = {label: result.summary(label) for label in result.results}
    stored = StoredResults({label: result.keys.get(label, "") for label in result.results}, cache_root, inline)
    return dataclasses.replace(result, results=stored, summaries=summaries)


def run_item(item: Item, cache_root: str | None, memo: dict[str, Any] | None = None) -> ItemResult:
    """Run ``item``'s stage chain from its input files; see :func:`run_chain`."""
    out = ItemResult(item.item_id, item.input_path, dict(item.sweep), item.input_label)
    state: dict[str, tuple[Any, str | None]] = {}
    for key, path in (item.paths or {"path": item.input_path}).items():
        try:
            state[key] = (path, hash_file(path))
        except OSError as exc:
            out.error = f"{path}: cannot read input ({exc.strerror or exc})"
            return out
    for key, value in item.values.items():
        state[key] = (value, hashlib.sha256(json.dumps(value, sort_keys=True, default=str).encode()).hexdigest())
    run_chain(item.calls, state, Cache(cache_root), out, memo)
    return out


def run_items(items: list[Item], cache_root: str | None) -> list[ItemResult]:
    """Run several items in turn, sharing their stage results in memory: a stage whose cache key
    an earlier item of the list already computed (the same input, params and upstream chain) is
    reused, not recomputed nor read back from the cache (e.g. the load, clean, decimate and spectrum
    that every part method of a fusion starts with)."""
    memo: dict[str, Any] = {}
    return [run_item(item, cache_root, memo) for item in items]


def run_records(items: list[Item], cache_root: str | None, keep: Collection[str] = ()) -> list[ItemResult]:
    """:func:`run_items`, returning each item's small record (:func:`to_record`): what every executor's worker runs
    (the local pool, a dask worker, and the client itself when it computes inline)."""
    return [to_record(result, cache_root, keep) for result in run_items(items, cache_root)]


def run_stages(chain: list[Any] | tuple[Any, ...], *, paths: dict[str, str | Path] | None = None,
               values: dict[str, Any] | None = None, cache_root: str | None = None, label: str = "") -> ItemResult:
    """Run a chain in config form on input files (``paths``: cached by content) and in-memory
    ``values`` (uncached, with everything downstream of them): the Python API's runner.

    Raises
    ------
    ConfigError
        A bad chain (unknown stage, bad params, an entry no input or earlier stage provides).
    InputError
        An input file that cannot be read.
    """
    paths, values = dict(paths or {}), dict(values or {})
    calls = resolve_chain(chain)
    check_chain(calls, set(paths) | set(values))
    label = label or str(next(iter(paths.values()), ""))
    out = ItemResult(label, label, {}, label)
    state: dict[str, tuple[Any, str | None]] = {k: (v, None) for k, v in values.items()}
    for key, path in paths.items():
        if not Path(path).is_dir():  # a folder is an input too (a DICOM series); its files are hashed
            check_readable_file(path)
        try:
            state[key] = (str(path), hash_file(path))
        except OSError as exc:
            raise InputError(path, f"cannot read input ({exc.strerror or exc})") from None
    run_chain(calls, state, Cache(cache_root), out)
    return out


def run_chain(calls: tuple[StageCall, ...] | list[StageCall], state: dict[str, tuple[Any, str | None]],
              cache: Cache, out: ItemResult, memo: dict[str, Any] | None = None) -> None:
    """Run ``calls`` on ``state`` ({entry: (value, cache key or None)}), recording into ``out``;
    ``memo`` ({cache key: result}) holds results already computed in this process.

    A :class:`TopomatchError` or any other exception inside a stage stops the chain and is
    recorded in ``out`` (the results of earlier stages are kept); ``KeyboardInterrupt``
    propagates.
    """
    for call in calls:
        spec = call.spec
        consumed = [state[k][1] for k in spec.consumes]
        key = None if None in consumed else stage_key(spec.name, spec.version, call.params.canonical(), consumed)
        out.keys[call.label] = key or ""
        out.stage_produces[call.label] = spec.produces
        t0 = time.perf_counter()
        if memo is not None and key in memo:
            hit, result = True, memo[key]
        else:
            hit, result = cache.get(key, functools.partial(_unusable, spec)) if key else (False, None)
        if not hit:
            try:
                result = spec.run({k: state[k][0] for k in spec.consumes}, call.params)
            except TopomatchError as exc:
                out.error, out.error_stage = _name_input(str(exc), out.input_path), call.label
                return
            except Exception as exc:  # a bug or a library failure: keep going with other items
                out.error = f"{out.input_path}: stage {call.label} failed: {type(exc).__name__}: {exc}"
                out.error_stage, out.traceback = call.label, traceback.format_exc()
                return
            if key:
                cache.put(key, result)
        if key and memo is not None:
            memo[key] = result
        out.seconds[call.label] = time.perf_counter() - t0
        out.cache_hits[call.label] = hit
        out.results[call.label] = result
        for k in spec.produces:
            state[k] = (getattr(result, k), f"{key}:{k}" if key else None)


@functools.lru_cache(maxsize=None)
def result_type(spec: StageSpec) -> type | None:
    """The class a stage's function is annotated to return (None when not a plain class)."""
    try:
        hint = typing.get_type_hints(spec.func).get("return")
    except Exception:  # an annotation that does not resolve: skip the type check
        return None
    return hint if isinstance(hint, type) else None


def _unusable(spec: StageSpec, value: Any) -> str | None:
    """Why a cached value cannot be the result of ``spec`` (None when it can)."""
    expected = result_type(spec)
    if expected is not None and not isinstance(value, expected):
        return f"a {type(value).__name__}, not the {expected.__name__} that stage {spec.name} returns"
    missing = [k for k in spec.produces if not hasattr(value, k)]
    if missing:
        return f"no {', '.join(missing)} for stage {spec.name}"
    return None


def _name_input(message: str, input_path: str) -> str:
    """Make sure an error message names the input file (a pair labelled ``a|b`` is named by either)."""
    named = not input_path or any(part and os.path.normpath(part) in message for part in input_path.split("|"))
    return message if named else f"{input_path}: {message}"
