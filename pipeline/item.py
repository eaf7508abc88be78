"""Running a stage chain: one item of a run (inside a worker), or any in-memory state (the API).

:func:`run_chain` is the one place where stages are called: it computes each call's cache key
from the stage name, version, canonical params and the keys of the consumed state entries,
reads the result from the cache or computes and stores it, and hands the produced entries on.
A state entry without a key (an in-memory value given by the Python API) makes everything
downstream of it uncached.
"""

from __future__ import annotations

import functools
import hashlib
import json
import time
import traceback
import typing
from dataclasses import dataclass, field
from typing import Any

from topomatch.pipeline.cache import Cache, hash_file, stage_key
from pathlib import Path

from topomatch.pipeline.config import Item, StageCall, check_chain, resolve_chain
from topomatch.pipeline.contract import StageSpec
from topomatch.pipeline.errors import InputError, TopomatchError
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

    @property
    def ok(self) -> bool:
        return self.error is None

    def final(self, state_key: str) -> Any:
        """The last value of a state entry (e.g. ``"mesh"``) that the chain produced."""
        value = None
        for label, result in self.results.items():
            if state_key in self.stage_produces.get(label, ()):
                value = getattr(result, state_key)
        return value

    def row(self) -> dict[str, Any]:
        """Flat table row: item, input, sweep values, status, then ``label.column`` summaries."""
        row: dict[str, Any] = {"item": self.item_id, "input": self.input_label or self.input_path}
        row.update(self.sweep)
        row["status"] = "ok" if self.ok else "failed"
        row["error"] = self.error or ""
        for label, result in self.results.items():
            summary = result.summary() if hasattr(result, "summary") else {}
            for column, value in summary.items():
                row[f"{label}.{column}"] = value
        return row


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
    named = not input_path or any(part and part in message for part in input_path.split("|"))
    return message if named else f"{input_path}: {message}"
