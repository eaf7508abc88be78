"""Reports that draw skeletons: the mesh shaded by the Morse function, iso-curves, the
skeleton on top, endpoints in red and the root as a gold star."""

from __future__ import annotations

from pathlib import Path
from typing import Literal

import numpy as np
from pydantic import Field

from pipeline.params import Params
from pipeline.reports import ReportOutput, gallery_layout, report


class SkeletonGalleryParams(Params):
    name: str = Field("skeletons", pattern=r"^[A-Za-z0-9_.-]+$", description="file name of the figure")
    graph: Literal["skeleton", "reeb"] = Field("skeleton", description="draw the pruned skeleton or the full Reeb graph")
    up: Literal["x", "y", "z"] = Field("y", description="the meshes' up axis")
    isolines: bool = Field(True, description="draw the iso-curves of the level sets")
    alpha: float = Field(0.45, gt=0, le=1, description="opacity of the mesh")
    elev: float = 15.0
    azim: float = -60.0
    columns: int = Field(4, ge=1)
    panel_size: float = Field(3.2, gt=0)


def draw_item(ax, r, params: SkeletonGalleryParams) -> str:
    """Draw one item's mesh, function, iso-curves and graph; return a caption."""
    from pipeline.render import UP_ORDER, draw_mesh, draw_skeleton, z_up

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
        from stages.reeb.prune import endpoints

        ends = endpoints(reeb.graph)
        draw_skeleton(ax, reeb.graph, endpoints=ends, up_order=order)
        caption = f"{reeb.n_nodes} nodes, {len(ends)} endpoints, cycles {reeb.cycle_rank}"
    return caption


@report("skeleton_gallery", params=SkeletonGalleryParams)
def skeleton_gallery_report(experiment, results, params: SkeletonGalleryParams) -> ReportOutput:
    """Each item's mesh shaded by its Morse function, with iso-curves, skeleton and endpoints."""
    import matplotlib.pyplot as plt

    rows, cols, cells = gallery_layout(results, params.columns)
    fig = plt.figure(figsize=(params.panel_size * cols, params.panel_size * rows))
    for r, cell in zip(results, cells):
        ax = fig.add_subplot(rows, cols, cell + 1, projection="3d")
        label = Path(r.input_path).name.split(".")[0]
        sweep = ", ".join(f"{k.split('.')[-1]}={v}" for k, v in r.sweep.items())
        if r.final("mesh") is None:
            ax.set_axis_off()
            ax.set_title(f"{label}\nfailed", fontsize=7, color="#b00")
            continue
        caption = draw_item(ax, r, params)
        kind = r.final("function").kind if r.final("function") is not None else ""
        ax.set_title(f"{label} ({kind}) {sweep}\n{caption}", fontsize=7)
    fig.subplots_adjust(left=0, right=1, bottom=0, top=0.94, wspace=0.0, hspace=0.12)
    return ReportOutput(figures={params.name: fig})
