"""Typed, frozen, validated stage parameters.

Every stage declares a subclass of :class:`Params`. Values coming from YAML or the
CLI are validated in *strict JSON mode*: no silent string-to-number coercion,
unknown keys rejected, and every error reported with its config path, e.g.
``stages[3].noise.sigma: Input should be a valid number, got 'x'``.
"""

from __future__ import annotations

import json
from typing import Any, Mapping, TypeVar

from pydantic import BaseModel, ConfigDict, ValidationError

from topomatch.pipeline.errors import ConfigError

P = TypeVar("P", bound="Params")


class Params(BaseModel):
    """Base of all stage and report parameter objects (frozen, strict, no extra keys)."""

    model_config = ConfigDict(extra="forbid", frozen=True, strict=True)

    def axis_label(self, name: str) -> str | None:
        """How figures name the parameter ``name`` with its unit (e.g. ``vertex noise σ (fraction of the
        bounding-box diagonal)``): its field's ``title``, or None; a subclass whose unit depends on
        another parameter overrides this."""
        field = type(self).model_fields.get(name)
        return field.title if field is not None else None

    @classmethod
    def parse(cls: type[P], data: Mapping[str, Any] | None, where: str) -> P:
        """Validate ``data`` (a YAML mapping) into ``cls``; errors name ``where``.

        Parameters
        ----------
        data : mapping or None
            Raw values; ``None`` means all defaults.
        where : str
            Config path of the mapping, used as the prefix of error messages.
        """
        if data is None:
            data = {}
        if not isinstance(data, Mapping):
            raise ConfigError(f"{where}: expected a mapping of parameters, got {data!r}")
        return validate_json_strict(cls, dict(data), where)

    def canonical(self) -> dict[str, Any]:
        """JSON-ready dict of all values (defaults included), used for cache keys."""
        return self.model_dump(mode="json")


def _python_scalar(value: Any) -> Any:
    """A numpy scalar as its Python number (an API option computed with numpy: ``seed=np.int64(3)``); anything else
    that JSON cannot hold is refused."""
    if getattr(value, "shape", None) == () and hasattr(value, "item"):
        return value.item()
    raise TypeError(f"Object of type {type(value).__name__} is not JSON serializable")


def validate_json_strict(model: type[BaseModel], data: Any, where: str) -> Any:
    """Validate plain YAML data against a pydantic model in strict JSON mode.

    Strict JSON mode accepts lists for tuples and strings for literals but never
    converts ``"5"`` to ``5``; errors become one :class:`ConfigError` listing every
    problem as ``path: message, got value``.
    """
    try:
        text = json.dumps(data, allow_nan=True, default=_python_scalar)
    except (TypeError, ValueError) as exc:
        raise ConfigError(f"{where}: values must be plain YAML scalars, lists and mappings ({exc})") from None
    try:
        return model.model_validate_json(text, strict=True)
    except ValidationError as exc:
        raise ConfigError(format_validation_error(exc, where)) from None


def format_validation_error(exc: ValidationError, where: str) -> str:
    """One line per problem: ``where.loc: message, got input``."""
    lines = []
    for err in exc.errors():
        loc = where
        for part in err["loc"]:
            loc += f"[{part}]" if isinstance(part, int) else (f".{part}" if loc else str(part))
        msg = err["msg"].removeprefix("Value error, ")
        if err["type"] == "extra_forbidden":
            msg = "unknown key"
        elif err["type"] != "missing" and err["loc"]:
            msg += f", got {err.get('input')!r}"
        lines.append(f"{loc}: {msg}" if loc else msg)
    return "\n".join(lines)
