"""Dissimilarities between descriptors: one query against an index, or all pairs.

Endpoint descriptors (RGPD, SRG) are compared by endpoint correspondence
(:mod:`topomatch.stages.matching.batch`, vectorised); with ``endpoint_window`` set, pairs
whose endpoint counts differ by more than the window get an infinite
dissimilarity (thesis §3.4 indexing). Vector descriptors use their baseline's
metric (:data:`topomatch.stages.retrieval.baselines.BASELINES`).
"""

from __future__ import annotations

import numpy as np

from topomatch.stages.matching.batch import one_to_many, pad_features
from topomatch.stages.retrieval.baselines import BASELINES
from topomatch.stages.retrieval.descriptor import Descriptor, MatchOptions
from topomatch.stages.spectral import heat_kernel

#: Index method name -> the (n, m) distance matrix of its vector descriptors.
VECTOR_METHODS = {
    "d2": BASELINES["d2"].distance_matrix,
    "sh": BASELINES["spherical_harmonics"].distance_matrix,
    "shapedna": BASELINES["shapedna"].distance_matrix,
    "hks": heat_kernel.distance_matrix,
}


def _endpoint_options(options: MatchOptions) -> dict:
    return {"correspondence": options.correspondence, "dissimilarity": options.dissimilarity,
            "unmatched_cost": options.unmatched_cost}


def dissimilarities(query: Descriptor, database: list[Descriptor], method: str,
                    options: MatchOptions | None = None) -> np.ndarray:
    """(len(database),) dissimilarities of ``query`` to every descriptor."""
    options = options or MatchOptions()
    if not database:
        return np.zeros(0)
    if method in VECTOR_METHODS:
        X = np.stack([d.data.ravel() for d in database])
        return VECTOR_METHODS[method](query.data.ravel()[None], X)[0]
    padded, counts = pad_features([d.data for d in database])
    out = one_to_many(query.data, padded, counts, **_endpoint_options(options))
    if options.endpoint_window is not None:
        out[np.abs(counts - len(query.data)) > options.endpoint_window] = np.inf
    return out


def dissimilarity_matrix(descriptors: list[Descriptor], method: str, options: MatchOptions | None = None) -> np.ndarray:
    """(n, n) matrix of all pairwise dissimilarities (row = query)."""
    options = options or MatchOptions()
    if method in VECTOR_METHODS:
        X = np.stack([d.data.ravel() for d in descriptors])
        return VECTOR_METHODS[method](X, X)
    padded, counts = pad_features([d.data for d in descriptors])
    M = np.stack([one_to_many(d.data, padded, counts, **_endpoint_options(options)) for d in descriptors])
    if options.endpoint_window is not None:
        M[np.abs(counts[:, None] - counts[None, :]) > options.endpoint_window] = np.inf
    return M
