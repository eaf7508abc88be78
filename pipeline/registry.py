"""The registry: the YAML name of a stage or report -> its spec, found by scanning the code.

Stages and reports mark themselves with the :func:`~topomatch.pipeline.contract.stage` and
:func:`~topomatch.pipeline.contract.report` decorators, which only attach a spec to the
function. No module is listed by name, so a new stage is one new module:

- :func:`get_stage` / :func:`get_report` find the module that defines a name by reading the
  source files of the scanned packages (:data:`SCANNED_PACKAGES`: the engine's built-in reports
  and all of ``topomatch.stages``) for ``@stage("name"`` / ``@report("name"`` without importing
  them, then import that one module. So a command imports only the science it runs
  (``topomatch register`` does not load the mesh, spectral and retrieval stacks).
- :func:`discover` imports every module of the scanned packages and collects every marked
  function (``topomatch stages``, and the fallback for a name the text scan did not find).

Two functions that claim the same name are an error. The cache may store the result types of
the scanned packages (:func:`topomatch.pipeline.codec.allow_packages`).
"""

from __future__ import annotations

import importlib
import importlib.util
import pkgutil
import re
import typing
from pathlib import Path
from typing import Any

from topomatch.pipeline.contract import ReportSpec, StageSpec
from topomatch.pipeline.errors import ConfigError
from topomatch.pipeline.params import Params

#: Packages whose modules are imported and searched for stages and reports (recursively).
SCANNED_PACKAGES: tuple[str, ...] = ("topomatch.pipeline.builtin_reports", "topomatch.stages")

STAGES: dict[str, StageSpec] = {}
REPORTS: dict[str, ReportSpec] = {}
_SCANNED: list[str] = []  # the modules searched so far, in order
_INDEX: dict[tuple[str, str], str] = {}  # (kind, name) -> module, from the source text

_DECORATOR = re.compile(r'^@(stage|report)\(\s*"([^"]+)"', re.MULTILINE)


def _package_files(name: str) -> list[tuple[str, Path]]:
    """(module name, source file) of a package and its sub-packages, or of one module, without
    importing them."""
    spec = importlib.util.find_spec(name)
    if spec is None:
        return []
    if not spec.submodule_search_locations:
        return [(name, Path(spec.origin))] if spec.origin and spec.origin.endswith(".py") else []
    out = []
    for folder in map(Path, spec.submodule_search_locations):
        for path in sorted(folder.rglob("*.py")):
            parts = path.relative_to(folder).with_suffix("").parts
            if any(not (folder.joinpath(*parts[:i]) / "__init__.py").is_file() for i in range(1, len(parts))):
                continue  # not inside a package
            dotted = ".".join([name, *(parts[:-1] if parts[-1] == "__init__" else parts)])
            out.append((dotted, path))
    return out


def source_index() -> dict[tuple[str, str], str]:
    """(``'stage'`` or ``'report'``, name) -> the module whose source marks it, read once."""
    if not _INDEX:
        for package in SCANNED_PACKAGES:
            for module, path in _package_files(package):
                for kind, name in _DECORATOR.findall(path.read_text(encoding="utf-8")):
                    _INDEX.setdefault((kind, name), module)
    return _INDEX


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
    """Import the scanned modules (once) and register all their stages and reports; return the stages."""
    if not _SCANNED:
        for name in scanned_modules():
            _collect(importlib.import_module(name))
            _SCANNED.append(name)
    return STAGES


def register_module(module) -> None:
    """Register the stages and reports of a module outside the scanned packages (a script, a notebook,
    a test), and allow its result types in the cache."""
    from topomatch.pipeline.codec import allow_packages

    _collect(module)
    allow_packages((module.__name__,))


def get_stage(name: str) -> StageSpec:
    """The stage called ``name``; a :class:`ConfigError` listing the known names otherwise."""
    return _lookup(STAGES, "stage", name)


def get_report(name: str) -> ReportSpec:
    """The report called ``name``; a :class:`ConfigError` listing the known names otherwise."""
    return _lookup(REPORTS, "report", name)


def _lookup(table: dict, kind: str, name: str):
    if name not in table:
        module = source_index().get((kind, name))
        if module is not None:
            _collect(importlib.import_module(module))
    if name not in table:
        discover()  # a name the text scan could not see
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


def _allow_cached_types() -> None:
    from topomatch.pipeline.codec import allow_packages

    allow_packages(SCANNED_PACKAGES)


_allow_cached_types()
