"""What the command modules share: declaring a command whose options are built only when it runs,
and printing a result as one JSON object (``--json``) or aligned ``key: value`` lines."""

from __future__ import annotations

import argparse
import json
import math
from typing import Any, Callable, Iterable


def command(sub, name: str, *, help: str, description: str, handler: Callable[[argparse.Namespace], int],
            build: Callable[[argparse.ArgumentParser], None]) -> None:
    """Add the subcommand ``name``; ``build(parser)`` adds its arguments, only when the command line
    asks for this command (or for all, ``sub.selected is None``): building options from the params
    models imports the stages, which ``topomatch --help`` and the other commands need not pay for."""
    p = sub.add_parser(name, help=help, description=description)
    p.set_defaults(handler=handler)
    if getattr(sub, "selected", None) in (None, name):
        build(p)


def path_argument(text: str) -> str:
    """An argparse type for a path option: refuses the empty string (which would silently mean
    'the current folder' or 'no output')."""
    if not text.strip():
        raise argparse.ArgumentTypeError("an empty path; give a file or folder name")
    return text


def _finite(value: Any) -> Any:
    """``value`` with every NaN or infinite float replaced by None (JSON has no NaN)."""
    if isinstance(value, float):
        return value if math.isfinite(value) else None
    if isinstance(value, dict):
        return {k: _finite(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_finite(v) for v in value]
    return value


def to_json(value: Any, **kwargs) -> str:
    """Strict JSON text of ``value``: NaN and infinities become null, never the invalid ``NaN``."""
    return json.dumps(_finite(value), allow_nan=False, **kwargs)


def print_result(summary: dict[str, Any], *, as_json: bool, keys: Iterable[str] | None = None) -> None:
    """Print ``summary`` as one JSON object, or as ``key: value`` lines (only ``keys``, in their order,
    leaving out empty values, when given)."""
    if as_json:
        print(to_json(summary))
        return
    shown = [k for k in (keys or summary) if k in summary and summary[k] not in ("", None, [])]
    width = max((len(k) for k in shown), default=0)
    for key in shown:
        print(f"{key:>{width}}: {summary[key]}")
