"""Retrieval metrics of a dissimilarity matrix, as the Princeton Shape Benchmark's ``psbTable`` computes them.

Reference: P. Shilane, P. Min, M. Kazhdan, T. Funkhouser, "The Princeton Shape Benchmark",
Shape Modeling International 2004, and the ``psbTable`` program distributed with the
benchmark (``psbTable.cpp``, P. Shilane). Every definition below follows that program; the
places where this module adds to it (mean average precision, the precision-recall curve,
options) are marked *addition*.

Ranked lists
------------
Row ``i`` of the dissimilarity matrix ``D`` (n, n) ranks the other ``n - 1`` items by
increasing ``D[i, j]``; **the query itself is removed from its own list** (psbTable sets
``D[i, i]`` to ``FLT_MAX`` and sorts; removing it is the same unless other entries reach
``FLT_MAX``). **Ties are broken by item index**: equal dissimilarities are listed in
increasing ``j`` (a stable sort of the row, as psbTable's comparison function does). So an
all-zero ``D`` ranks every list in index order. ``D`` need not be symmetric (each row is
the query's own list); ``+inf`` is allowed (ranked last), ``NaN`` is rejected.
psbTable reads the matrix as float32, so two float64 values closer than float32 resolution
tie there but not here; ``psb_float32=True`` rounds ``D`` to float32 first to reproduce that.

Per-query metrics
-----------------
With ``C`` the size of the query's class (the query included), ``R = C - 1`` the number of
relevant items in its list, ``N = n - 1`` the list length and ``G_r`` = 1 when the item at
rank ``r`` (1-based) is in the query's class:

- **NN** (nearest neighbour) = ``G_1``.
- **FT** (first tier) = (hits in the top ``R``) / ``R``.
- **ST** (second tier) = (hits in the top ``min(2R, N)``) / ``R``.
- **E** (E-measure) over the top ``K = min(32, N)``: ``P = h / K``, ``Rc = h / R`` with ``h`` the
  hits in the top ``K``, ``E = 2 / (1/P + 1/Rc) = 2 h / (K + R)`` (0 when ``h = 0``). Its maximum
  is ``2 min(R, K) / (K + R)``, i.e. 1 only when ``R = K``. The cut-off is ``e_cutoff`` (32, as
  psbTable's ``K``).
- **DCG**: ``DCG_1 = G_1``, ``DCG_r = DCG_{r-1} + G_r / log2(r)`` summed over the whole list,
  divided by the ideal value ``1 + sum_{r=2..R} 1 / log2(r)`` (all relevant items first).
- **AP** (*addition*, average precision, not interpolated) = mean over the ``R`` relevant items of
  the precision at their rank; **mAP** is its average.
- **Interpolated precision-recall** (*addition*): ``P_interp(rho) = max {P_k : recall_k >= rho}``
  over the ranks ``k`` (``P_k = hits in top k / k``, ``recall_k = hits in top k / R``), at the
  recall levels ``rho = j / recall_steps``, ``j = 0..recall_steps``. The default
  ``recall_steps = 20`` gives the 21 levels 0, 0.05, ..., 1 (use 10 for the classical 11-point
  curve). ``P_interp(0)`` is the best precision anywhere in the list. The hit count for level
  ``j`` is computed in integers, ``ceil(j R / recall_steps)``, so no level is lost to round-off.

A query whose class has a single member (``R = 0``) gets 0 for every metric (psbTable's FT,
ST and DCG; its E would be NaN there and is 0 here).

Averages
--------
- **micro**: mean over the evaluated queries;
- **macro**: mean over the evaluated classes of the per-class means (each class counts once).
As in psbTable, classes with at most 2 members (``CUTOFF = 2``) take no part in either average
(``min_class_size = 3``); their items stay in the ranked lists of the others as non-relevant.
psbTable also skips its "miscellaneous" class; pass its label in ``ignore_labels`` for that.
The precision-recall curve is averaged in the same two ways (per recall level).

Numerics: psbTable accumulates DCG in float32; this module uses float64, so DCG can differ
from psbTable's output in the 7th digit. With ``psb_float32=True`` the rankings are identical.

Chance level: :func:`chance_levels` gives the exact expectation of every metric when each
ranked list is a uniformly random permutation (e.g. NN, FT = ``R / N``, ST = ``min(2R, N) / N``,
AP = ``H_N / N + (R - 1)(N - H_N) / (N (N - 1))`` with ``H_N`` the harmonic number).

Cost: O(n^2 log n) for the sorts, vectorised over blocks of rows (memory O(block * n)); a
400 x 400 matrix takes about 10 ms (``benchmarks/baselines.py``).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Hashable, Iterable, Literal, NamedTuple

import numpy as np

#: Names of the per-query metrics, in table order (keys of ``micro`` / ``macro``).
METRIC_NAMES: tuple[str, ...] = ("nn", "first_tier", "second_tier", "e_measure", "dcg", "map")

#: psbTable's E-measure cut-off (its ``K``).
PSB_E_CUTOFF = 32
#: psbTable leaves classes with at most this many models out of the averages (its ``CUTOFF``).
PSB_CUTOFF = 2

# rows per block when ranking: bounds the (block, n) temporaries to ~2**22 entries
_BLOCK_ENTRIES = 1 << 22


# --------------------------------------------------------------------------- results


class PrecisionRecall(NamedTuple):
    """An averaged interpolated precision-recall curve.

    Attributes
    ----------
    recall : (L,) float64
        Recall levels ``j / recall_steps``, ``j = 0..recall_steps``.
    precision : (L,) float64
        Interpolated precision at each level.
    """

    recall: np.ndarray
    precision: np.ndarray


@dataclass(frozen=True, eq=False)
class RetrievalMetrics:
    """PSB retrieval metrics of a dissimilarity matrix (see the module docstring).

    Attributes
    ----------
    labels : (n,) array
        The class label of each item, as given.
    class_size : (n,) int64
        ``C``, the size of each item's class (the item included).
    evaluated : (n,) bool
        Queries that take part in the averages (class size >= ``min_class_size``, label not
        ignored).
    nn, first_tier, second_tier, e_measure, dcg, average_precision : (n,) float64
        Per-query metrics (computed for every query, evaluated or not).
    recall_levels : (L,) float64
        The recall levels of the precision-recall curve.
    precision_at_recall : (n, L) float64
        Per-query interpolated precision at ``recall_levels``.
    micro, macro : dict
        ``{name: value}`` for the names in :data:`METRIC_NAMES` ('map' is the mean of
        ``average_precision``); NaN when nothing is evaluated.
    micro_pr, macro_pr : (L,) float64
        Micro- and macro-averaged interpolated precision-recall curves.
    per_class : dict
        ``{label: {name: value, ..., 'size': C}}`` for every evaluated class (class means).
    e_cutoff : int
        The E-measure cut-off used (``min(e_cutoff, n - 1)`` in effect).
    """

    labels: np.ndarray
    class_size: np.ndarray
    evaluated: np.ndarray
    nn: np.ndarray
    first_tier: np.ndarray
    second_tier: np.ndarray
    e_measure: np.ndarray
    dcg: np.ndarray
    average_precision: np.ndarray
    recall_levels: np.ndarray
    precision_at_recall: np.ndarray
    micro: dict[str, float]
    macro: dict[str, float]
    micro_pr: np.ndarray
    macro_pr: np.ndarray
    per_class: dict[Hashable, dict[str, float]] = field(default_factory=dict)
    e_cutoff: int = PSB_E_CUTOFF

    @property
    def n(self) -> int:
        """Number of items."""
        return int(self.labels.shape[0])

    def per_query(self) -> dict[str, np.ndarray]:
        """``{name: (n,) array}`` for the names in :data:`METRIC_NAMES`."""
        return {"nn": self.nn, "first_tier": self.first_tier, "second_tier": self.second_tier,
                "e_measure": self.e_measure, "dcg": self.dcg, "map": self.average_precision}

    def precision_recall(self, average: Literal["micro", "macro"] = "micro") -> PrecisionRecall:
        """The averaged interpolated precision-recall curve."""
        if average not in ("micro", "macro"):
            raise ValueError(f"average must be 'micro' or 'macro', got {average!r}")
        return PrecisionRecall(self.recall_levels, self.micro_pr if average == "micro" else self.macro_pr)

    def as_dict(self) -> dict[str, Any]:
        """JSON-ready summary: micro and macro averages, both curves, per-class means."""
        return {
            "n": self.n,
            "evaluated": int(self.evaluated.sum()),
            "e_cutoff": self.e_cutoff,
            "micro": dict(self.micro),
            "macro": dict(self.macro),
            "recall_levels": self.recall_levels.tolist(),
            "micro_pr": self.micro_pr.tolist(),
            "macro_pr": self.macro_pr.tolist(),
            "per_class": {str(k): dict(v) for k, v in self.per_class.items()},
        }

    def table(self, name: str = "method") -> str:
        """The micro and macro averages as a two-row markdown table."""
        head = "| " + " | ".join([name, "average", "NN", "FT", "ST", "E", "DCG", "mAP"]) + " |"
        rule = "|" + "---|" * 8
        rows = []
        for avg, values in (("micro", self.micro), ("macro", self.macro)):
            rows.append("| " + " | ".join([name, avg] + [f"{values[k]:.3f}" for k in METRIC_NAMES]) + " |")
        return "\n".join([head, rule, *rows])


# --------------------------------------------------------------------------- validation


def _check_matrix(D: Any) -> np.ndarray:
    D = np.asarray(D)
    if D.ndim != 2 or D.shape[0] != D.shape[1]:
        raise ValueError(f"D must be a square (n, n) dissimilarity matrix, got shape {D.shape}")
    if D.shape[0] < 2:
        raise ValueError(f"need at least 2 items to rank, got D of shape {D.shape}")
    if not np.issubdtype(D.dtype, np.number) or np.iscomplexobj(D):
        raise ValueError(f"D must hold real numbers, got dtype {D.dtype}")
    nan = np.isnan(D)
    if nan.any():
        first = tuple(int(i) for i in np.argwhere(nan)[0])
        raise ValueError(f"D has {int(nan.sum())} NaN entries (first at {first}); NaN cannot be ranked")
    return D


def _check_inputs(D: Any, labels: Any) -> tuple[np.ndarray, np.ndarray]:
    D = _check_matrix(D)
    labels = np.asarray(labels)
    if labels.shape != (D.shape[0],):
        raise ValueError(f"labels must have shape ({D.shape[0]},) to match D {D.shape}, got {labels.shape}")
    return D, labels


def _check_options(e_cutoff: int, recall_steps: int, min_class_size: int) -> None:
    for name, value, lo in (("e_cutoff", e_cutoff, 1), ("recall_steps", recall_steps, 1),
                            ("min_class_size", min_class_size, 1)):
        if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < lo:
            raise ValueError(f"{name} must be an integer >= {lo}, got {value!r}")


def _codes_and_mask(labels: np.ndarray, min_class_size: int, ignore_labels: Iterable[Hashable]
                    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Integer class codes (n,), class sizes (n,), the evaluated mask (n,), the unique labels."""
    uniq, codes = np.unique(labels, return_inverse=True)
    codes = codes.reshape(-1).astype(np.int64)
    sizes = np.bincount(codes)
    class_size = sizes[codes]
    ignore = set(ignore_labels)
    ignored = np.fromiter((x in ignore for x in labels.tolist()), dtype=bool, count=labels.shape[0])
    evaluated = (class_size >= min_class_size) & ~ignored
    return codes, class_size, evaluated, uniq


# --------------------------------------------------------------------------- ranking


def _row_blocks(n: int) -> Iterable[np.ndarray]:
    step = max(1, _BLOCK_ENTRIES // max(n, 1))
    for start in range(0, n, step):
        yield np.arange(start, min(n, start + step))


def _rank_rows(D: np.ndarray, rows: np.ndarray) -> np.ndarray:
    """Ranked lists (len(rows), n - 1) of the given query rows: self removed, stable by index."""
    n = D.shape[0]
    cols = np.arange(n - 1)
    # the list of the other items of query i, in index order: j for j < i, j + 1 for j >= i
    others = cols[None, :] + (cols[None, :] >= rows[:, None])
    vals = np.take_along_axis(D[rows], others, axis=1)
    order = np.argsort(vals, axis=1, kind="stable")
    return np.take_along_axis(others, order, axis=1)


def ranked_lists(D: np.ndarray, *, psb_float32: bool = False) -> np.ndarray:
    """The ranked list of every query, the query removed, ties broken by index.

    Parameters
    ----------
    D : (n, n) array of real numbers
        Dissimilarities; row ``i`` ranks the items for query ``i``. No NaN.
    psb_float32 : bool
        Round ``D`` to float32 first (as psbTable reads it).

    Returns
    -------
    (n, n - 1) int64
        ``out[i]`` lists the items ``j != i`` by increasing ``D[i, j]``, equal values in
        increasing ``j``.
    """
    D = _check_matrix(D)
    if psb_float32:
        D = D.astype(np.float32)
    out = np.empty((D.shape[0], D.shape[0] - 1), dtype=np.int64)
    for rows in _row_blocks(D.shape[0]):
        out[rows] = _rank_rows(D, rows)
    return out


# --------------------------------------------------------------------------- metrics


def _dcg_weights(N: int) -> np.ndarray:
    """psbTable's discount of rank r (1-based): 1 for r = 1, 1 / log2(r) for r >= 2; (N,)."""
    w = np.ones(N)
    if N > 1:
        w[1:] = 1.0 / np.log2(np.arange(2, N + 1))
    return w


def _block_metrics(G: np.ndarray, R: np.ndarray, e_cutoff: int, recall_steps: int,
                   w: np.ndarray, ideal_cum: np.ndarray) -> dict[str, np.ndarray]:
    """Per-query metrics of a block of relevance rows ``G`` (b, N) with ``R`` (b,) relevant each."""
    b, N = G.shape
    ar = np.arange(b)
    has = R > 0
    Rs = np.maximum(R, 1)
    cum = np.cumsum(G, axis=1, dtype=np.int64)
    nn = G[:, 0].astype(np.float64)
    ft = np.where(has, cum[ar, Rs - 1] / Rs, 0.0)
    t2 = np.minimum(2 * Rs, N)
    st = np.where(has, cum[ar, t2 - 1] / Rs, 0.0)
    K = min(e_cutoff, N)
    h = cum[:, K - 1]
    e = np.where(has & (h > 0), 2.0 * h / (K + Rs), 0.0)
    dcg = np.where(has, (G @ w) / ideal_cum[np.minimum(Rs, N) - 1], 0.0)
    ranks = np.arange(1, N + 1)
    prec = cum / ranks
    ap = np.where(has, np.where(G, prec, 0.0).sum(axis=1) / Rs, 0.0)
    # interpolated precision: running max of the precision from the end of the list
    pmax = np.maximum.accumulate(prec[:, ::-1], axis=1)[:, ::-1]
    j = np.arange(recall_steps + 1)
    # hits needed for level j: ceil(j R / steps), in integers; the level is reached at the rank of that hit
    need = np.where(has[:, None], (j[None, :] * R[:, None] + recall_steps - 1) // recall_steps, 0)  # (b, L)
    _, hit_pos = np.nonzero(G)  # row-major: the ranks (0-based) of the relevant items of each row, in order
    pos = np.zeros(need.shape, dtype=np.int64)  # need = 0 (recall 0): the best precision of the whole list
    if hit_pos.size:
        start = np.concatenate(([0], np.cumsum(G.sum(axis=1))[:-1]))  # each row's first entry in hit_pos
        idx = np.minimum(start[:, None] + need - 1, hit_pos.size - 1)
        pos = np.where(need > 0, hit_pos[np.maximum(idx, 0)], 0)
    pr = np.where(has[:, None], pmax[ar[:, None], pos], 0.0)
    return {"nn": nn, "first_tier": ft, "second_tier": st, "e_measure": e, "dcg": dcg, "map": ap, "pr": pr}


def _averages(per_query: dict[str, np.ndarray], codes: np.ndarray, evaluated: np.ndarray
              ) -> tuple[dict[str, Any], dict[str, Any], dict[int, dict[str, Any]]]:
    """Micro (over evaluated queries) and macro (over evaluated classes of class means) averages."""
    classes = np.unique(codes[evaluated])
    micro: dict[str, Any] = {}
    macro: dict[str, Any] = {}
    per_class: dict[int, dict[str, Any]] = {int(c): {} for c in classes}
    for name, values in per_query.items():
        ev = values[evaluated]
        micro[name] = ev.mean(axis=0) if ev.shape[0] else np.full(values.shape[1:], np.nan)
        means = [values[codes == c].mean(axis=0) for c in classes]
        for c, m in zip(classes, means):
            per_class[int(c)][name] = m
        macro[name] = np.mean(means, axis=0) if means else np.full(values.shape[1:], np.nan)
    return micro, macro, per_class


def retrieval_metrics(
    D: np.ndarray,
    labels: Any,
    *,
    e_cutoff: int = PSB_E_CUTOFF,
    recall_steps: int = 20,
    min_class_size: int = PSB_CUTOFF + 1,
    ignore_labels: Iterable[Hashable] = (),
    psb_float32: bool = False,
) -> RetrievalMetrics:
    """NN, first tier, second tier, E-measure, DCG, mAP and the interpolated PR curve of ``D``.

    Definitions, tie-breaking and averaging are those of psbTable (module docstring).

    Parameters
    ----------
    D : (n, n) array of real numbers
        Full dissimilarity matrix; row ``i`` ranks the collection for query ``i`` (the
        diagonal is ignored). No NaN; ``inf`` allowed.
    labels : (n,) array
        Class label of each item (any comparable type: ints, strings).
    e_cutoff : int
        Length of the list prefix for the E-measure (psbTable: 32).
    recall_steps : int
        The precision-recall curve is sampled at ``j / recall_steps``, ``j = 0..recall_steps``
        (default 20: 0, 0.05, ..., 1).
    min_class_size : int
        Classes smaller than this take no part in the averages (psbTable: 3, i.e. classes
        of at most 2 models are skipped).
    ignore_labels : iterable
        Labels whose items are not evaluated as queries (e.g. the PSB miscellaneous class);
        they stay in the ranked lists of the other queries.
    psb_float32 : bool
        Round ``D`` to float32 before ranking, as psbTable reads it (identical tie-breaking).

    Returns
    -------
    RetrievalMetrics

    Raises
    ------
    ValueError
        ``D`` not square or smaller than 2 x 2, NaN in ``D``, ``labels`` of the wrong shape,
        an option out of range.
    """
    D, labels = _check_inputs(D, labels)
    _check_options(e_cutoff, recall_steps, min_class_size)
    if psb_float32:
        D = D.astype(np.float32)
    n = D.shape[0]
    N = n - 1
    codes, class_size, evaluated, uniq = _codes_and_mask(labels, min_class_size, ignore_labels)
    w = _dcg_weights(N)
    ideal_cum = np.cumsum(w)
    names = METRIC_NAMES + ("pr",)
    out = {k: np.empty(n) for k in METRIC_NAMES}
    out["pr"] = np.empty((n, recall_steps + 1))
    for rows in _row_blocks(n):
        ranked = _rank_rows(D, rows)
        G = codes[ranked] == codes[rows][:, None]
        block = _block_metrics(G, class_size[rows] - 1, e_cutoff, recall_steps, w, ideal_cum)
        for k in names:
            out[k][rows] = block[k]
    micro, macro, per_class_codes = _averages(out, codes, evaluated)
    sizes = np.bincount(codes)
    per_class = {}
    for c, vals in per_class_codes.items():
        label = uniq[c].item() if hasattr(uniq[c], "item") else uniq[c]
        entry = {k: float(vals[k]) for k in METRIC_NAMES}
        entry["size"] = int(sizes[c])
        per_class[label] = entry
    return RetrievalMetrics(
        labels=labels,
        class_size=class_size,
        evaluated=evaluated,
        nn=out["nn"],
        first_tier=out["first_tier"],
        second_tier=out["second_tier"],
        e_measure=out["e_measure"],
        dcg=out["dcg"],
        average_precision=out["map"],
        recall_levels=np.arange(recall_steps + 1) / recall_steps,
        precision_at_recall=out["pr"],
        micro={k: float(micro[k]) for k in METRIC_NAMES},
        macro={k: float(macro[k]) for k in METRIC_NAMES},
        micro_pr=np.asarray(micro["pr"], dtype=np.float64),
        macro_pr=np.asarray(macro["pr"], dtype=np.float64),
        per_class=per_class,
        e_cutoff=int(min(e_cutoff, N)),
    )


def precision_recall(
    D: np.ndarray,
    labels: Any,
    *,
    recall_steps: int = 20,
    average: Literal["micro", "macro"] = "micro",
    min_class_size: int = PSB_CUTOFF + 1,
    ignore_labels: Iterable[Hashable] = (),
    psb_float32: bool = False,
) -> PrecisionRecall:
    """The averaged interpolated precision-recall curve of ``D``.

    ``P_interp(rho) = max {precision at rank k : recall at rank k >= rho}`` per query, at
    ``rho = j / recall_steps`` (default 0, 0.05, ..., 1), averaged over the queries (``'micro'``)
    or over the classes of the class means (``'macro'``). Other parameters as in
    :func:`retrieval_metrics`.

    Returns
    -------
    PrecisionRecall
        ``(recall, precision)``, both (recall_steps + 1,) float64; unpacks as a tuple.
    """
    if average not in ("micro", "macro"):
        raise ValueError(f"average must be 'micro' or 'macro', got {average!r}")
    m = retrieval_metrics(D, labels, recall_steps=recall_steps, min_class_size=min_class_size,
                          ignore_labels=ignore_labels, psb_float32=psb_float32)
    return m.precision_recall(average)


def chance_levels(
    labels: Any,
    *,
    e_cutoff: int = PSB_E_CUTOFF,
    min_class_size: int = PSB_CUTOFF + 1,
    ignore_labels: Iterable[Hashable] = (),
) -> dict[str, dict[str, float]]:
    """Exact expected metrics when every ranked list is a uniformly random permutation.

    For a query with ``R`` relevant items among ``N = n - 1``: NN = FT = ``R / N``;
    ST = ``min(2R, N) / N``; E = ``2 K R / (N (K + R))`` with ``K = min(e_cutoff, N)``;
    DCG = ``(R / N) sum_{r<=N} w_r / sum_{r<=R} w_r`` (``w`` the DCG discounts);
    AP = ``H_N / N + (R - 1)(N - H_N) / (N (N - 1))`` (``H_N = sum_{r<=N} 1/r``); 0 when ``R = 0``.
    (E and the tiers are linear in the hit counts, so their expectations are exact; AP's follows
    from ``E[1/rank] = H_N / N`` and ``P(rank_j < rank_i | rank_i = k) = (k - 1) / (N - 1)``.)

    Returns
    -------
    dict
        ``{'micro': {name: value}, 'macro': {name: value}}`` averaged like
        :func:`retrieval_metrics` (names of :data:`METRIC_NAMES`).
    """
    labels = np.asarray(labels)
    if labels.ndim != 1 or labels.shape[0] < 2:
        raise ValueError(f"labels must have shape (n,) with n >= 2, got {labels.shape}")
    _check_options(e_cutoff, 1, min_class_size)
    codes, class_size, evaluated, _ = _codes_and_mask(labels, min_class_size, ignore_labels)
    N = labels.shape[0] - 1
    R = (class_size - 1).astype(np.float64)
    has = R > 0
    w = _dcg_weights(N)
    ideal = np.cumsum(w)[np.maximum(R.astype(np.int64), 1) - 1]
    K = min(e_cutoff, N)
    H = float(np.sum(1.0 / np.arange(1, N + 1)))
    ap = H / N + ((R - 1) * (N - H) / (N * (N - 1)) if N > 1 else 0.0)
    per_query = {
        "nn": R / N,
        "first_tier": R / N,
        "second_tier": np.where(has, np.minimum(2 * R, N) / N, 0.0),
        "e_measure": 2.0 * K * R / (N * (K + R)),
        "dcg": np.where(has, (R / N) * w.sum() / ideal, 0.0),
        "map": np.where(has, ap, 0.0),
    }
    micro, macro, _ = _averages(per_query, codes, evaluated)
    return {"micro": {k: float(v) for k, v in micro.items()}, "macro": {k: float(v) for k, v in macro.items()}}
