"""Speed and memory of ranking: one query against an index, the full matrix, a simulated 100k index.

Usage::

    .venv/bin/python benchmarks/retrieval.py [--db w.db --method srg] [--simulated 100000]

With ``--db`` it loads the real descriptors of an index (e.g. SHREC'07 Watertight indexed with
``topomatch index``); otherwise it draws endpoint-feature sets with 0-12 endpoints. It times
(median of ``--repeat``): one query against the whole index (ranking only, the query's descriptor
given), the full n x n dissimilarity matrix, and one query against a simulated index of
``--simulated`` shapes (chunked, so memory stays bounded), with tracemalloc's peak. Reference in
the same process: ``np.argsort`` of n random floats x 1000 (a machine-speed unit).
"""

from __future__ import annotations

import argparse
import statistics
import time
import tracemalloc

import numpy as np

from stages.retrieval.descriptor import Descriptor, MatchOptions
from stages.retrieval.ranking import dissimilarities, dissimilarity_matrix


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


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--db")
    parser.add_argument("--method", default="srg")
    parser.add_argument("--simulated", type=int, default=100_000)
    parser.add_argument("--repeat", type=int, default=5)
    args = parser.parse_args()
    rng = np.random.default_rng(0)
    options = MatchOptions(unmatched_cost=0.2)
    if args.db:
        from pipeline.shape_index import ShapeIndex

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
