"""Fusion of several descriptors' dissimilarities, and manifold-ranking re-ranking.

A fused retrieval method (a record of :mod:`topomatch.stages.retrieval.catalogue`, e.g.
``topomatch``) ranks shapes by several complementary
descriptors at once: the intrinsic skeleton (AGD Reeb graph with heat-kernel endpoint
signatures), the heat-kernel-signature histograms, ShapeDNA, D2 and the spherical harmonic
descriptor. Each part's dissimilarities are divided by that part's **median dissimilarity over
the database** (so every part has the same typical size and none dominates by its units), and
the parts are summed with equal weights (no weight was fitted to a benchmark).

Re-ranking (optional, on by default for ``topomatch``): **manifold ranking** (D. Zhou, J. Weston,
A. Gretton, O. Bousquet, B. Schölkopf, "Ranking on data manifolds", NIPS 2003). The collection
becomes a k-nearest-neighbour graph with affinities ``W_ij = exp(-d_ij^2 / (s_i s_j))`` (local
scaling: ``s_i`` = distance to the i-th item's k-th neighbour; L. Zelnik-Manor, P. Perona,
NIPS 2004), symmetrised and normalised ``S = D^-1/2 W D^-1/2``; the ranking scores are
``F = (I - alpha S)^-1``, i.e. similarity diffused along the graph, so two shapes related through
a chain of close neighbours rank higher than their direct distance says. It uses the database's
own structure (no labels). The output dissimilarity is ``1 - F_ij / max F`` for a collection
and ``1 - F_qj / max_j F_qj`` over the database items j for one query (one linear solve; the
best match gets 0): rankings are those of the scores; values compare within a row. Cost: O(n^3) dense linear algebra, about 0.02 s for 400
shapes; for very large indexes rank without it (``rerank_k: null``).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class Fusion:
    """A fused retrieval method: its part methods, and the manifold-ranking settings.

    Attributes
    ----------
    parts : tuple of str
        Method names (keys of :data:`topomatch.stages.retrieval.catalogue.METHODS`), equally weighted.
    rerank_k : int or None
        Neighbours of the manifold-ranking graph; None = no re-ranking.
    rerank_alpha : float
        Diffusion weight in (0, 1).
    """

    parts: tuple[str, ...]
    rerank_k: int | None
    rerank_alpha: float


def median_scale(D: np.ndarray) -> float:
    """Median of the finite off-diagonal entries of a square matrix (1 when there are none or it is 0)."""
    D = np.asarray(D, dtype=np.float64)
    off = D[~np.eye(len(D), dtype=bool)]
    off = off[np.isfinite(off)]
    scale = float(np.median(off)) if off.size else 1.0
    return scale if scale > 0 else 1.0


def fuse(parts: list[np.ndarray], scales: list[float]) -> np.ndarray:
    """Equal-weight sum of dissimilarity arrays (any common shape), each divided by its scale."""
    if not parts:
        raise ValueError("fuse: no parts")
    return sum(np.asarray(P, dtype=np.float64) / s for P, s in zip(parts, scales))


def _ranking_graph(D: np.ndarray, k: int) -> np.ndarray:
    """(n, n) normalised affinity S of the symmetrised k-nearest-neighbour graph (locally scaled)."""
    D = np.array(D, dtype=np.float64)
    n = len(D)
    if not np.all(np.isfinite(D)):
        D[~np.isfinite(D)] = 2 * D[np.isfinite(D)].max(initial=1.0)
    np.fill_diagonal(D, 0.0)
    k = max(1, min(k, n - 1))
    order = np.argpartition(D, k, axis=1)  # [:, k] is the k-th nearest, [:, :k + 1] the k + 1 nearest
    scale = np.maximum(D[np.arange(n), order[:, k]], 1e-300)
    W = np.exp(-D ** 2 / (scale[:, None] * scale[None, :]))
    keep = np.zeros((n, n), dtype=bool)
    keep[np.arange(n)[:, None], order[:, : k + 1]] = True
    W = np.where(keep, W, 0.0)
    W = (W + W.T) / 2
    d = W.sum(axis=1)
    return W / np.sqrt(d[:, None] * d[None, :])


def manifold_ranking(D: np.ndarray, k: int = 10, alpha: float = 0.9) -> np.ndarray:
    """Re-ranked (n, n) dissimilarity of a square dissimilarity matrix (module docstring).

    Parameters
    ----------
    D : (n, n) float64
        Non-negative dissimilarities (``inf`` allowed: no edge); the diagonal is ignored.
    k : int
        Neighbours per item (clipped to n - 1).
    alpha : float
        In (0, 1): how far similarity diffuses.

    Returns
    -------
    (n, n) float64 ``1 - F / F.max()`` in [0, 1], symmetric (``F = (I - alpha S)^-1`` is).
    """
    n = len(D)
    if n < 3:
        return np.array(D, dtype=np.float64)
    F = np.linalg.inv(np.eye(n) - alpha * _ranking_graph(D, k))
    F = (F + F.T) / 2  # symmetric up to round-off
    return 1.0 - F / F.max()


def manifold_ranking_row(D: np.ndarray, row: int, k: int = 10, alpha: float = 0.9) -> np.ndarray:
    """Row ``row`` of the manifold ranking of ``D`` (n, n) by one linear solve, ``1 - F_row / max F_row``.

    Ranks exactly as :func:`manifold_ranking`'s row (same scores, another positive scale).
    """
    n = len(D)
    if n < 3:
        return np.array(D[row], dtype=np.float64)
    e = np.zeros(n)
    e[row] = 1.0
    f = np.linalg.solve(np.eye(n) - alpha * _ranking_graph(D, k), e)
    return 1.0 - f / f.max()


def fused_matrix(part_matrices: list[np.ndarray], fusion: Fusion) -> np.ndarray:
    """(n, n) fused (and re-ranked) dissimilarities of a collection from its parts' (n, n) matrices."""
    D = fuse(part_matrices, [median_scale(P) for P in part_matrices])
    return manifold_ranking(D, fusion.rerank_k, fusion.rerank_alpha) if fusion.rerank_k else D


def fused_query(query_rows: list[np.ndarray], part_matrices: list[np.ndarray], fusion: Fusion) -> np.ndarray:
    """(n,) fused dissimilarities of one query to a database.

    ``query_rows``: per part, the (n,) dissimilarities of the query to the database;
    ``part_matrices``: per part, the database's (n, n) matrix (scales, and the graph for re-ranking:
    the query joins the database's graph as an (n + 1)-th item).
    """
    scales = [median_scale(P) for P in part_matrices]
    row = fuse(query_rows, scales)
    if not fusion.rerank_k:
        return row
    n = len(row)
    A = np.zeros((n + 1, n + 1))
    A[:n, :n] = fuse(part_matrices, scales)
    A[n, :n] = A[:n, n] = row
    score = 1.0 - manifold_ranking_row(A, n, fusion.rerank_k, fusion.rerank_alpha)[:n]  # the query's own node left out
    return 1.0 - score / score.max()  # 0 for the best database match
