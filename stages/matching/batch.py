"""Dissimilarities of one query against many skeletons at once (vectorised).

Endpoint feature sets have different sizes; they are padded to a common size
with NaN rows, and the greedy correspondence (:mod:`topomatch.stages.matching.correspondence`,
globally closest pair first) runs on all pairs together: each round takes, in
every pair, the smallest cost among free rows and columns. ``min(n1, n2)``
rounds of an argmin over (pairs, e1 * e2) costs. The result equals
:func:`topomatch.stages.matching.dissimilarity.match_features` with the same options
(tested), up to ties between equal costs.
"""

from __future__ import annotations

import numpy as np

from topomatch.stages.matching.correspondence import Correspondence
from topomatch.stages.matching.dissimilarity import Dissimilarity, match_features


def pad_features(sets: list[np.ndarray]) -> tuple[np.ndarray, np.ndarray]:
    """Stack (n_i, d) feature arrays into (len(sets), max n_i, d) with NaN padding, and the counts."""
    counts = np.array([len(s) for s in sets], dtype=np.int64)
    width = int(counts.max(initial=0))
    # the width of the non-empty sets; with none, of the empty (0, d) ones (a collection of shapes without endpoints)
    dims = {s.shape[1] for s in sets if len(s)} or {s.shape[1] for s in sets if np.ndim(s) == 2} or {3}
    if len(dims) > 1:
        raise ValueError(f"endpoint feature sets of different widths: {sorted(dims)}")
    out = np.full((len(sets), max(width, 1), dims.pop()), np.nan)
    for i, s in enumerate(sets):
        out[i, : len(s)] = s
    return out, counts


def one_to_many(
    query: np.ndarray,
    database: np.ndarray,
    counts: np.ndarray,
    *,
    correspondence: Correspondence = "greedy",
    dissimilarity: Dissimilarity = "matched",
    unmatched_cost: float = 0.0,
    chunk: int = 20000,
) -> np.ndarray:
    """Dissimilarity of ``query`` (e, d) to every padded feature set in ``database`` (p, w, d).

    Returns (p,) float64. ``optimal`` correspondence falls back to one
    ``match_features`` call per pair (not vectorised).
    """
    query = np.asarray(query, dtype=np.float64)
    p = len(database)
    out = np.empty(p)
    if correspondence != "greedy":
        for i in range(p):
            out[i] = match_features(query, database[i, : counts[i]], correspondence=correspondence,
                                    dissimilarity=dissimilarity, unmatched_cost=unmatched_cost).dissimilarity
        return out
    e = len(query)
    for start in range(0, p, chunk):
        D = database[start:start + chunk]
        n = counts[start:start + chunk]
        if e == 0:
            out[start:start + chunk] = 0.0 if dissimilarity == "double_sum" else unmatched_cost * n
            continue
        C = np.sqrt(((query[None, :, None, :] - D[:, None, :, :]) ** 2).sum(-1))  # (q, e, w), NaN on padding
        if dissimilarity == "double_sum":
            out[start:start + chunk] = np.nansum(C, axis=(1, 2))
            continue
        C = np.where(np.isnan(C), np.inf, C)
        q, _, w = C.shape
        total = np.zeros(q)
        rounds = np.minimum(n, e)
        flat = C.reshape(q, -1)
        for r in range(int(rounds.max(initial=0))):
            active = rounds > r
            idx = np.argmin(flat, axis=1)
            best = flat[np.arange(q), idx]
            total += np.where(active, best, 0.0)
            i, j = np.divmod(idx, w)
            C[np.arange(q), i, :] = np.inf
            C[np.arange(q), :, j] = np.inf
        out[start:start + chunk] = total + unmatched_cost * np.abs(n - e)
    return out


def many_to_many(sets: list[np.ndarray], **options) -> np.ndarray:
    """Full (n, n) dissimilarity matrix of a list of endpoint feature sets."""
    padded, counts = pad_features(sets)
    return np.stack([one_to_many(s, padded, counts, **options) for s in sets])
