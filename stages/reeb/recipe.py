"""The skeleton of one mesh as a stage chain, shared by ``topomatch skeleton``, the Python API and
the skeleton retrieval methods.

load -> clean (the largest connected component) -> morse -> level_sets -> reeb_graph -> prune.
The chain names only what differs from the stages' own defaults (the Morse function is the
``morse`` stage's default, 22 level sets, 1 % pruning, ...), so every default is defined once,
in the stages' params.
"""

from __future__ import annotations

from typing import Any

#: The chain in config form (a stage name, or {name: {param: value}}).
SKELETON_CHAIN: tuple[Any, ...] = (
    "load",
    {"clean": {"components": "largest"}},
    "morse",
    "level_sets",
    "reeb_graph",
    "prune",
)


def skeleton_chain(function: str | None = None) -> list[Any]:
    """:data:`SKELETON_CHAIN` with ``morse.function`` set (None: the stage's default)."""
    if function is None:
        return list(SKELETON_CHAIN)
    return [{"morse": {"function": function}} if entry == "morse" else entry for entry in SKELETON_CHAIN]
