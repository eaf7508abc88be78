"""Queries against a large index: the approximate-nearest-neighbour shortlist against exact ranking.

Usage::

    .venv/bin/python benchmarks/retrieval_large.py --db w.db [--shapes 100000] [--queries 30] [--json F]

``--db``: an index with the parts of the default method (e.g. SHREC'07 Watertight, ``topomatch index``).
Its real descriptors are copied with noise into a simulated index of ``--shapes`` shapes (each copy:
every vector part plus 5 % of that coordinate's spread in Gaussian noise, clipped at 0; every
endpoint feature plus 2 % noise), so the large index has the structure of real shapes (clusters of
near-duplicates around each of them). Queries are fresh noisy copies, not in the index.

For each query, in the same process: the **exact** fused ranking over the whole index (every kept
part's dissimilarities to all shapes, scaled and order-weighted: what a query would cost without a
shortlist) and the **shortlisted** one (:func:`topomatch.stages.retrieval.shortlist.shortlisted_dissimilarities`,
the function ``Collection.query`` uses on large indexes). Reported: median seconds of each, their
ratio, recall@10 of the shortlisted top 10 against the exact top 10, the graph's build time and
size, and tracemalloc's peak during a shortlisted query.
"""

from __future__ import annotations

import argparse
import json
import statistics
import time
import tracemalloc
from pathlib import Path

import numpy as np

from topomatch.retrieval import open_index
from topomatch.stages.retrieval.catalogue import DEFAULT_METHOD, get_method
from topomatch.stages.retrieval.descriptor import Descriptor
from topomatch.stages.retrieval.fusion import fuse, scale_factor
from topomatch.stages.retrieval.ranking import dissimilarities
from topomatch.stages.retrieval.shortlist import (SHORTLIST, Shortlist, sample_fusion, shortlisted_dissimilarities,
                                                  vector_parts)


def noisy_copies(descriptors: dict[str, list[Descriptor]], sources: np.ndarray,
                 rng: np.random.Generator) -> dict[str, list[Descriptor]]:
    """Copies of the shapes ``sources`` with noise (module docstring)."""
    out = {}
    for part, ds in descriptors.items():
        if ds[0].kind == "vector":
            X = np.stack([d.data.ravel() for d in ds])
            Y = np.maximum(X[sources] + 0.05 * X.std(axis=0) * rng.normal(size=(len(sources), X.shape[1])), 0)
            out[part] = [Descriptor("vector", y) for y in Y]
        else:
            out[part] = [Descriptor("endpoints", ds[s].data + 0.02 * rng.normal(size=ds[s].data.shape),
                                    ds[s].n_endpoints) for s in sources]
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--db", required=True)
    ap.add_argument("--shapes", type=int, default=100_000)
    ap.add_argument("--queries", type=int, default=30)
    ap.add_argument("--query-seed", type=int, default=2,
                    help="seed of the queries (1: the tuning queries that chose SHORTLIST; 2: the report queries)")
    ap.add_argument("--shortlists", type=int, nargs="+", default=[SHORTLIST],
                    help="shortlist lengths to measure on the same index and queries")
    ap.add_argument("--json")
    args = ap.parse_args()
    rng = np.random.default_rng(0)
    method = get_method(DEFAULT_METHOD)
    fusion = method.fusion
    rows, real = open_index(args.db).parts(DEFAULT_METHOD)
    options = {p: get_method(p).match_options() for p in fusion.parts}
    database = noisy_copies(real, rng.integers(0, len(rows), args.shapes), rng)
    t = time.perf_counter()
    scales, decision = sample_fusion(database, fusion, options.get)
    t_sample = time.perf_counter() - t
    parts = vector_parts(decision)
    keys = np.arange(args.shapes, dtype=np.uint64)
    t = time.perf_counter()
    ann = Shortlist.build(keys, {p: np.stack([d.data.ravel() for d in database[p]]) for p in parts},
                          {p: scales[p] for p in parts})
    t_build = time.perf_counter() - t
    qrng = np.random.default_rng([1000, args.query_seed])  # queries independent of the database's draw
    queries = noisy_copies(real, qrng.integers(0, len(rows), args.queries), qrng)
    t_exact, exact_top = [], []
    for q in range(args.queries):
        query = {p: queries[p][q] for p in fusion.parts}
        t = time.perf_counter()
        exact = fuse([dissimilarities(query[p], database[p], p, options[p]) for p in decision.kept],
                     [scales[p] * scale_factor(fusion, decision, p) for p in decision.kept], fusion.order_weights)
        t_exact.append(time.perf_counter() - t)
        exact_top.append(set(np.argsort(exact, kind="stable")[:10].tolist()))
    result = {"shapes": args.shapes, "queries": args.queries, "query_seed": args.query_seed,
              "kept": list(decision.kept), "embedded": list(parts), "default_shortlist": SHORTLIST,
              "sample_seconds": t_sample, "build_seconds": t_build, "exact_seconds": statistics.median(t_exact),
              "shortlists": []}
    print(f"simulated index: {args.shapes:,} shapes from {args.db} ({len(rows)} real); kept {', '.join(decision.kept)}; "
          f"embedded {', '.join(parts)}; {args.queries} queries, seed {args.query_seed}")
    print(f"scales and screening from a sample of 1,000 (once per index): {t_sample:.2f} s; "
          f"HNSW graph build (once; then incremental): {t_build:.1f} s; "
          f"one query, exact fused ranking over all shapes (median, the reference): {result['exact_seconds']:.3f} s")
    print("| shortlist | one query (median) | speed-up over exact | recall@10 (mean; worst query) | peak memory |")
    print("|---:|---:|---:|---:|---:|")
    for count in args.shortlists:
        t_short, recall, peak = [], [], []
        for q in range(args.queries):
            query = {p: queries[p][q] for p in fusion.parts}
            tracemalloc.start()
            t = time.perf_counter()
            short = shortlisted_dissimilarities(query, database, fusion, ann, keys, scales, decision, options.get,
                                                count)
            t_short.append(time.perf_counter() - t)
            peak.append(tracemalloc.get_traced_memory()[1] / 2**20)
            tracemalloc.stop()
            recall.append(len(exact_top[q] & set(np.argsort(short, kind="stable")[:10].tolist())) / 10)
        row = {"shortlist": count, "shortlisted_seconds": statistics.median(t_short),
               "recall_at_10": float(np.mean(recall)), "recall_at_10_min": float(np.min(recall)),
               "peak_mib": float(np.max(peak))}
        result["shortlists"].append(row)
        print(f"| {count} | {row['shortlisted_seconds']:.4f} s | {result['exact_seconds'] / row['shortlisted_seconds']:.0f}x "
              f"| {row['recall_at_10']:.3f}; {row['recall_at_10_min']:.1f} | {row['peak_mib']:.1f} MiB |")
    if args.json:
        Path(args.json).write_text(json.dumps(result, indent=1))


if __name__ == "__main__":
    main()
