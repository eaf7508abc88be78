"""Speed and memory of the mixture-distance skeleton (thesis ch. 3) against mesh size.

Usage::

    .venv/bin/python benchmarks/mixture_skeleton.py [--mesh PATH] [--repeat 5] [--plot docs/figures/...png]

The mesh defaults to the horse of the data root ($TOPOMATCH_DATA_ROOT/meshes/classic/
horse_cyberware.ply, 96,966 faces), else the bundled koala. It is upsampled (libigl midpoint
subdivision) and decimated (fast-simplification) to a ladder of sizes up to 1.3 M faces. For each
size it times, median of ``--repeat`` runs, loading and cleaning excluded:

- the skeleton: mixture distance + level values + Reeb graph (closedness known from ``clean``)
  + pruning, i.e. what ``topomatch skeleton --function mixture`` computes after cleaning;
- the same with the closed-manifold check done inside the Reeb graph;
- the libigl reference ``igl.cotmatrix(V, F)`` on the same mesh (one O(m) sparse assembly),
  so that the ratio skeleton / cotmatrix is comparable across machines.

Peak memory of one skeleton run is measured with tracemalloc (numpy buffers included).
Prints a markdown table and JSON; writes the time-vs-size plot with ``--plot``.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import time
import tracemalloc
from pathlib import Path

import igl
import numpy as np

from topomatch.stages.mesh.decimate import simplify_to_target
from topomatch.stages.mesh.io import read_mesh
from topomatch.stages.morse.mixture import mixture_distance
from topomatch.stages.reeb.level_sets import level_values
from topomatch.stages.reeb.prune import make_skeleton
from topomatch.stages.reeb.reeb_graph import reeb_graph

REPO = Path(__file__).resolve().parents[1]


def skeleton(V, F, closed):
    mf = mixture_distance(V, F)
    R = reeb_graph(V, F, mf.values, level_values(mf.values, 22), root=mf.root, closed=closed)
    return make_skeleton(R, 0.01)


def median_time(fn, repeat):
    times = []
    for _ in range(repeat):
        t = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t)
    return statistics.median(times)


def ladder(V, F, targets):
    """Meshes with about ``targets`` faces: upsample enough, then decimate down."""
    out = []
    for target in targets:
        Vt, Ft = V, F
        while len(Ft) < target:
            Vt, Ft = igl.upsample(Vt, Ft, number_of_subdivs=1)
        if len(Ft) > target * 1.02:
            Vt, Ft, _ = simplify_to_target(Vt, Ft, target)
        out.append((Vt, Ft))
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    root = os.environ.get("TOPOMATCH_DATA_ROOT")
    default = Path(root) / "meshes/classic/horse_cyberware.ply" if root else REPO / "data/meshes/odedstein_koala_low_resolution.obj.gz"
    parser.add_argument("--mesh", type=Path, default=default)
    parser.add_argument("--repeat", type=int, default=5)
    parser.add_argument("--targets", type=int, nargs="+", default=[25_000, 100_000, 400_000, 800_000, 1_300_000])
    parser.add_argument("--plot", type=Path)
    args = parser.parse_args()

    mesh, _ = read_mesh(args.mesh)
    rows = []
    for V, F in ladder(mesh.V, mesh.F, args.targets):
        skeleton(V, F, True)  # warm-up
        t_skel = median_time(lambda: skeleton(V, F, True), args.repeat)
        t_check = median_time(lambda: skeleton(V, F, None), args.repeat)
        t_cot = median_time(lambda: igl.cotmatrix(V, F), args.repeat)
        tracemalloc.start()
        S = skeleton(V, F, True)
        peak = tracemalloc.get_traced_memory()[1]
        tracemalloc.stop()
        rows.append({"faces": len(F), "vertices": len(V), "skeleton_s": t_skel, "with_closed_check_s": t_check,
                     "igl_cotmatrix_s": t_cot, "ratio_to_cotmatrix": t_skel / t_cot, "peak_MiB": peak / 2**20,
                     "nodes": S.graph.number_of_nodes(), "endpoints": len(S.endpoints)})
    print(f"mesh: {args.mesh.name}, median of {args.repeat} runs")
    print("| faces | skeleton (s) | + closed check (s) | igl.cotmatrix (s) | skeleton / cotmatrix | peak MiB |")
    print("|---:|---:|---:|---:|---:|---:|")
    for r in rows:
        print(f"| {r['faces']:,} | {r['skeleton_s']:.3f} | {r['with_closed_check_s']:.3f} | {r['igl_cotmatrix_s']:.3f} "
              f"| {r['ratio_to_cotmatrix']:.2f} | {r['peak_MiB']:.0f} |")
    faces = np.array([r["faces"] for r in rows], float)
    secs = np.array([r["skeleton_s"] for r in rows])
    slope = np.polyfit(np.log(faces), np.log(secs), 1)[0]
    print(f"log-log slope of time vs faces: {slope:.2f} (1.0 = linear)")
    print(json.dumps(rows))
    if args.plot:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt

        fig, ax = plt.subplots(figsize=(5.5, 4))
        ax.plot(faces, secs, "o-", label="mixture skeleton")
        ax.plot(faces, [r["igl_cotmatrix_s"] for r in rows], "s--", label="igl.cotmatrix (reference)")
        ax.plot(faces, secs[-1] * faces / faces[-1], ":", color="gray", label="linear in m")
        ax.set_xscale("log")
        ax.set_yscale("log")
        ax.set_xlabel("faces m")
        ax.set_ylabel("seconds (median)")
        ax.set_title(f"Mixture-distance skeleton, N = 22 ({args.mesh.name})", fontsize=9)
        ax.grid(alpha=0.3, which="both")
        ax.legend(fontsize=8)
        fig.tight_layout()
        fig.savefig(args.plot, dpi=120)
        print(f"wrote {args.plot}")


if __name__ == "__main__":
    main()
