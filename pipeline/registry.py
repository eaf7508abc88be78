"""The registry: the YAML name of a stage, report or input kind -> its spec, found through package metadata.

Stages, reports and input kinds mark themselves with the :func:`~topomatch.pipeline.contract.stage`,
:func:`~topomatch.pipeline.contract.report` and :func:`~topomatch.pipeline.contract.input_kind`
decorators, which only attach a spec to the function. A
distribution declares its own as entry points, one per name, in the groups of :data:`GROUPS`
(topomatch's are in its ``pyproject.toml``)::

    [project.entry-points."topomatch.stages"]
    decimate = "topomatch.stages.mesh.decimate:decimate"

- :func:`get_stage` / :func:`get_report` / :func:`get_input` find the name among the entry points of every installed
  distribution and import that one module: a command imports only the science it runs, and a
  user's package that declares entry points is found in every process where it is installed (Dask
  workers included) with no call of its own. A name declared by two distributions is an error.
- :func:`discover` imports every module of topomatch's own packages (:data:`BUILTIN_PACKAGES`) and
  every declared entry point (``topomatch stages``). It is also the fallback for a name the metadata
  does not declare, or declares at a place that no longer has it: an editable install reads the
  dist-info written by the last ``pip install -e .``, so a stage added since is still found, at the
  cost of importing every built-in module until the next install.
- :func:`register_module` adds the stages of a module that no distribution declares (a script, a
  notebook, a test), in this process only.

Two functions that claim the same name are an error naming both modules. The cache may store the
result types of the built-in packages and of the packages that declare entry points
(:func:`topomatch.pipeline.codec.allow_packages`).
"""

from __future__ import annotations

import importlib
import pkgutil
import re
import typing
from importlib.metadata import EntryPoint, entry_points
from typing import Any

from topomatch.pipeline.contract import InputSpec, ReportSpec, StageSpec
from topomatch.pipeline.errors import ConfigError
from topomatch.pipeline.params import Params

#: Entry-point group of each kind of function.
GROUPS: dict[str, str] = {"stage": "topomatch.stages", "report": "topomatch.reports", "input": "topomatch.inputs"}

#: topomatch's own packages: every module in them is imported by :func:`discover` (recursively).
BUILTIN_PACKAGES: tuple[str, ...] = ("topomatch.pipeline.builtin_reports", "topomatch.stages")

STAGES: dict[str, StageSpec] = {}
REPORTS: dict[str, ReportSpec] = {}
INPUTS: dict[str, InputSpec] = {}
_TABLES: dict[str, dict] = {"stage": STAGES, "report": REPORTS, "input": INPUTS}
_WORDS = {"stage": ("stage", "stages"), "report": ("report", "reports"), "input": ("kind of input", "kinds of input")}
_SPEC_KINDS: dict[type, str] = {StageSpec: "stage", ReportSpec: "report", InputSpec: "input"}
_SCANNED: list[str] = []  # the built-in modules imported by discover(), in order
_DECLARED: dict[str, dict[str, list[EntryPoint]]] = {}  # kind -> name -> entry points, read once


def declared(kind: str) -> dict[str, list[EntryPoint]]:
    """Name -> the entry points that declare it, over every installed distribution, for ``kind``
    ``'stage'``, ``'report'`` or ``'input'`` (read from the metadata once per process)."""
    if kind not in _DECLARED:
        table: dict[str, list[EntryPoint]] = {}
        for ep in entry_points(group=GROUPS[kind]):
            table.setdefault(ep.name, []).append(ep)
        _DECLARED[kind] = table
    return _DECLARED[kind]


def _origin(ep: EntryPoint) -> str:
    dist = getattr(ep, "dist", None)
    return f"{ep.value} (distribution {dist.name})" if dist is not None else ep.value


def _builtin(module: str) -> bool:
    return any(module == p or module.startswith(p + ".") for p in BUILTIN_PACKAGES)


def _load_declared(kind: str, name: str) -> bool:
    """Import and register the module that the metadata names for ``name``; False when none is declared,
    or when a built-in entry is out of date (then :func:`discover` finds the name)."""
    eps = declared(kind).get(name, [])
    if len({ep.value for ep in eps}) > 1:
        raise ConfigError(f"{kind} {name!r} is declared twice: by " + " and by ".join(sorted(map(_origin, eps))))
    if not eps:
        return False
    ep = eps[0]
    try:
        spec = getattr(ep.load(), f"{kind}_spec")
        if spec.name != name:
            raise ValueError(f"the function is the {kind} {spec.name!r}")
    except Exception as exc:  # noqa: BLE001 - any failure to import a declared module is reported by name
        if _builtin(ep.module):
            return False  # metadata older than this checkout's code
        raise ConfigError(f"{kind} {name!r}: cannot load the entry point {_origin(ep)}: "
                          f"{type(exc).__name__}: {exc}") from None
    _collect(importlib.import_module(ep.module))
    return True


def builtin_modules(packages: tuple[str, ...] = BUILTIN_PACKAGES) -> list[str]:
    """Names of every module in ``packages`` (a package's own ``__init__`` included), sorted."""
    names: list[str] = []
    for name in packages:
        module = importlib.import_module(name)
        names.append(name)
        if hasattr(module, "__path__"):
            names += [m.name for m in pkgutil.walk_packages(module.__path__, prefix=name + ".")]
    return sorted(set(names))


def marked(module) -> list[StageSpec | ReportSpec | InputSpec]:
    """The specs of the stages, reports and input kinds defined in ``module`` (not those it imports)."""
    specs = []
    for obj in vars(module).values():
        if getattr(obj, "__module__", None) == module.__name__:
            specs += [s for s in (getattr(obj, f"{kind}_spec", None) for kind in GROUPS) if s is not None]
    return specs


def spec_kind(spec: StageSpec | ReportSpec | InputSpec) -> str:
    """``'stage'``, ``'report'`` or ``'input'``: the kind of function a spec describes."""
    return _SPEC_KINDS[type(spec)]


def _collect(module) -> None:
    for spec in marked(module):
        kind = spec_kind(spec)
        table = _TABLES[kind]
        known = table.get(spec.name)
        if known is not None and known.func is not spec.func:
            raise ConfigError(f"{kind} {spec.name!r} is defined twice: in {known.func.__module__} and "
                              f"{spec.func.__module__}")
        table[spec.name] = spec


def discover() -> dict[str, StageSpec]:
    """Import the built-in modules and every declared entry point (once) and register all their stages and
    reports; return the stages."""
    if not _SCANNED:
        for name in builtin_modules():
            _collect(importlib.import_module(name))
            _SCANNED.append(name)
        for kind in GROUPS:
            for name in declared(kind):
                _load_declared(kind, name)
    return STAGES


def register_module(module) -> None:
    """Register the stages and reports of a module that no distribution declares (a script, a notebook,
    a test) in this process, and allow its result types in the cache."""
    from topomatch.pipeline.codec import allow_packages

    _collect(module)
    allow_packages((module.__name__,))


def get_stage(name: str) -> StageSpec:
    """The stage called ``name``; a :class:`ConfigError` listing the known names otherwise."""
    return _lookup("stage", name)


def get_report(name: str) -> ReportSpec:
    """The report called ``name``; a :class:`ConfigError` listing the known names otherwise."""
    return _lookup("report", name)


def get_input(name: str, where: str = "") -> InputSpec:
    """The input kind called ``name`` (a key under a config's ``inputs:``); a :class:`ConfigError` starting
    with ``where`` and listing the known kinds otherwise."""
    return _lookup("input", name, where)


def _lookup(kind: str, name: str, where: str = ""):
    table = _TABLES[kind]
    if name not in table and not _load_declared(kind, name):
        discover()  # a name the metadata does not declare (yet)
    try:
        return table[name]
    except KeyError:
        one, many = _WORDS[kind]
        raise ConfigError(f"{where + ': ' if where else ''}unknown {one} {name!r}; known {many}: "
                          f"{', '.join(sorted(table))}") from None


def type_label(hint: Any) -> str:
    """Readable name of a type hint: ``int``, ``'a' | 'b'``, ``list[str]``, ``float | None``."""
    if typing.get_origin(hint) is typing.Literal:
        return " | ".join(repr(a) for a in typing.get_args(hint))
    if isinstance(hint, type) and not typing.get_args(hint):
        return hint.__name__
    return re.sub(r"\b(?:\w+\.)+(\w+)", r"\1", str(hint)).replace("NoneType", "None")  # no module paths


def model_in(hint: Any) -> type[Params] | None:
    """The parameter model a type hint holds (``M`` in ``list[M]`` or ``M | None``), or None."""
    if isinstance(hint, type) and issubclass(hint, Params):
        return hint
    return next((m for m in map(model_in, typing.get_args(hint)) if m is not None), None)


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
    """Allow the built-in packages' types in the cache, and the package of each declared entry point's
    module (the module itself when it is top-level): read here, in every process that runs stages."""
    from topomatch.pipeline.codec import allow_packages

    declared_modules = {ep.module for kind in GROUPS for eps in declared(kind).values() for ep in eps
                        if not _builtin(ep.module)}
    allow_packages(BUILTIN_PACKAGES + tuple(m.rpartition(".")[0] or m for m in sorted(declared_modules)))


_allow_cached_types()
