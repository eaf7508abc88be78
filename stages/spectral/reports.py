"""Spectral figures (thesis Figs. 4.3, 4.4): sparsity of Q and K, the first eigenfunctions, the level sets of phi_2."""

from __future__ import annotations

from pathlib import Path
from typing import Literal

from pydantic import Field

from topomatch.pipeline.contract import Params, ReportOutput, report



class SpectralFiguresParams(Params):
    name: str = Field("spectral", pattern=r"^[A-Za-z0-9_.-]+$", description="prefix of the figure files")
    eigenfunctions: int = Field(3, ge=1, le=9, description="phi_1 .. phi_k drawn on each mesh")
    levels: int = Field(22, ge=2, description="iso-curves of phi_2 drawn in the last panel")
    mass: Literal["full", "voronoi"] = "full"
    up: Literal["x", "y", "z"] = "y"
    max_items: int = Field(3, ge=1, description="first items drawn")
    elev: float = 15.0
    azim: float = -60.0


@report("spectral_figures", params=SpectralFiguresParams)
def spectral_figures_report(experiment, results, params: SpectralFiguresParams) -> ReportOutput:
    """Sparsity patterns of Q and K, the first eigenfunctions and the level sets of phi_2 (Figs. 4.3-4.4)."""
    import matplotlib.pyplot as plt
    from mpl_toolkits.mplot3d.art3d import Line3DCollection

    from topomatch.stages.mesh.render import UP_ORDER, draw_mesh, z_up
    from topomatch.stages.reeb.level_sets import isolines, level_values
    from topomatch.stages.spectral.eigen import smallest_eigenpairs
    from topomatch.stages.spectral.laplacian import laplacian

    unique = {r.input_path: r for r in reversed(results) if r.ok and r.final("mesh") is not None}
    items = [unique[p] for p in dict.fromkeys(r.input_path for r in results) if p in unique][: params.max_items]
    k = max(params.eigenfunctions, 2)
    fig_spy, axes_spy = plt.subplots(len(items), 2, figsize=(7, 3.4 * len(items)), squeeze=False)
    cols = params.eigenfunctions + 1
    fig_phi = plt.figure(figsize=(3.0 * cols, 3.2 * len(items)))
    rows = []
    for row, r in enumerate(items):
        mesh = r.final("mesh")
        lap = laplacian(mesh, params.mass)
        eig = smallest_eigenpairs(lap.Q, lap.K, k, V=mesh.V, F=mesh.F)
        label = Path(r.input_path).name.split(".")[0]
        for ax, M, title in ((axes_spy[row][0], lap.Q, "Q (cotangent)"), (axes_spy[row][1], lap.K, f"K ({params.mass} mass)")):
            ax.spy(M, markersize=0.3, color="black")
            ax.set_title(f"{label}: {title}, nnz = {M.nnz:,}", fontsize=8)
            ax.set_xlabel("column (vertex index)", fontsize=7)
            ax.set_ylabel("row (vertex index)", fontsize=7)
            ax.tick_params(labelsize=6)
        for j in range(params.eigenfunctions):
            ax = fig_phi.add_subplot(len(items), cols, row * cols + j + 1, projection="3d")
            draw_mesh(ax, z_up(mesh, params.up), values=eig.vectors[:, j], cmap="coolwarm",
                      elev=params.elev, azim=params.azim)
            ax.set_title(f"{label}: φ{j + 1}, λ{j + 1} = {eig.values[j]:.4g}", fontsize=7)
        ax = fig_phi.add_subplot(len(items), cols, row * cols + cols, projection="3d")
        phi2 = eig.vectors[:, 1]
        draw_mesh(ax, z_up(mesh, params.up), values=phi2, cmap="coolwarm", elev=params.elev, azim=params.azim,
                  alpha=0.6)
        ax.computed_zorder = False
        seg = isolines(mesh.V, mesh.F, phi2, level_values(phi2, params.levels)).segments[:, :, list(UP_ORDER[params.up])]
        ax.add_collection3d(Line3DCollection(seg, colors="black", linewidths=0.6))
        ax.set_title(f"{label}: {params.levels} level sets of φ2", fontsize=7)
        rows.append({"input": label, "vertices": mesh.n_vertices, "nnz_Q": int(lap.Q.nnz), "nnz_K": int(lap.K.nnz),
                     **{f"lambda_{j + 1}": float(eig.values[j]) for j in range(k)}, "solver": eig.method})
    fig_spy.suptitle("Sparsity of the stiffness Q and mass K matrices (Q φ = λ K φ)", fontsize=9)
    fig_spy.tight_layout()
    fig_phi.suptitle("Leading Laplace–Beltrami eigenfunctions (each scaled to its own range)", fontsize=9)
    fig_phi.subplots_adjust(left=0, right=1, bottom=0.08, top=1 - 0.5 / fig_phi.get_figheight(), wspace=0.0,
                            hspace=0.15)  # half an inch above the panels' titles for the figure's title
    bar = fig_phi.add_axes((0.3, 0.03, 0.4, 0.015))
    fig_phi.colorbar(plt.cm.ScalarMappable(cmap="coolwarm"), cax=bar, orientation="horizontal", ticks=[0, 1])
    bar.set_xticklabels(["min", "max"], fontsize=7)
    bar.set_xlabel("eigenfunction value", fontsize=7)
    return ReportOutput(tables={f"{params.name}_eigenvalues": rows},
                        figures={f"{params.name}_sparsity": fig_spy, f"{params.name}_eigenfunctions": fig_phi})
