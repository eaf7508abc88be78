"""Retrieval benchmark report: several descriptor methods of the same run compared on labelled meshes.

For every method (a catalogue method, :mod:`topomatch.stages.retrieval.catalogue`, whose descriptor
a stage label of the chain holds) and every fusion of the catalogue whose parts are all there
(:mod:`topomatch.stages.retrieval.fusion`) it computes the full dissimilarity matrix, the PSB
metrics (:mod:`topomatch.stages.retrieval.metrics`), and writes:

- ``<name>_metrics``: micro and macro NN, FT, ST, E, DCG, mAP per method (table);
- ``<name>_pr``: interpolated precision-recall curves of all methods (thesis Figs. 3.13 / 4.10);
- ``<name>_7x7_<method>``: dissimilarities between the first model (rows) and the second model
  (columns) of seven classes, with the smallest value per row marked: a correct match is a star on
  the diagonal (thesis Tables 3.1 / 4.1);
- ``<name>_top<k>_<method>``: rendered thumbnails of the top-k results of a few queries
  (thesis Tables 3.2 / 4.2: k = 10; 3.3 / 4.3: k = 5);
- ``<name>_samples``: the first models of every class (thesis Fig. 3.12);
- ``<name>_ablation``: each fusion without re-ranking and without each of its parts.
"""

from __future__ import annotations

from dataclasses import replace
from functools import partial
from pathlib import Path

from typing import Annotated, Literal

import numpy as np
from pydantic import Field, field_validator

from topomatch.pipeline.contract import ConfigError, Params, ReportOutput, report
from topomatch.stages.retrieval.catalogue import DEFAULT_METHOD, METHODS, Method, get_method
from topomatch.stages.retrieval.fusion import Fusion
from topomatch.stages.retrieval.labels import read_labels

#: Faces of a rendered thumbnail (1.3 inches across): meshes with more are drawn decimated.
THUMBNAIL_FACES = 1500


class MethodsParams(Params):
    """Which methods a retrieval report compares (shared by the benchmark and the robustness reports)."""

    methods: dict[str, str] = Field(description="catalogue method -> stage label holding its descriptor, e.g. "
                                                "{rgpd: endpoint_descriptor, d2: d2}")
    fusions: list[str] = Field(default_factory=list, description="catalogue fusions to rank too (their parts must "
                                                                 "be in methods), e.g. [topomatch]")
    extra_fusions: dict[str, list[str]] = Field(default_factory=dict, description="ad-hoc fusions for experiments: "
                                                "name -> methods (re-ranked like the default fusion)")
    rerank_k: Annotated[int, Field(ge=1)] | Literal["auto"] | None = Field(None, description="fusions: neighbours of the manifold-ranking "
                                                   "graph, or auto (round(sqrt(n) / 2)); none: the fusion's own")
    rerank_alpha: float | None = Field(None, gt=0, lt=1, description="fusions: manifold-ranking diffusion weight "
                                                                     "(none: the fusion's own)")
    labels: str = Field(description="CSV with relative_path and class columns (path template)")
    unmatched_cost: float | None = Field(None, ge=0, allow_inf_nan=False,
                                         description="endpoint methods: cost per unmatched endpoint (none: each "
                                                     "method's own)")
    correspondence: Literal["greedy", "greedy_sequential", "optimal"] | None = Field(
        None, description="endpoint methods: correspondence (none: each method's own)")

    @field_validator("methods")
    @classmethod
    def _known_methods(cls, value: dict[str, str]) -> dict[str, str]:
        for name in value:
            if name not in METHODS or METHODS[name].kind == "fusion":
                raise ValueError(f"{name!r} is not a method of the catalogue (methods: "
                                 f"{', '.join(m.name for m in METHODS.values() if m.kind != 'fusion')})")
        return value

    @field_validator("fusions")
    @classmethod
    def _known_fusions(cls, value: list[str]) -> list[str]:
        for name in value:
            if name not in METHODS or METHODS[name].kind != "fusion":
                raise ValueError(f"{name!r} is not a fusion of the catalogue (fusions: "
                                 f"{', '.join(m.name for m in METHODS.values() if m.kind == 'fusion')})")
        return value

    def method(self, name: str) -> Method:
        """The catalogue record of a method named in the report (ConfigError for an unknown one)."""
        return get_method(name)

    def all_fusions(self) -> dict[str, Fusion]:
        """The catalogue fusions and the ad-hoc ones, with this report's re-ranking overrides."""
        base = {name: get_method(name).fusion for name in self.fusions}
        default = get_method(DEFAULT_METHOD).fusion
        base.update({name: default.with_parts(parts) for name, parts in self.extra_fusions.items()})
        out = {}
        for name, f in base.items():
            missing = [p for p in f.parts if p not in self.methods]
            if missing:
                raise ConfigError(f"fusion {name}: its parts {', '.join(missing)} are not in methods")
            out[name] = replace(f, rerank_k=self.rerank_k if self.rerank_k is not None else f.rerank_k,
                                rerank_alpha=self.rerank_alpha if self.rerank_alpha is not None else f.rerank_alpha)
        return out


class RetrievalBenchmarkParams(MethodsParams):
    name: str = Field("retrieval", pattern=r"^[A-Za-z0-9_.-]+$", description="prefix of the output files")
    table_classes: list[str] = Field(default_factory=lambda: ["human", "glasses", "ant", "octopus", "teddy", "hand",
                                                              "plier"],
                                     description="classes of the 7x7 table (one model each: the first)")
    queries: list[str] = Field(default_factory=lambda: ["human", "hand", "octopus", "plier"],
                               description="classes whose first model is a top-10 query")
    thumbnails: bool = Field(True, description="render the top-k grids (slow: about 1 s per thumbnail)")
    thumbnail_methods: list[str] | None = Field(None, description="methods whose top-k grids are rendered (none: "
                                                                  "every method and fusion)")
    top_k: list[Annotated[int, Field(ge=1, le=20)]] = Field(default_factory=lambda: [10], description=(
        "lengths of the rendered rankings: one grid <name>_top<k>_<method> per k (thesis: 10 for McGill, 5 for "
        "Princeton)"))
    samples_per_class: Annotated[int, Field(ge=0, le=5)] = Field(0, description=(
        "render <name>_samples: the first n models of every class (thesis Fig. 3.12: two per class); 0: none"))


def _labels(experiment, template: str) -> dict[str, str]:
    return read_labels(experiment.resolve_path(template, where="labels"))


@report("retrieval_benchmark", params=RetrievalBenchmarkParams)
def retrieval_benchmark_report(experiment, results, params: RetrievalBenchmarkParams) -> ReportOutput:
    """PSB metrics, precision-recall curves, a 7x7 dissimilarity table and top-k grids per method."""
    import matplotlib.pyplot as plt

    from topomatch.stages.retrieval.fusion import fused_matrix
    from topomatch.stages.retrieval.metrics import retrieval_metrics

    fusions = params.all_fusions()
    unknown = [m for m in params.thumbnail_methods or [] if m not in params.methods and m not in fusions]
    if unknown:
        raise ConfigError(f"retrieval_benchmark: thumbnail_methods {', '.join(unknown)} are not among the report's "
                          f"methods and fusions ({', '.join([*params.methods, *fusions])})")
    labels = _labels(experiment, params.labels)
    items = [r for r in results if r.ok and str(Path(r.input_path).resolve()) in labels]
    if len(items) < 2:
        raise ConfigError(f"retrieval_benchmark: fewer than two labelled items (labels: {params.labels})")
    y = np.array([labels[str(Path(r.input_path).resolve())] for r in items])
    matrices = {method: _method_matrix(items, method, label, params) for method, label in params.methods.items()}
    out = ReportOutput()
    ablation = []
    for name, fusion in fusions.items():
        parts = list(fusion.parts)
        kept = sorted(set.intersection(*(set(matrices[p][0]) for p in parts)))
        variants = {name: (parts, fusion.rerank_k), f"{name} (no re-ranking)": (parts, None)}
        if len(parts) > 1:
            variants.update({f"{name} without {p}": ([q for q in parts if q != p], fusion.rerank_k) for p in parts})
        for variant, (use, k) in variants.items():
            D = fused_matrix([_restrict(matrices[p], kept) for p in use], fusion.with_parts(use, rerank_k=k))
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
        if params.thumbnails and (params.thumbnail_methods is None or method in params.thumbnail_methods):
            queries = [first_of[c] for c in params.queries if c in first_of and first_of[c] in where]
            for k in params.top_k:
                out.figures[f"{params.name}_top{k}_{method}"] = partial(_top_k_grid, items, y, D, kept, where, queries,
                                                                        method, k)  # drawn when written
    if params.thumbnails and params.samples_per_class:
        out.figures[f"{params.name}_samples"] = partial(_class_samples, items, y, params.samples_per_class)
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
    return kept, dissimilarity_matrix(descriptors, params.method(method), _match_options(method, params))


def _match_options(method: str, params: MethodsParams):
    """Endpoint matching options of a report method: the report's overrides, else the method's own."""
    return params.method(method).match_options(unmatched_cost=params.unmatched_cost,
                                               correspondence=params.correspondence)


def _restrict(matrix: tuple[list[int], np.ndarray], kept: list[int]) -> np.ndarray:
    """The rows and columns of ``kept`` items from a (method indices, matrix) pair."""
    where = {i: k for k, i in enumerate(matrix[0])}
    idx = np.array([where[i] for i in kept], dtype=np.int64)
    return matrix[1][np.ix_(idx, idx)]


def _top_k_grid(items, y, D, kept, where, queries, method, k):
    """One row per query: the query, then its ``k`` nearest other models; green the query's class, red not."""
    import matplotlib.pyplot as plt

    from topomatch.stages.mesh.render import draw_mesh

    fig = plt.figure(figsize=((k + 1) * 1.3, len(queries) * 1.5 + 0.75))
    for row, q in enumerate(queries):
        d = D[where[q]].copy()
        order = [kept[j] for j in np.argsort(d, kind="stable") if kept[j] != q][:k]
        for col, i in enumerate([q] + order):
            ax = fig.add_subplot(len(queries), k + 1, row * (k + 1) + col + 1, projection="3d")
            hit = y[i] == y[q]
            draw_mesh(ax, items[i].final("mesh"), max_faces=THUMBNAIL_FACES,
                      color=(0.55, 0.6, 0.75) if col == 0 else ((0.6, 0.8, 0.6) if hit else (0.85, 0.55, 0.55)))
            ax.set_title(("query: " if col == 0 else f"{col}. ") + str(y[i]), fontsize=6,
                         color="black" if col == 0 or hit else "#b00")
    _title_above(fig, f"Top-{k} retrieval ({method}); green: same class, red: other class")
    return fig


def _title_above(fig, title: str, header: float = 0.75) -> None:
    """The figure's title in a band of ``header`` inches above the panels and their titles (3D panels'
    titles sit well above their axes: a default suptitle runs into them)."""
    height = fig.get_figheight()
    fig.subplots_adjust(left=0, right=1, bottom=0, top=1 - header / height, wspace=0, hspace=0.25)
    fig.suptitle(title, fontsize=9, y=1 - 0.12 / height, va="top")


def _class_samples(items, y, n):
    """The first ``n`` models of every class, classes in order of first appearance, ``2 n`` per row."""
    import matplotlib.pyplot as plt

    from topomatch.stages.mesh.render import draw_mesh

    picks = [i for c in dict.fromkeys(y) for i in np.flatnonzero(y == c)[:n]]
    columns = 2 * n * 2
    rows = -(-len(picks) // columns)
    fig = plt.figure(figsize=(columns * 1.3, rows * 1.5 + 0.75))
    for k, i in enumerate(picks):
        ax = fig.add_subplot(rows, columns, k + 1, projection="3d")
        draw_mesh(ax, items[i].final("mesh"), color=(0.6, 0.65, 0.8), max_faces=THUMBNAIL_FACES)
        ax.set_title(f"{y[i]} {Path(items[i].input_path).name.split('.')[0]}", fontsize=6)
    _title_above(fig, f"{n} models of each of the {len(dict.fromkeys(y))} classes")
    return fig


class RetrievalRobustnessParams(MethodsParams):
    name: str = Field("robustness", pattern=r"^[A-Za-z0-9_.-]+$", description="prefix of the output files")


@report("retrieval_robustness", params=RetrievalRobustnessParams)
def retrieval_robustness_report(experiment, results, params: RetrievalRobustnessParams) -> ReportOutput:
    """Perturbed queries (every sweep point but the first) searched against the clean index (the first point).

    For each sweep point and method: ``self@1`` over all ``n`` queries, the fraction whose own clean original
    ranks first, and the PSB metrics of the ranking with the original removed (so a perturbed query must
    still find the other members of its class), averaged over the ``class_queries`` queries of classes PSB
    evaluates. The first sweep point ("clean") queries the index with its own items: its self@1 is 1 by
    construction (a check of the ranking), its class metrics are the index's leave-one-out retrieval.
    """
    import matplotlib.pyplot as plt

    from topomatch.stages.retrieval.fusion import decide, fused_query
    from topomatch.stages.retrieval.metrics import retrieval_metrics
    from topomatch.stages.retrieval.ranking import dissimilarities

    fusions = params.all_fusions()
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
            single[method] = np.stack([dissimilarities(found[p].results[label].descriptor, database, params.method(method),
                                                       options)
                                       for p in paths])
        for name, fusion in fusions.items():
            mats = [matrices[m][1][np.ix_(idx, idx)] for m in fusion.parts]
            decision = decide(mats, fusion, graph_size=len(paths) + 1)  # the same database for every query
            single[name] = np.stack([fused_query([single[m][q] for m in fusion.parts], mats, fusion, decision)
                                     for q in range(len(paths))])
        for method, Q in single.items():
            metrics = retrieval_metrics(Q, y)  # the diagonal, the query's own original, is left out
            self_first = float(np.mean(np.diag(Q) <= Q.min(axis=1)))
            rows.append({"perturbation": "clean" if point == points[0] else
                         _point_name({k: v for k, v in point.items() if v != points[0][k]}), "method": method,
                         "n": len(paths), "self@1": round(self_first, 4),
                         "class_queries": int(metrics.evaluated.sum()),
                         **{k: round(float(v), 4) for k, v in metrics.micro.items()}})
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
        ax.set_ylabel({"map": "mean average precision", "self@1": "fraction of queries"}[metric], fontsize=8)
        ax.set_title({"map": "mAP, perturbed query vs clean index (own original removed)",
                      "self@1": "own clean original ranked first"}[metric], fontsize=8)
        ax.grid(axis="y", alpha=0.3)
    handles, names_ = axes[0].get_legend_handles_labels()
    fig.legend(handles, names_, loc="upper center", ncol=len(methods), fontsize=7, frameon=False)
    fig.tight_layout(rect=(0, 0, 1, 0.92))
    out.figures[f"{params.name}_metrics"] = fig
    note = small_collection_note(np.array([labels[str(Path(p).resolve())] for p in db_paths]))
    if note:
        out.notes.append(note)
    return out


def small_collection_note(labels: np.ndarray, few: int = 10) -> str | None:
    """A caution for the run page when the class metrics rest on fewer than ``few`` queries (None otherwise).

    PSB metrics count a query only when its class has more than ``PSB_CUTOFF`` members, so on a small
    collection they average over a handful of queries and one query moves them by 1 / that number.
    """
    from topomatch.stages.retrieval.metrics import PSB_CUTOFF

    names, sizes = np.unique(labels, return_counts=True)
    counted = {str(c): int(n) for c, n in zip(names, sizes) if n > PSB_CUTOFF}
    q = sum(counted.values())
    if q >= few:
        return None
    classes = ", ".join(f"{c} ({n})" for c, n in counted.items()) or "none"
    return (f"Small collection: the class metrics (NN, tiers, E, DCG, mAP) average over only {q} queries, the "
            f"members of the classes with more than {PSB_CUTOFF} shapes ({classes}); one query moves them by "
            f"{1 / max(q, 1):.2f}, so no method can be told apart from another by them here. self@1 counts all "
            f"{len(labels)} shapes and is the measure of this run.")


def _point_name(point: dict) -> str:
    return ",".join(f"{k}={v}" for k, v in point.items())
