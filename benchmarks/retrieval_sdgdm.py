"""SD-GDM alone: its settings chosen on the tune side, then reported (issue 29).

Usage::

    TOPOMATCH_DATA_ROOT=../shared/data .venv/bin/python benchmarks/retrieval_sdgdm.py \\
        --watertight ../shared/data/meshes/shrec07_watertight \\
        --tune /tmp/stress/{strong_tune,similar_tune,hard_tune2,twins_tune,hires_tune} \\
        --report /tmp/stress/{similar_report,fresh2_report_open,twins_report,hires_report} \\
        --points 64 128 --cache /tmp/sdgdm_cache --json benchmarks/results/retrieval_sdgdm.json

Each folder holds meshes and a ``labels.csv``. Every mesh goes through the ``sdgdm`` method's prefix (``--mesh
full``: cleaned, holes capped; ``decimated``: the intrinsic parts' 6,000-face copy, the first version; cached by the
pipeline under ``--cache``, the spectra too), then its geodesic
distance matrix of ``max(--points)`` farthest-point samples is computed once; the smaller sample counts are its
leading rows and columns (farthest-point sampling is incremental). The variants (samples, k, distance on the
ratios or on their logarithms) are then pure array work. The rule, fixed before any number was read: on the tune
side (the tune collections and Watertight half A: the even-indexed classes, sorted by name), the variant with the
best mean mAP, ties within 0.005 going to the cheaper (fewer samples, then smaller k).
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import numpy as np

from topomatch.pipeline.item import run_stages
from topomatch.stages.retrieval.baselines import sdgdm
from topomatch.stages.retrieval.catalogue import INTRINSIC_MESH_CHAIN, SDGDM_MESH_CHAIN
from topomatch.stages.retrieval.labels import read_labels
from topomatch.stages.retrieval.metrics import retrieval_metrics
from topomatch.stages.retrieval.baselines.vectors import pairwise


def collection_spectra(folder: Path, points: int, cache: str, chain) -> tuple[list[str], np.ndarray, dict, list[float]]:
    """Labels, singular values (n, points) of the leading-sample matrices for each sample count, seconds per mesh."""
    labels = read_labels(folder / "labels.csv")
    names, spectra, seconds = [], {}, []
    for path, label in sorted(labels.items()):
        r = run_stages(chain, paths={"path": path}, cache_root=cache)
        if not r.ok:
            raise SystemExit(f"{path}: {r.error}")
        mesh = list(r.results.values())[-1].mesh
        t = time.perf_counter()
        _, G = sdgdm.geodesic_distance_matrix(mesh, points)
        seconds.append(time.perf_counter() - t)
        names.append(label)
        for p in POINTS:
            if p <= points:
                s = np.sort(np.abs(np.linalg.eigvalsh(G[:p, :p])))[::-1]
                spectra.setdefault(p, []).append(s)
    return names, {p: np.array(v) for p, v in spectra.items()}, seconds


POINTS = [64, 128, 256]
KS = (5, 10, 20, 40)
DISTANCES = ("l2", "log")


def matrix(S: np.ndarray, k: int, dist: str) -> np.ndarray:
    X = S[:, 1:k] / S[:, :1]
    if dist == "log":
        X = np.log(np.maximum(X, sdgdm.LOG_FLOOR))
    return pairwise(X, metric="euclidean")


def scores(D: np.ndarray, labels) -> tuple[float, float]:
    m = retrieval_metrics(D, np.asarray(labels))
    return float(m.micro["nn"]), float(m.micro["map"])


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--watertight", type=Path)
    ap.add_argument("--tune", type=Path, nargs="*", default=[])
    ap.add_argument("--report", type=Path, nargs="*", default=[])
    ap.add_argument("--only-spectra", action="store_true", help="compute and save the spectra, no table")
    ap.add_argument("--cache", default="/tmp/sdgdm_cache")
    ap.add_argument("--json", type=Path)
    ap.add_argument("--mesh", choices=("full", "decimated"), default="full",
                    help="the method's mesh (cleaned, holes capped), or the intrinsic parts' 6,000-face copy")
    ap.add_argument("--points", type=int, nargs="*", default=list(POINTS), help="sample counts of the grid")
    args = ap.parse_args()
    POINTS[:] = args.points
    points = max(POINTS)
    chain = SDGDM_MESH_CHAIN if args.mesh == "full" else INTRINSIC_MESH_CHAIN
    data = {}
    for folder in [f for f in (args.watertight, *args.tune, *args.report) if f is not None]:
        t = time.perf_counter()
        saved = Path(args.cache) / f"sdgdm_spectra_{folder.name}_{args.mesh}_{points}.npz"  # the spectra, for re-runs
        if saved.exists():
            z = np.load(saved)
            data[folder.name] = (list(z["labels"]), {p: z[f"s{p}"] for p in POINTS}, list(z["seconds"]))
        else:
            data[folder.name] = collection_spectra(folder, points, args.cache, chain)
            saved.parent.mkdir(parents=True, exist_ok=True)
            np.savez(saved, labels=np.array(data[folder.name][0]), seconds=np.array(data[folder.name][2]),
                     **{f"s{p}": S for p, S in data[folder.name][1].items()})
        print(f"{folder.name}: {len(data[folder.name][0])} meshes, {time.perf_counter() - t:.0f} s, geodesic matrix of "
              f"{points} samples: median {np.median(data[folder.name][2]):.3f} s per mesh", flush=True)
    if args.only_spectra:
        return
    wt_labels, wt_spectra, _ = data[args.watertight.name]
    classes = sorted(set(wt_labels))
    half_a = np.isin(wt_labels, classes[0::2])
    colls = {}  # name -> (labels, {p: spectra}, side)
    colls["Watertight half A"] = ([l for l, a in zip(wt_labels, half_a) if a], {p: S[half_a] for p, S in wt_spectra.items()}, "tune")
    colls["Watertight half B"] = ([l for l, a in zip(wt_labels, half_a) if not a], {p: S[~half_a] for p, S in wt_spectra.items()}, "report")
    colls["Watertight"] = (wt_labels, wt_spectra, "report")
    for f in args.tune:
        colls[f.name] = (data[f.name][0], data[f.name][1], "tune")
    for f in args.report:
        colls[f.name] = (data[f.name][0], data[f.name][1], "report")
    rows = []
    for p in POINTS:
        for k in KS:
            for dist in DISTANCES:
                res = {name: scores(matrix(S[p], k, dist), labels) for name, (labels, S, _) in colls.items()}
                tune_map = float(np.mean([res[n][1] for n, c in colls.items() if c[2] == "tune"]))
                rows.append({"points": p, "k": k, "distance": dist, "tune_mean_map": tune_map, "results": res})
    best = max(r["tune_mean_map"] for r in rows)
    chosen = min((r for r in rows if r["tune_mean_map"] >= best - 0.005), key=lambda r: (r["points"], r["k"]))
    names = list(colls)
    print("| points | k | distance | tune mean mAP | " + " | ".join(f"{n} ({colls[n][2]})" for n in names) + " |")
    print("|---" * (4 + len(names)) + "|")
    for r in rows:
        mark = "**" if r is chosen else ""
        print(f"| {mark}{r['points']} | {r['k']} | {r['distance']}{mark} | {r['tune_mean_map']:.3f} | "
              + " | ".join(f"{r['results'][n][0]:.3f} / {r['results'][n][1]:.3f}" for n in names) + " |")
    print(f"chosen: {chosen['points']} points, k = {chosen['k']}, {chosen['distance']}")
    if args.json:
        costs = {n: float(np.median(v[2])) for n, v in data.items()}
        args.json.write_text(json.dumps({"rows": rows, "chosen": {k: chosen[k] for k in ("points", "k", "distance")},
                                         "mesh": args.mesh, "median_seconds_per_mesh_geodesics_of_max_points": costs}, indent=1))


if __name__ == "__main__":
    main()
