"""What the command modules share: declaring a command whose options are built only when it runs,
and printing a result as one JSON object (``--json``) or aligned ``key: value`` lines."""

from __future__ import annotations

import argparse
import json
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


def print_result(summary: dict[str, Any], *, as_json: bool, keys: Iterable[str] | None = None) -> None:
    """Print ``summary`` as one JSON object, or as ``key: value`` lines (only ``keys``, in their order,
    leaving out empty values, when given)."""
    if as_json:
        print(json.dumps(summary))
        return
    shown = [k for k in (keys or summary) if k in summary and summary[k] not in ("", None, [])]
    width = max((len(k) for k in shown), default=0)
    for key in shown:
        print(f"{key:>{width}}: {summary[key]}")
