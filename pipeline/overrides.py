"""``--set key=value``: command-line overrides of a config's raw data (a config key, a stage's parameter, a
sweep), before it is validated."""

from __future__ import annotations

import copy
from typing import Any

from topomatch.pipeline.chain import entry_name
from topomatch.pipeline.errors import ConfigError
from topomatch.pipeline.mappings import set_path
from topomatch.pipeline.schema import RawConfig
from topomatch.pipeline.yaml_loading import load_yaml


def apply_overrides(data: dict[str, Any], overrides: list[str]) -> dict[str, Any]:
    """Apply CLI ``--set key=value`` overrides to raw config data.

    ``key`` is either a dotted path into the config (``executor.kind``,
    ``name``), ``sweep.stage.param`` for a sweep (value: a list), or
    ``stage.param`` for a stage of the chain (``noise.sigma``); a param may
    be nested (``register.metric.alpha``). Values are parsed as YAML scalars
    (``0.01``, ``true``, ``[1, 2]``).
    """
    data = copy.deepcopy(data)
    for item in overrides:
        if "=" not in item:
            raise ConfigError(f"--set {item!r}: expected key=value")
        key, text = item.split("=", 1)
        try:
            value = load_yaml(text)
        except ConfigError as exc:
            raise ConfigError(f"--set {item!r}: the value is {exc}") from None
        parts = key.strip().split(".")
        if parts[0] == "sweep" and len(parts) >= 3:  # sweep keys contain a dot: sweep.<stage>.<param>
            _section(data, "sweep", dict, item)[".".join(parts[1:])] = value
            continue
        if parts[0] in RawConfig.model_fields:
            set_path(data, parts, value, f"--set {key}")
            continue
        if len(parts) < 2:
            raise ConfigError(f"--set {key}: expected a config key or stage.param")
        swept = data.get("sweep") if isinstance(data.get("sweep"), dict) else {}
        if key.strip() in swept:  # the sweep sets it at every point: a chain value would be silently ignored
            raise ConfigError(f"--set {key}: the config sweeps {key.strip()} over {swept[key.strip()]!r}, which sets it "
                              f"at every sweep point; set the sweep instead, e.g. --set 'sweep.{key.strip()}=[{text}]'")
        entries = _section(data, "stages", list, item)
        positions = [i for i, e in enumerate(entries) if entry_name(e) == parts[0]]
        if len(positions) != 1:
            raise ConfigError(f"--set {key}: the chain has {len(positions)} stages called {parts[0]!r}, expected exactly one")
        i = positions[0]
        entry = entries[i]
        params = copy.deepcopy(dict(entry[parts[0]] or {})) if isinstance(entry, dict) else {}
        set_path(params, parts[1:], value, f"--set {key}")
        entries[i] = {parts[0]: params}
    return data


def _section(data: dict[str, Any], name: str, kind: type, item: str) -> Any:
    """``data[name]`` (created empty when absent or null) for ``--set item``; a ConfigError when it is not a ``kind``."""
    if data.get(name) is None:
        data[name] = kind()
    section = data[name]
    if not isinstance(section, kind):
        raise ConfigError(f"--set {item!r}: the config's {name!r} is a {type(section).__name__}, "
                          f"not a {'mapping' if kind is dict else 'list'}")
    return section
