"""The stage cache's typed format against pickle, on real stage results (a measurement, not a test).

Usage::

    TOPOMATCH_DATA_ROOT=../shared/data .venv/bin/python benchmarks/cache_codec.py [--every 20]

Runs the Watertight config's chain (every retrieval descriptor, skeletons included) on every
``--every``-th SHREC'07 Watertight mesh, then writes and reads every stage result with
:mod:`topomatch.pipeline.codec` and with pickle (the reference, in the same process; pickle is
what the cache used before and what it must never load again). Prints the total load and dump
times and sizes. Without the data root it uses the bundled meshes.
"""

from __future__ import annotations

import argparse
import glob
import os
import pickle
import time
from pathlib import Path

import yaml

from topomatch.pipeline import codec
from topomatch.pipeline.config import build_experiment
from topomatch.pipeline.item import run_item

REPO = Path(__file__).resolve().parents[1]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--every", type=int, default=20, help="every n-th Watertight mesh (default 20: 20 meshes)")
    args = parser.parse_args()
    root = os.environ.get("TOPOMATCH_DATA_ROOT")
    files = sorted(glob.glob(f"{root}/meshes/shrec07_watertight/*/*.off.gz"))[:: args.every] if root else []
    files = files or sorted(str(p) for p in (REPO / "data" / "meshes").glob("*.obj.gz"))
    stages = yaml.safe_load((REPO / "configs" / "retrieval" / "watertight.yaml").read_text())["stages"]
    experiment = build_experiment({"name": "codec", "inputs": {"meshes": files}, "stages": stages,
                                   "executor": {"workers": 1}})
    results = [r for item in experiment.items() for r in run_item(item, None).results.values()]

    def measure(dump, load) -> tuple[float, float, int]:
        t = time.perf_counter()
        blobs = [dump(v) for v in results]
        t_dump = time.perf_counter() - t
        t = time.perf_counter()
        for b in blobs:
            load(b)
        return t_dump, time.perf_counter() - t, sum(map(len, blobs))

    ours = measure(codec.dumps, codec.loads)
    ref = measure(lambda v: pickle.dumps(v, protocol=pickle.HIGHEST_PROTOCOL), pickle.loads)
    print(f"{len(results)} stage results of {len(files)} meshes")
    print("| format | dump (s) | load (s) | size (MiB) |")
    print("|---|---:|---:|---:|")
    for name, (d, l, n) in (("codec (.npz + JSON)", ours), ("pickle (reference)", ref)):
        print(f"| {name} | {d:.3f} | {l:.3f} | {n / 2**20:.1f} |")
    print(f"| ratio | {ours[0] / ref[0]:.2f} | {ours[1] / ref[1]:.2f} | {ours[2] / ref[2]:.2f} |")


if __name__ == "__main__":
    main()
