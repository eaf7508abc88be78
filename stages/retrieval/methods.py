"""Retrieval methods: the stage chain that turns a mesh into a descriptor, per method.

``rgpd`` and ``srg`` are the thesis's methods (chapters 3 and 4): skeleton from the
mixture distance or the Fiedler vector, pruned, then endpoint features. The
baselines compute a vector from the cleaned mesh. Each chain is an ordinary
stage list, so indexing runs through the pipeline's executors and cache.
"""

from __future__ import annotations

SKELETON_CHAIN = [
    "load",
    {"clean": {"components": "largest"}},
    None,  # the Morse function
    {"level_sets": {"levels": 22}},
    "reeb_graph",
    {"prune": {"min_area_fraction": 0.01}},
    "endpoint_descriptor",
]


def _skeleton(function: str) -> list:
    return [entry if entry is not None else {"morse": {"function": function}} for entry in SKELETON_CHAIN]


METHODS: dict[str, list] = {
    "rgpd": _skeleton("mixture"),
    "srg": _skeleton("fiedler"),
    "d2": ["load", {"clean": {"components": "largest"}}, "d2"],
    "sh": ["load", {"clean": {"components": "largest"}}, "spherical_harmonics"],
    "shapedna": ["load", {"clean": {"components": "largest"}}, "shapedna"],
}

#: Methods whose descriptors are skeleton endpoint features (compared by correspondence).
ENDPOINT_METHODS = ("rgpd", "srg")
