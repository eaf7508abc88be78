"""Retrieval benchmark report: several descriptor methods of the same run compared on labelled meshes.

For every method (a stage label whose result carries a ``descriptor``) and every fusion of
methods (:mod:`topomatch.stages.retrieval.fusion`) it computes the full dissimilarity matrix, the PSB
metrics (:mod:`topomatch.stages.retrieval.metrics`), and writes:

- ``<name>_metrics``: micro and macro NN, FT, ST, E, DCG, mAP per method (table);
- ``<name>_pr``: interpolated precision-recall curves of all methods (thesis Figs. 3.13 / 4.10);
- ``<name>_7x7_<method>``: dissimilarities between the first model (rows) and the second model
  (columns) of seven classes, with the smallest value per row marked: a correct match is a star on
  the diagonal (thesis Tables 3.1 / 4.1);
- ``<name>_top10_<method>``: rendered thumbnails of the top-10 results of a few queries
  (thesis Tables 3.2 / 4.2);
- ``<name>_ablation``: each fusion without re-ranking and without each of its parts.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
from pydantic import Field

from topomatch.pipeline.errors import ConfigError
from topomatch.pipeline.params import Params
from topomatch.pipeline.paths import resolve_input
from topomatch.pipeline.reports import ReportOutput, report
from topomatch.pipeline.shape_index import read_labels


class RetrievalBenchmarkParams(Params):
    name: str = Field("retrieval", pattern=r"^[A-Za-z0-9_.-]+$", description="prefix of the output files")
    methods: dict[str, str] = Field(description="method name -> stage label holding its descriptor, e.g. "
                                                "{rgpd: endpoint_descriptor, d2: d2}")
    labels: str = Field(description="CSV with relative_path and class columns (path template)")
    fusions: dict[str, list[str]] = Field(default_factory=dict, description="fused method name -> the methods "
                                          "it sums (names from 'methods'), e.g. {topomatch: [agd, hks, d2]}")
    rerank_k: int | None = Field(10, ge=1, description="fusions: neighbours of the manifold-ranking graph; "
                                                       "none = no re-ranking")
    rerank_alpha: float = Field(0.9, gt=0, lt=1, description="fusions: manifold-ranking diffusion weight")
    unmatched_cost: float | None = Field(None, ge=0, description="endpoint methods: cost per unmatched endpoint "
                                                                 "(none: the method's default, UNMATCHED_COST)")
    correspondence: str = Field("greedy", pattern="^(greedy|greedy_sequential|optimal)$")
    table_classes: list[str] = Field(default_factory=lambda: ["human", "glasses", "ant", "octopus", "teddy", "hand",
                                                              "plier"],
                                     description="classes of the 7x7 table (one model each: the first)")
    queries: list[str] = Field(default_factory=lambda: ["human", "hand", "octopus", "plier"],
                               description="classes whose first model is a top-10 query")
    thumbnails: bool = Field(True, description="render the top-10 grids (slow: about 1 s per thumbnail)")


def _labels(experiment, template: str) -> dict[str, str]:
    base = experiment.source.parent if experiment.source else Path.cwd()
    (path,) = resolve_input(template, base_dir=base, root=experiment.data_root, where="reports.retrieval.labels")[:1]
    return read_labels(path)


@report("retrieval_benchmark", params=RetrievalBenchmarkParams)
def retrieval_benchmark_report(experiment, results, params: RetrievalBenchmarkParams) -> ReportOutput:
    """PSB metrics, precision-recall curves, a 7x7 dissimilarity table and top-10 grids per method."""
    import matplotlib.pyplot as plt

    from topomatch.stages.retrieval.fusion import Fusion, fused_matrix
    from topomatch.stages.retrieval.metrics import retrieval_metrics

    labels = _labels(experiment, params.labels)
    items = [r for r in results if r.ok and str(Path(r.input_path).resolve()) in labels]
    if len(items) < 2:
        raise ConfigError(f"retrieval_benchmark: fewer than two labelled items (labels: {params.labels})")
    y = np.array([labels[str(Path(r.input_path).resolve())] for r in items])
    matrices = {method: _method_matrix(items, method, label, params) for method, label in params.methods.items()}
    for name, parts in params.fusions.items():
        unknown = [p for p in parts if p not in matrices]
        if unknown:
            raise ConfigError(f"retrieval_benchmark.fusions.{name}: {', '.join(unknown)} not in methods")
    out = ReportOutput()
    ablation = []
    for name, parts in params.fusions.items():
        kept = sorted(set.intersection(*(set(matrices[p][0]) for p in parts)))
        variants = {name: (parts, params.rerank_k), f"{name} (no re-ranking)": (parts, None)}
        if len(parts) > 1:
            variants.update({f"{name} without {p}": ([q for q in parts if q != p], params.rerank_k) for p in parts})
        for variant, (use, k) in variants.items():
            D = fused_matrix([_restrict(matrices[p], kept) for p in use], Fusion(tuple(use), k, params.rerank_alpha))
            if variant == name:
                matrices[name] = (kept, D)
            m = retrieval_metrics(D, y[kept]).micro
            ablation.append({"fusion": variant, "parts": "+".join(use), "re-ranking": k is not None,
                             **{key: round(float(v), 4) for key, v in m.items()}})
    metric_rows, curves = [], {}
    first_of = {c: int(np.flatnonzero(y == c)[0]) for c in dict.fromkeys(y)}
    second_of = {c: int(np.flatnonzero(y == c)[1]) for c in dict.fromkeys(y) if (y == c).sum() > 1}
    for method, (kept, D) in matrices.items():
        m = retrieval_metrics(D, y[kept])
        for avg, values in (("micro", m.micro), ("macro", m.macro)):
            metric_rows.append({"method": method, "average": avg, "n": len(kept),
                                **{k: round(float(v), 4) for k, v in values.items()}})
        curves[method] = m.precision_recall("micro")
        where = {i: k for k, i in enumerate(kept)}
        # rows: the first model of each class; columns: the second, so the diagonal compares two
        # different models of one class (the correct match should be the row minimum)
        rows_i = [first_of[c] for c in params.table_classes if c in second_of and first_of[c] in where]
        cols_i = [second_of[c] for c in params.table_classes if c in second_of and second_of[c] in where]
        table = []
        for i in rows_i:
            row = {"query": f"{y[i]} {Path(items[i].input_path).name.split('.')[0]}"}
            values = [D[where[i], where[j]] for j in cols_i]
            best = int(np.argmin(values))
            for k, j in enumerate(cols_i):
                row[f"{y[j]} {Path(items[j].input_path).name.split('.')[0]}"] = f"{values[k]:.4f}" + (" *" if k == best else "")
            table.append(row)
        out.tables[f"{params.name}_7x7_{method}"] = table
        if params.thumbnails:
            queries = [first_of[c] for c in params.queries if c in first_of and first_of[c] in where]
            out.figures[f"{params.name}_top10_{method}"] = _top10_grid(items, y, D, kept, where, queries, method)
    out.tables[f"{params.name}_metrics"] = metric_rows
    if ablation:
        out.tables[f"{params.name}_ablation"] = ablation
    fig, ax = plt.subplots(figsize=(5.5, 4.5))
    for method, (recall, precision) in curves.items():
        ax.plot(recall, precision, marker="o", markersize=3, label=method)
    ax.set_xlabel("recall")
    ax.set_ylabel("precision (interpolated, micro-averaged)")
    ax.set_xlim(0, 1)
    ax.set_ylim(0, 1.02)
    ax.grid(alpha=0.3)
    ax.legend(loc="lower left", fontsize=8)
    ax.set_title(f"Precision-recall, {len(items)} labelled meshes", fontsize=9)
    fig.tight_layout()
    out.figures[f"{params.name}_pr"] = fig
    return out


def _method_matrix(items, method: str, label: str, params) -> tuple[list[int], np.ndarray]:
    """Indices of the items that have ``label``'s descriptor, and their full dissimilarity matrix."""
    from topomatch.stages.retrieval.ranking import dissimilarity_matrix

    kept = [i for i, r in enumerate(items) if label in r.results]
    descriptors = [items[i].results[label].descriptor for i in kept]
    return kept, dissimilarity_matrix(descriptors, _comparison(method), _match_options(method, params))


def _comparison(method: str) -> str:
    """How a report method's descriptors compare: its own vector metric, or endpoint matching."""
    from topomatch.stages.retrieval.ranking import VECTOR_METHODS

    return method if method in VECTOR_METHODS else "srg"  # endpoint descriptors share one comparison


def _match_options(method: str, params):
    """Endpoint matching options of a report method (the params' unmatched cost, else the method's default)."""
    from topomatch.stages.retrieval.methods import default_match_options

    cost = {} if params.unmatched_cost is None else {"unmatched_cost": params.unmatched_cost}
    return default_match_options(method, correspondence=params.correspondence, **cost)


def _restrict(matrix: tuple[list[int], np.ndarray], kept: list[int]) -> np.ndarray:
    """The rows and columns of ``kept`` items from a (method indices, matrix) pair."""
    where = {i: k for k, i in enumerate(matrix[0])}
    idx = np.array([where[i] for i in kept], dtype=np.int64)
    return matrix[1][np.ix_(idx, idx)]


def _top10_grid(items, y, D, kept, where, queries, method):
    import matplotlib.pyplot as plt

    from topomatch.pipeline.render import draw_mesh

    fig = plt.figure(figsize=(11 * 1.3, len(queries) * 1.5))
    for row, q in enumerate(queries):
        d = D[where[q]].copy()
        order = [kept[k] for k in np.argsort(d, kind="stable") if kept[k] != q][:10]
        for col, i in enumerate([q] + order):
            ax = fig.add_subplot(len(queries), 11, row * 11 + col + 1, projection="3d")
            mesh = items[i].final("mesh")
            hit = y[i] == y[q]
            draw_mesh(ax, mesh, color=(0.55, 0.6, 0.75) if col == 0 else ((0.6, 0.8, 0.6) if hit else (0.85, 0.55, 0.55)))
            ax.set_title(("query: " if col == 0 else f"{col}. ") + str(y[i]), fontsize=6,
                         color="black" if col == 0 or hit else "#b00")
    fig.suptitle(f"Top-10 retrieval ({method}); green: same class, red: other class", fontsize=9)
    fig.subplots_adjust(left=0, right=1, bottom=0, top=0.9, wspace=0, hspace=0.25)
    return fig


class RetrievalRobustnessParams(Params):
    name: str = Field("robustness", pattern=r"^[A-Za-z0-9_.-]+$", description="prefix of the output files")
    methods: dict[str, str] = Field(description="method name -> stage label holding its descriptor")
    fusions: dict[str, list[str]] = Field(default_factory=dict, description="fused method -> its methods")
    rerank_k: int | None = Field(10, ge=1, description="fusions: manifold-ranking neighbours; none = no re-ranking")
    rerank_alpha: float = Field(0.9, gt=0, lt=1, description="fusions: manifold-ranking diffusion weight")
    labels: str = Field(description="CSV with relative_path and class columns (path template)")
    unmatched_cost: float | None = Field(None, ge=0, description="endpoint methods: cost per unmatched endpoint "
                                                                 "(none: the method's default)")
    correspondence: str = Field("greedy", pattern="^(greedy|greedy_sequential|optimal)$")


@report("retrieval_robustness", params=RetrievalRobustnessParams)
def retrieval_robustness_report(experiment, results, params: RetrievalRobustnessParams) -> ReportOutput:
    """Perturbed queries (every sweep point but the first) searched against the clean index (the first point).

    For each sweep point and method: ``self@1``, the fraction of queries whose own clean original
    ranks first, and the PSB metrics of the ranking with the original removed (so a perturbed
    query must still find the other members of its class). The first sweep point is the clean
    index, evaluated leave-one-out.
    """
    import matplotlib.pyplot as plt

    from topomatch.stages.retrieval.fusion import Fusion, fused_query
    from topomatch.stages.retrieval.metrics import retrieval_metrics
    from topomatch.stages.retrieval.ranking import dissimilarities

    labels = _labels(experiment, params.labels)
    points = experiment.sweep_points()
    by_point: dict[str, dict[str, object]] = {}
    for r in results:
        if r.ok and str(Path(r.input_path).resolve()) in labels:
            by_point.setdefault(_point_name(r.sweep), {})[r.input_path] = r
    clean = by_point.get(_point_name(points[0]), {})
    db_paths = sorted(clean)
    if len(db_paths) < 2:
        raise ConfigError("retrieval_robustness: fewer than two labelled clean items (the first sweep point)")
    db_items = [clean[p] for p in db_paths]
    position = {p: i for i, p in enumerate(db_paths)}
    matrices = {m: _method_matrix(db_items, m, label, params) for m, label in params.methods.items()}
    if any(len(kept) != len(db_items) for kept, _ in matrices.values()):
        raise ConfigError("retrieval_robustness: every clean item needs every method's descriptor")
    fusions = {name: Fusion(tuple(parts), params.rerank_k, params.rerank_alpha) for name, parts in params.fusions.items()}
    rows = []
    for point in points:
        found = by_point.get(_point_name(point), {})
        paths = [p for p in db_paths if p in found and all(label in found[p].results
                                                           for label in params.methods.values())]
        idx = np.array([position[p] for p in paths], dtype=np.int64)
        y = np.array([labels[str(Path(p).resolve())] for p in paths])
        single = {}
        for method, label in params.methods.items():
            options = _match_options(method, params)
            database = [db_items[i].results[label].descriptor for i in idx]
            kind = _comparison(method)
            single[method] = np.stack([dissimilarities(found[p].results[label].descriptor, database, kind, options)
                                       for p in paths])
        for name, fusion in fusions.items():
            mats = [matrices[m][1][np.ix_(idx, idx)] for m in fusion.parts]
            single[name] = np.stack([fused_query([single[m][q] for m in fusion.parts], mats, fusion)
                                     for q in range(len(paths))])
        for method, Q in single.items():
            m = retrieval_metrics(Q, y).micro  # the diagonal, the query's own original, is left out
            self_first = float(np.mean(np.diag(Q) <= Q.min(axis=1)))
            rows.append({"perturbation": "clean (leave-one-out)" if point == points[0] else
                         _point_name({k: v for k, v in point.items() if v != points[0][k]}), "method": method, "n": len(paths),
                         "self@1": round(self_first, 4), **{k: round(float(v), 4) for k, v in m.items()}})
    out = ReportOutput()
    out.tables[f"{params.name}_metrics"] = rows
    methods = list(dict.fromkeys(r["method"] for r in rows))
    names = list(dict.fromkeys(r["perturbation"] for r in rows))
    fig, axes = plt.subplots(1, 2, figsize=(10, 3.8))
    for ax, metric in zip(axes, ("map", "self@1")):
        width = 0.8 / len(methods)
        for k, method in enumerate(methods):
            values = [next(r[metric] for r in rows if r["method"] == method and r["perturbation"] == p) for p in names]
            ax.bar(np.arange(len(names)) + k * width, values, width, label=method)
        ax.set_xticks(np.arange(len(names)) + 0.4 - width / 2, names, rotation=20, ha="right", fontsize=7)
        ax.set_ylim(0, 1.05)
        ax.set_title({"map": "mAP, perturbed query vs clean index (own original removed)",
                      "self@1": "own clean original ranked first"}[metric], fontsize=8)
        ax.grid(axis="y", alpha=0.3)
    handles, names_ = axes[0].get_legend_handles_labels()
    fig.legend(handles, names_, loc="upper center", ncol=len(methods), fontsize=7, frameon=False)
    fig.tight_layout(rect=(0, 0, 1, 0.92))
    out.figures[f"{params.name}_metrics"] = fig
    return out


def _point_name(point: dict) -> str:
    return ",".join(f"{k}={v}" for k, v in point.items())
