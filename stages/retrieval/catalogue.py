"""The retrieval methods: one record per method, the only place where a method is defined.

A :class:`Method` says how a mesh becomes a descriptor (its stage chain, in config form), how
two descriptors compare (``kind`` and ``distance``) and with which default options (the cost of
an unmatched endpoint), or, for a fusion, which methods it combines and how it re-ranks. The CLI
(choices, help, defaults), the Python API, the shape index, ranking, evaluation, the reports and
the benchmarks all read :data:`METHODS`; adding a descriptor is one module (params, descriptor,
distance, stage) plus one record here (docs/engine.md shows an example).

Methods (SHREC'07 Watertight numbers in docs/retrieval.md):

- ``rgpd``, ``srg``: the thesis's skeletons (ch. 3: mixture distance; ch. 4: Fiedler vector),
  endpoint features (a, dv, dc) matched by the greedy correspondence;
- ``agd``: intrinsic skeleton (average geodesic distance) with heat-kernel endpoint signatures;
- ``hks``: heat-kernel-signature histograms; ``gps``: distributions of distances in the global point signature
  embedding (Rustamov 2007; not a part of the default fusion); ``shapedna``: normalised Laplace-Beltrami spectrum (read from
  the shared spectrum; ``shapedna-full``: its own eigen-solve on the full mesh, kept for comparison);
- ``sdgdm``: the spectrum of the geodesic distance matrix (Smeets et al. 2012), on the cleaned, capped full mesh
  (not a fusion part);
- ``d2``, ``sh``: extrinsic baselines (shape distribution, spherical harmonics); ``lfd``: the light field
  descriptor (Chen et al. 2003), a view-based extrinsic part (not a part of the default fusion);
- ``topomatch``: the adaptive fusion of agd, hks, shapedna, d2 and sh (a part dropped when its agreement
  with the others is below 0.5 of the best part's, each kept part scaled by its median, a pair's two
  smallest scaled dissimilarities averaged, re-ranked by manifold ranking, k from the collection's size, alpha = 0.95,
  with the cosine of the items' diffusion states);
  ``topomatch-equal``: the first fusion (equal weights, k = 10), kept for comparison.

The intrinsic methods (agd, hks, shapedna) work on a copy decimated to 6,000 faces, its holes capped
(``fill_holes``), and share its 40 leading eigenpairs (:data:`SPECTRAL_CHAIN`; computed once per mesh
when indexing).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Callable, Literal

import numpy as np

from topomatch.pipeline.contract import ConfigError
from topomatch.stages.reeb.recipe import skeleton_chain
from topomatch.stages.retrieval import gps, hks
from topomatch.stages.retrieval.baselines import d2, light_field, sdgdm, shapedna, spherical_harmonics
from topomatch.stages.retrieval.descriptor import MatchOptions
from topomatch.stages.retrieval.fusion import Fusion

#: Cleaned mesh: the prefix of the vector baselines.
CLEAN_CHAIN: tuple[Any, ...] = ("load", {"clean": {"components": "largest"}})

#: Sampling of the extrinsic methods: a quarter of the stages' defaults (2^18 pairs, 2^17 points), chosen
#: by ``benchmarks/retrieval_part_costs.py`` on tune collections (same retrieval, 4x less sampling).
D2_PAIRS = 1 << 16
SH_POINTS = 1 << 15

#: Cleaned, decimated (6,000 faces) mesh, its holes capped, and its 40 leading eigenpairs: the intrinsic methods'
#: prefix (40, not the earlier 60, chosen by ``benchmarks/retrieval_part_costs.py`` on tune collections: the same
#: retrieval, ARPACK 1.6x faster; the capping adopted on 2026-12-02 by a rule written before the tune
#: collections were indexed with it, docs/retrieval.md).
SPECTRAL_CHAIN: tuple[Any, ...] = CLEAN_CHAIN + (
    {"decimate": {"target_faces": 6000}},
    {"clean": {"components": "largest"}},
    "fill_holes",
    {"spectrum": {"k": 40}},
)

#: The same decimated, capped copy without the spectrum (geodesics, no Laplacian eigenpairs).
INTRINSIC_MESH_CHAIN: tuple[Any, ...] = SPECTRAL_CHAIN[:-1]

#: SD-GDM's mesh: cleaned and capped, **not** decimated -- the 6,000-face copy (fast-simplification) bridges parts
#: that nearly touch, and a geodesic distance matrix is destroyed by such shortcuts (docs/retrieval.md, "SD-GDM, alone").
SDGDM_MESH_CHAIN: tuple[Any, ...] = CLEAN_CHAIN + ("fill_holes",)


@dataclass(frozen=True)
class Method:
    """One retrieval method.

    Attributes
    ----------
    name : str
        The name users type (``--method``) and the index stores.
    title : str
        One line for help texts and tables.
    kind : {'endpoints', 'vector', 'fusion'}
        Endpoint features compared by correspondence, a fixed-length vector compared by
        ``distance``, or a fusion of other methods.
    chain : tuple
        Stage chain (config form) from a mesh file to the ``descriptor`` state entry (not for fusions).
    distance : callable, optional
        Vector methods: ``distance(X (n, d), Y (m, d)) -> (n, m)``.
    unmatched_cost : float
        Endpoint methods: default cost per endpoint left without a partner.
    fusion : Fusion, optional
        Fusions: the part methods and the re-ranking.
    """

    name: str
    title: str
    kind: Literal["endpoints", "vector", "fusion"]
    chain: tuple[Any, ...] = ()
    distance: Callable[..., np.ndarray] | None = None
    unmatched_cost: float = 0.0
    fusion: Fusion | None = None

    @property
    def parts(self) -> tuple[str, ...]:
        """The methods whose descriptors this one needs: a fusion's parts, or itself."""
        return self.fusion.parts if self.fusion is not None else (self.name,)

    def match_options(self, **overrides: Any) -> MatchOptions:
        """The endpoint matching options of this method (its unmatched cost), with ``overrides``
        (None values are ignored); vector methods ignore them."""
        given = {k: v for k, v in overrides.items() if v is not None}
        return MatchOptions.model_validate({"unmatched_cost": self.unmatched_cost, **given})


#: The parts of the fusions.
FUSION_PARTS = ("agd", "hks", "shapedna", "d2", "sh")

METHODS: dict[str, Method] = {m.name: m for m in (
    Method("rgpd", "mixture-distance skeleton endpoints (thesis ch. 3)", "endpoints",
           tuple(skeleton_chain("mixture")) + ("endpoint_descriptor",), unmatched_cost=0.3),
    Method("srg", "Fiedler-vector skeleton endpoints (thesis ch. 4)", "endpoints",
           tuple(skeleton_chain("fiedler")) + ("endpoint_descriptor",), unmatched_cost=0.3),
    Method("agd", "intrinsic skeleton (average geodesic distance) with heat-kernel endpoint signatures",
           "endpoints", SPECTRAL_CHAIN + ({"morse": {"function": "agd"}}, "level_sets", "reeb_graph", "prune",
                                          "endpoint_hks_descriptor"), unmatched_cost=0.5),
    Method("hks", "heat-kernel-signature histograms", "vector", SPECTRAL_CHAIN + ("hks",),
           distance=hks.distance_matrix),
    Method("gps", "distributions of global point signature distances (Rustamov 2007) over the shared spectrum's 20 "
           "leading eigenpairs", "vector", SPECTRAL_CHAIN + ("gps",), distance=gps.distance_matrix),
    Method("shapedna", "ShapeDNA, the normalised Laplace-Beltrami spectrum (Reuter 2006), read from the shared "
           "spectrum of the 6,000-face copy", "vector", SPECTRAL_CHAIN + ("shapedna_of_spectrum",),
           distance=shapedna.distance_matrix),
    Method("shapedna-full", "ShapeDNA with its own eigen-solve on the full mesh (consistent FEM mass; kept for "
           "comparison)", "vector", CLEAN_CHAIN + ("shapedna",), distance=shapedna.distance_matrix),
    Method("d2", "D2 shape distribution (Osada 2002), 2^16 point pairs", "vector",
           CLEAN_CHAIN + ({"d2": {"n_pairs": D2_PAIRS}},), distance=d2.distance_matrix),
    Method("sh", "rotation-invariant spherical harmonics (Kazhdan 2003), 2^15 surface points", "vector",
           CLEAN_CHAIN + ({"spherical_harmonics": {"n_points": SH_POINTS}},),
           distance=spherical_harmonics.distance_matrix),
    Method("sdgdm", "SD-GDM, the logarithms of the 40 leading singular values of the geodesic distance matrix of 64 "
           "farthest-point samples over the largest (Smeets 2012), on the cleaned, capped full mesh", "vector",
           SDGDM_MESH_CHAIN + ("sdgdm",), distance=sdgdm.distance_matrix),
    Method("lfd", "light field descriptor (Chen 2003): Zernike and Fourier features of the silhouettes seen from 5 "
           "dodecahedra's vertices, compared under the dodecahedron's 60 rotations", "vector",
           CLEAN_CHAIN + ("light_field",), distance=light_field.distance_matrix),
    Method("topomatch", "adaptive fusion of agd, hks, shapedna, d2 and sh: a part whose nearest neighbours agree "
           "with the others' less than 0.5 of the best part's is dropped, each kept part scaled by its median, a "
           "pair's two smallest scaled dissimilarities averaged, re-ranked by manifold ranking (k from the collection's size, "
           "alpha = 0.95, the cosine of the items' diffusion states)",
           "fusion", fusion=Fusion(FUSION_PARTS, rerank_k="auto", rerank_alpha=0.95, order_weights=(1, 1), screen=0.5,
                                   agreement_power=0.0, rerank_normalisation=0.5, agreement_rule="mean")),
    Method("topomatch-equal", "the first fusion (kept for comparison): agd, hks, shapedna, d2 and sh with equal "
           "weights, manifold ranking with k = 10", "fusion",
           fusion=Fusion(FUSION_PARTS, rerank_k=10, rerank_alpha=0.9)),
)}

#: Default of the commands on a collection (index, query, evaluate): the adaptive fusion, chosen by
#: the selection protocol of docs/retrieval.md (tune collections only) and reported on the others.
DEFAULT_METHOD = "topomatch"

#: Default of ``match`` (two meshes, no collection): the best method that compares two shapes on
#: their own (a fusion needs a collection's scales).
DEFAULT_PAIR_METHOD = "hks"


def get_method(name: str) -> Method:
    """The record of ``name``; a :class:`ConfigError` listing the methods otherwise."""
    try:
        return METHODS[name]
    except KeyError:
        raise ConfigError(f"unknown retrieval method {name!r}; methods: {', '.join(METHODS)}") from None


def help_text(names: list[str] | None = None) -> str:
    """One line per method (of ``names``, default all), for ``--help``."""
    return "; ".join(f"{m.name}: {m.title}" for m in METHODS.values() if names is None or m.name in names)
