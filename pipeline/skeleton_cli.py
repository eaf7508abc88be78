"""``topomatch skeleton MESH``: one mesh -> its skeleton, without a config file.

Runs the stage chain load -> clean (largest component) -> morse -> level_sets ->
reeb_graph -> prune through the same item runner as ``topomatch run`` (no cache),
prints a summary or one JSON object, and with ``--out`` writes the skeleton as
GraphML, JSON and an OBJ polyline, the unpruned Reeb graph as GraphML, and a
figure.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

from topomatch.pipeline.errors import InputError, StageError


def skeleton_config(mesh: Path, args: argparse.Namespace) -> dict:
    """The equivalent experiment config (printed with --show-config)."""
    return {
        "name": "skeleton",
        "inputs": {"meshes": [str(mesh)]},
        "stages": [
            "load",
            {"clean": {"components": "largest"}},
            {"morse": {"function": args.function}},
            {"level_sets": {"levels": args.levels}},
            {"reeb_graph": {"root_mode": args.root_mode}},
            {"prune": {"min_area_fraction": args.min_area_fraction}},
        ],
        "executor": {"kind": "local", "workers": 1},
    }


def add_parser(sub) -> None:
    p = sub.add_parser("skeleton", help="compute the Reeb-graph skeleton of one mesh",
                       description="Compute the Reeb-graph skeleton of one mesh (load, clean, Morse function, "
                                   "level sets, Reeb graph, prune) and print its counts.")
    p.add_argument("mesh", help="mesh file (OFF, OBJ, PLY, STL, optionally .gz)")
    p.add_argument("--function", default="fiedler",
                   choices=["fiedler", "mixture", "euclidean", "affine", "height", "geodesic"],
                   help="Morse function (default: fiedler, thesis ch. 4; mixture is ch. 3)")
    p.add_argument("--levels", type=int, default=22, help="number of level-set bands N (default 22)")
    p.add_argument("--min-area-fraction", type=float, default=0.01,
                   help="prune terminal branches with a smaller area share (default 0.01)")
    p.add_argument("--root-mode", default="first_band", choices=["first_band", "nearest", "none"],
                   help="how the centre joins the mixture-distance graph (default: first_band, thesis)")
    p.add_argument("--out", metavar="DIR", help="write skeleton.graphml/.json/.obj, reeb.graphml and skeleton.png")
    p.add_argument("--json", action="store_true", help="print one JSON object on stdout")
    p.set_defaults(handler=cmd_skeleton)


def cmd_skeleton(args: argparse.Namespace) -> int:
    from topomatch.pipeline.config import build_experiment
    from topomatch.pipeline.item import run_item

    mesh_path = Path(args.mesh)
    if not mesh_path.exists():
        raise InputError(mesh_path, "file not found")
    experiment = build_experiment(skeleton_config(mesh_path.resolve(), args))
    (item,) = experiment.items()
    result = run_item(item, None)
    if not result.ok:
        raise StageError(result.error or "failed")
    clean, morse = result.results["clean"], result.results["morse"]
    reeb, skeleton = result.results["reeb_graph"].reeb, result.results["prune"].skeleton
    mesh = result.final("mesh")
    info = morse.function.info
    summary = {
        "mesh": str(mesh_path),
        "function": args.function,
        "levels": args.levels,
        "n_vertices": mesh.n_vertices,
        "n_faces": mesh.n_faces,
        "genus": clean.after.genus,
        "n_nodes": skeleton.graph.number_of_nodes(),
        "n_edges": skeleton.graph.number_of_edges(),
        "n_endpoints": len(skeleton.endpoints),
        "cycle_rank": reeb.cycle_rank,
        "reeb_nodes": reeb.n_nodes,
        "removed_branches": skeleton.removed_branches,
        "lambda2": info.get("lambda2"),
        "seconds": {label: round(s, 6) for label, s in result.seconds.items()},
    }
    if args.out:
        summary["files"] = write_outputs(Path(args.out), result, args)
    if args.json:
        print(json.dumps(summary))
    else:
        for key, value in summary.items():
            print(f"{key:>17}: {value}")
    return 0


def write_outputs(out: Path, result, args) -> list[str]:
    """Skeleton files and a figure in ``out``; returns the paths written."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from topomatch.pipeline.cache import atomic_write_bytes
    from topomatch.pipeline.skeleton_reports import SkeletonGalleryParams, draw_item
    from topomatch.stages.reeb.export import write_graphml, write_json, write_polyline

    out.mkdir(parents=True, exist_ok=True)
    skeleton, reeb = result.results["prune"].skeleton, result.results["reeb_graph"].reeb
    paths = [out / "skeleton.graphml", out / "skeleton.json", out / "skeleton.obj", out / "reeb.graphml",
             out / "skeleton.png"]
    write_graphml(skeleton.graph, paths[0])
    write_json(skeleton.graph, paths[1])
    write_polyline(skeleton.graph, paths[2])
    write_graphml(reeb.graph, paths[3])
    fig = plt.figure(figsize=(6, 6))
    ax = fig.add_subplot(projection="3d")
    caption = draw_item(ax, result, SkeletonGalleryParams())
    ax.set_title(f"{Path(args.mesh).name} ({args.function}, N={args.levels})\n{caption}", fontsize=9)
    import io

    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=120, bbox_inches="tight")
    plt.close(fig)
    atomic_write_bytes(paths[4], buf.getvalue())
    return [str(p) for p in paths]


if __name__ == "__main__":  # pragma: no cover
    from topomatch.pipeline.cli import main

    sys.exit(main())
