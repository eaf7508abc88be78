"""Reports on endpoint features (thesis §3.3, Figs. 3.4-3.6): a skeleton's endpoints, the shortest
paths between endpoints and from the root (centroid), and their features a, dv, dc."""

from __future__ import annotations

from pathlib import Path
import numpy as np
from pydantic import Field

from topomatch.pipeline.contract import ReportOutput, report
from topomatch.stages.reeb.reports import ItemRowsParams

#: Colours of the highlighted paths (one per endpoint, cycled).
PATH_COLOURS = ((0.12, 0.47, 0.71, 1), (1.0, 0.5, 0.05, 1), (0.17, 0.63, 0.17, 1), (0.58, 0.4, 0.74, 1),
                (0.55, 0.34, 0.29, 1), (0.89, 0.47, 0.76, 1), (0.09, 0.75, 0.81, 1), (0.74, 0.74, 0.13, 1))


class EndpointPathsParams(ItemRowsParams):
    name: str = Field("endpoint_paths", pattern=r"^[A-Za-z0-9_.-]+$", description="file name of the figure and table")
    max_items: int = Field(3, ge=1, le=12, description="items shown (one row each)")
    source: int = Field(0, ge=0, description="the endpoint (in row order) whose paths to the others are drawn")
    panel_size: float = Field(3.2, gt=0, description="inches per panel")


@report("endpoint_paths", params=EndpointPathsParams)
def endpoint_paths_report(experiment, results, params: EndpointPathsParams) -> ReportOutput:
    """Per skeleton: its endpoints, the shortest paths from one endpoint to the others (the relative node
    path dv) and from the root to every endpoint (the relative centroid path dc), and a table of each
    endpoint's features a, dv, dc."""
    import matplotlib.pyplot as plt
    import networkx as nx
    from matplotlib.lines import Line2D

    from topomatch.stages.matching.features import endpoint_features
    from topomatch.stages.mesh.render import UP_ORDER
    from topomatch.stages.reeb.render import draw_scene, view_basis

    chosen = [r for r in results if r.ok and r.final("skeleton") is not None
              and all(r.sweep.get(k) == v for k, v in params.where.items())][:params.max_items]
    order = list(UP_ORDER[params.up])
    fig = plt.figure(figsize=(params.panel_size * 3, params.panel_size * max(len(chosen), 1) + 0.5))
    rows = []
    for i, r in enumerate(chosen):
        mesh, function, skeleton = r.final("mesh"), r.final("function"), r.final("skeleton")
        G = nx.Graph(skeleton.graph)  # shortest paths by edge length: keep the shorter of parallel edges
        for a, b, d in skeleton.graph.edges(data=True):
            G[a][b]["length"] = min(G[a][b].get("length", np.inf), d["length"])
        for v in G.nodes:
            G.nodes[v]["pos"] = np.asarray(G.nodes[v]["pos"], float)[order]
        f = endpoint_features(skeleton.graph)
        ends, root = f.endpoints, f.root
        label = Path(r.input_path).name.split(".")[0]
        for e, (a, dv, dc) in zip(ends, f.features):
            rows.append({"item": r.item_id, "endpoint": str(e), "a": float(a), "dv": float(dv), "dc": float(dc)})
        number = min(params.source, len(ends) - 1)
        source = ends[number] if ends else None
        panels = [("endpoints", []),
                  (f"paths from endpoint {number}", [(nx.shortest_path(G, source, e, weight="length"),
                                                          PATH_COLOURS[k % len(PATH_COLOURS)])
                                                         for k, e in enumerate(ends) if e != source and
                                                         nx.has_path(G, source, e)] if source is not None else []),
                  ("paths from the root (centroid)", [(nx.shortest_path(G, root, e, weight="length"),
                                                      PATH_COLOURS[k % len(PATH_COLOURS)])
                                                     for k, e in enumerate(ends) if nx.has_path(G, root, e)])]
        B = view_basis(params.elev, params.azim)
        for j, (title, paths) in enumerate(panels):
            ax = fig.add_subplot(max(len(chosen), 1), 3, i * 3 + j + 1)
            draw_scene(ax, mesh.V[:, order], mesh.F, values=None if function is None else function.values,
                       graph=G, endpoints=ends, elev=params.elev, azim=params.azim, alpha=0.3, paths=paths)
            if j == 0:  # number the endpoints (their rows in the table)
                for k, e in enumerate(ends):
                    x, y, _ = G.nodes[e]["pos"] @ B.T
                    ax.annotate(str(k), (x, y), xytext=(4, 4), textcoords="offset points", fontsize=7, color="#900")
            ax.set_title(f"{label}: {title}" + (f"\n{len(ends)} endpoints" if j == 0 else ""), fontsize=7)
    handles = [Line2D([], [], color="red", marker="o", ls="none", label="endpoint (numbered as in the table)"),
               Line2D([], [], color="gold", marker="*", markeredgecolor="black", ls="none", ms=10,
                      label="root (centroid)"),
               Line2D([], [], color=PATH_COLOURS[0], lw=3, label="shortest path along the skeleton")]
    fig.legend(handles=handles, loc="lower center", ncol=3, fontsize=7, frameon=False)
    fig.suptitle("Endpoints and shortest paths: between endpoints (relative node path dv) and from the root "
                 "(relative centroid path dc)", fontsize=9)
    fig.subplots_adjust(left=0, right=1, bottom=0.5 / (params.panel_size * max(len(chosen), 1) + 0.5), top=0.9,
                        wspace=0.02, hspace=0.2)
    return ReportOutput(tables={params.name: rows}, figures={params.name: fig})
