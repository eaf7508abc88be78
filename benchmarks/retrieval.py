"""Speed and memory of ranking: one query against an index, the full matrix, a simulated 100k index.

Usage::

    .venv/bin/python benchmarks/retrieval.py [--db w.db --method srg] [--simulated 100000]
    .venv/bin/python benchmarks/retrieval.py --db w.db --method topomatch

With ``--db`` it loads the real descriptors of an index (e.g. SHREC'07 Watertight indexed with
``topomatch index``); otherwise it draws endpoint-feature sets with 0-12 endpoints. It times
(median of ``--repeat``): one query against the whole index (ranking only, the query's descriptor
given), the full n x n dissimilarity matrix, and one query against a simulated index of
``--simulated`` shapes (chunked, so memory stays bounded), with tracemalloc's peak. Reference in
the same process: ``np.argsort`` of n random floats x 1000 (a machine-speed unit).

For a fused method (``topomatch``) the database's part matrices are prepared once (timed
separately: a server keeps them); the query time is then the parts' one-to-many rows, the
scaled sum and the manifold-ranking solve on n + 1 items; the full matrix includes the
re-ranking. The simulated index is then timed for the fusion without re-ranking (agd-like
11-column endpoint sets plus the four vector descriptors), which is linear in its size.

It also times what a user runs: ``topomatch query MESH --db DB --method M --json`` (a new process;
MESH the first indexed shape), first with the database's saved part matrices removed from the
index's cache (as the first query after indexing), then again (they are read back); the command's
own ``ranking`` seconds and the process's wall time are shown.
"""

from __future__ import annotations

import argparse
import json
import statistics
import subprocess
import sys
import time
import tracemalloc

import numpy as np

from topomatch.stages.retrieval.catalogue import get_method
from topomatch.stages.retrieval.descriptor import Descriptor
from topomatch.stages.retrieval.ranking import dissimilarities, dissimilarity_matrix


def median_time(fn, repeat: int) -> float:
    out = []
    for _ in range(repeat):
        t = time.perf_counter()
        fn()
        out.append(time.perf_counter() - t)
    return statistics.median(out)


def simulated(n: int, rng: np.random.Generator) -> list[Descriptor]:
    counts = rng.integers(0, 13, size=n)
    return [Descriptor("endpoints", rng.random((c, 3)), int(c)) for c in counts]


def simulated_fusion(n: int, rng: np.random.Generator) -> dict[str, list[Descriptor]]:
    counts = rng.integers(0, 13, size=n)
    sizes = {"hks": 256, "shapedna": 30, "d2": 64, "sh": 32 * 17}
    out = {"agd": [Descriptor("endpoints", rng.random((c, 11)), int(c)) for c in counts]}
    out.update({m: [Descriptor("vector", rng.random(k)) for _ in range(n)] for m, k in sizes.items()})
    return out


def fused_benchmark(args, rng) -> None:
    from topomatch.retrieval import open_index
    from topomatch.stages.retrieval.fusion import fused_matrix, fused_query, median_scale

    fusion = get_method(args.method).fusion
    rows, parts = open_index(args.db).parts(args.method)
    n = len(rows)
    opts = {p: get_method(p).match_options() for p in fusion.parts}

    def prepare():
        return [dissimilarity_matrix(parts[p], p, opts[p]) for p in fusion.parts]

    t_prepare = median_time(prepare, max(1, args.repeat // 2))
    mats = prepare()

    def query(q=0):
        rows_q = [dissimilarities(parts[p][q], parts[p], p, opts[p]) for p in fusion.parts]
        return fused_query(rows_q, mats, fusion)

    t_query = median_time(query, args.repeat)
    t_matrix = median_time(lambda: fused_matrix(mats, fusion), args.repeat)
    big = simulated_fusion(args.simulated, rng)
    sample = {p: big[p][:500] for p in fusion.parts}
    scales = [median_scale(dissimilarity_matrix(sample[p], p, opts[p])) for p in fusion.parts]
    tracemalloc.start()
    t0 = time.perf_counter()
    total = sum(dissimilarities(big[p][0], big[p], p, opts[p]) / s for p, s in zip(fusion.parts, scales))
    t_big = time.perf_counter() - t0
    peak = tracemalloc.get_traced_memory()[1] / 2**20
    tracemalloc.stop()
    assert total.shape == (args.simulated,)
    x = rng.random(n)
    t_ref = median_time(lambda: [np.argsort(x) for _ in range(1000)], args.repeat)
    command = query_command(args, rows[0].path, [(parts[p], p, opts[p]) for p in fusion.parts])
    print(f"source: {args.db} ({args.method} = {' + '.join(fusion.parts)}, {n} shapes)")
    print("| measurement | seconds | / reference |")
    print("|---|---:|---:|")
    print(f"| database part matrices, once per index ({n} x {n} x {len(mats)}) | {t_prepare:.3f} | "
          f"{t_prepare / t_ref:.1f} |")
    print(f"| one query against {n} (part rows + fusion + manifold ranking) | {t_query:.4f} | {t_query / t_ref:.2f} |")
    print(f"| full {n} x {n} fused, re-ranked matrix (from the part matrices) | {t_matrix:.3f} | {t_matrix / t_ref:.1f} |")
    print(f"| one query against {args.simulated:,} simulated, fusion without re-ranking (peak {peak:.0f} MiB) | "
          f"{t_big:.3f} | {t_big / t_ref:.1f} |")
    for name, (wall, ranking) in command.items():
        print(f"| `topomatch query`, {name}: ranking / whole process | {ranking:.3f} / {wall:.2f} | "
              f"{ranking / t_ref:.1f} / {wall / t_ref:.0f} |")
    print(f"| reference: 1000 x argsort of {n} floats | {t_ref:.4f} | 1 |")


def query_command(args, mesh: str, parts: list[tuple]) -> dict[str, tuple[float, float]]:
    """{"first query" | "repeated query": (process wall seconds, the command's ranking seconds)}, medians:
    the first with the index's saved part matrices removed before each run."""
    from topomatch.pipeline.cache import Cache
    from topomatch.retrieval import cache_dir
    from topomatch.stages.retrieval.ranking import matrix_key

    cache = Cache(cache_dir(args.db))
    saved = [matrix_key(descriptors, p, options) for descriptors, p, options in parts]
    cmd = [sys.executable, "-m", "topomatch", "query", mesh, "--db", args.db, "--method", args.method, "--json"]
    out: dict[str, tuple[float, float]] = {}
    for name, forget in (("first query", True), ("repeated query", False)):
        runs = []
        for _ in range(max(1, args.repeat // 2)):
            if forget:
                for key in saved:
                    cache.remove(key)
            t = time.perf_counter()
            done = subprocess.run(cmd, capture_output=True, text=True, check=True)
            runs.append((time.perf_counter() - t, json.loads(done.stdout)["seconds"]["ranking"]))
        out[name] = (statistics.median(r[0] for r in runs), statistics.median(r[1] for r in runs))
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--db")
    parser.add_argument("--method", default="srg")
    parser.add_argument("--simulated", type=int, default=100_000)
    parser.add_argument("--repeat", type=int, default=5)
    args = parser.parse_args()
    rng = np.random.default_rng(0)
    method = get_method(args.method)
    if method.kind == "fusion":
        if not args.db:
            parser.error(f"--method {args.method} needs --db (an index with all its parts)")
        fused_benchmark(args, rng)
        return
    options = method.match_options()
    if args.db:
        from topomatch.shape_index import ShapeIndex

        with ShapeIndex(args.db) as index:
            rows = index.rows(args.method)
        descriptors = [Descriptor(r.kind, r.descriptor, r.n_endpoints) for r in rows]
        source = f"{args.db} ({args.method}, {len(rows)} shapes)"
    else:
        descriptors = simulated(400, rng)
        source = "400 simulated endpoint sets"
    n = len(descriptors)
    t_query = median_time(lambda: dissimilarities(descriptors[0], descriptors, args.method, options), args.repeat)
    t_matrix = median_time(lambda: dissimilarity_matrix(descriptors, args.method, options), max(1, args.repeat // 2))
    big = simulated(args.simulated, rng)
    tracemalloc.start()
    t0 = time.perf_counter()
    dissimilarities(big[0], big, "srg", options)
    t_big = time.perf_counter() - t0
    peak = tracemalloc.get_traced_memory()[1] / 2**20
    tracemalloc.stop()
    x = rng.random(n)
    t_ref = median_time(lambda: [np.argsort(x) for _ in range(1000)], args.repeat)
    print(f"source: {source}")
    print("| measurement | seconds | / reference |")
    print("|---|---:|---:|")
    print(f"| one query against {n} (ranking) | {t_query:.4f} | {t_query / t_ref:.2f} |")
    print(f"| full {n} x {n} matrix | {t_matrix:.3f} | {t_matrix / t_ref:.1f} |")
    print(f"| one query against {args.simulated:,} simulated (peak {peak:.0f} MiB) | {t_big:.3f} | {t_big / t_ref:.1f} |")
    print(f"| reference: 1000 x argsort of {n} floats | {t_ref:.4f} | 1 |")


if __name__ == "__main__":
    main()
