"""A config's ``inputs:`` -> :class:`InputUnit` objects: files for state entries and plain values, checked to exist.

The engine knows no kind of input by name. Each key under ``inputs:`` is an input kind that a domain
declares, as it declares its stages (:func:`~topomatch.pipeline.contract.input_kind`, entry-point group
``topomatch.inputs``): the type of the key's value, the state entries each unit provides, and the function
that turns the value into units. The mesh stages declare ``meshes``; registration declares ``images``,
``pairs`` and ``pairs_csv`` (its words, fixed / moving / truth, stay in ``stages/registration``).

Here: the kind's spec and decorator (:class:`InputSpec`, :func:`input_kind`, re-exported by the contract), the
unit (:class:`InputUnit`), the file resolver handed to every kind (:class:`InputFiles`: globs and
``{bundled}`` / ``{data_root}`` templates, :mod:`topomatch.pipeline.paths`), the one-file-per-unit helper
most kinds use (:meth:`InputFiles.each`), and the checks of a config's ``inputs`` mapping
(:func:`check_inputs`, :func:`resolve_inputs_config`).
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable

from pydantic import TypeAdapter, ValidationError

from topomatch.pipeline.errors import ConfigError
from topomatch.pipeline.params import format_validation_error
from topomatch.pipeline.paths import display_path, resolve_input


@dataclass(frozen=True)
class InputUnit:
    """One input of a run: files for state entries (``paths``) and plain values (``values``)."""

    label: str
    paths: dict[str, Path]
    values: dict[str, Any] = field(default_factory=dict)

    @property
    def primary(self) -> Path:
        return next(iter(self.paths.values()))


@dataclass(frozen=True)
class InputFiles:
    """Path templates -> existing files, relative to the config's folder (``base_dir``)."""

    base_dir: Path
    data_root: Path | None

    def __call__(self, template: str, where: str, base: Path | None = None) -> list[Path]:
        """The files ``template`` names (a glob may name several), relative to ``base`` (default: the
        config's folder); ConfigError / InputError naming ``where`` and the file when there are none."""
        return resolve_input(template, base_dir=base or self.base_dir, root=self.data_root, where=where)

    def one(self, template: str, where: str, base: Path | None = None) -> Path:
        """The first file ``template`` names."""
        return self(template, where, base)[0]

    def each(self, templates: list[str], where: str, state: str = "path") -> list[InputUnit]:
        """One unit per file the templates name, its path under ``state``, labelled ``{bundled}/...`` /
        ``{data_root}/...``; a file that two templates (or overlapping globs) name is one unit, not two."""
        units, seen = [], set()
        for i, template in enumerate(templates):
            for path in self(template, f"{where}[{i}]"):
                if path.resolve() not in seen:
                    seen.add(path.resolve())
                    units.append(InputUnit(display_path(path, self.data_root), {state: path}))
        return units


@dataclass(frozen=True)
class InputSpec:
    """One kind of input, a key under a config's ``inputs:``: its YAML name, the type of its value (a type
    hint that pydantic validates in strict JSON mode, e.g. ``list[str]``), the state entries each of its units
    provides to the first stage, and ``func(value, files) -> list[InputUnit]`` (``files``: an
    :class:`InputFiles` resolving path templates relative to the config)."""

    name: str
    func: Callable[[Any, InputFiles], list[InputUnit]]
    schema: Any
    provides: tuple[str, ...]
    doc: str


def input_kind(name: str, *, schema: Any, provides: tuple[str, ...]) -> Callable[[Callable], Callable]:
    """Mark ``func`` as the input kind ``name`` (decorator; attaches ``func.input_spec``)."""

    def mark(func: Callable) -> Callable:
        func.input_spec = InputSpec(name, func, schema, tuple(provides), (func.__doc__ or "").strip().partition("\n")[0])
        return func

    return mark


def check_inputs(inputs: dict[str, Any], get_input: Callable[..., InputSpec]) -> list[tuple[InputSpec, Any]]:
    """Each key of a config's ``inputs`` mapping with its kind's spec (``get_input(name, where=...)``: the
    registry's lookup) and its value, validated (strict JSON mode) against the kind's type, in the config's order.

    Raises
    ------
    ConfigError
        An unknown kind (listing the known ones), or a value of the wrong type (``inputs.<kind>...``).
    """
    checked = []
    for name, value in inputs.items():
        spec = get_input(name, where=f"inputs.{name}")
        try:  # as a one-key mapping, so that errors read inputs.<kind>[...]: message, got value
            (value,) = TypeAdapter(dict[str, spec.schema]).validate_json(json.dumps({name: value}), strict=True).values()
        except ValidationError as exc:
            raise ConfigError(format_validation_error(exc, "inputs")) from None
        checked.append((spec, value))
    return checked


def given_state(checked: list[tuple[InputSpec, Any]]) -> set[str]:
    """The state entries the inputs that the config gives (non-empty values) provide before the first stage."""
    return {key for spec, value in checked if value for key in spec.provides}


def resolve_inputs_config(checked: list[tuple[InputSpec, Any]], *, base_dir: Path,
                          data_root: Path | None) -> list[InputUnit]:
    """Expand every given input (:func:`check_inputs`) into :class:`InputUnit` objects, files checked to exist."""
    files = InputFiles(base_dir, data_root)
    units: list[InputUnit] = []
    for spec, value in checked:
        if value:
            units += spec.func(value, files)
    return units
