"""Shape descriptors for retrieval, one per method, and the distances between them.

A :class:`Descriptor` is either the endpoint features of a skeleton (RGPD: mixture
distance; SRG: Fiedler vector; AGD with heat-kernel signatures; compared by endpoint
correspondence, see :mod:`topomatch.stages.matching`) or a fixed-length vector (D2, spherical
harmonics, ShapeDNA, HKS histograms, compared by a vector distance). The ``descriptor`` state
entry carries it from the stage that computes it to the index. The endpoint descriptors' stages
and the matching options are here; each vector descriptor has its own module; the methods are
records of :mod:`topomatch.stages.retrieval.catalogue`.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

import numpy as np
from pydantic import Field

from topomatch.pipeline.contract import Params, StageResult, stage
from topomatch.stages.matching.features import endpoint_features, endpoint_signatures
from topomatch.stages.spectral.heat_kernel import HKSTimes, heat_kernel_signature


@dataclass(frozen=True, eq=False)
class Descriptor:
    """What the index stores for one mesh.

    Attributes
    ----------
    kind : {'endpoints', 'vector'}
    data : ndarray
        (n, 3) endpoint features (a, dv, dc), (n, 3 + s) with an endpoint signature, or a 1-D vector.
    n_endpoints : int or None
        Endpoint count (endpoint descriptors only).
    """

    kind: str
    data: np.ndarray
    n_endpoints: int | None = None


@dataclass(frozen=True, eq=False)
class DescriptorResult(StageResult):
    descriptor: Descriptor

    def summary(self) -> dict:
        d = self.descriptor
        return {"kind": d.kind, "size": int(d.data.shape[0]), "endpoints": d.n_endpoints}


class EndpointDescriptorParams(Params):
    """Parameters of the ``endpoint_descriptor`` stage (none yet; kept for the cache key)."""


@stage("endpoint_descriptor", params=EndpointDescriptorParams, version=1, consumes=("skeleton",),
       produces=("descriptor",))
def endpoint_descriptor(skeleton, *, params: EndpointDescriptorParams) -> DescriptorResult:
    """Endpoint features (relative area, node path, centroid path) of the pruned skeleton."""
    f = endpoint_features(skeleton.graph)
    return DescriptorResult(Descriptor("endpoints", f.features, f.n))


class EndpointHKSParams(HKSTimes):
    """Parameters of the ``endpoint_hks_descriptor`` stage: the HKS times and the signature's weight."""

    weight: float = Field(0.3, ge=0, description="scale of the signature columns against (a, dv, dc)")


@stage("endpoint_hks_descriptor", params=EndpointHKSParams, version=1, consumes=("skeleton", "spectrum"),
       produces=("descriptor",))
def endpoint_hks_descriptor(skeleton, spectrum, *, params: EndpointHKSParams) -> DescriptorResult:
    """Endpoint features (a, dv, dc) plus the mean heat kernel signature of each endpoint's region.

    The skeleton and the spectrum must come from the same mesh (same vertex numbering).
    """
    f = endpoint_features(skeleton.graph)
    sig = endpoint_signatures(skeleton.graph, f.endpoints, heat_kernel_signature(spectrum, params.times()),
                              spectrum.mass)
    return DescriptorResult(Descriptor("endpoints", np.hstack([f.features, params.weight * sig]), f.n))


class MatchOptions(Params):
    """How two endpoint descriptors are compared (thesis Algorithm 2 and eq. 3.12)."""

    correspondence: Literal["greedy", "greedy_sequential", "optimal"] = Field(
        "greedy", description="globally closest pairs first, the literal sequential Algorithm 2, or optimal")
    dissimilarity: Literal["matched", "double_sum"] = Field(
        "matched", description="sum over matched pairs, or the literal double sum of eq. 3.12")
    unmatched_cost: float = Field(ge=0, allow_inf_nan=False, description="added per endpoint left without a partner "
                                  "(each method's default is in its catalogue record)")
    endpoint_window: int | None = Field(None, ge=0, description="only compare skeletons whose endpoint "
                                        "counts differ by at most this (thesis indexing: 2-3); left out, all are compared")
