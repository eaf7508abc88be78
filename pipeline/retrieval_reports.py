"""Retrieval benchmark report: several descriptor methods of the same run compared on labelled meshes.

For every method (a stage label whose result carries a ``descriptor``) it computes the full
dissimilarity matrix, the PSB metrics (:mod:`stages.retrieval.metrics`), and writes:

- ``<name>_metrics``: micro and macro NN, FT, ST, E, DCG, mAP per method (table);
- ``<name>_pr``: interpolated precision-recall curves of all methods (thesis Figs. 3.13 / 4.10);
- ``<name>_7x7_<method>``: dissimilarities between the first model (rows) and the second model
  (columns) of seven classes, with the smallest value per row marked: a correct match is a star on
  the diagonal (thesis Tables 3.1 / 4.1);
- ``<name>_top10_<method>``: rendered thumbnails of the top-10 results of a few queries
  (thesis Tables 3.2 / 4.2).
"""

from __future__ import annotations

import csv
from pathlib import Path

import numpy as np
from pydantic import Field

from pipeline.errors import ConfigError
from pipeline.params import Params
from pipeline.paths import resolve_input
from pipeline.reports import ReportOutput, report


class RetrievalBenchmarkParams(Params):
    name: str = Field("retrieval", pattern=r"^[A-Za-z0-9_.-]+$", description="prefix of the output files")
    methods: dict[str, str] = Field(description="method name -> stage label holding its descriptor, e.g. "
                                                "{rgpd: endpoint_descriptor, d2: d2}")
    labels: str = Field(description="CSV with relative_path and class columns (path template)")
    unmatched_cost: float = Field(0.2, ge=0, description="endpoint methods: cost per unmatched endpoint")
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
    with open(path, newline="", encoding="utf-8") as fh:
        rows = list(csv.DictReader(fh))
    key = "relative_path" if rows and "relative_path" in rows[0] else "path"
    col = "class" if rows and "class" in rows[0] else "label"
    return {str((path.parent / r[key]).resolve()): r[col] for r in rows}


@report("retrieval_benchmark", params=RetrievalBenchmarkParams)
def retrieval_benchmark_report(experiment, results, params: RetrievalBenchmarkParams) -> ReportOutput:
    """PSB metrics, precision-recall curves, a 7x7 dissimilarity table and top-10 grids per method."""
    import matplotlib.pyplot as plt

    from stages.retrieval.descriptor import MatchOptions
    from stages.retrieval.metrics import retrieval_metrics
    from stages.retrieval.ranking import VECTOR_METHODS, dissimilarity_matrix

    labels = _labels(experiment, params.labels)
    items = [r for r in results if r.ok and str(Path(r.input_path).resolve()) in labels]
    if len(items) < 2:
        raise ConfigError(f"retrieval_benchmark: fewer than two labelled items (labels: {params.labels})")
    y = np.array([labels[str(Path(r.input_path).resolve())] for r in items])
    options = MatchOptions(correspondence=params.correspondence, unmatched_cost=params.unmatched_cost)
    out = ReportOutput()
    metric_rows, curves = [], {}
    first_of = {c: int(np.flatnonzero(y == c)[0]) for c in dict.fromkeys(y)}
    second_of = {c: int(np.flatnonzero(y == c)[1]) for c in dict.fromkeys(y) if (y == c).sum() > 1}
    for method, label in params.methods.items():
        kept = [i for i, r in enumerate(items) if label in r.results]
        descriptors = [items[i].results[label].descriptor for i in kept]
        kind = method if method in VECTOR_METHODS else "srg"  # endpoint descriptors share one comparison
        D = dissimilarity_matrix(descriptors, kind, options)
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
    fig, ax = plt.subplots(figsize=(5.5, 4.5))
    for method, (recall, precision) in curves.items():
        ax.plot(recall, precision, marker="o", markersize=3, label=method)
    ax.set_xlabel("recall")
    ax.set_ylabel("precision (interpolated, micro-averaged)")
    ax.set_xlim(0, 1)
    ax.set_ylim(0, 1.02)
    ax.grid(alpha=0.3)
    ax.legend()
    ax.set_title(f"Precision-recall, {len(items)} labelled meshes", fontsize=9)
    fig.tight_layout()
    out.figures[f"{params.name}_pr"] = fig
    return out


def _top10_grid(items, y, D, kept, where, queries, method):
    import matplotlib.pyplot as plt

    from pipeline.render import draw_mesh

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
