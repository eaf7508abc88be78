"""Report collections from real, artist-made poses (Sumner and Popovic's deformation-transfer meshes).

Usage::

    .venv/bin/python benchmarks/retrieval_sumner.py SOURCES OUT
    topomatch index OUT/sumner --db s.db --labels OUT/sumner/labels.csv; topomatch evaluate --db s.db

``SOURCES`` holds the OBJ files of R. W. Sumner and J. Popovic, "Deformation transfer for triangle
meshes", SIGGRAPH 2004 (academic use; not bundled): ``cat-*.obj`` and ``lion-*.obj`` (10 poses each,
reference included; ``models/highpoly/{cat,lion}-poses.tgz`` of github.com/mickare/
Deformation-Transfer-for-Triangle-Meshes) and ``horse-*.obj``, ``horse_ref.obj`` (11; ``bin/`` of
github.com/Golevka/deformation-transfer), searched recursively. Two collections of the 31 meshes,
classes cat, lion and horse (two similar felines and a horse, every pose made by an artist, not by
this project's ARAP posing): ``sumner`` as they are (the cat and lion meshes are open at the neck
and paws) and ``sumner_open`` with holes cut in 60 % of them (:func:`retrieval_collections.cut_holes`,
seed 18). Report only: built on 2026-12-02 (third session) after the default was chosen.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np
from retrieval_collections import write_member

import topomatch


def build(sources: Path, out: Path, *, open_fraction: float, seed: int) -> int:
    """Write the collection (OFF files and labels.csv) into ``out``; returns the number of meshes."""
    files = sorted(p for p in sources.rglob("*.obj") if p.name.split("-")[0].split("_")[0] in ("cat", "lion", "horse"))
    if not files:
        raise SystemExit(f"{sources}: no cat-*.obj, lion-*.obj or horse-*.obj found")
    out.mkdir(parents=True, exist_ok=True)
    rng = np.random.default_rng(seed)
    rows = ["relative_path,class"]
    for path in files:
        mesh = topomatch.read_mesh(path)
        V, F = np.asarray(mesh.V, float), np.asarray(mesh.F, np.int64)
        rows.append(write_member(out, path.stem, path.name.split("-")[0].split("_")[0], V, F, rng, open_fraction))
    (out / "labels.csv").write_text("\n".join(rows) + "\n")
    return len(rows) - 1


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("sources", type=Path, help="folder with the Sumner OBJ files (searched recursively)")
    ap.add_argument("out", type=Path)
    args = ap.parse_args()
    for name, fraction, seed in (("sumner", 0.0, 0), ("sumner_open", 0.6, 18)):
        print(f"{args.out / name}: {build(args.sources, args.out / name, open_fraction=fraction, seed=seed)} meshes")


if __name__ == "__main__":
    main()
