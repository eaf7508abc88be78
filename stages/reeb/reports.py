"""Reports that draw skeletons: the mesh shaded by the Morse function, iso-curves, the
skeleton on top, endpoints in red and the root as a gold star."""

from __future__ import annotations

import textwrap
from pathlib import Path
from typing import Literal

import numpy as np
from pydantic import Field, field_validator

from topomatch.pipeline.contract import (ConfigError, Params, ReportOutput, axis_label, gallery_layout, report,
                                        series_style, sweep_ticks, sweep_value_labels)


class SkeletonGalleryParams(Params):
    name: str = Field("skeletons", pattern=r"^[A-Za-z0-9_.-]+$", description="file name of the figure")
    graph: Literal["skeleton", "reeb", "none"] = Field(
        "skeleton", description="draw the pruned skeleton, the full Reeb graph, or no graph (the function and level sets)")
    up: Literal["x", "y", "z"] = Field("y", description="the meshes' up axis")
    isolines: bool = Field(True, description="draw the iso-curves of the level sets")
    where: dict[str, float | int | str | bool] = Field(default_factory=dict,
                                                       description="only items with these sweep values")
    alpha: float = Field(0.45, gt=0, le=1, description="opacity of the mesh")
    elev: float = 15.0
    azim: float = -60.0
    columns: int = Field(4, ge=1)
    panel_size: float = Field(3.2, gt=0)
    title: str = Field("", description="figure title (default: none; the run page heads it with the name)")


#: Names of the Morse functions for colour bars and captions.
FUNCTION_NAMES = {"mixture": "mixture distance", "euclidean": "Euclidean distance to the centroid",
                  "affine": "affine distance", "fiedler": "Fiedler vector", "height": "height",
                  "geodesic": "geodesic distance", "agd": "average geodesic distance"}


def draw_item(ax, r, params: SkeletonGalleryParams) -> str:
    """Draw one item's mesh coloured by its Morse function, iso-curves and graph, depth-sorted
    (:func:`topomatch.stages.reeb.render.draw_scene`) on a 2D axis; return a caption."""
    from topomatch.stages.mesh.render import UP_ORDER
    from topomatch.stages.reeb.prune import endpoints
    from topomatch.stages.reeb.render import draw_scene

    mesh, function = r.final("mesh"), r.final("function")
    level_sets, reeb, skeleton = r.final("level_sets"), r.final("reeb"), r.final("skeleton")
    order = list(UP_ORDER[params.up])
    graph, ends, caption = None, (), ""
    if params.graph == "skeleton" and skeleton is not None:
        graph, ends = skeleton.graph, skeleton.endpoints
        caption = f"{len(ends)} endpoints, {skeleton.cycle_rank} cycle{'s' * (skeleton.cycle_rank != 1)}"
    elif params.graph == "reeb" and reeb is not None:
        graph = reeb.graph
        ends = endpoints(graph)
        caption = f"{reeb.n_nodes} nodes, {len(ends)} endpoints, {reeb.cycle_rank} cycle{'s' * (reeb.cycle_rank != 1)}"
    if graph is not None:
        graph = graph.copy()  # positions in display orientation, the result's graph untouched
        for n in graph.nodes:
            graph.nodes[n]["pos"] = np.asarray(graph.nodes[n]["pos"], float)[order]
    if params.graph == "none" and level_sets is not None:
        caption = f"{level_sets.n_levels} bands, {len(level_sets.curves.level)} iso-curve segments"
    iso = level_sets.curves.segments[:, :, order] if (params.isolines and level_sets is not None) else None
    draw_scene(ax, mesh.V[:, order], mesh.F, values=None if function is None else function.values, cmap="coolwarm",
               isolines=iso, graph=graph, endpoints=ends, elev=params.elev, azim=params.azim, alpha=params.alpha)
    return caption


def add_skeleton_keys(fig, *, isolines: bool, functions: set[str], root: bool, graph: bool = True) -> None:
    """A colour bar of the Morse function (each shape's own range, minimum to maximum) and a legend of
    the skeleton's marks, along the bottom of ``fig``."""
    import matplotlib as mpl

    from topomatch.stages.reeb.render import skeleton_legend_handles

    names = ", ".join(sorted(FUNCTION_NAMES.get(f, f) for f in functions)) or "Morse function"
    height = fig.get_figheight()  # the keys take the bottom 0.9 inch, whatever the figure's size
    cax = fig.add_axes([0.05, 0.5 / height, 0.36, 0.14 / height])
    bar = fig.colorbar(mpl.cm.ScalarMappable(norm=mpl.colors.Normalize(0, 1), cmap="coolwarm"), cax=cax,
                       orientation="horizontal", ticks=[0, 0.5, 1])
    bar.ax.set_xticklabels(["min", "", "max"], fontsize=7)
    bar.set_label(f"{names[:1].upper() + names[1:]}\n(each shape: its minimum to its maximum)", fontsize=7)
    handles = skeleton_legend_handles(isolines=isolines, root=root)
    if not graph:
        handles = handles[-1:] if isolines else []
    fig.legend(handles=handles, loc="lower left",
               bbox_to_anchor=(0.47, 0.0), ncol=2, fontsize=7, frameon=False)


@report("skeleton_gallery", params=SkeletonGalleryParams)
def skeleton_gallery_report(experiment, results, params: SkeletonGalleryParams) -> ReportOutput:
    """Each item's mesh shaded by its Morse function (colour bar), with iso-curves, skeleton, endpoints
    (red) and root (gold star), drawn depth-sorted."""
    import matplotlib.pyplot as plt

    chosen = [r for r in results if all(r.sweep.get(k) == v for k, v in params.where.items())]
    if not chosen:
        raise ConfigError(f"skeleton_gallery {params.name}: where {params.where} matches none of the "
                          f"{len(results)} items")
    results = chosen
    rows, cols, cells = gallery_layout(results, params.columns)
    keys_height = 0.9  # inches for the colour bar and legend
    fig = plt.figure(figsize=(params.panel_size * cols, params.panel_size * rows + keys_height))
    functions, title_lines = set(), 2
    for r, cell in zip(results, cells):
        ax = fig.add_subplot(rows, cols, cell + 1)
        label = Path(r.input_path).name.split(".")[0]
        sweep = ", ".join(sweep_value_labels(experiment, r.sweep, skip=(*params.where, "morse.function")))
        if r.final("mesh") is None:
            ax.set_axis_off()
            ax.set_title(f"{label}\nfailed", fontsize=7, color="#b00")
            continue
        caption = draw_item(ax, r, params)
        function = r.final("function")
        kind = function.kind if function is not None else ""
        functions.add(kind)
        # wrapped to the panel's width (about 14 characters of 7 pt text per inch): long names and several sweep
        # values would run into the next panel's title
        head = textwrap.fill(f"{label} ({FUNCTION_NAMES.get(kind, kind)}) {sweep}", width=int(params.panel_size * 14))
        ax.set_title(f"{head}\n{caption}", fontsize=7)
        title_lines = max(title_lines, head.count("\n") + 1 + caption.count("\n") + 1)
    bottom = keys_height / (params.panel_size * rows + keys_height)
    top_inches = 0.12 * title_lines + 0.06 + 0.45 * bool(params.title)  # panel titles (7 pt lines), then the title
    fig.subplots_adjust(left=0, right=1, bottom=bottom, top=1 - top_inches / (params.panel_size * rows + keys_height),
                        wspace=0.02, hspace=0.18)
    if params.title:
        fig.suptitle(params.title, fontsize=10)
    roots = params.graph != "none" and any("root" in getattr(r.final(params.graph), "graph", ())
                                           for r in results if r.ok)
    add_skeleton_keys(fig, isolines=params.isolines, functions=functions - {""}, root=roots,
                      graph=params.graph != "none")
    return ReportOutput(figures={params.name: fig})


# --------------------------------------------------------------------------- the algorithm step by step (thesis Fig. 3.2)


class ItemRowsParams(Params):
    """Figures with one row of panels per item: which items, and the view."""

    where: dict[str, float | int | str | bool] = Field(default_factory=dict,
                                                       description="only items with these sweep values")
    max_items: int = Field(2, ge=1, le=12, description="items shown (one row each)")
    up: Literal["x", "y", "z"] = Field("y", description="the meshes' up axis")
    elev: float = 15.0
    azim: float = -60.0
    panel_size: float = Field(2.6, gt=0, description="inches per panel")


class ReebStepsParams(ItemRowsParams):
    name: str = Field("reeb_steps", pattern=r"^[A-Za-z0-9_.-]+$", description="file name of the figure and table")
    steps: list[int] = Field(default_factory=lambda: [1, 3, 6, 11, 16, 22], min_length=1,
                             description="numbers of bands processed, one panel each (the last: all)")


@report("reeb_steps", params=ReebStepsParams)
def reeb_steps_report(experiment, results, params: ReebStepsParams) -> ReportOutput:
    """Reeb graph extraction step by step (Algorithm 1): after k bands, the bands swept so far in colour,
    the rest grey, and the graph of their components; a table of nodes, edges and cycles per step."""
    import matplotlib.pyplot as plt

    from topomatch.stages.mesh.render import UP_ORDER
    from topomatch.stages.reeb.prune import cycle_rank
    from topomatch.stages.reeb.render import draw_scene

    chosen = [r for r in results if r.ok and r.final("reeb") is not None and r.final("level_sets") is not None
              and all(r.sweep.get(k) == v for k, v in params.where.items())][:params.max_items]
    order = list(UP_ORDER[params.up])
    cols = len(params.steps)
    fig = plt.figure(figsize=(params.panel_size * cols, params.panel_size * max(len(chosen), 1) + 0.6))
    rows = []
    for i, r in enumerate(chosen):
        mesh, ls, reeb = r.final("mesh"), r.final("level_sets"), r.final("reeb")
        function = r.final("function")
        n = ls.n_levels
        face_band = np.asarray(ls.vertex_band)[mesh.F].min(axis=1)
        V = mesh.V[:, order]
        graph = reeb.graph.copy()  # positions in the drawing's axis order, once per item
        for v in graph.nodes:
            graph.nodes[v]["pos"] = np.asarray(graph.nodes[v]["pos"], float)[order]
        for j, k in enumerate(params.steps):
            k = min(k, n)
            sub = graph.subgraph([v for v, d in graph.nodes(data=True) if v == "root" or d["band"] < k])
            cycles = cycle_rank(sub)  # cycles of the surface, the root left out
            rows.append({"item": r.item_id, "bands": k, "of": n, "nodes": sub.number_of_nodes(),
                         "edges": sub.number_of_edges(), "cycles": cycles})
            ax = fig.add_subplot(max(len(chosen), 1), cols, i * cols + j + 1)
            iso = ls.curves.segments[ls.curves.level < k][:, :, order]
            draw_scene(ax, V, mesh.F, values=None if function is None else function.values,
                       isolines=iso, graph=sub, endpoints=(), elev=params.elev, azim=params.azim, alpha=0.5,
                       faded=face_band >= k)
            ax.set_title(f"{Path(r.input_path).name.split('.')[0]}: {k} of {n} bands\n{sub.number_of_nodes()} nodes, "
                         f"{cycles} cycle{'s' * (cycles != 1)}", fontsize=7)
    fig.suptitle("Reeb graph extraction step by step: bands swept so far in colour, their components as nodes",
                 fontsize=10)
    fig.subplots_adjust(left=0, right=1, bottom=0, top=1 - 0.6 / (params.panel_size * max(len(chosen), 1) + 0.6),
                        wspace=0.02, hspace=0.2)
    return ReportOutput(tables={params.name: rows}, figures={params.name: fig})


# --------------------------------------------------------------------------- stability against a reference item


def skeleton_points(graph, per_edge: int = 8, matrix: np.ndarray | None = None) -> np.ndarray:
    """Points sampled along the skeleton's edges (root edges excluded), (k, 3); ``matrix`` (4, 4)
    maps them back through the inverse of a similarity transform."""
    pts = []
    t = np.linspace(0.0, 1.0, per_edge)[:, None]
    for a, b in graph.edges():
        if "root" in (a, b):
            continue
        p, q = np.asarray(graph.nodes[a]["pos"]), np.asarray(graph.nodes[b]["pos"])
        pts.append(p + t * (q - p))
    if not pts:
        pts = [np.array([d["pos"] for v, d in graph.nodes(data=True) if v != "root"])]
    P = np.vstack(pts)
    if matrix is not None:
        inv = np.linalg.inv(matrix)
        P = P @ inv[:3, :3].T + inv[:3, 3]
    return P


def skeleton_distance(A: np.ndarray, B: np.ndarray) -> tuple[float, float]:
    """(symmetric mean nearest-point distance, Hausdorff distance) of two point sets."""
    from scipy.spatial import cKDTree

    dab = cKDTree(B).query(A)[0]
    dba = cKDTree(A).query(B)[0]
    return float((dab.mean() + dba.mean()) / 2), float(max(dab.max(), dba.max()))


class StabilityParams(Params):
    name: str = Field("stability", pattern=r"^[A-Za-z0-9_.-]+$", description="file name of the table and figure")
    reference: dict[str, float | int | str | bool] = Field(
        description="sweep values of the reference item of each input (e.g. {noise.sigma: 0.0})")
    x: str = Field(description="sweep key on the x axis of the figure")
    undo_transform: bool = Field(False, description="map skeletons back through the inverse of the transform stage")
    title: str = Field("", description="figure title (default: what is compared against what)")


@report("skeleton_stability", params=StabilityParams)
def skeleton_stability_report(experiment, results, params: StabilityParams) -> ReportOutput:
    """Per item: genus, cycle ranks, endpoint count and the distance of its skeleton to the reference
    item's skeleton (same input), relative to the reference mesh's bounding-box diagonal."""
    import matplotlib.pyplot as plt

    unknown = [k for k in (*params.reference, params.x) if k not in experiment.raw.sweep]
    if unknown:  # a misspelt key drew an empty figure and said nothing
        raise ConfigError(f"skeleton_stability {params.name}: {', '.join(unknown)} is not a sweep key of the config "
                          f"(sweep keys: {', '.join(experiment.raw.sweep) or 'none'})")

    def matrix(r):
        t = r.results.get("transform")
        return t.matrix if (params.undo_transform and t is not None) else None

    def group(r):  # the input and the sweep values that are not being compared
        return (r.input_path,) + tuple(sorted((k, str(v)) for k, v in r.sweep.items()
                                              if k not in params.reference and k != params.x))

    refs = {group(r): r for r in results if r.ok and all(r.sweep.get(k) == v for k, v in params.reference.items())}
    rows = []
    for r in results:
        if not r.ok or group(r) not in refs:
            continue
        ref, skel = refs[group(r)], r.final("skeleton")
        ref_mesh = ref.final("mesh")
        diag = float(np.linalg.norm(ref_mesh.V.max(axis=0) - ref_mesh.V.min(axis=0)))
        mean_d, haus = skeleton_distance(skeleton_points(skel.graph, matrix=matrix(r)),
                                         skeleton_points(ref.final("skeleton").graph, matrix=matrix(ref)))
        clean = r.results.get("clean")
        rows.append({
            "item": r.item_id, "input": Path(r.input_path).name, **r.sweep,
            "genus": clean.after.genus if clean is not None else None,
            "reeb_cycle_rank": r.final("reeb").cycle_rank, "skeleton_cycle_rank": skel.cycle_rank,
            "endpoints": len(skel.endpoints), "endpoints_reference": len(ref.final("skeleton").endpoints),
            "distance_mean_rel": mean_d / diag, "distance_hausdorff_rel": haus / diag,
        })
    fig, axes = plt.subplots(1, 2, figsize=(10, 3.8))
    def line(row):
        return " ".join([row["input"].split(".")[0]] + sweep_value_labels(experiment, row, skip=(params.x,)))

    numeric_x = True
    for i, name in enumerate(dict.fromkeys(line(row) for row in rows)):
        pts = sorted((row[params.x], row["distance_mean_rel"], row["endpoints"]) for row in rows
                     if line(row) == name and params.x in row)
        numeric_x = numeric_x and not (pts and isinstance(pts[0][0], str))
        xs = [p[0] for p in pts] if numeric_x else list(range(len(pts)))
        axes[0].plot(xs, [p[1] for p in pts], label=name, **series_style(i))
        axes[1].plot(xs, [p[2] for p in pts], label=name, **series_style(i))
    reference = ", ".join(f"{axis_label(experiment, results, k).split(' (')[0]} = {v}" for k, v in params.reference.items())
    xlabel = axis_label(experiment, results, params.x)
    axes[0].set_ylabel("mean distance to the reference skeleton\n(× bounding-box diagonal)")
    axes[0].set_title("Skeleton displacement", fontsize=10)
    axes[1].set_ylabel("endpoints (degree-1 nodes)")
    axes[1].set_title("Endpoint count", fontsize=10)
    axes[1].yaxis.get_major_locator().set_params(integer=True)
    for ax in axes:
        ax.set_xlabel(xlabel)
        ax.grid(alpha=0.3)
        if numeric_x and rows:
            sweep_ticks(ax, [row[params.x] for row in rows if params.x in row])
    fig.suptitle(params.title or f"Skeleton stability against {xlabel.split(' (')[0]} (reference: {reference})",
                 fontsize=11)
    fig.tight_layout()
    handles, labels = axes[0].get_legend_handles_labels()
    fig.legend(handles, labels, loc="center left", bbox_to_anchor=(1.0, 0.5), fontsize=8, frameon=False)
    return ReportOutput(tables={params.name: rows}, figures={params.name: fig})


# --------------------------------------------------------------------------- exports for other tools


class ExportParams(Params):
    folder: str = Field("exports", pattern=r"^[A-Za-z0-9_.-]+$", description="folder of the run to write into")
    meshes: list[str] = Field(default_factory=lambda: ["final"], description=(
        "meshes to write: 'final' (the last mesh of the chain) and/or labels of stages that produce a mesh "
        "(clean, decimate, noise, ...); [] writes none"))
    mesh_format: Literal["ply", "obj", "off"] = Field("ply", description="mesh file format")
    graphs: list[Literal["skeleton", "reeb"]] = Field(default_factory=lambda: ["skeleton"], description=(
        "graphs to write: the pruned skeleton and/or the unpruned Reeb graph"))
    graph_formats: list[Literal["ply", "obj", "graphml", "json"]] = Field(
        default_factory=lambda: ["ply"], min_length=1, description="graph file formats (PLY polyline first)")
    where: dict[str, float | int | str | bool] = Field(default_factory=dict,
                                                       description="only items with these sweep values")

    @field_validator("folder")
    @classmethod
    def _inside_the_run(cls, value: str) -> str:
        if value in (".", "..") or value in RUN_FOLDERS:
            raise ValueError(f"{value!r} is not a folder of its own inside the run folder (not '.', '..' or one of "
                             f"{', '.join(RUN_FOLDERS)}); e.g. exports")
        return value


#: The run folder's own sub-folders, which an export must not write into.
RUN_FOLDERS = ("figures", "tables", "views", "assets")


def item_file_stem(r) -> str:
    """A file-name stem unique to an item: the input's stem and its sweep values (the input's whole label when two
    inputs share a file name: the item id names them by their paths then)."""
    base = r.item_id.split("[", 1)[0]
    stem = Path(r.input_path).name.split(".")[0] if base == Path(r.input_path).name else base.strip("{}/.")
    sweep = "_".join(f"{k.split('.')[-1]}-{v}" for k, v in r.sweep.items())
    return "".join(c if c.isalnum() or c in "._-" else "-" for c in (f"{stem}_{sweep}" if sweep else stem))


@report("export", params=ExportParams)
def export_report(experiment, results, params: ExportParams) -> ReportOutput:
    """Write each item's meshes (final, cleaned, decimated, ...) and skeletons as files other tools open
    (PLY / OBJ / OFF meshes; PLY or OBJ polylines, GraphML, JSON graphs) into ``exports/``."""
    from topomatch.stages.mesh.export import mesh_text
    from topomatch.stages.reeb.export import skeleton_text

    files: dict[str, bytes] = {}
    rows = []
    for r in results:
        if not r.ok or any(r.sweep.get(k) != v for k, v in params.where.items()):
            continue
        stem = item_file_stem(r)
        for which in params.meshes:
            if which == "final":
                mesh = r.final("mesh")
            elif which in r.results:
                if "mesh" not in r.stage_produces.get(which, ()):
                    raise ConfigError(f"export: stage {which!r} produces no mesh; choose among "
                                      f"{[k for k, v in r.stage_produces.items() if 'mesh' in v]}")
                mesh = r.results[which].mesh
            else:
                raise ConfigError(f"export: no stage {which!r} in the chain (stages: {list(r.results)})")
            if mesh is None:
                continue
            path = f"{params.folder}/{stem}/mesh_{which}.{params.mesh_format}"
            files[path] = mesh_text(mesh.V, mesh.F, params.mesh_format).encode()
            rows.append({"item": r.item_id, "what": f"mesh ({which})", "file": path,
                         "vertices": mesh.n_vertices, "faces": mesh.n_faces, "edges": ""})
        for kind in params.graphs:
            value = r.final(kind)
            if value is None:
                continue
            for fmt in params.graph_formats:
                path = f"{params.folder}/{stem}/{kind}.{fmt}"
                files[path] = skeleton_text(value.graph, fmt).encode()
                rows.append({"item": r.item_id, "what": kind, "file": path, "vertices": value.graph.number_of_nodes(),
                             "faces": "", "edges": value.graph.number_of_edges()})
    return ReportOutput(tables={params.folder: rows}, files=files)


# --------------------------------------------------------------------------- interactive 3D views


class Skeleton3DParams(Params):
    name: str = Field("skeletons_3d", pattern=r"^[A-Za-z0-9_.-]+$", description="file name of the view")
    graph: Literal["skeleton", "reeb"] = Field("skeleton", description="the pruned skeleton or the full Reeb graph")
    where: dict[str, float | int | str | bool] = Field(default_factory=dict,
                                                       description="only items with these sweep values")
    up: Literal["x", "y", "z"] = Field("y", description="the meshes' up axis (the camera's up)")
    max_items: int = Field(12, ge=1, le=48, description="views on the page at most (the first items)")
    columns: int = Field(3, ge=1, le=6, description="views side by side")
    height: int = Field(420, ge=200, le=1200, description="pixels per row of views")
    opacity: float = Field(0.55, gt=0, le=1, description="opacity of the surface")
    title: str = Field("", description="heading on the run page (default: the name in words)")


def plotly_js() -> bytes:
    """plotly.js as shipped inside the installed ``plotly`` package (the page works offline)."""
    from importlib.resources import files

    return files("plotly").joinpath("package_data", "plotly.min.js").read_bytes()


def _item_traces(r, params: Skeleton3DParams, show_legend: bool) -> list:
    """The plotly traces of one item: the mesh coloured by the Morse function, the graph's edges as
    lines, endpoints (red) and the root (gold diamond)."""
    import plotly.graph_objects as go

    from topomatch.stages.reeb.prune import endpoints

    mesh, function = r.final("mesh"), r.final("function")
    kind = function.kind if function is not None else ""
    V, F = mesh.V, mesh.F
    intensity = None
    if function is not None:  # each shape from its minimum (0) to its maximum (1), as in the static figures
        f = np.asarray(function.values, float)
        intensity = (f - f.min()) / (np.ptp(f) or 1.0)
    traces = [go.Mesh3d(x=V[:, 0], y=V[:, 1], z=V[:, 2], i=F[:, 0], j=F[:, 1], k=F[:, 2],
                        intensity=intensity, colorscale="RdBu_r", cmin=0.0, cmax=1.0,
                        opacity=params.opacity, name="surface", showscale=show_legend,
                        colorbar=dict(title=dict(text="Morse function<br>(min 0, max 1)", side="right"),
                                      len=0.6, thickness=12),
                        hovertemplate=f"{FUNCTION_NAMES.get(kind, kind)}: %{{intensity:.3f}} of its range"
                                      "<extra>surface</extra>")]
    value = r.final(params.graph)
    if value is None:
        return traces
    graph = value.graph
    ends = list(value.endpoints) if params.graph == "skeleton" else endpoints(graph)
    xs, ys, zs = [], [], []
    for a, b in graph.edges():
        for n in (a, b):
            p = graph.nodes[n]["pos"]
            xs.append(float(p[0])); ys.append(float(p[1])); zs.append(float(p[2]))
        xs.append(None); ys.append(None); zs.append(None)
    traces.append(go.Scatter3d(x=xs, y=ys, z=zs, mode="lines", line=dict(color="black", width=5),
                               name="skeleton edge", legendgroup="edge", showlegend=show_legend, hoverinfo="skip"))
    if ends:
        P = np.array([graph.nodes[n]["pos"] for n in ends], float)
        traces.append(go.Scatter3d(x=P[:, 0], y=P[:, 1], z=P[:, 2], mode="markers", name="endpoint",
                                   marker=dict(color="red", size=6), legendgroup="end", showlegend=show_legend,
                                   text=[str(n) for n in ends], hovertemplate="endpoint %{text}<extra></extra>"))
    if "root" in graph:
        p = graph.nodes["root"]["pos"]
        traces.append(go.Scatter3d(x=[p[0]], y=[p[1]], z=[p[2]], mode="markers", name="root",
                                   marker=dict(color="gold", size=9, symbol="diamond", line=dict(color="black", width=1)),
                                   legendgroup="root", showlegend=show_legend, hovertemplate="root<extra></extra>"))
    return traces


@report("skeleton_3d", params=Skeleton3DParams)
def skeleton_3d_report(experiment, results, params: Skeleton3DParams) -> ReportOutput:
    """Interactive 3D views (rotate, zoom, hover), side by side: each mesh coloured by its Morse function,
    with its skeleton as lines, endpoints (red) and root (gold); plotly.js is written into the run's
    ``assets/`` folder, so the page works offline."""
    from plotly.subplots import make_subplots

    chosen = [r for r in results if r.ok and r.final("mesh") is not None
              and all(r.sweep.get(k) == v for k, v in params.where.items())][:params.max_items]
    if not chosen:
        return ReportOutput(notes=["no item to show (none succeeded, or none matches 'where')"])
    cols = min(params.columns, len(chosen))
    rows = -(-len(chosen) // cols)
    titles = []
    for r in chosen:
        function = r.final("function")
        kind = function.kind if function is not None else ""
        sweep = ", ".join(f"{k.split('.')[-1]}={v}" for k, v in r.sweep.items() if k not in params.where)
        titles.append(f"{Path(r.input_path).name.split('.')[0]} {sweep}".strip() + (f" ({kind})" if kind else ""))
    fig = make_subplots(rows=rows, cols=cols, specs=[[{"type": "scene"}] * cols for _ in range(rows)],
                        subplot_titles=titles, horizontal_spacing=0.01, vertical_spacing=0.04)
    for i, r in enumerate(chosen):
        for trace in _item_traces(r, params, show_legend=i == 0):
            fig.add_trace(trace, row=i // cols + 1, col=i % cols + 1)
    up = {a: float(a == params.up) for a in "xyz"}
    eye = {"x": {"x": 0.3, "y": 1.6, "z": 1.2}, "y": {"x": 1.2, "y": 0.3, "z": 1.6}, "z": {"x": 1.6, "y": -1.2, "z": 0.3}}
    fig.update_scenes(aspectmode="data", xaxis_visible=False, yaxis_visible=False, zaxis_visible=False,
                      camera=dict(up=up, eye=eye[params.up]))
    fig.update_layout(height=params.height * rows + 40, margin=dict(l=0, r=0, t=30, b=40),
                      legend=dict(orientation="h", y=0.0, yanchor="top", x=0.0), paper_bgcolor="white")
    fragment = fig.to_html(full_html=False, include_plotlyjs=False, div_id=f"view-{params.name}",
                           config={"displaylogo": False, "responsive": True})
    return ReportOutput(html={params.name: f"<div class='view3d'>{fragment}</div>"},
                        files={"assets/plotly.min.js": plotly_js()},
                        notes=["Drag to rotate, scroll to zoom, hover for values; double-click resets a view."])
