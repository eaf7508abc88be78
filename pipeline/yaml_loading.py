"""Loading YAML text strictly and within bounds: configs, ``--set`` values.

PyYAML's safe loader never runs code, but it accepts what a careful reader would reject, and a few
hundred bytes can cost minutes and gigabytes:

- **duplicate keys**: the last one silently wins (a config with two ``stages:`` keys loses a
  chain); here a duplicate is an error naming the key and both lines;
- **aliases** ("billion laughs"): nine levels of ``&a [*b, *b, ...]`` expand to 10^9 values when
  the data is walked; here the expanded size of the document is counted on the node graph before
  anything is built, and a document of more than :data:`MAX_NODES` values is refused;
- **nesting**: deep ``[[[[...]]]]`` overflows Python's stack; more than :data:`MAX_DEPTH` levels is
  refused, and a stack overflow while parsing is reported as such;
- **size**: a config of more than :data:`MAX_BYTES` is refused before it is parsed;
- **numbers**: YAML 1.1 reads ``1e-3`` (no dot) as the string ``'1e-3'``; here it is the float
  0.001, as in YAML 1.2 and JSON.
"""

from __future__ import annotations

import re
from pathlib import Path
from typing import Any

import yaml

from topomatch.pipeline.errors import ConfigError, InputError

#: Largest YAML text (bytes).
MAX_BYTES = 4 * 2**20
#: Largest number of values a document may expand to, aliases counted as often as they are used.
MAX_NODES = 200_000
#: Deepest nesting of lists and mappings.
MAX_DEPTH = 64


class _StrictLoader(yaml.SafeLoader):
    """The safe loader, refusing duplicate mapping keys."""

    def construct_mapping(self, node: yaml.MappingNode, deep: bool = False) -> dict:
        seen: dict[Any, int] = {}
        for key_node, _ in node.value:
            key = self.construct_object(key_node, deep=True)
            try:
                first = seen.get(key)
            except TypeError:  # an unhashable key: the base class reports it
                break
            if first is not None:
                raise ConfigError(f"duplicate key {key!r} on lines {first + 1} and {key_node.start_mark.line + 1} "
                                  "(the second would silently replace the first)")
            seen[key] = key_node.start_mark.line
        return super().construct_mapping(node, deep=deep)


# YAML 1.2's float syntax (exponent without a dot: 1e-3, 2E5), which PyYAML's 1.1 resolver reads as a string
_StrictLoader.add_implicit_resolver(
    "tag:yaml.org,2002:float", re.compile(r"^[-+]?(?:[0-9][0-9_]*)(?:\.[0-9_]*)?[eE][-+]?[0-9]+$"),
    list("-+0123456789"))


def _check_size(root: yaml.Node) -> None:
    """Refuse a node graph that expands to more than MAX_NODES values or nests deeper than MAX_DEPTH."""
    sizes: dict[int, int] = {}

    def size(node: yaml.Node, depth: int) -> int:
        if depth > MAX_DEPTH:
            raise ConfigError(f"nested more than {MAX_DEPTH} levels deep (line {node.start_mark.line + 1})")
        known = sizes.get(id(node))
        if known is not None:
            return known
        if isinstance(node, yaml.SequenceNode):
            total = 1 + sum(size(child, depth + 1) for child in node.value)
        elif isinstance(node, yaml.MappingNode):
            total = 1 + sum(size(k, depth + 1) + size(v, depth + 1) for k, v in node.value)
        else:
            total = 1
        if total > MAX_NODES:
            raise ConfigError(f"expands to more than {MAX_NODES:,} values (aliases repeated, line "
                              f"{node.start_mark.line + 1}): refused")
        sizes[id(node)] = total
        return total

    size(root, 0)


_BRACKETS = re.compile(r"[\[\]{}]")


def _flow_depth(text: str) -> int:
    """Deepest nesting of flow brackets (a quick over-estimate: brackets inside strings count too)."""
    depth = deepest = 0
    for ch in _BRACKETS.findall(text):
        depth = depth + 1 if ch in "[{" else max(depth - 1, 0)
        deepest = max(deepest, depth)
    return deepest


def load_yaml(text: str) -> Any:
    """Parse one YAML document strictly (module docstring).

    Raises
    ------
    ConfigError
        Not valid YAML, a duplicate key, too large, too deep, or expanding too far; the message
        says which and where (the caller adds the file name).
    """
    if len(text.encode("utf-8", "replace")) > MAX_BYTES:
        raise ConfigError(f"larger than {MAX_BYTES // 2**20} MiB: refused")
    if _flow_depth(text) > MAX_DEPTH:
        raise ConfigError(f"nested more than {MAX_DEPTH} levels deep: refused")
    loader = _StrictLoader(text)
    try:
        node = loader.get_single_node()
        if node is None:
            return None
        _check_size(node)
        return loader.construct_document(node)
    except yaml.YAMLError as exc:  # one line: the problem and where (PyYAML's own text spans several)
        mark = getattr(exc, "problem_mark", None)
        where = f" (line {mark.line + 1}, column {mark.column + 1})" if mark is not None else ""
        raise ConfigError(f"not valid YAML: {getattr(exc, 'problem', None) or exc}{where}") from None
    except RecursionError:
        raise ConfigError(f"nested too deeply to parse (more than {MAX_DEPTH} levels are refused)") from None
    finally:
        loader.dispose()


def read_yaml(path: str | Path) -> dict[str, Any]:
    """Safe-load a YAML mapping; errors name the file."""
    path = Path(path)
    if not path.exists():
        raise InputError(path, "config file not found")
    if path.is_dir():
        raise InputError(path, "is a folder, not a config file: give the YAML file")
    if not path.is_file():  # a FIFO would block the read
        raise InputError(path, "not a regular file (a FIFO, socket or device): a config is a YAML text file")
    try:
        if path.stat().st_size > 4 * 2**20:
            raise ConfigError(f"{path}: config file larger than 4 MiB: refused")
        data = path.read_bytes()
    except OSError as exc:
        raise InputError(path, f"cannot read config ({exc.strerror or exc})") from None
    try:
        text = data.decode("utf-8")
    except UnicodeDecodeError as exc:
        raise ConfigError(f"{path}: not UTF-8 text (byte 0x{data[exc.start]:02x} at offset {exc.start}): a config "
                          f"is a YAML text file") from None
    try:
        data = load_yaml(text)
    except ConfigError as exc:
        raise ConfigError(f"{path}: {exc}") from None
    if not isinstance(data, dict):
        raise ConfigError(f"{path}: a config must be a YAML mapping, got {type(data).__name__}")
    return data
