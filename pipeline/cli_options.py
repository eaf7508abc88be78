"""Command-line options generated from params models, so that the CLI cannot drift from them.

A command names the fields it exposes by their dotted path into a set of models (``morse.function``,
``register.metric.alpha``); :func:`add_options` derives each option's flag (the last name, dashed:
``--function``, ``--alpha``), type, choices (a ``Literal``), ``--x/--no-x`` for a bool, and its help
from the field's description and default. Options left out on the command line are absent from
the parsed namespace (``argparse.SUPPRESS``), so the models' own defaults apply: every default is
defined once, in the params. :func:`given_options` collects the given values as nested mappings
and validates each with its field, naming the option in any error
(``--unmatched-cost: Input should be greater than or equal to 0, got -1.0``). :func:`add_set_option` and
:func:`set_options` give a command ``--set path=value`` for every other field of its models
(``--set check.min_structure=0``), validated the same way.
"""

from __future__ import annotations

import argparse
import json
import types
import typing
from dataclasses import dataclass
from typing import Annotated, Any, Mapping, Sequence

from topomatch.pipeline.errors import ConfigError
from topomatch.pipeline.mappings import set_path

if typing.TYPE_CHECKING:  # pydantic is imported when options are built: `topomatch --help` does not pay for it
    from pydantic import BaseModel
    from pydantic.fields import FieldInfo


@dataclass(frozen=True)
class Option:
    """One exposed field: its dotted ``path`` (first name: a key of the models mapping), and
    optionally its ``flag`` and a ``default_help`` that replaces the shown default."""

    path: str
    flag: str | None = None
    default_help: str | None = None

    @property
    def name(self) -> str:
        return self.flag or "--" + self.path.split(".")[-1].replace("_", "-")

    @property
    def dest(self) -> str:
        return "opt__" + self.path.replace(".", "__")


def _option(spec: str | Option) -> Option:
    return spec if isinstance(spec, Option) else Option(spec)


def field_of(models: Mapping[str, type[BaseModel]], path: str) -> tuple[FieldInfo, Any]:
    """The pydantic field at ``path`` and its resolved annotation."""
    from pydantic import BaseModel

    head, *rest = path.split(".")
    model: Any = models[head]
    info, hint = None, None
    for part in rest:
        if not (isinstance(model, type) and issubclass(model, BaseModel)) or part not in model.model_fields:
            raise KeyError(f"no field {path!r}")
        info = model.model_fields[part]
        hint = typing.get_type_hints(model).get(part, info.annotation)
        model = _strip_optional(hint)
    if info is None:
        raise KeyError(f"{path!r} names a model, not a field")
    return info, hint


def _strip_optional(hint: Any) -> Any:
    args = [a for a in typing.get_args(hint) if a is not type(None)]
    if typing.get_origin(hint) in (typing.Union, types.UnionType) and len(args) == 1:
        return args[0]
    return hint


def _default_text(info: FieldInfo) -> str:
    default = info.get_default(call_default_factory=True)
    return "none" if default is None else str(default)


def add_options(parser: argparse.ArgumentParser, models: Mapping[str, type[BaseModel]],
                specs: Sequence[str | Option]) -> None:
    """Add one option per field path in ``specs`` (see the module docstring)."""
    for spec in map(_option, specs):
        info, hint = field_of(models, spec.path)
        base = _strip_optional(hint)
        shown = spec.default_help if spec.default_help is not None else _default_text(info)
        text = info.description or ""
        if "(default:" not in text:  # a description may say its default itself
            text = f"{text} (default: {shown})".strip()
        kwargs: dict[str, Any] = {"dest": spec.dest, "default": argparse.SUPPRESS, "help": text}
        if base is bool:
            kwargs["action"] = argparse.BooleanOptionalAction
        elif typing.get_origin(base) is typing.Literal:
            kwargs["choices"] = list(typing.get_args(base))
        elif base in (int, float, str):
            kwargs["type"] = base
            kwargs["metavar"] = {int: "N", float: "X", str: "TEXT"}[base]
        else:
            raise TypeError(f"{spec.path}: no command-line form for the type {hint}")
        parser.add_argument(spec.name, **kwargs)


def _validated(info: FieldInfo, value: Any, name: str) -> Any:
    """``value`` if ``info``'s field accepts it (strict, as from JSON); else a ConfigError naming ``name``."""
    from pydantic import TypeAdapter, ValidationError

    try:
        TypeAdapter(Annotated[info.annotation, info]).validate_json(json.dumps(value, allow_nan=True), strict=True)
    except ValidationError as exc:
        raise ConfigError(f"{name}: {exc.errors()[0]['msg'].removeprefix('Value error, ')}, got {value!r}") from None
    return value


def given_options(args: argparse.Namespace, models: Mapping[str, type[BaseModel]],
                  specs: Sequence[str | Option]) -> dict[str, dict[str, Any]]:
    """The values given on the command line as ``{head: nested mapping}``, each validated by its field.

    Raises
    ------
    ConfigError
        A value the field rejects; the message names the option.
    """
    out: dict[str, dict[str, Any]] = {}
    for spec in map(_option, specs):
        if hasattr(args, spec.dest):
            value = _validated(field_of(models, spec.path)[0], getattr(args, spec.dest), spec.name)
            set_path(out, spec.path, value, spec.name)
    return out


def add_set_option(parser: argparse.ArgumentParser, models: Mapping[str, type[BaseModel]], default: str) -> None:
    """``--set path=value`` (repeatable) for any field of ``models``; a path without a model's name is one of
    ``default``'s (:func:`set_options`)."""
    parser.add_argument("--set", dest="set_values", action="append", default=[], metavar="PARAM=VALUE",
                        help=f"set any parameter: a {default} parameter by its dotted path (check.min_structure=0), or "
                             f"{' / '.join(sorted(models))}.<path>; the value is read as YAML; repeatable "
                             f"(`topomatch stages --json` lists every parameter)")


def set_options(out: dict[str, dict[str, Any]], items: Sequence[str], models: Mapping[str, type[BaseModel]],
                default: str) -> dict[str, dict[str, Any]]:
    """``out`` (from :func:`given_options`) with each ``--set path=value`` of ``items`` validated by its field and
    set (later items win).

    Raises
    ------
    ConfigError
        Not ``key=value``, no such field (named), or a value the field rejects.
    """
    from topomatch.pipeline.yaml_loading import load_yaml

    for item in items:
        key, sep, text = item.partition("=")
        if not sep or not key.strip():
            raise ConfigError(f"--set {item!r}: expected param=value")
        path = key.strip() if key.strip().split(".")[0] in models else f"{default}.{key.strip()}"
        try:
            info, _ = field_of(models, path)
        except KeyError:
            parent, _, _ = path.rpartition(".")
            try:
                known = _strip_optional(field_of(models, parent)[1]).model_fields if "." in parent else \
                    models[parent].model_fields
            except (KeyError, AttributeError):
                known = models[default].model_fields
                parent = default
            raise ConfigError(f"--set {key.strip()}: no such parameter (those of {parent}: "
                              f"{', '.join(known)})") from None
        try:
            given = load_yaml(text)
        except ConfigError as exc:  # the YAML's own message, named by the option that gave it
            raise ConfigError(f"--set {key.strip()}: {exc}") from None
        value = _validated(info, given, f"--set {key.strip()}")
        set_path(out, path, value, f"--set {key.strip()}")
    return out
