"""Nested parameter mappings: ``stage.group.param`` paths written into ``{stage: {group: {param: value}}}``,
and one mapping merged into another key by key. The config's ``--set`` and sweeps, the command-line options,
the Python API's keyword options and the registration's per-dimension defaults all build their parameter
mappings with these two functions."""

from __future__ import annotations

from typing import Any, Mapping, Sequence

from topomatch.pipeline.errors import ConfigError


def set_path(target: dict[str, Any], path: str | Sequence[str], value: Any, where: str = "") -> dict[str, Any]:
    """``target[p0][p1]... = value`` for ``path`` (``"register.metric.alpha"`` or its parts), creating mappings on
    the way; returns ``target``.

    Raises
    ------
    ConfigError
        A part of the path already holds something that is not a mapping (named with ``where``).
    """
    parts = path.split(".") if isinstance(path, str) else list(path)
    node = target
    for part in parts[:-1]:
        node = node.setdefault(part, {})
        if not isinstance(node, dict):
            raise ConfigError(f"{where or '.'.join(parts)}: {part!r} is not a mapping")
    node[parts[-1]] = value
    return target


def deep_merge(base: Mapping[str, Any], top: Mapping[str, Any]) -> dict[str, Any]:
    """A new mapping: ``base`` with ``top``'s values, nested mappings merged key by key (``top`` wins)."""
    out = dict(base)
    for key, value in top.items():
        out[key] = deep_merge(out[key], value) if isinstance(value, Mapping) and isinstance(out.get(key), Mapping) \
            else value
    return out
