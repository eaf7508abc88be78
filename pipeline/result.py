"""Base class of stage results."""

from __future__ import annotations

from typing import Any


class StageResult:
    """Mixin for the named result structures (frozen dataclasses) that stages return.

    ``summary()`` gives the scalars that go into the run's tables, keyed by short
    column names; the runner prefixes them with the stage name.
    """

    def summary(self) -> dict[str, Any]:
        return {}
