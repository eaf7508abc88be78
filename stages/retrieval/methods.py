"""Retrieval methods: the stage chain that turns a mesh into a descriptor, per method.

``rgpd`` and ``srg`` are the thesis's methods (chapters 3 and 4): skeleton from the
mixture distance or the Fiedler vector, pruned, then endpoint features. The
baselines compute a vector from the cleaned mesh. ``agd`` (intrinsic skeleton: the
Reeb graph of the average geodesic distance, endpoint features plus the heat kernel
signature of each endpoint) and ``hks`` (heat-kernel-signature histograms) work on a
copy decimated to 6,000 faces and share its spectrum through the cache. Each chain is
an ordinary stage list, so indexing runs through the pipeline's executors and cache.

:data:`FUSIONS` (from :mod:`topomatch.stages.retrieval.fusion`) are methods made of other methods:
``topomatch`` fuses agd, hks, shapedna, d2 and sh and re-ranks by manifold ranking.
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


#: Cleaned, decimated (6,000 faces) mesh and its 60 leading eigenpairs: the intrinsic methods' prefix.
SPECTRAL_CHAIN = [
    "load",
    {"clean": {"components": "largest"}},
    {"decimate": {"target_faces": 6000}},
    {"clean": {"components": "largest"}},
    {"spectrum": {"k": 60}},
]

METHODS: dict[str, list] = {
    "rgpd": _skeleton("mixture"),
    "srg": _skeleton("fiedler"),
    "d2": ["load", {"clean": {"components": "largest"}}, "d2"],
    "sh": ["load", {"clean": {"components": "largest"}}, "spherical_harmonics"],
    "shapedna": ["load", {"clean": {"components": "largest"}}, "shapedna"],
    "hks": SPECTRAL_CHAIN + ["hks"],
    "agd": SPECTRAL_CHAIN + [
        {"morse": {"function": "agd"}},
        {"level_sets": {"levels": 22}},
        "reeb_graph",
        {"prune": {"min_area_fraction": 0.01}},
        "endpoint_hks_descriptor",
    ],
}

#: Methods whose descriptors are skeleton endpoint features (compared by correspondence).
ENDPOINT_METHODS = ("rgpd", "srg", "agd")

#: Unmatched-endpoint cost per endpoint method (thesis methods: 0.2, measured in docs/retrieval.md).
UNMATCHED_COST = {"rgpd": 0.2, "srg": 0.2, "agd": 0.5}


def default_match_options(method: str, **overrides):
    """The :class:`~topomatch.stages.retrieval.descriptor.MatchOptions` a method is compared with by default
    (its unmatched-endpoint cost; vector methods ignore the options), with ``overrides``."""
    from topomatch.stages.retrieval.descriptor import MatchOptions

    return MatchOptions(**{"unmatched_cost": UNMATCHED_COST.get(method, 0.0), **overrides})
