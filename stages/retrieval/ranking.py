"""Dissimilarities between descriptors of one method: one query against a database, or all pairs.

How a method compares comes from its catalogue record (:mod:`topomatch.stages.retrieval.catalogue`):
vector descriptors by the record's ``distance``; endpoint descriptors by endpoint correspondence
(:mod:`topomatch.stages.matching.batch`, vectorised) with the record's matching options unless
others are given; with ``endpoint_window`` set, pairs whose endpoint counts differ by more than the
window get an infinite dissimilarity (thesis §3.4 indexing). Fusions are ranked by
:mod:`topomatch.stages.retrieval.fusion` from their parts' matrices.
"""

from __future__ import annotations

import numpy as np

from topomatch.stages.matching.batch import one_to_many, pad_features
from topomatch.stages.retrieval.catalogue import Method, get_method
from topomatch.stages.retrieval.descriptor import Descriptor, MatchOptions


def _method(method: Method | str) -> Method:
    m = get_method(method) if isinstance(method, str) else method
    if m.kind == "fusion":
        raise ValueError(f"{m.name} is a fusion: rank its parts ({', '.join(m.parts)}) and fuse them")
    return m


def _endpoint_options(options: MatchOptions) -> dict:
    return {"correspondence": options.correspondence, "dissimilarity": options.dissimilarity,
            "unmatched_cost": options.unmatched_cost}


def dissimilarities(query: Descriptor, database: list[Descriptor], method: Method | str,
                    options: MatchOptions | None = None) -> np.ndarray:
    """(len(database),) dissimilarities of ``query`` to every descriptor (options: the method's by default)."""
    m = _method(method)
    if not database:
        return np.zeros(0)
    if m.kind == "vector":
        X = np.stack([d.data.ravel() for d in database])
        return m.distance(query.data.ravel()[None], X)[0]
    options = options or m.match_options()
    padded, counts = pad_features([d.data for d in database])
    out = one_to_many(query.data, padded, counts, **_endpoint_options(options))
    if options.endpoint_window is not None:
        out[np.abs(counts - len(query.data)) > options.endpoint_window] = np.inf
    return out


def dissimilarity_matrix(descriptors: list[Descriptor], method: Method | str,
                         options: MatchOptions | None = None) -> np.ndarray:
    """(n, n) matrix of all pairwise dissimilarities (row = query; options: the method's by default)."""
    m = _method(method)
    if m.kind == "vector":
        X = np.stack([d.data.ravel() for d in descriptors])
        return m.distance(X, X)
    options = options or m.match_options()
    padded, counts = pad_features([d.data for d in descriptors])
    M = np.stack([one_to_many(d.data, padded, counts, **_endpoint_options(options)) for d in descriptors])
    if options.endpoint_window is not None:
        M[np.abs(counts[:, None] - counts[None, :]) > options.endpoint_window] = np.inf
    return M
