"""Speed of the baseline descriptors (D2, spherical harmonics, ShapeDNA) and, optionally, their
retrieval quality on SHREC'07 Watertight.

Usage::

    .venv/bin/python benchmarks/baselines.py [--repeat 5] [--meshes NAME ...] [--json OUT]
    OMP_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1 .venv/bin/python benchmarks/baselines.py --watertight [--workers 2] [--variants] [--json OUT]

(one BLAS thread per worker process: two workers on two cores are already a full load, and
threaded BLAS inside ARPACK would oversubscribe the cores).

Timing: each descriptor (default parameters) on a few bundled meshes of ``data/meshes``, run
``--repeat`` times after one warm-up, interleaved; the median wall time is reported as a
markdown table. Loading is excluded. Then the 400 x 400 distance matrix of each baseline
(random descriptors of the default sizes) and :func:`~topomatch.stages.retrieval.metrics.retrieval_metrics`
on it. Medians (not minima) are reported: on a shared machine single runs vary by 2-10x.

``--watertight`` computes the three descriptors for the 400 meshes of
``$TOPOMATCH_DATA_ROOT/meshes/shrec07_watertight`` (``labels.csv``), each first cleaned with
the ``clean`` stage's defaults (merge duplicates, drop degenerate faces: bearing/351 has five
zero-area triangles that the Laplacian rejects), in ``--workers`` processes, then the full dissimilarity matrices and the PSB metrics
(:func:`topomatch.stages.retrieval.metrics.retrieval_metrics`), printed as one markdown table.
``--variants`` adds ShapeDNA with ``normalization='area'`` and k = 50 and D2 with 128
bins (the variants reuse the sampled distances and the eigenvalues, so the per-mesh time of
a variant is only its extra work). Nothing is written unless ``--json`` is given.

Recorded results (2 shared cores, Python 3.11, numpy 2.4, one BLAS thread, 5 repeats)
------------------------------------------------------------------------------------
Descriptor time, median ms: D2 91-100, spherical harmonics 58-62 (both nearly independent of
the mesh size: they work on 2^19 / 2^17 surface samples), ShapeDNA (k = 30) 13 ms on 810
vertices, 48 on 3.6k, 93-122 on 7-8k. The 400 x 400 distance matrix: D2 2.7 ms, SH 24 ms,
ShapeDNA 1.3 ms; ``retrieval_metrics`` on it 9.5 ms.

SHREC'07 Watertight, 400 meshes, default parameters (micro = macro: 20 classes of 20)::

    method                    NN     FT     ST     E      DCG    mAP    s/mesh
    d2                        0.725  0.366  0.523  0.360  0.706  0.405  0.17
    spherical_harmonics       0.805  0.358  0.484  0.336  0.703  0.403  0.09
    shapedna (lambda A / i)   0.850  0.499  0.651  0.457  0.802  0.561  0.35 (k = 50 computed)
    d2, 128 bins              0.728  0.368  0.524  0.360  0.706  0.406
    shapedna, lambda A        0.750  0.399  0.530  0.371  0.720  0.435
    shapedna, k = 50          0.870  0.512  0.653  0.463  0.805  0.571
    shapedna, k = 50, lambda A 0.720 0.408  0.539  0.379  0.720  0.444

All 400 descriptors of the three methods took 204 s with 2 workers (load included).
"""

from __future__ import annotations

import argparse
import csv
import json
import os
import platform
import statistics
import sys
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

from topomatch.stages.mesh.clean import CleanParams, clean_mesh  # noqa: E402
from topomatch.stages.mesh.io import read_mesh  # noqa: E402
from topomatch.stages.retrieval.baselines import d2, shapedna, spherical_harmonics  # noqa: E402
from topomatch.stages.retrieval.metrics import METRIC_NAMES, retrieval_metrics  # noqa: E402

#: The baselines measured here: name -> (module with descriptor / distance_matrix, params type).
BASELINES = {"d2": (d2, d2.D2Params),
             "spherical_harmonics": (spherical_harmonics, spherical_harmonics.SphericalHarmonicsParams),
             "shapedna": (shapedna, shapedna.ShapeDNAParams)}

DEFAULT_MESHES = ("torus.off", "odedstein_hand_lowres.obj.gz", "odedstein_koala_low_resolution.obj.gz",
                  "odedstein_human_man.obj.gz", "odedstein_cat-low-resolution.obj.gz",
                  "odedstein_hand_closed.obj.gz")


def time_descriptors(names: list[str], repeat: int) -> list[dict]:
    rows = []
    for name in names:
        mesh, _ = read_mesh(REPO / "data" / "meshes" / name)
        row = {"mesh": name, "vertices": mesh.n_vertices, "faces": mesh.n_faces}
        times: dict[str, list[float]] = {k: [] for k in BASELINES}
        for b, P in BASELINES.values():  # warm-up (imports, cached tables)
            b.descriptor(mesh, P())
        for _ in range(repeat):
            for key, (b, P) in BASELINES.items():
                params = P()
                start = time.perf_counter()
                b.descriptor(mesh, params)
                times[key].append(time.perf_counter() - start)
        for key, ts in times.items():
            row[f"{key}_ms"] = 1000 * statistics.median(ts)
        rows.append(row)
    return rows


def timing_table(rows: list[dict]) -> str:
    keys = list(BASELINES)
    lines = ["| mesh | vertices | faces | " + " | ".join(f"{k} (ms)" for k in keys) + " |",
             "|---|---:|---:|" + "---:|" * len(keys)]
    for r in rows:
        lines.append(f"| {r['mesh']} | {r['vertices']} | {r['faces']} | "
                     + " | ".join(f"{r[f'{k}_ms']:.0f}" for k in keys) + " |")
    return "\n".join(lines)


def time_matrices(repeat: int, n: int = 400, classes: int = 20) -> list[dict]:
    """Median time of the n x n distance matrix of each baseline (random descriptors of the default
    shapes) and of :func:`retrieval_metrics` on it."""
    rng = np.random.default_rng(0)
    shapes = {"d2": (64,), "spherical_harmonics": (32, 17), "shapedna": (30,)}
    labels = np.repeat(np.arange(classes), n // classes)
    rows = []
    for key, shape in shapes.items():
        X = rng.random((n, *shape))
        ts = []
        for _ in range(repeat):
            start = time.perf_counter()
            D = BASELINES[key][0].distance_matrix(X)
            ts.append(time.perf_counter() - start)
        rows.append({"what": f"{key} distance_matrix ({n} x {n})", "ms": 1000 * statistics.median(ts)})
    ts = []
    for _ in range(repeat):
        start = time.perf_counter()
        retrieval_metrics(D, labels)
        ts.append(time.perf_counter() - start)
    rows.append({"what": f"retrieval_metrics ({n} x {n}, {classes} classes)", "ms": 1000 * statistics.median(ts)})
    return rows


# --------------------------------------------------------------------------- Watertight


def _variants(with_variants: bool) -> dict[str, tuple[str, object]]:
    """label -> (baseline, params) of the methods evaluated on Watertight."""
    out = {name: (name, P()) for name, (_, P) in BASELINES.items()}
    if with_variants:
        out["d2_128bins"] = ("d2", d2.D2Params(bins=128))
        out["shapedna_area"] = ("shapedna", shapedna.ShapeDNAParams(normalization="area"))
        out["shapedna_k50"] = ("shapedna", shapedna.ShapeDNAParams(k=50))
        out["shapedna_k50_area"] = ("shapedna", shapedna.ShapeDNAParams(k=50, normalization="area"))
    return out


def _describe(args: tuple[str, bool]) -> dict[str, object]:
    """All descriptors of one mesh. Variants reuse the expensive part: the D2 distances are
    histogrammed with each bin count, and the eigenvalues are computed once for the largest k
    (the k smallest are the same whatever k) and normalised each way."""
    path, with_variants = args
    mesh = clean_mesh(read_mesh(path)[0], CleanParams()).mesh  # e.g. bearing/351 has 5 zero-area triangles
    variants = _variants(with_variants)
    out: dict[str, object] = {}
    cache: dict[str, object] = {}
    k_max = max(p.k for base, p in variants.values() if base == "shapedna")
    for label, (base, params) in variants.items():
        start = time.perf_counter()
        try:
            if base == "d2":
                if "d2" not in cache:
                    cache["d2"] = d2.distances(mesh, params)
                x = cache["d2"]
                k = np.minimum((x * (params.bins / params.max_distance)).astype(np.int64), params.bins - 1)
                out[label] = np.bincount(k, minlength=params.bins) / float(x.shape[0])
            elif base == "shapedna":
                if "dna" not in cache:
                    cache["dna"] = shapedna.eigenvalues(mesh, k_max, params.mass)
                vals, area = cache["dna"]
                out[label] = shapedna.normalize(vals[:params.k], area, params.normalization)
            else:
                out[label] = BASELINES[base][0].descriptor(mesh, params)
        except Exception as exc:  # a bad mesh must not stop the others; reported below
            out[label] = f"{type(exc).__name__}: {exc}"  # text: not every exception type pickles
        out[label + "_s"] = time.perf_counter() - start
    return out


def watertight(root: Path, workers: int, with_variants: bool) -> tuple[str, dict]:
    folder = root / "meshes" / "shrec07_watertight"
    with open(folder / "labels.csv", newline="") as fh:
        entries = list(csv.DictReader(fh))
    paths = [str(folder / e["relative_path"]) for e in entries]
    labels = np.array([e["class"] for e in entries])
    start = time.perf_counter()
    with ProcessPoolExecutor(max_workers=workers) as pool:
        results = list(pool.map(_describe, [(p, with_variants) for p in paths], chunksize=4))
    wall = time.perf_counter() - start
    lines = ["| method | avg | NN | FT | ST | E | DCG | mAP | s/mesh |", "|---|---|" + "---:|" * 7]
    summary: dict[str, dict] = {"n": len(paths), "wall_seconds": wall, "workers": workers, "methods": {}}
    for label, (base, _) in _variants(with_variants).items():
        ok = [i for i, r in enumerate(results) if not isinstance(r[label], str)]
        failed = {paths[i]: str(results[i][label]) for i in range(len(paths)) if i not in set(ok)}
        X = np.stack([results[i][label] for i in ok])
        t0 = time.perf_counter()
        D = BASELINES[base][0].distance_matrix(X)
        t_matrix = time.perf_counter() - t0
        m = retrieval_metrics(D, labels[ok])
        per_mesh = statistics.median(results[i][label + "_s"] for i in ok)
        for avg, vals in (("micro", m.micro), ("macro", m.macro)):
            lines.append(f"| {label} | {avg} | " + " | ".join(f"{vals[k]:.3f}" for k in METRIC_NAMES)
                         + f" | {per_mesh:.3f} |")
        summary["methods"][label] = {"micro": m.micro, "macro": m.macro, "micro_pr": m.micro_pr.tolist(),
                                     "median_seconds_per_mesh": per_mesh, "matrix_seconds": t_matrix,
                                     "failed": failed}
    return "\n".join(lines), summary


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeat", type=int, default=5)
    ap.add_argument("--meshes", nargs="*", default=list(DEFAULT_MESHES))
    ap.add_argument("--watertight", action="store_true", help="also evaluate on SHREC'07 Watertight")
    ap.add_argument("--data-root", default=os.environ.get("TOPOMATCH_DATA_ROOT"))
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--variants", action="store_true", help="with --watertight: also parameter variants")
    ap.add_argument("--json", type=Path, help="write the results as JSON to this file")
    args = ap.parse_args(argv)

    print(f"python {platform.python_version()}, numpy {np.__version__}, {os.cpu_count()} CPUs\n")
    rows = time_descriptors(args.meshes, args.repeat)
    print(f"Median wall time of one descriptor (default parameters, {args.repeat} repeats):\n")
    print(timing_table(rows))
    matrices = time_matrices(args.repeat)
    print("\n| step | median (ms) |\n|---|---:|")
    for r in matrices:
        print(f"| {r['what']} | {r['ms']:.1f} |")
    result: dict = {"timing": rows, "matrices": matrices}
    if args.watertight:
        if not args.data_root:
            print("\n--watertight needs --data-root or TOPOMATCH_DATA_ROOT (e.g. ../shared/data)", file=sys.stderr)
            return 2
        table, summary = watertight(Path(args.data_root), args.workers, args.variants)
        print(f"\nSHREC'07 Watertight ({summary['n']} meshes, {summary['workers']} workers, "
              f"{summary['wall_seconds']:.0f} s for all descriptors):\n")
        print(table)
        for label, s in summary["methods"].items():
            if s["failed"]:
                print(f"\n{label}: {len(s['failed'])} meshes failed: {s['failed']}")
        result["watertight"] = summary
    if args.json:
        args.json.write_text(json.dumps(result, indent=1))
        print(f"\nwrote {args.json}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
