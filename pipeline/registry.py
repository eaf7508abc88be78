"""The registry: the YAML name of a stage or report -> its spec, found by scanning the code.

Stages and reports mark themselves with the :func:`~topomatch.pipeline.contract.stage` and
:func:`~topomatch.pipeline.contract.report` decorators, which only attach a spec to the
function. :func:`discover` imports every module of the scanned packages
(:data:`SCANNED_PACKAGES`: the engine's built-in reports and all of ``topomatch.stages``) and
collects the marked functions; no module is listed by name, so a new stage is one new module.
Two functions that claim the same name are an error.
"""

from __future__ import annotations

import importlib
import pkgutil
import typing
from typing import Any

from topomatch.pipeline.contract import ReportSpec, StageSpec
from topomatch.pipeline.errors import ConfigError
from topomatch.pipeline.params import Params

#: Packages whose modules are imported and searched for stages and reports (recursively).
SCANNED_PACKAGES: tuple[str, ...] = ("topomatch.pipeline.builtin_reports", "topomatch.stages")

STAGES: dict[str, StageSpec] = {}
REPORTS: dict[str, ReportSpec] = {}
_SCANNED: list[str] = []  # the modules searched so far, in order


def scanned_modules(packages: tuple[str, ...] = SCANNED_PACKAGES) -> list[str]:
    """Names of every module in ``packages`` (a package's own ``__init__`` included), sorted."""
    names: list[str] = []
    for name in packages:
        module = importlib.import_module(name)
        names.append(name)
        if hasattr(module, "__path__"):
            names += [m.name for m in pkgutil.walk_packages(module.__path__, prefix=name + ".")]
    return sorted(set(names))


def _collect(module) -> None:
    for obj in vars(module).values():
        if getattr(obj, "__module__", None) != module.__name__:
            continue  # imported from elsewhere: registered by its own module
        for attr, table in (("stage_spec", STAGES), ("report_spec", REPORTS)):
            spec = getattr(obj, attr, None)
            if spec is None:
                continue
            known = table.get(spec.name)
            if known is not None and known.func is not spec.func:
                raise RuntimeError(f"{attr.split('_')[0]} {spec.name!r} is defined twice: in "
                                   f"{known.func.__module__} and {module.__name__}")
            table[spec.name] = spec


def discover() -> dict[str, StageSpec]:
    """Import the scanned modules (once) and register their stages and reports; return the stages."""
    if not _SCANNED:
        for name in scanned_modules():
            _collect(importlib.import_module(name))
            _SCANNED.append(name)
        from topomatch.pipeline.codec import register_types

        register_types(importlib.import_module(name) for name in _SCANNED)
    return STAGES


def register_module(module) -> None:
    """Register the stages and reports of a module outside the scanned packages (a script, a notebook,
    a test), and allow its result types in the cache. Call it after :func:`discover`."""
    from topomatch.pipeline.codec import register_types

    discover()
    _collect(module)
    register_types([module])


def get_stage(name: str) -> StageSpec:
    """The stage called ``name``; a :class:`ConfigError` listing the known names otherwise."""
    return _lookup(STAGES, "stage", name)


def get_report(name: str) -> ReportSpec:
    """The report called ``name``; a :class:`ConfigError` listing the known names otherwise."""
    return _lookup(REPORTS, "report", name)


def _lookup(table: dict, kind: str, name: str):
    discover()
    try:
        return table[name]
    except KeyError:
        raise ConfigError(f"unknown {kind} {name!r}; known {kind}s: {', '.join(sorted(table))}") from None


def type_label(hint: Any) -> str:
    """Readable name of a type hint: ``int``, ``'a' | 'b'``, ``list[str]``, ``float | None``."""
    if typing.get_origin(hint) is typing.Literal:
        return " | ".join(repr(a) for a in typing.get_args(hint))
    if isinstance(hint, type) and not typing.get_args(hint):
        return hint.__name__
    return str(hint).replace("typing.", "").replace("NoneType", "None")


def describe_params(params: type[Params]) -> list[tuple[str, str, Any, str]]:
    """(name, type, default, description) for each field of a params type."""
    rows = []
    hints = typing.get_type_hints(params)
    for field_name, field in params.model_fields.items():
        hint = hints.get(field_name, field.annotation)
        default = field.get_default(call_default_factory=True)
        rows.append((field_name, type_label(hint), default, field.description or ""))
    return rows
