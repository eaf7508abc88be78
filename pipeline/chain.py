"""The stage chain: config entries (``name`` or ``{name: {params}}``) -> validated :class:`StageCall` objects,
the check that every stage's inputs are provided, and a chain with some parameters changed (:func:`chain_with`).
The reports of a config are resolved the same way (:func:`resolve_reports`)."""

from __future__ import annotations

import copy
from dataclasses import dataclass
from typing import Any

from topomatch.pipeline.contract import StageSpec
from topomatch.pipeline.errors import ConfigError
from topomatch.pipeline.mappings import deep_merge
from topomatch.pipeline.params import Params
from topomatch.pipeline.registry import get_report, get_stage


@dataclass(frozen=True)
class StageCall:
    """One entry of the stage chain, with validated params."""

    index: int
    label: str  # unique within the chain: the name, or name#k for repeats
    spec: StageSpec
    params: Params

    @property
    def where(self) -> str:
        return f"stages[{self.index}].{self.spec.name}"


@dataclass(frozen=True)
class ReportCall:
    index: int
    name: str
    params: Params


def entry_name(entry: Any) -> str | None:
    """The stage (or report) name of a chain entry, None when it is not one."""
    if isinstance(entry, str):
        return entry
    if isinstance(entry, dict) and len(entry) == 1:
        return next(iter(entry))
    return None


def split_entry(entry: Any, where: str) -> tuple[str, dict[str, Any]]:
    """(name, params) of a chain entry; a ConfigError naming ``where`` when it is not one."""
    name = entry_name(entry)
    if name is None:
        raise ConfigError(f"{where}: expected a stage name or a mapping {{name: {{params}}}} with one key, got {entry!r}")
    params = entry[name] if isinstance(entry, dict) else None
    return name, dict(params or {})


def resolve_chain(entries: list[Any] | tuple[Any, ...]) -> tuple[StageCall, ...]:
    """Stage calls (validated params, unique labels) of a chain in config form (names or {name: params})."""
    calls, seen = [], {}
    for i, entry in enumerate(entries):
        name, spec, params = _resolve(entry, f"stages[{i}]", get_stage)
        seen[name] = seen.get(name, 0) + 1
        label = name if seen[name] == 1 else f"{name}#{seen[name]}"
        calls.append(StageCall(i, label, spec, params))
    return tuple(calls)


def _resolve(entry: Any, where: str, lookup) -> tuple[str, Any, Params]:
    """(name, spec, validated params) of a stage or report entry; ``lookup``: the registry's get_stage or
    get_report. Errors name ``where`` (``stages[3]``, ``reports[0].table``)."""
    name, params = split_entry(entry, where)
    try:
        spec = lookup(name)
    except ConfigError as exc:
        raise ConfigError(f"{where}: {exc}") from None
    return name, spec, spec.params.parse(params, f"{where}.{name}")


def check_chain(calls: tuple[StageCall, ...], available: set[str]) -> None:
    """Check that every stage's consumed entries are ``available`` initially or produced earlier."""
    available = set(available)
    for call in calls:
        missing = [k for k in call.spec.consumes if k not in available]
        if missing:
            raise ConfigError(
                f"{call.where}: needs {', '.join(repr(m) for m in missing)}, which neither the inputs "
                f"nor an earlier stage provide (available: {', '.join(sorted(available)) or 'nothing'})"
            )
        available.update(call.spec.produces)


def chain_with(chain: list[Any] | tuple[Any, ...], overrides: dict[str, dict[str, Any]]) -> list[Any]:
    """``chain`` (config form) with ``overrides`` {stage name: {param: value}} merged into the one stage
    of each name (nested mappings are merged key by key)."""
    out = list(chain)
    for name, values in overrides.items():
        positions = [i for i, e in enumerate(out) if entry_name(e) == name]
        if len(positions) != 1:
            raise ConfigError(f"the chain has {len(positions)} stages called {name!r}, expected exactly one")
        i = positions[0]
        entry = out[i]
        params = copy.deepcopy(dict(entry[name] or {})) if isinstance(entry, dict) else {}
        out[i] = {name: deep_merge(params, values)}
    return out


def resolve_reports(entries: list[Any]) -> tuple[ReportCall, ...]:
    """Report calls (validated params) of a config's ``reports`` entries."""
    out = []
    for i, entry in enumerate(entries):
        name, _, params = _resolve(entry, f"reports[{i}]", get_report)
        out.append(ReportCall(i, name, params))
    return tuple(out)
