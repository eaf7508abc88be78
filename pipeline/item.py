"""Running the stage chain of one item, with caching (executed inside workers)."""

from __future__ import annotations

import hashlib
import json
import time
import traceback
from dataclasses import dataclass, field
from typing import Any

from topomatch.pipeline.cache import Cache, hash_file, stage_key
from topomatch.pipeline.config import Item
from topomatch.pipeline.errors import TopomatchError
from topomatch.pipeline.registry import discover


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


def run_item(item: Item, cache_root: str | None) -> ItemResult:
    """Run ``item``'s stage chain; every stage result is read from or written to the cache.

    A :class:`TopomatchError` or any other exception inside a stage stops this
    item's chain and is recorded (the results of earlier stages are kept);
    ``KeyboardInterrupt`` propagates.
    """
    discover()
    cache = Cache(cache_root)
    out = ItemResult(item.item_id, item.input_path, dict(item.sweep), item.input_label)
    state: dict[str, tuple[Any, str]] = {}
    for key, path in (item.paths or {"path": item.input_path}).items():
        try:
            state[key] = (path, hash_file(path))
        except OSError as exc:
            out.error = f"{path}: cannot read input ({exc.strerror or exc})"
            return out
    for key, value in item.values.items():
        state[key] = (value, hashlib.sha256(json.dumps(value, sort_keys=True, default=str).encode()).hexdigest())
    for call in item.calls:
        spec = call.spec
        key = stage_key(spec.name, spec.version, call.params.canonical(), [state[k][1] for k in spec.consumes])
        out.keys[call.label] = key
        out.stage_produces[call.label] = spec.produces
        t0 = time.perf_counter()
        hit, result = cache.get(key)
        if not hit:
            try:
                result = spec.run({k: state[k][0] for k in spec.consumes}, call.params)
            except TopomatchError as exc:
                out.error, out.error_stage = _name_input(str(exc), item), call.label
                return out
            except Exception as exc:  # a bug or a library failure: keep going with other items
                out.error = f"{item.input_path}: stage {call.label} failed: {type(exc).__name__}: {exc}"
                out.error_stage, out.traceback = call.label, traceback.format_exc()
                return out
            cache.put(key, result)
        out.seconds[call.label] = time.perf_counter() - t0
        out.cache_hits[call.label] = hit
        out.results[call.label] = result
        for k in spec.produces:
            state[k] = (getattr(result, k), f"{key}:{k}")
    return out


def _name_input(message: str, item: Item) -> str:
    """Make sure an error message names the input file."""
    return message if item.input_path in message else f"{item.input_path}: {message}"
