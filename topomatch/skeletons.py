"""The skeleton of one mesh: the Python API behind ``topomatch skeleton``.

:func:`skeleton` runs the chain of :data:`topomatch.stages.reeb.recipe.SKELETON_CHAIN` (load,
clean to the largest component, Morse function, level sets, Reeb graph, prune) through the
engine's runner, exactly as ``topomatch skeleton`` and a config do, with the stages' own
defaults for every option not given. :func:`write_skeleton_files` writes what ``--out`` writes.
"""

from __future__ import annotations

import io
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from topomatch.pipeline.config import chain_with
from topomatch.pipeline.mappings import set_path
from topomatch.pipeline.errors import ConfigError, StageError
from topomatch.pipeline.files import atomic_write_bytes
from topomatch.pipeline.item import ItemResult, run_stages
from topomatch.stages.mesh.mesh import Mesh
from topomatch.stages.reeb.recipe import SKELETON_CHAIN

#: The options of a skeleton (stage.param), shared by :func:`skeleton` and ``topomatch skeleton``.
SKELETON_OPTIONS = ("morse.function", "level_sets.levels", "reeb_graph.root_mode", "prune.min_area_fraction")


@dataclass(frozen=True, eq=False)
class Skeleton:
    """The skeleton of one mesh, with the counts ``topomatch skeleton --json`` prints.

    The JSON fields (:meth:`to_dict`) are ``mesh`` (the input's name), ``function``, ``levels``,
    ``n_vertices``, ``n_faces`` (of the cleaned mesh), ``genus``, ``n_boundary_loops`` (0 for a closed mesh; an open
    one's Laplacian has natural, Neumann, boundary conditions), ``n_nodes``, ``n_edges``,
    ``n_endpoints``, ``cycle_rank``, ``reeb_nodes``, ``removed_branches`` (pruning), ``lambda2``
    (Fiedler function only, else None), ``seconds`` (per stage) and ``warnings`` (what makes the
    result doubtful, e.g. a non-manifold mesh; empty when nothing does). Besides them: ``graph`` (the
    pruned skeleton, a networkx MultiGraph with node attributes ``pos``, ``band``, ``value``,
    ``area``, ``members``), ``endpoints`` (its degree-1 nodes), ``reeb`` (the unpruned Reeb graph),
    ``mesh_used`` (the cleaned mesh the function lives on), ``values`` (the Morse function on its
    vertices, (n,)) and ``item`` (every stage result).
    """

    mesh: str
    function: str
    levels: int
    n_vertices: int
    n_faces: int
    genus: int
    n_boundary_loops: int
    n_nodes: int
    n_edges: int
    n_endpoints: int
    cycle_rank: int
    reeb_nodes: int
    removed_branches: int
    lambda2: float | None
    seconds: dict[str, float]
    warnings: list[str]
    graph: Any = field(repr=False)
    endpoints: list = field(repr=False)
    reeb: Any = field(repr=False)
    mesh_used: Mesh = field(repr=False)
    values: Any = field(repr=False)
    item: ItemResult = field(repr=False)

    #: The fields printed by ``--json``, in order.
    JSON_FIELDS = ("mesh", "function", "levels", "n_vertices", "n_faces", "genus", "n_boundary_loops", "n_nodes",
                   "n_edges", "n_endpoints", "cycle_rank", "reeb_nodes", "removed_branches", "lambda2", "seconds",
                   "warnings")

    def to_dict(self) -> dict[str, Any]:
        """The JSON fields as a plain dict."""
        return {k: getattr(self, k) for k in self.JSON_FIELDS}


def skeleton(mesh: Mesh | str | Path, *, function: str | None = None, levels: int | None = None,
             root_mode: str | None = None, min_area_fraction: float | None = None) -> Skeleton:
    """The Reeb-graph skeleton of a mesh (a :class:`Mesh` or a mesh file).

    Parameters
    ----------
    mesh : Mesh or path
        A file is read by the ``load`` stage; a Mesh starts the chain at ``clean``.
    function : {'fiedler', 'mixture', 'euclidean', 'affine', 'height', 'geodesic', 'agd'}, optional
        The Morse function (default: the ``morse`` stage's, the Fiedler vector).
    levels : int, optional
        Number of level-set bands N (default: the ``level_sets`` stage's, 22).
    root_mode : {'first_band', 'nearest', 'none'}, optional
        How the centre joins a rooted function's graph (default: the ``reeb_graph`` stage's).
    min_area_fraction : float, optional
        Prune terminal branches with a smaller area share (default: the ``prune`` stage's, 0.01).

    Returns
    -------
    Skeleton

    Raises
    ------
    InputError
        An unreadable or unusable mesh (names it).
    ConfigError
        An option out of range (names it).
    StageError
        A stage failed (e.g. no eigensolver converged).
    """
    given = {"morse.function": function, "level_sets.levels": levels, "reeb_graph.root_mode": root_mode,
             "prune.min_area_fraction": min_area_fraction}
    overrides: dict[str, dict[str, Any]] = {}
    for path, value in given.items():
        if value is not None:
            set_path(overrides, path, value)
    return skeleton_with(mesh, overrides)


def skeleton_with(mesh: Mesh | str | Path, overrides: dict[str, dict[str, Any]]) -> Skeleton:
    """:func:`skeleton` with the options as ``{stage: {param: value}}`` (what the CLI collects)."""
    chain = chain_with(SKELETON_CHAIN, overrides)
    if isinstance(mesh, Mesh):
        result = run_stages(chain[1:], values={"mesh": mesh}, label=mesh.name)
        name = mesh.name
    else:
        result = run_stages(chain, paths={"path": Path(mesh)})
        name = str(mesh)
    if not result.ok:
        raise StageError(result.error or f"{name}: skeleton failed")
    r = result.results
    morse, level_sets = r["morse"], r["level_sets"]
    reeb, pruned = r["reeb_graph"].reeb, r["prune"].skeleton
    used = result.final("mesh")
    after = r["clean"].after
    warnings = []
    if not after.is_manifold:
        warnings.append(f"the cleaned mesh has {after.n_nonmanifold_edges} non-manifold edges and "
                        f"{after.n_nonmanifold_vertices} non-manifold vertices: its genus is undefined and the "
                        f"Reeb graph's loops need not match a surface (a config with "
                        f"clean: {{fail_on_nonmanifold: true}} refuses such meshes)")
    return Skeleton(
        mesh=name, function=morse.function.kind, levels=level_sets.level_sets.n_levels,
        n_vertices=used.n_vertices, n_faces=used.n_faces, genus=after.genus, n_boundary_loops=after.n_boundary_loops,
        n_nodes=pruned.graph.number_of_nodes(), n_edges=pruned.graph.number_of_edges(),
        n_endpoints=len(pruned.endpoints), cycle_rank=reeb.cycle_rank, reeb_nodes=reeb.n_nodes,
        removed_branches=pruned.removed_branches, lambda2=morse.function.info.get("lambda2"),
        seconds={label: round(s, 6) for label, s in result.seconds.items()}, warnings=warnings,
        graph=pruned.graph, endpoints=list(pruned.endpoints), reeb=reeb, mesh_used=used,
        values=morse.function.values, item=result)


def write_skeleton_files(result: Skeleton, out: str | Path, formats: tuple[str, ...] | list[str] = ("ply",), *,
                         figure: bool = True) -> list[str]:
    """Write the skeleton and the unpruned Reeb graph in each of ``formats`` (``skeleton.ply``,
    ``reeb.ply``, ...: PLY polylines by default, also ``obj``, ``graphml``, ``json``; see
    :mod:`topomatch.stages.reeb.export`) and, with ``figure``, ``skeleton.png`` into ``out``; return
    their paths."""
    from topomatch.stages.reeb.export import SKELETON_FORMATS, write_skeleton

    unknown = [f for f in formats if f not in SKELETON_FORMATS]
    if unknown or not formats:
        raise ConfigError(f"skeleton file formats must be among {', '.join(SKELETON_FORMATS)}, got "
                          f"{', '.join(map(str, unknown)) or 'none'}")
    out = Path(out)
    paths = []
    for fmt in dict.fromkeys(formats):
        for name, graph in (("skeleton", result.graph), ("reeb", result.reeb.graph)):
            paths.append(out / f"{name}.{fmt}")
            write_skeleton(graph, paths[-1])
    if figure:
        paths.append(out / "skeleton.png")
        atomic_write_bytes(paths[-1], skeleton_png(result))
    return [str(p) for p in paths]


def skeleton_png(result: Skeleton, *, dpi: int = 150) -> bytes:
    """The skeleton over its mesh (coloured by the Morse function, endpoints and root marked) as PNG bytes."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from topomatch.stages.reeb.reports import FUNCTION_NAMES, SkeletonGalleryParams, add_skeleton_keys, draw_item

    fig = plt.figure(figsize=(6, 6.8))
    ax = fig.add_axes([0.02, 0.16, 0.96, 0.76])
    caption = draw_item(ax, result.item, SkeletonGalleryParams())
    name = FUNCTION_NAMES.get(result.function, result.function)
    ax.set_title(f"Skeleton of {Path(result.mesh).name} ({name}, {result.levels} levels)\n{caption}", fontsize=9)
    add_skeleton_keys(fig, isolines=True, functions={result.function}, root="root" in result.graph)
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=dpi, bbox_inches="tight")
    plt.close(fig)
    return buf.getvalue()
