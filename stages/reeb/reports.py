"""Reports that draw skeletons: the mesh shaded by the Morse function, iso-curves, the
skeleton on top, endpoints in red and the root as a gold star."""

from __future__ import annotations

from pathlib import Path
from typing import Literal

import numpy as np
from pydantic import Field

from topomatch.pipeline.contract import Params, ReportOutput, gallery_layout, report


class SkeletonGalleryParams(Params):
    name: str = Field("skeletons", pattern=r"^[A-Za-z0-9_.-]+$", description="file name of the figure")
    graph: Literal["skeleton", "reeb"] = Field("skeleton", description="draw the pruned skeleton or the full Reeb graph")
    up: Literal["x", "y", "z"] = Field("y", description="the meshes' up axis")
    isolines: bool = Field(True, description="draw the iso-curves of the level sets")
    where: dict[str, float | int | str | bool] = Field(default_factory=dict,
                                                       description="only items with these sweep values")
    alpha: float = Field(0.45, gt=0, le=1, description="opacity of the mesh")
    elev: float = 15.0
    azim: float = -60.0
    columns: int = Field(4, ge=1)
    panel_size: float = Field(3.2, gt=0)


def draw_item(ax, r, params: SkeletonGalleryParams) -> str:
    """Draw one item's mesh, function, iso-curves and graph; return a caption."""
    from topomatch.stages.mesh.render import UP_ORDER, draw_mesh, z_up
    from topomatch.stages.reeb.render import draw_skeleton

    mesh, function = r.final("mesh"), r.final("function")
    level_sets, reeb, skeleton = r.final("level_sets"), r.final("reeb"), r.final("skeleton")
    order = list(UP_ORDER[params.up])
    ax.computed_zorder = False
    draw_mesh(ax, z_up(mesh, params.up), values=None if function is None else function.values,
              cmap="coolwarm", elev=params.elev, azim=params.azim, alpha=params.alpha)
    if params.isolines and level_sets is not None:
        from mpl_toolkits.mplot3d.art3d import Line3DCollection

        seg = level_sets.curves.segments[:, :, order]
        ax.add_collection3d(Line3DCollection(seg, colors="0.25", linewidths=0.4, alpha=0.6))
    caption = ""
    if params.graph == "skeleton" and skeleton is not None:
        draw_skeleton(ax, skeleton.graph, endpoints=skeleton.endpoints, up_order=order)
        caption = f"{len(skeleton.endpoints)} endpoints, cycles {skeleton.cycle_rank}"
    elif reeb is not None:
        from topomatch.stages.reeb.prune import endpoints

        ends = endpoints(reeb.graph)
        draw_skeleton(ax, reeb.graph, endpoints=ends, up_order=order)
        caption = f"{reeb.n_nodes} nodes, {len(ends)} endpoints, cycles {reeb.cycle_rank}"
    return caption


@report("skeleton_gallery", params=SkeletonGalleryParams)
def skeleton_gallery_report(experiment, results, params: SkeletonGalleryParams) -> ReportOutput:
    """Each item's mesh shaded by its Morse function, with iso-curves, skeleton and endpoints."""
    import matplotlib.pyplot as plt

    results = [r for r in results if all(r.sweep.get(k) == v for k, v in params.where.items())]
    rows, cols, cells = gallery_layout(results, params.columns)
    fig = plt.figure(figsize=(params.panel_size * cols, params.panel_size * rows))
    for r, cell in zip(results, cells):
        ax = fig.add_subplot(rows, cols, cell + 1, projection="3d")
        label = Path(r.input_path).name.split(".")[0]
        sweep = ", ".join(f"{k.split('.')[-1]}={v}" for k, v in r.sweep.items()
                          if k not in params.where and k != "morse.function")
        if r.final("mesh") is None:
            ax.set_axis_off()
            ax.set_title(f"{label}\nfailed", fontsize=7, color="#b00")
            continue
        caption = draw_item(ax, r, params)
        kind = r.final("function").kind if r.final("function") is not None else ""
        ax.set_title(f"{label} ({kind}) {sweep}\n{caption}", fontsize=7)
    fig.subplots_adjust(left=0, right=1, bottom=0, top=0.94, wspace=0.0, hspace=0.12)
    return ReportOutput(figures={params.name: fig})


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


@report("skeleton_stability", params=StabilityParams)
def skeleton_stability_report(experiment, results, params: StabilityParams) -> ReportOutput:
    """Per item: genus, cycle ranks, endpoint count and the distance of its skeleton to the reference
    item's skeleton (same input), relative to the reference mesh's bounding-box diagonal."""
    import matplotlib.pyplot as plt

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
        extra = [f"{k.split('.')[-1]}={row[k]}" for k in experiment.raw.sweep if k != params.x and k in row]
        return " ".join([row["input"].split(".")[0]] + extra)

    for name in dict.fromkeys(line(row) for row in rows):
        pts = sorted((row[params.x], row["distance_mean_rel"], row["endpoints"]) for row in rows
                     if line(row) == name and params.x in row)
        xs = list(range(len(pts))) if pts and isinstance(pts[0][0], str) else [p[0] for p in pts]
        axes[0].plot(xs, [p[1] for p in pts], marker="o", label=name)
        axes[1].plot(xs, [p[2] for p in pts], marker="o", label=name)
    axes[0].set_ylabel("skeleton distance to reference / bbox diagonal")
    axes[1].set_ylabel("endpoints")
    for ax in axes:
        ax.set_xlabel(params.x)
        ax.grid(alpha=0.3)
    axes[1].legend(fontsize=7)
    fig.tight_layout()
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


def item_file_stem(r) -> str:
    """A file-name stem unique to an item: the input's stem and its sweep values."""
    stem = Path(r.input_path).name.split(".")[0]
    sweep = "_".join(f"{k.split('.')[-1]}-{v}" for k, v in r.sweep.items())
    return "".join(c if c.isalnum() or c in "._-" else "-" for c in (f"{stem}_{sweep}" if sweep else stem))


@report("export", params=ExportParams)
def export_report(experiment, results, params: ExportParams) -> ReportOutput:
    """Write each item's meshes (final, cleaned, decimated, ...) and skeletons as files other tools open
    (PLY / OBJ / OFF meshes; PLY or OBJ polylines, GraphML, JSON graphs) into ``exports/``."""
    from topomatch.pipeline.contract import ConfigError
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
            value = r.final("skeleton") if kind == "skeleton" else r.final("reeb")
            if value is None:
                continue
            for fmt in params.graph_formats:
                path = f"{params.folder}/{stem}/{kind}.{fmt}"
                files[path] = skeleton_text(value.graph, fmt).encode()
                rows.append({"item": r.item_id, "what": kind, "file": path, "vertices": value.graph.number_of_nodes(),
                             "faces": "", "edges": value.graph.number_of_edges()})
    return ReportOutput(tables={params.folder: rows}, files=files)
