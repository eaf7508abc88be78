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


#: Version of the dissimilarities: bump it when a method's distance or the endpoint matching changes, so
#: that matrices saved by :func:`saved_dissimilarity_matrix` before the change are not used.
DISSIMILARITY_VERSION = 1

#: Matrices of collections up to this size are saved (n^2 float64: 200 MB at 5,000 shapes; larger
#: indexes rank through the shortlist, never through a full matrix).
SAVED_MATRIX_MAX = 5000


def _comparison(method: Method | str, options: MatchOptions | None, what: str):
    """A SHA-256 started with ``what``, the version, the method and the options it compares with (endpoint
    methods; vector methods have none)."""
    import hashlib
    import json

    m = _method(method)
    options = options or m.match_options()
    return hashlib.sha256(json.dumps([what, DISSIMILARITY_VERSION, m.name,
                                      options.model_dump(mode="json") if m.kind == "endpoints" else None]).encode())


def matrix_key(descriptors: list[Descriptor], method: Method | str, options: MatchOptions | None = None) -> str:
    """SHA-256 of everything :func:`dissimilarity_matrix` reads: the method, its options, the version and
    every descriptor (kind, endpoint count, dtype, shape and bytes, in order)."""
    h = _comparison(method, options, "dissimilarity_matrix")
    for d in descriptors:
        data = np.ascontiguousarray(d.data)
        h.update(f"|{d.kind}|{d.n_endpoints}|{data.dtype.str}|{data.shape}|".encode())
        h.update(data.tobytes())
    return h.hexdigest()


def saved_dissimilarity_matrix(descriptors: list[Descriptor], method: Method | str, options: MatchOptions | None,
                               cache, slot: str) -> np.ndarray:
    """:func:`dissimilarity_matrix`, read from ``cache`` (a :class:`~topomatch.pipeline.cache.Cache`, e.g. an
    index's) when the same descriptors were compared before with the same method and options, else
    computed and saved there. A database matrix costs n^2 comparisons (1.4 s for 400 endpoint sets), a
    query's row n: saving it makes a repeated query cost its row only.

    ``slot`` names the use (e.g. ``"all"``, ``"labelled"``): one matrix is kept per slot, method and
    options, and a new one replaces it (the index's cache does not grow as the index changes).
    """
    n = len(descriptors)
    if n > SAVED_MATRIX_MAX:
        return dissimilarity_matrix(descriptors, method, options)
    key = matrix_key(descriptors, method, options)
    hit, M = cache.get(key, lambda v: None if isinstance(v, np.ndarray) and v.shape == (n, n) and v.dtype.kind == "f"
                       else "not an (n, n) float matrix")
    if hit:
        return M
    M = dissimilarity_matrix(descriptors, method, options)
    slot_key = _comparison(method, options, f"saved matrix slot {slot}").hexdigest()
    had, previous = cache.get(slot_key, lambda v: None if isinstance(v, str) else "not a key")
    if cache.put(key, M):
        if had and previous != key:
            cache.remove(previous)
        cache.put(slot_key, key)
    return M
