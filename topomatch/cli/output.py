"""How a command prints its result: one JSON object (``--json``) or aligned ``key: value`` lines."""

from __future__ import annotations

import json
from typing import Any, Iterable


def print_result(summary: dict[str, Any], *, as_json: bool, keys: Iterable[str] | None = None) -> None:
    """Print ``summary`` as one JSON object, or as ``key: value`` lines (only ``keys``, in their order,
    leaving out empty values, when given)."""
    if as_json:
        print(json.dumps(summary))
        return
    shown = [k for k in (keys or summary) if k in summary and summary[k] not in ("", None)]
    width = max((len(k) for k in shown), default=0)
    for key in shown:
        print(f"{key:>{width}}: {summary[key]}")
