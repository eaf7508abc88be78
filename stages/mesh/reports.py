"""Reports that draw meshes: ``mesh_gallery`` (the final mesh of every item)."""

from __future__ import annotations

from pathlib import Path
from typing import Literal

from pydantic import Field

from topomatch.pipeline.contract import Params, ReportOutput, gallery_layout, report


class MeshGalleryParams(Params):
    name: str = Field("meshes", pattern=r"^[A-Za-z0-9_.-]+$", description="file name of the figure")
    state: str = Field("mesh", description="state entry to draw (the last value the chain produced)")
    up: Literal["x", "y", "z"] = Field("y", description="the meshes' up axis (most OBJ files: y)")
    elev: float = 15.0
    azim: float = -60.0
    columns: int = Field(5, ge=1, description="panels per row when there is no sweep")
    panel_size: float = Field(2.6, gt=0, description="inches per panel")


@report("mesh_gallery", params=MeshGalleryParams)
def mesh_gallery_report(experiment, results, params: MeshGalleryParams) -> ReportOutput:
    """The final mesh of every item (rows: inputs, columns: sweep points)."""
    import matplotlib.pyplot as plt

    from topomatch.stages.mesh.render import draw_mesh, z_up

    rows, cols, cells = gallery_layout(results, params.columns)
    fig = plt.figure(figsize=(params.panel_size * cols, params.panel_size * rows))
    for r, cell in zip(results, cells):
        ax = fig.add_subplot(rows, cols, cell + 1, projection="3d")
        mesh = r.final(params.state)
        label = Path(r.input_path).name.split(".")[0]
        sweep = ", ".join(f"{k.split('.')[-1]}={v}" for k, v in r.sweep.items())
        if mesh is None:
            ax.set_axis_off()
            ax.set_title(f"{label}\nfailed", fontsize=7, color="#b00")
            continue
        draw_mesh(ax, z_up(mesh, params.up), elev=params.elev, azim=params.azim)
        ax.set_title(f"{label} {sweep}\n{mesh.n_faces} faces", fontsize=7)
    fig.subplots_adjust(left=0, right=1, bottom=0, top=0.95, wspace=0.0, hspace=0.12)
    return ReportOutput(figures={params.name: fig})
