"""``topomatch skeleton MESH``: one mesh -> its skeleton, without a config file.

Options come from the stages' params (:data:`topomatch.skeletons.SKELETON_OPTIONS`); the summary or
``--json`` object is :class:`topomatch.skeletons.Skeleton`'s fields; ``--out`` writes the skeleton
and the unpruned Reeb graph as PLY polylines (``--format`` adds or chooses OBJ, GraphML, JSON) and a
figure.
"""

from __future__ import annotations

import argparse

from topomatch.cli.common import command, input_path, path_argument, print_result, warn
from topomatch.pipeline.cli_options import add_options, given_options
from topomatch.pipeline.files import check_writable_folder


def _models() -> dict:
    """The params models of the stages whose options the command exposes (by stage name)."""
    from topomatch.stages.morse.stage import MorseParams
    from topomatch.stages.reeb.level_sets import LevelSetParams
    from topomatch.stages.reeb.prune import PruneParams
    from topomatch.stages.reeb.reeb_graph import ReebParams

    return {"morse": MorseParams, "level_sets": LevelSetParams, "reeb_graph": ReebParams, "prune": PruneParams}


def add_parsers(sub) -> None:
    command(sub, "skeleton", help="compute the Reeb-graph skeleton of one mesh",
            description="Compute the Reeb-graph skeleton of one mesh (load, clean to the largest component, "
                        "Morse function, level sets, Reeb graph, prune) and print its counts.",
            handler=cmd_skeleton, build=_arguments)


def _arguments(p: argparse.ArgumentParser) -> None:
    from topomatch.skeletons import SKELETON_OPTIONS

    p.add_argument("mesh", type=input_path,
                   help="mesh file (OFF, OBJ, PLY, STL, optionally .gz; bundled:NAME for a bundled one)")
    add_options(p, _models(), SKELETON_OPTIONS)
    p.add_argument("--out", type=path_argument, metavar="DIR",
                   help="write skeleton.FMT and reeb.FMT (the unpruned Reeb graph) for each --format, and skeleton.png")
    p.add_argument("--format", dest="formats", type=_formats, default=["ply"], metavar="FMT[,FMT]",
                   help="file formats of --out: ply (polyline, default; open3d and trimesh read its edges), obj "
                        "(polyline), graphml, json (networkx node-link); comma-separated, e.g. ply,graphml")
    p.add_argument("--json", action="store_true", help="print one JSON object on stdout")


def _formats(text: str) -> list[str]:
    """An argparse type: comma-separated skeleton formats."""
    from topomatch.stages.reeb.export import SKELETON_FORMATS

    formats = [f.strip().lower().lstrip(".") for f in text.split(",") if f.strip()]
    bad = [f for f in formats if f not in SKELETON_FORMATS]
    if bad or not formats:
        raise argparse.ArgumentTypeError(f"expected formats among {', '.join(SKELETON_FORMATS)}, got {text!r}")
    return formats


def cmd_skeleton(args: argparse.Namespace) -> int:
    from topomatch.skeletons import SKELETON_OPTIONS, skeleton_with, write_skeleton_files

    if args.out:
        check_writable_folder(args.out)  # before the skeleton is computed, not after
    elif args.formats != ["ply"]:
        warn("--format applies to the files of --out, which is not given: no files are written")
    result = skeleton_with(args.mesh, given_options(args, _models(), SKELETON_OPTIONS))
    summary = result.to_dict()
    if args.out:
        summary["files"] = write_skeleton_files(result, args.out, args.formats)
    print_result(summary, as_json=args.json)
    for warning in result.warnings:
        warn(f"{args.mesh}: {warning}")
    return 0
