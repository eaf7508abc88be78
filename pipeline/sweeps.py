"""Sweeps: ``sweep: {stage.param: [values]}`` -> the points of a run (a grid, or one key at a time), each point's
stage calls with the swept parameters set, and the check of every sweep key and value before anything runs."""

from __future__ import annotations

import itertools
from typing import Any

from pydantic import BaseModel

from topomatch.pipeline.chain import StageCall
from topomatch.pipeline.errors import ConfigError
from topomatch.pipeline.mappings import set_path
from topomatch.pipeline.schema import RawConfig


def sweep_points(raw: RawConfig) -> list[dict[str, Any]]:
    """The sweep points of ``raw``, in config order: the Cartesian product of the sweep values (``grid``), or
    the baseline (every key at its first value) then one key at a time (``one_at_a_time``)."""
    keys = list(raw.sweep)
    if raw.sweep_mode == "grid":
        return [dict(zip(keys, combo)) for combo in itertools.product(*(raw.sweep[k] for k in keys))]
    baseline = {k: raw.sweep[k][0] for k in keys}
    return [baseline] + [{**baseline, k: v} for k in keys for v in raw.sweep[k][1:]]


def sweep_target(key: str, calls: tuple[StageCall, ...]) -> tuple[int, list[str]]:
    """(position in the chain, parameter path) of a sweep key ``stage.param`` or ``stage.group.param``."""
    if key.count(".") < 1:
        raise ConfigError(f"sweep.{key}: expected 'stage.param'")
    name, *path = key.split(".")
    matches = [i for i, c in enumerate(calls) if c.label == name]  # a label: 'decimate' is the first, 'decimate#2' ...
    if not matches:
        matches = [i for i, c in enumerate(calls) if c.spec.name == name]
    if len(matches) != 1:
        raise ConfigError(f"sweep.{key}: the chain has {len(matches)} stages called {name!r}, expected exactly one "
                          f"(name a repeated stage by its label: {name}#2, {name}#3, ...)")
    model: Any = calls[matches[0]].spec.params
    for depth, part in enumerate(path):
        fields = getattr(model, "model_fields", None)
        if fields is None or part not in fields:
            known = ", ".join(fields or {}) or "none"
            where = ".".join([name, *path[:depth]])
            raise ConfigError(f"sweep.{key}: {where!r} has no parameter {part!r} (parameters: {known})")
        model = _model_of(fields[part].annotation)
    return matches[0], path


def _model_of(annotation: Any) -> Any:
    """The pydantic model inside an annotation (``Model`` or ``Model | None``), else None."""
    import typing

    for candidate in (annotation, *typing.get_args(annotation)):
        if isinstance(candidate, type) and issubclass(candidate, BaseModel):
            return candidate
    return None


def with_overrides(calls: tuple[StageCall, ...], point: dict[str, Any]) -> list[StageCall]:
    """``calls`` with the parameters of the sweep ``point`` ({stage.param: value}) set."""
    out = list(calls)
    for key, value in point.items():
        pos, path = sweep_target(key, calls)
        call = out[pos]
        values = call.params.model_dump(mode="json")
        set_path(values, path, value, f"sweep.{key}")
        out[pos] = StageCall(call.index, call.label, call.spec, call.spec.params.parse(values, f"sweep.{call.spec.name}"))
    return out


def check_sweeps(raw: RawConfig, calls: tuple[StageCall, ...]) -> None:
    """Check every sweep key and value against the chain (a ConfigError naming ``sweep.key[j]``)."""
    for key, values in raw.sweep.items():
        sweep_target(key, calls)
        for j, value in enumerate(values):
            try:
                with_overrides(calls, {key: value})
            except ConfigError as exc:
                raise ConfigError(str(exc).replace(f"sweep.{key}", f"sweep.{key}[{j}]", 1)) from None
