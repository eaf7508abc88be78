"""Stage registry: the YAML name of a stage -> (function, params type, version, data flow).

A stage is a plain function ``func(*consumed, params) -> result``. It reads the
state entries named in ``consumes`` (e.g. ``"mesh"``) and its result object
provides the attributes named in ``produces``, which become the new state
entries for the next stage. ``version`` is part of the cache key: bump it when
the output of the algorithm changes.

Stages register themselves with the :func:`stage` decorator when their module is
imported; :func:`discover` imports every stage module listed in
``STAGE_MODULES``.
"""

from __future__ import annotations

import importlib
import typing
from dataclasses import dataclass
from typing import Any, Callable

from topomatch.pipeline.errors import ConfigError
from topomatch.pipeline.params import Params

#: Modules that define stages and reports (imported by :func:`discover`).
STAGE_MODULES: tuple[str, ...] = (
    "topomatch.stages.mesh.io",
    "topomatch.stages.mesh.clean",
    "topomatch.stages.mesh.decimate",
    "topomatch.stages.mesh.noise",
    "topomatch.stages.mesh.transform",
    "topomatch.stages.mesh.measures",
    "topomatch.stages.crosscheck.decimation",
    "topomatch.stages.spectral.laplacian",
    "topomatch.stages.spectral.fiedler",
    "topomatch.stages.spectral.spectrum",
    "topomatch.stages.spectral.heat_kernel",
    "topomatch.stages.morse.stage",
    "topomatch.stages.reeb.level_sets",
    "topomatch.stages.reeb.reeb_graph",
    "topomatch.stages.reeb.prune",
    "topomatch.stages.crosscheck.libigl_reference",
    "topomatch.stages.registration.io",
    "topomatch.stages.registration.misalign",
    "topomatch.stages.registration.register",
    "topomatch.stages.registration.simpleitk_reference",
    "topomatch.stages.registration.evaluate",
    "topomatch.stages.registration.landscape",
    "topomatch.stages.retrieval.descriptor",
    "topomatch.stages.retrieval.baseline_stages",
    "topomatch.pipeline.reports",
    "topomatch.pipeline.skeleton_reports",
    "topomatch.pipeline.retrieval_reports",
    "topomatch.pipeline.registration_reports",
)


@dataclass(frozen=True)
class StageSpec:
    """One registered stage."""

    name: str
    func: Callable[..., Any]
    params: type[Params]
    version: int
    consumes: tuple[str, ...]
    produces: tuple[str, ...]
    doc: str

    def run(self, state_values: dict[str, Any], params: Params) -> Any:
        """Call the stage on the consumed state values."""
        args = [state_values[k] for k in self.consumes]
        return self.func(*args, params=params)


STAGES: dict[str, StageSpec] = {}


def stage(
    name: str,
    *,
    params: type[Params],
    version: int,
    consumes: tuple[str, ...] = ("mesh",),
    produces: tuple[str, ...] = (),
) -> Callable[[Callable[..., Any]], Callable[..., Any]]:
    """Register ``func`` as the stage ``name`` (decorator)."""

    def register(func: Callable[..., Any]) -> Callable[..., Any]:
        if name in STAGES and STAGES[name].func is not func:
            raise RuntimeError(f"stage {name!r} registered twice")
        doc = (func.__doc__ or "").strip().splitlines()[0] if func.__doc__ else ""
        STAGES[name] = StageSpec(name, func, params, version, tuple(consumes), tuple(produces), doc)
        return func

    return register


def discover() -> dict[str, StageSpec]:
    """Import all stage modules so that they register; return the registry."""
    for module in STAGE_MODULES:
        importlib.import_module(module)
    return STAGES


def get_stage(name: str) -> StageSpec:
    """The stage called ``name``; a :class:`ConfigError` listing the known names otherwise."""
    discover()
    try:
        return STAGES[name]
    except KeyError:
        known = ", ".join(sorted(STAGES))
        raise ConfigError(f"unknown stage {name!r}; known stages: {known}") from None


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
        type_name = type_label(hint)
        default = field.get_default(call_default_factory=True)
        rows.append((field_name, type_name, default, field.description or ""))
    return rows
