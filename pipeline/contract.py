"""The contract between the engine and the science: all that ``stages/`` imports from ``pipeline/``.

A stage is a plain function ``func(*consumed_state, params) -> result``; a report is a function
``func(experiment, results, params) -> ReportOutput``; an input kind (a key under a config's ``inputs:``)
is a function ``func(value, files) -> list[InputUnit]``. The :func:`stage`, :func:`report` and
:func:`input_kind` decorators only attach their metadata (:class:`StageSpec`, :class:`ReportSpec`,
:class:`InputSpec`) to the function;
the engine's registry (:mod:`topomatch.pipeline.registry`) finds them by the entry points that
their distribution declares (``pyproject.toml``). Nothing here imports the runner, the cache or the CLI, and nothing here
knows a domain.

Re-exported for the stages: the error types, :class:`Params` (typed, frozen, strict parameter
models) and the atomic file writers.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from typing import Any, Callable

from topomatch.pipeline.errors import ConfigError, InputError, InputWarning, StageError, TopomatchError
from topomatch.pipeline.files import atomic_write_bytes, atomic_write_text, check_readable_file, limit_from_env
from topomatch.pipeline.inputs import InputFiles, InputSpec, InputUnit, input_kind
from topomatch.pipeline.mappings import deep_merge
from topomatch.pipeline.params import Params

__all__ = [
    "ConfigError", "InputError", "InputWarning", "StageError", "TopomatchError", "Params", "StageResult", "StageSpec", "stage",
    "ReportOutput", "ReportSpec", "report", "gallery_layout", "axis_label", "atomic_write_bytes", "atomic_write_text",
    "check_readable_file", "limit_from_env", "deep_merge", "InputFiles", "InputSpec", "InputUnit", "input_kind",
]


class StageResult:
    """Mixin for the named result structures (frozen dataclasses) that stages return.

    ``summary()`` gives the scalars that go into the run's tables, keyed by short column
    names; the runner prefixes them with the stage label. ``column_labels`` names some of them for
    figure axes, with units (``{"area": "surface area (mesh units²)"}``).
    """

    column_labels: dict[str, str] = {}

    def summary(self) -> dict[str, Any]:
        return {}


def _first_doc_line(func: Callable) -> str:
    return (func.__doc__ or "").strip().splitlines()[0] if func.__doc__ else ""


@dataclass(frozen=True)
class StageSpec:
    """One stage: its YAML name, function, params type, version and data flow.

    ``consumes`` names the state entries passed to the function (in order); ``produces`` the
    attributes of its result that become state entries for the next stage. ``version`` is part
    of the cache key: bump it when the algorithm's output changes.
    """

    name: str
    func: Callable[..., Any]
    params: type[Params]
    version: int
    consumes: tuple[str, ...]
    produces: tuple[str, ...]
    doc: str

    def run(self, state_values: dict[str, Any], params: Params) -> Any:
        """Call the stage on the consumed state values."""
        return self.func(*[state_values[k] for k in self.consumes], params=params)


def stage(name: str, *, params: type[Params], version: int, consumes: tuple[str, ...] = ("mesh",),
          produces: tuple[str, ...] = ()) -> Callable[[Callable[..., Any]], Callable[..., Any]]:
    """Mark ``func`` as the stage ``name`` (decorator; attaches ``func.stage_spec``)."""

    def mark(func: Callable[..., Any]) -> Callable[..., Any]:
        func.stage_spec = StageSpec(name, func, params, version, tuple(consumes), tuple(produces),
                                    _first_doc_line(func))
        return func

    return mark


@dataclass
class ReportOutput:
    """Tables (name -> rows) and figures (name -> matplotlib Figure, or a function of no arguments that draws
    one: the engine calls it when it writes the figure and closes each figure once written, so a report with
    many heavy figures holds one at a time) of one report, notes, files
    (path relative to the run folder -> bytes, e.g. exported meshes) and HTML fragments for the
    run page (self-contained: an interactive view, whose scripts the page loads from ``assets``)."""

    tables: dict[str, list[dict[str, Any]]] = field(default_factory=dict)
    figures: dict[str, Any] = field(default_factory=dict)
    notes: list[str] = field(default_factory=list)
    files: dict[str, bytes] = field(default_factory=dict)
    html: dict[str, str] = field(default_factory=dict)


@dataclass(frozen=True)
class ReportSpec:
    """One report: its YAML name, function, params type and one-line doc."""

    name: str
    func: Callable[..., ReportOutput]
    params: type[Params]
    doc: str


def report(name: str, *, params: type[Params]) -> Callable[[Callable[..., ReportOutput]], Callable[..., ReportOutput]]:
    """Mark ``func`` as the report ``name`` (decorator; attaches ``func.report_spec``)."""

    def mark(func: Callable[..., ReportOutput]) -> Callable[..., ReportOutput]:
        func.report_spec = ReportSpec(name, func, params, _first_doc_line(func))
        return func

    return mark


def gallery_layout(results, columns: int) -> tuple[int, int, list[int]]:
    """(rows, cols, panel index per item result) of a figure grid: inputs x sweep points, or the
    items wrapped ``columns`` to a row when the run has no sweep."""
    inputs = list(dict.fromkeys(r.input_path for r in results))
    points = list(dict.fromkeys(json.dumps(r.sweep, sort_keys=True) for r in results))
    if len(points) == 1:
        cols = min(columns, len(results))
        return -(-len(results) // cols), cols, list(range(len(results)))
    cells = [inputs.index(r.input_path) * len(points) + points.index(json.dumps(r.sweep, sort_keys=True))
             for r in results]
    return len(inputs), len(points), cells


def sweep_ticks(ax, values) -> None:
    """x ticks at the swept values themselves when there are few (2-8; ``%g``), so that a sweep such as
    0, 0.001, 0.002, 0.004 is read at its points and its labels never run together; else at most 6 ticks."""
    from matplotlib.ticker import MaxNLocator

    xs = sorted({float(v) for v in values})
    if 1 < len(xs) <= 8:
        ax.set_xticks(xs, [f"{v:g}" for v in xs])
    else:
        ax.xaxis.set_major_locator(MaxNLocator(6))


def sweep_value_labels(experiment, values: dict, skip=()) -> list[str]:
    """``param=value`` for each sweep key of the experiment that ``values`` holds (a results row or an item's
    sweep point) and ``skip`` does not: how a legend or a panel title tells apart items of one input."""
    return [f"{k.split('.')[-1]}={values[k]}" for k in experiment.raw.sweep if k not in skip and k in values]


def series_style(i: int) -> dict:
    """Plot keywords of the ``i``-th line of a figure: the 10 default colours, then the same colours dashed,
    then dotted (with another marker), so that no two of up to 30 lines look alike."""
    return {"color": f"C{i % 10}", "linestyle": ("-", "--", ":")[i // 10 % 3], "marker": "osD"[i // 10 % 3]}


def axis_label(experiment, results, key: str) -> str:
    """How a figure names a sweep key or results column, with its unit.

    ``stage.param`` (a sweep key): the stage's params :meth:`~Params.axis_label`; ``stage.column`` (a
    results column): the stage result's ``column_labels``; otherwise the key in words
    (``skeleton_cycle_rank`` -> ``skeleton cycle rank``).
    """
    label, _, rest = key.partition(".")
    if rest:
        for call in getattr(experiment, "calls", ()):
            if call.label == label and rest in type(call.params).model_fields:
                named = call.params.axis_label(rest)
                if named:
                    return named
        for r in results:
            value = getattr(r, "results", {}).get(label)
            if value is not None:
                named = getattr(type(value), "column_labels", {}).get(rest)
                if named:
                    return named
                break
    return (rest or key).replace("_", " ")
