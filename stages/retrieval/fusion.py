"""Fusion of several descriptors' dissimilarities: part screening, order-weighted combination, re-ranking.

A fused retrieval method (a record of :mod:`topomatch.stages.retrieval.catalogue`, e.g. ``topomatch``)
ranks shapes by several complementary descriptors at once (the intrinsic skeleton, heat-kernel
signatures, ShapeDNA, D2, spherical harmonics). Each part's dissimilarities are first divided by
that part's **median dissimilarity over the database**, so that every part has the same typical size.
Then, with no labels, from the collection itself:

1. **Agreement** (``agreement_power``, ``screen``): each part's k = 5 nearest neighbours of every
   database item are compared with every other part's; the mean overlap is the part's
   *agreement*. A part that carries no class information on a collection (D2 or spherical
   harmonics on articulated shapes in new poses) agrees with the others at chance level; parts
   that see the same classes agree far above it (measured in docs/retrieval.md: 0.04-0.08 against
   0.19-0.47). Each kept part's scale is multiplied by (agreement / best)^agreement_power, so a
   part that agrees less looks farther and drops out of the smallest values of step 2; ``screen``
   drops parts below that fraction of the best agreement outright. ``agreement_rule`` says what a part's
   agreement is compared with (issue 29): ``'mean'`` (the first rule) averages its overlap with every other
   part, so two parts that see the same wrong thing (D2 and spherical harmonics, both extrinsic, on real
   poses) raise each other's agreement and pass the screen; ``'consensus'`` compares the part with the
   *consensus* of the others (the plain sum of their median-scaled dissimilarities, the part itself left
   out), where a minority that sees the same wrong thing weighs only its share; ``'iterative'`` repeats
   that against the consensus of the parts kept so far, dropping parts below the screen, until the kept
   set no longer changes, so a part dropped no longer props up its partner.
2. **Order-weighted averaging** (``order_weights``; R. R. Yager, IEEE SMC 1988): for each pair of
   shapes the parts' scaled dissimilarities are sorted, smallest first, and averaged with
   decreasing weights, so a pair that two parts find close is close even when a third finds it
   far: one part's failure on a pair (a pose, a hole, a scale) does not drag the pair apart.
   ``None`` gives every part the same weight (a plain sum).
3. **Manifold ranking** (``rerank_k``; D. Zhou et al., "Ranking on data manifolds", NIPS 2003):
   the collection becomes a k-nearest-neighbour graph with affinities
   ``W_ij = exp(-d_ij^2 / (s_i s_j))`` (local scaling, ``s_i`` = distance to the k-th neighbour;
   Zelnik-Manor and Perona, NIPS 2004), symmetrised and normalised ``S = D^-1/2 W D^-1/2``; the
   scores ``F = (I - alpha S)^-1`` diffuse similarity along the graph. ``rerank_k='auto'`` ties k
   to the collection's size, ``round(sqrt(n) / 2)`` (at least 3): 5 for 100 shapes, 10 for 400,
   so small collections (and small classes) are not smoothed across classes.
   With ``rerank_normalisation`` = beta > 0 the scores are divided by the items' self-scores,
   ``G_ij = F_ij / (F_ii F_jj)^beta`` (beta = 1/2: the cosine of the two items' diffusion states, F
   being positive definite): an item in a large, dense class has a large ``F_jj`` and otherwise
   collects the similarity of a small neighbouring class's queries (a hub; Radovanovic et al.,
   JMLR 2010) -- the failure seen on similar characters, a query's own small class losing its first
   answer to a large similar one. The output is ``1 - G_ij / max G`` for a collection and
   ``1 - G_qj / max_j G_qj`` over the database items j for one query (the best match gets 0).
   O(n^3): about 0.02 s for 400 shapes; for very large indexes rank without it (``rerank_k: null``).

Every setting was chosen by the selection protocol of docs/retrieval.md (tune collections only).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from typing import Literal

import numpy as np

#: Neighbours compared by the screening's agreement.
AGREEMENT_NEIGHBOURS = 5

#: What a part's agreement is measured against (:attr:`Fusion.agreement_rule`; module docstring, step 1).
AgreementRule = Literal["mean", "consensus", "iterative"]
AGREEMENT_RULES: tuple[str, ...] = ("mean", "consensus", "iterative")


@dataclass(frozen=True)
class Fusion:
    """A fused retrieval method: its parts, how they are combined and how the result is re-ranked.

    Attributes
    ----------
    parts : tuple of str
        Method names (keys of :data:`topomatch.stages.retrieval.catalogue.METHODS`).
    rerank_k : int, 'auto' or None
        Neighbours of the manifold-ranking graph ('auto': :func:`rerank_neighbours`); None = no re-ranking.
    rerank_alpha : float
        Diffusion weight in (0, 1).
    order_weights : tuple of float, optional
        Weights of the smallest, second smallest, ... scaled dissimilarity of a pair (truncated to
        the parts kept, then normalised); None = equal weights (a plain sum).
    screen : float, optional
        Drop parts whose agreement is below ``screen`` times the best part's; None = keep all.
    agreement_power : float
        A kept part's scale is multiplied by (its agreement / the best agreement) ** agreement_power:
        a part that agrees less with the others looks farther, so the order weighting counts it
        less (:func:`scale_factor`); 0 = every part at its median scale.
    rerank_normalisation : float
        beta >= 0: manifold-ranking scores divided by the items' self-scores to that power (module
        docstring, step 3); 0 = Zhou et al.'s scores as they are.
    agreement_rule : {'mean', 'consensus', 'iterative'}
        What a part's agreement is measured against (module docstring, step 1): its mean overlap with every
        other part ('mean', the first rule), its overlap with the consensus of the other parts
        ('consensus'), or with the consensus of the parts kept so far, screened again until the kept set is
        stable ('iterative').
    """

    parts: tuple[str, ...]
    rerank_k: int | Literal["auto"] | None
    rerank_alpha: float
    order_weights: tuple[float, ...] | None = None
    screen: float | None = None
    agreement_power: float = 0.0
    rerank_normalisation: float = 0.0
    agreement_rule: AgreementRule = "mean"

    def __post_init__(self):
        if self.agreement_rule not in AGREEMENT_RULES:
            raise ValueError(f"Fusion.agreement_rule: expected one of {', '.join(AGREEMENT_RULES)}, "
                             f"got {self.agreement_rule!r}")

    def with_parts(self, parts, rerank_k=...) -> "Fusion":
        """The same fusion over other parts (and optionally another ``rerank_k``)."""
        return replace(self, parts=tuple(parts), **({} if rerank_k is ... else {"rerank_k": rerank_k}))


@dataclass(frozen=True)
class FusionDecision:
    """What a fusion did on a collection: which parts it kept (and why), and the re-ranking neighbours."""

    kept: tuple[str, ...]
    dropped: tuple[str, ...]
    agreement: dict[str, float]  # empty when the fusion neither screens nor weights by agreement
    rerank_k: int | None

    def to_dict(self) -> dict:
        return {"kept": list(self.kept), "dropped": list(self.dropped),
                "agreement": {p: round(a, 4) for p, a in self.agreement.items()}, "rerank_k": self.rerank_k}

    @classmethod
    def from_dict(cls, d: dict) -> "FusionDecision":
        """The decision :meth:`to_dict` wrote (agreements rounded to 4 decimals)."""
        return cls(tuple(d["kept"]), tuple(d["dropped"]), dict(d["agreement"]), d.get("rerank_k"))


def median_scale(D: np.ndarray) -> float:
    """Median of the finite off-diagonal entries of a square matrix (1 when there are none or it is 0)."""
    D = np.asarray(D, dtype=np.float64)
    off = D[~np.eye(len(D), dtype=bool)]
    off = off[np.isfinite(off)]
    scale = float(np.median(off)) if off.size else 1.0
    return scale if scale > 0 else 1.0


def fuse(parts: list[np.ndarray], scales: list[float], order_weights: tuple[float, ...] | None = None) -> np.ndarray:
    """Combination of dissimilarity arrays (any common shape), each divided by its scale.

    Equal weights (a sum) when ``order_weights`` is None; else, element by element, the weighted
    mean of the scaled values sorted smallest first (weights truncated to ``len(parts)``).
    """
    if not parts:
        raise ValueError("fuse: no parts")
    scaled = [np.asarray(P, dtype=np.float64) / s for P, s in zip(parts, scales)]
    if order_weights is None:
        return sum(scaled)
    w = np.asarray(order_weights[: len(scaled)], dtype=np.float64)
    if any(np.isnan(x).any() for x in scaled):  # NaN sorts last in np.sort, but min/max would spread it
        smallest = np.sort(np.stack(scaled), axis=0)[: len(w)]
    else:
        smallest = np.stack(_sorted_elementwise(scaled)[: len(w)])
    return np.tensordot(w / w.sum(), smallest, axes=1)


def _sorted_elementwise(arrays: list[np.ndarray]) -> list[np.ndarray]:
    """The arrays' values sorted element by element, smallest first (as ``np.sort(np.stack(arrays), axis=0)``
    without NaN), by an odd-even transposition network of ``np.minimum`` / ``np.maximum``: for the few parts
    of a fusion about 10x faster than sorting along a short first axis, and exact (no arithmetic)."""
    vals = list(arrays)
    for r in range(len(vals)):
        for i in range(r % 2, len(vals) - 1, 2):
            vals[i], vals[i + 1] = np.minimum(vals[i], vals[i + 1]), np.maximum(vals[i], vals[i + 1])
    return vals


def _neighbour_sets(D: np.ndarray, k: int) -> np.ndarray:
    """(n, k) int: row i holds the k nearest other items of item i (in no order; ties broken arbitrarily)."""
    D = np.array(D, dtype=np.float64)
    D[~np.isfinite(D)] = np.inf
    np.fill_diagonal(D, np.inf)
    return np.argpartition(D, k - 1, axis=1)[:, :k]


def _overlap(a: np.ndarray, b: np.ndarray) -> float:
    """Mean fraction of common neighbours of two (n, k) neighbour sets, row by row."""
    n, k = a.shape
    # (n, k, k) comparisons of k distinct indices each
    return (a[:, :, None] == b[:, None, :]).sum() / (n * k)


def agreement(part_matrices: list[np.ndarray], k: int = AGREEMENT_NEIGHBOURS) -> np.ndarray:
    """(P,) mean overlap of each part's k-nearest-neighbour sets with every other part's, in [0, 1]."""
    n = len(part_matrices[0])
    if len(part_matrices) < 2 or n < 3:
        return np.ones(len(part_matrices))
    k = min(k, n - 1)
    sets = [_neighbour_sets(P, k) for P in part_matrices]
    pair = np.array([[_overlap(a, b) for b in sets] for a in sets])
    return (pair.sum(axis=1) - np.diag(pair)) / (len(sets) - 1)


def _consensus(part_matrices: list[np.ndarray], members) -> np.ndarray:
    """The plain sum of the median-scaled matrices of the parts ``members`` (non-finite entries: infinitely far)."""
    total = sum(np.asarray(part_matrices[i], dtype=np.float64) / median_scale(part_matrices[i]) for i in members)
    return np.where(np.isfinite(total), total, np.inf)


def consensus_agreement(part_matrices: list[np.ndarray], kept=None, k: int = AGREEMENT_NEIGHBOURS) -> np.ndarray:
    """(P,) overlap of each part's k-nearest-neighbour sets with those of the consensus of the parts ``kept``
    (indices; default all) other than itself, in [0, 1] (:func:`_consensus`; 1 for a part with no other part kept)."""
    P, n = len(part_matrices), len(part_matrices[0])
    kept = list(range(P)) if kept is None else list(kept)
    if P < 2 or n < 3:
        return np.ones(P)
    k = min(k, n - 1)
    sets = [_neighbour_sets(M, k) for M in part_matrices]
    out = np.ones(P)
    for p in range(P):
        others = [q for q in kept if q != p]
        if others:
            out[p] = _overlap(sets[p], _neighbour_sets(_consensus(part_matrices, others), k))
    return out


def screened(part_matrices: list[np.ndarray], rule: str, screen: float | None,
             agreements: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """((P,) agreement, (P,) bool kept) of the parts by ``rule`` (:attr:`Fusion.agreement_rule`): a part is kept
    when its agreement is at least ``screen`` times the best part's (every part when ``screen`` is None).
    ``agreements``: the rule's first agreement when already computed (for 'mean', :func:`agreement`; for the
    others, :func:`consensus_agreement` of every part)."""
    P = len(part_matrices)
    if rule == "mean":
        a = agreement(part_matrices) if agreements is None else np.asarray(agreements)
    else:
        a = consensus_agreement(part_matrices) if agreements is None else np.asarray(agreements)
    keep = a >= (screen or 0.0) * a.max()
    if rule != "iterative" or not screen:
        return a, keep
    seen = {tuple(keep)}
    for _ in range(2 * P):  # the kept set shrinks or settles within a few rounds; a cycle stops at its first repeat
        a = consensus_agreement(part_matrices, np.flatnonzero(keep))
        new = a >= screen * a.max()
        if tuple(new) == tuple(keep) or tuple(new) in seen:
            keep = new
            break
        seen.add(tuple(new))
        keep = new
    return a, keep


def rerank_neighbours(fusion: Fusion, n: int) -> int | None:
    """The manifold-ranking neighbours of ``fusion`` on a graph of ``n`` items (None: no re-ranking)."""
    if fusion.rerank_k == "auto":
        return max(3, int(round(math.sqrt(n) / 2)))
    return fusion.rerank_k


def decide(part_matrices: list[np.ndarray], fusion: Fusion, graph_size: int | None = None,
           agreements: np.ndarray | None = None) -> FusionDecision:
    """Screen the parts of ``fusion`` on a database's (n, n) part matrices (module docstring, step 1).
    ``agreements``: the first agreement of ``fusion.agreement_rule`` on these matrices when already computed
    (:func:`agreement` for 'mean', :func:`consensus_agreement` otherwise; it depends on them only, so many fusions of
    one collection can share it)."""
    n = graph_size if graph_size is not None else len(part_matrices[0])
    if fusion.screen is None and not fusion.agreement_power:
        return FusionDecision(fusion.parts, (), {}, rerank_neighbours(fusion, n))
    a, keep = screened(part_matrices, fusion.agreement_rule, fusion.screen, agreements)
    return FusionDecision(tuple(p for p, k in zip(fusion.parts, keep) if k),
                          tuple(p for p, k in zip(fusion.parts, keep) if not k),
                          {p: float(x) for p, x in zip(fusion.parts, a)}, rerank_neighbours(fusion, n))


def _ranking_graph(D: np.ndarray, k: int) -> np.ndarray:
    """(n, n) normalised affinity S of the symmetrised k-nearest-neighbour graph (locally scaled)."""
    D = np.array(D, dtype=np.float64)
    n = len(D)
    if not np.all(np.isfinite(D)):
        D[~np.isfinite(D)] = 2 * D[np.isfinite(D)].max(initial=1.0)
    np.fill_diagonal(D, 0.0)
    k = max(1, min(k, n - 1))
    kth = np.partition(D, k, axis=1)[:, k]  # the k-th nearest (index 0 is the item itself)
    scale = kth.copy()
    # an item with k or more exact duplicates has a k-th distance of 0 (and 0 / 0 made NaN): its scale
    # is the distance to its nearest distinct item instead, else (all items equal) 1
    zero = ~(scale > 0)
    if zero.any():
        nearest = np.where(D[zero] > 0, D[zero], np.inf).min(axis=1)
        scale[zero] = np.where(np.isfinite(nearest), nearest, 1.0)
    W = np.exp(-D ** 2 / (scale[:, None] * scale[None, :]))
    # the k nearest and every item tied with the k-th (identical copies are all neighbours or none)
    W = np.where(D <= kth[:, None], W, 0.0)
    W = (W + W.T) / 2
    d = W.sum(axis=1)
    return W / np.sqrt(d[:, None] * d[None, :])


def _ranking_scores(D: np.ndarray, k: int, alpha: float) -> np.ndarray:
    """(n, n) diffusion scores ``F = (I - alpha S)^-1`` of the graph of ``D``, symmetric (up to round-off)."""
    F = np.linalg.inv(np.eye(len(D)) - alpha * _ranking_graph(D, k))
    return (F + F.T) / 2


def manifold_ranking(D: np.ndarray, k: int = 10, alpha: float = 0.9, normalisation: float = 0.0) -> np.ndarray:
    """Re-ranked (n, n) dissimilarity of a square dissimilarity matrix (module docstring).

    Parameters
    ----------
    D : (n, n) float64
        Non-negative dissimilarities (``inf`` allowed: no edge); the diagonal is ignored.
    k : int
        Neighbours per item (clipped to n - 1).
    alpha : float
        In (0, 1): how far similarity diffuses.
    normalisation : float
        beta: scores divided by ``(F_ii F_jj)^beta`` (0: none).

    Returns
    -------
    (n, n) float64 ``1 - G / G.max()`` in [0, 1], symmetric (``G = F / (f f^T)^beta``, ``f = diag F``).
    """
    n = len(D)
    if n < 3:
        return np.array(D, dtype=np.float64)
    G = _ranking_scores(D, k, alpha)
    if normalisation:
        f = np.diag(G) ** -normalisation
        G = G * f[:, None] * f[None, :]
    return 1.0 - G / G.max()


def manifold_ranking_row(D: np.ndarray, row: int, k: int = 10, alpha: float = 0.9,
                         normalisation: float = 0.0) -> np.ndarray:
    """Row ``row`` of the manifold ranking of ``D`` (n, n), ``1 - G_row / max G_row``: one linear solve
    without ``normalisation``, else the inverse (the self-scores of every item).

    Ranks exactly as :func:`manifold_ranking`'s row (same scores, another positive scale).
    """
    n = len(D)
    if n < 3:
        return np.array(D[row], dtype=np.float64)
    if normalisation:
        F = _ranking_scores(D, k, alpha)
        g = F[row] * np.diag(F) ** -normalisation
    else:
        e = np.zeros(n)
        e[row] = 1.0
        g = np.linalg.solve(np.eye(n) - alpha * _ranking_graph(D, k), e)
    return 1.0 - g / g.max()


def _kept(items: list, fusion: Fusion, decision: FusionDecision) -> list:
    return [x for p, x in zip(fusion.parts, items) if p in decision.kept]


def scale_factor(fusion: Fusion, decision: FusionDecision, part: str) -> float:
    """Multiplier of a kept part's median scale: (agreement / best agreement) ** agreement_power (1 when off)."""
    if not fusion.agreement_power or not decision.agreement:
        return 1.0
    best = max(decision.agreement.values())
    return (max(decision.agreement[part], 1e-12) / best) ** fusion.agreement_power if best > 0 else 1.0


def kept_scales(part_matrices: list[np.ndarray], fusion: Fusion, decision: FusionDecision) -> list[float]:
    """The scales of the kept parts (median dissimilarity times :func:`scale_factor`), in ``decision.kept`` order."""
    return [median_scale(P) * scale_factor(fusion, decision, p)
            for p, P in zip(fusion.parts, part_matrices) if p in decision.kept]


def fused_matrix(part_matrices: list[np.ndarray], fusion: Fusion, decision: FusionDecision | None = None) -> np.ndarray:
    """(n, n) fused (and re-ranked) dissimilarities of a collection from its parts' (n, n) matrices
    (what was kept and why: :func:`decide`, computed here unless given)."""
    decision = decision or decide(part_matrices, fusion)
    mats = _kept(part_matrices, fusion, decision)
    D = fuse(mats, kept_scales(part_matrices, fusion, decision), fusion.order_weights)
    k = decision.rerank_k
    return manifold_ranking(D, k, fusion.rerank_alpha, fusion.rerank_normalisation) if k else D


def fused_query(query_rows: list[np.ndarray], part_matrices: list[np.ndarray], fusion: Fusion,
                decision: FusionDecision | None = None) -> np.ndarray:
    """(n,) fused dissimilarities of one query to a database.

    ``query_rows``: per part, the (n,) dissimilarities of the query to the database;
    ``part_matrices``: per part, the database's (n, n) matrix (screening, scales, and the graph for
    re-ranking: the query joins the database's graph as an (n + 1)-th item). The screening looks at
    the database alone, so every query of a database uses the same parts: pass ``decision``
    (``decide(part_matrices, fusion, graph_size=n + 1)``) to compute it once for many queries.

    Values: with re-ranking, the query's row of :func:`manifold_ranking_row` on the (n + 1)-item graph,
    ``1 - G_qj / max_i G_qi`` over every item, the query's own node included (with beta = 1/2, one minus the
    cosine of the diffusion states, the entry :func:`manifold_ranking` would give); items the diffusion does
    not reach (1: no path in the neighbour graph, or a score below round-off) follow every reached one, ranked
    by their fused dissimilarity f as ``1 + f / (1 + f)`` in [1, 2); an item at fused dissimilarity 0 (as close
    as can be in the parts the order weights read) is 0 and comes first. Without re-ranking (no ``rerank_k``,
    or a database of one shape): the fused dissimilarities.
    """
    n = len(query_rows[0])
    decision = decision or decide(part_matrices, fusion, graph_size=n + 1)
    rows, mats = _kept(query_rows, fusion, decision), _kept(part_matrices, fusion, decision)
    scales = kept_scales(part_matrices, fusion, decision)
    row = fuse(rows, scales, fusion.order_weights)
    if not decision.rerank_k or n + 1 < 3:
        return row
    A = np.zeros((n + 1, n + 1))
    A[:n, :n] = fuse(mats, scales, fusion.order_weights)
    A[n, :n] = A[:n, n] = row
    # the first match is 0 only when it scores like the query itself, not whenever it is the database's best
    out = manifold_ranking_row(A, n, decision.rerank_k, fusion.rerank_alpha, fusion.rerank_normalisation)[:n]
    with np.errstate(invalid="ignore"):
        beyond = np.where(np.isfinite(row), 1.0 + row / (1.0 + row), np.inf)
    out = np.where(out >= 1.0, beyond, out)
    # an item at fused dissimilarity 0 comes first: on a small graph the diffusion can score a well-connected
    # neighbour above it
    same = row == 0
    if same.any():
        out = np.where(same, 0.0, np.maximum(out, np.finfo(float).tiny))
    return out
