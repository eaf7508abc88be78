"""``topomatch match | index | query | evaluate``: shape matching and retrieval from the command line.

- ``match A B``: dissimilarity of two meshes, the endpoint correspondence, both endpoint counts.
- ``index PATHS... --db FILE``: descriptors of a collection into a SQLite index
  (:mod:`topomatch.pipeline.shape_index`), computed through the pipeline's executors and stage cache
  (``FILE.cache/``); unchanged meshes are skipped, an interrupted index resumes, a bad mesh is
  recorded as failed with its reason.
- ``query MESH --db FILE``: the ranked list of the closest indexed shapes.
- a fused method (``--method topomatch``, :mod:`topomatch.stages.retrieval.fusion`) indexes each of its
  parts and ranks by their fused, re-ranked dissimilarities.
- ``evaluate --db FILE``: the full dissimilarity matrix of the labelled rows, PSB metrics, and
  the matrix written to an ``.npz`` file.
"""

from __future__ import annotations

import argparse
import hashlib
import json
import sys
import time
from pathlib import Path

import numpy as np

from topomatch.pipeline.errors import ConfigError, InputError, StageError

MESH_SUFFIXES = (".off", ".obj", ".ply", ".stl")


def _method_args(p: argparse.ArgumentParser, default: str = "srg") -> None:
    from topomatch.stages.retrieval.fusion import FUSIONS
    from topomatch.stages.retrieval.methods import METHODS

    p.add_argument("--method", default=default, choices=sorted(METHODS) + sorted(FUSIONS),
                   help=f"descriptor: rgpd (mixture-distance skeleton, thesis ch. 3), srg (Fiedler skeleton, ch. 4), "
                        f"agd (intrinsic skeleton + heat-kernel endpoint signatures), hks (heat kernel signature "
                        f"histograms), d2, sh (spherical harmonics), shapedna"
                        ", or topomatch (all of agd, hks, shapedna, d2, sh fused, re-ranked; the best)"
                        f" (default {default})")


def _match_args(p: argparse.ArgumentParser) -> None:
    p.add_argument("--correspondence", default="greedy", choices=["greedy", "greedy_sequential", "optimal"],
                   help="endpoint correspondence (default greedy: globally closest pairs first)")
    p.add_argument("--dissimilarity", default="matched", choices=["matched", "double_sum"],
                   help="sum over matched pairs (default) or the literal double sum of eq. 3.12")
    p.add_argument("--unmatched-cost", type=float, default=0.0, help="cost per endpoint without a partner")
    p.add_argument("--endpoint-window", type=int, default=None,
                   help="compare only skeletons whose endpoint counts differ by at most this (thesis: 2-3)")


def _options(args):
    from topomatch.stages.retrieval.descriptor import MatchOptions

    return MatchOptions(correspondence=args.correspondence, dissimilarity=args.dissimilarity,
                        unmatched_cost=args.unmatched_cost, endpoint_window=args.endpoint_window)


def add_parsers(sub) -> None:
    p = sub.add_parser("match", help="dissimilarity of two meshes", description="Dissimilarity of two meshes "
                       "by their skeleton endpoints (or a baseline descriptor), with the correspondence.")
    p.add_argument("a", help="first mesh")
    p.add_argument("b", help="second mesh")
    _method_args(p)
    _match_args(p)
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.set_defaults(handler=cmd_match)

    p = sub.add_parser("index", help="index a collection of meshes", description="Compute descriptors of meshes "
                       "and store them in a SQLite index; unchanged meshes are skipped.")
    p.add_argument("paths", nargs="+", help="mesh files or folders (searched recursively)")
    p.add_argument("--db", required=True, help="index file (SQLite), created if missing")
    _method_args(p)
    p.add_argument("--labels", help="CSV with columns relative_path (or path) and class (or label), paths "
                                    "relative to the CSV's folder")
    p.add_argument("--workers", type=int, default=None, help="worker processes (default: all cores)")
    p.add_argument("--executor", default="local", choices=["local", "dask"], help="local processes or dask")
    p.add_argument("--retry-failed", action="store_true", help="recompute meshes recorded as failed")
    p.add_argument("--no-progress", action="store_true", help="hide the progress bar")
    p.set_defaults(handler=cmd_index)

    p = sub.add_parser("query", help="closest indexed shapes to a mesh", description="Rank the indexed shapes "
                       "by dissimilarity to a query mesh.")
    p.add_argument("mesh", help="query mesh")
    p.add_argument("--db", required=True, help="index file")
    p.add_argument("-k", type=int, default=10, help="results to show (default 10)")
    _method_args(p)
    _match_args(p)
    p.add_argument("--json", action="store_true", help="print JSON")
    p.set_defaults(handler=cmd_query)

    p = sub.add_parser("evaluate", help="retrieval metrics of a labelled index", description="Full dissimilarity "
                       "matrix of the labelled shapes of an index, PSB metrics (NN, FT, ST, E, DCG, mAP).")
    p.add_argument("--db", required=True, help="index file")
    _method_args(p)
    _match_args(p)
    p.add_argument("--out", help="where to write the matrix (.npz; default next to the index)")
    p.add_argument("--json", action="store_true", help="print JSON")
    p.set_defaults(handler=cmd_evaluate)


# --------------------------------------------------------------------------- shared


def method_experiment(method: str, paths: list[Path], *, workers: int | None = 1, executor: str = "local"):
    """The experiment that computes ``method``'s descriptor for each mesh path."""
    from topomatch.pipeline.config import build_experiment
    from topomatch.stages.retrieval.methods import METHODS

    return build_experiment({
        "name": f"index-{method}",
        "inputs": {"meshes": [str(p) for p in paths] or ["(no input)"]},
        "stages": METHODS[method],
        "executor": {"kind": executor, "workers": workers},
    }, resolve_inputs=bool(paths))


def params_of(experiment) -> tuple[dict, str]:
    """The method's resolved stage chain and its hash (part of the index key)."""
    resolved = experiment.resolved()
    params = {"stages": resolved["stages"], "stage_versions": resolved["stage_versions"]}
    return params, hashlib.sha256(json.dumps(params, sort_keys=True).encode()).hexdigest()[:16]


def compute_descriptor(path: Path, method: str, cache: str | None):
    """Descriptor of one mesh (through the stage cache); raises StageError with the reason on failure."""
    from topomatch.pipeline.item import run_item

    if not path.exists():
        raise InputError(path, "file not found")
    (item,) = method_experiment(method, [path.resolve()]).items()
    result = run_item(item, cache)
    if not result.ok:
        raise StageError(result.error or f"{path}: failed")
    return result.final("descriptor"), result


def _cache_for(db: Path) -> str:
    return str(db.with_name(db.name + ".cache"))


# --------------------------------------------------------------------------- match


def cmd_match(args) -> int:
    from topomatch.stages.matching.dissimilarity import match_features
    from topomatch.stages.retrieval.fusion import FUSIONS

    if args.method in FUSIONS:
        raise ConfigError(f"match: {args.method} is a fused method whose scales and re-ranking come from a "
                          f"collection; index the meshes and use query, or match with one of its parts "
                          f"({', '.join(FUSIONS[args.method].parts)})")
    from topomatch.stages.retrieval.methods import ENDPOINT_METHODS
    from topomatch.stages.retrieval.ranking import dissimilarities

    da, _ = compute_descriptor(Path(args.a), args.method, None)
    db, _ = compute_descriptor(Path(args.b), args.method, None)
    out = {"a": args.a, "b": args.b, "method": args.method}
    if args.method in ENDPOINT_METHODS:
        o = _options(args)
        m = match_features(da.data, db.data, correspondence=o.correspondence, dissimilarity=o.dissimilarity,
                           unmatched_cost=o.unmatched_cost)
        out.update({
            "dissimilarity": m.dissimilarity,
            "endpoints_a": int(len(da.data)), "endpoints_b": int(len(db.data)),
            "correspondence": [{"a": int(i), "b": int(j), "cost": float(c), "features_a": da.data[i].tolist(),
                                "features_b": db.data[j].tolist()} for i, j, c in zip(m.rows, m.cols, m.costs)],
        })
    else:
        out["dissimilarity"] = float(dissimilarities(da, [db], args.method)[0])
    if args.json:
        print(json.dumps(out))
    else:
        print(f"dissimilarity ({args.method}): {out['dissimilarity']:.6g}")
        if "correspondence" in out:
            print(f"endpoints: {out['endpoints_a']} vs {out['endpoints_b']}")
            for pair in out["correspondence"]:
                print(f"  endpoint {pair['a']:>2} <-> {pair['b']:>2}   Phi = {pair['cost']:.4f}")
    return 0


# --------------------------------------------------------------------------- index


def mesh_files(paths: list[str]) -> list[Path]:
    """Mesh files from files and folders (recursive), sorted, de-duplicated."""
    out: list[Path] = []
    for p in map(Path, paths):
        if p.is_dir():
            out += [f for f in sorted(p.rglob("*")) if f.is_file() and _is_mesh(f)]
        elif p.exists():
            out.append(p)
        else:
            raise InputError(p, "file not found")
    return list(dict.fromkeys(f.resolve() for f in out))


def _is_mesh(path: Path) -> bool:
    name = path.name.lower().removesuffix(".gz")
    return name.endswith(MESH_SUFFIXES)


def part_methods(method: str) -> tuple[str, ...]:
    """The methods whose descriptors ``method`` needs: its fusion's parts, or itself."""
    from topomatch.stages.retrieval.fusion import FUSIONS

    return FUSIONS[method].parts if method in FUSIONS else (method,)


def cmd_index(args) -> int:
    """Index every part method of ``args.method`` in one pass of the executor.

    The parts' items run in one pool, ordered part by part, so that the stages they share (load,
    clean, decimate, spectrum) are computed once and read from the cache afterwards.
    """
    import dataclasses

    from tqdm import tqdm

    from topomatch.pipeline import executors
    from topomatch.pipeline.cache import hash_file
    from topomatch.pipeline.shape_index import ShapeIndex

    files = mesh_files(args.paths)
    if not files:
        raise InputError(None, f"no mesh files ({', '.join(MESH_SUFFIXES)}, optionally .gz) in {' '.join(args.paths)}")
    from topomatch.pipeline.shape_index import read_labels

    labels = read_labels(args.labels) if args.labels else {}
    db_path = Path(args.db)
    hashes = {str(f): hash_file(f) for f in files}
    t0 = time.perf_counter()
    plans, todo = {}, []
    with ShapeIndex(db_path) as index:
        for method in part_methods(args.method):
            experiment = method_experiment(method, files, workers=args.workers, executor=args.executor)
            params, phash = params_of(experiment)
            known = index.known(method, phash, include_failed=not args.retry_failed)
            mine = [dataclasses.replace(item, item_id=f"{method}/{item.item_id}") for item in experiment.items()
                    if hashes[item.input_path] not in known]
            plans[method] = {"params": params, "phash": phash, "todo": len(mine), "done": 0, "failed": 0,
                             "seconds": 0.0}
            todo += mine
        with tqdm(total=len(todo), desc=f"index {args.method}", unit="item", disable=args.no_progress) as bar:
            for r in executors.execute(todo, _cache_for(db_path), experiment.raw.executor):
                method = r.item_id.split("/", 1)[0]
                plan = plans[method]
                d = r.final("descriptor")
                index.put(content_hash=hashes[r.input_path], path=r.input_path, label=labels.get(r.input_path),
                          method=method, params_hash=plan["phash"], params=plan["params"],
                          status="ok" if r.ok else "failed", reason=r.error,
                          n_endpoints=None if d is None else d.n_endpoints, kind=None if d is None else d.kind,
                          descriptor=None if d is None else d.data, seconds=sum(r.seconds.values()))
                plan["done"] += r.ok
                plan["failed"] += not r.ok
                plan["seconds"] += sum(r.seconds.values())
                bar.update()
        if labels:
            index.set_labels(labels)
    for method, plan in plans.items():
        print(f"{db_path}: {plan['done']} indexed, {plan['failed']} failed, {len(files) - plan['todo']} unchanged "
              f"(skipped) [{method}, {plan['seconds']:.1f} s of worker time]")
    print(f"{db_path}: {args.method} indexed in {time.perf_counter() - t0:.1f} s")
    failed = [(method, plan) for method, plan in plans.items() if plan["failed"]]
    with ShapeIndex(db_path) as index:
        for method, plan in failed:
            for row in index.rows(method, plan["phash"], status="failed"):
                print(f"  failed ({method}): {row.reason}", file=sys.stderr)
    return 0


# --------------------------------------------------------------------------- query / evaluate


def _indexed(db: str, method: str):
    from topomatch.pipeline.shape_index import ShapeIndex
    from topomatch.stages.retrieval.descriptor import Descriptor

    db_path = Path(db)
    if not db_path.exists():
        raise InputError(db_path, "index not found (create it with topomatch index)")
    phash = params_of(method_experiment(method, []))[1]
    with ShapeIndex(db_path) as index:
        rows = index.rows(method, phash)
        if not rows:
            present = ", ".join(f"{m} ({n} ok)" for m, _, n in index.methods()) or "nothing"
            raise ConfigError(f"{db_path}: no shapes indexed with method {method!r} and the current parameters "
                              f"(the index has: {present})")
    return rows, [Descriptor(r.kind, r.descriptor, r.n_endpoints) for r in rows]


def indexed_parts(db: str, method: str):
    """Index rows present for every part of ``method`` (same order), and {part: descriptors}."""
    parts = part_methods(method)
    indexed = {part: _indexed(db, part) for part in parts}
    common = set.intersection(*({r.path for r in rows} for rows, _ in indexed.values()))
    rows = [r for r in indexed[parts[0]][0] if r.path in common]
    descriptors = {}
    for part, (part_rows, part_descriptors) in indexed.items():
        by_path = {r.path: d for r, d in zip(part_rows, part_descriptors)}
        descriptors[part] = [by_path[r.path] for r in rows]
    return rows, descriptors


def _part_options(part: str, method: str, args):
    """Matching options of one part: the user's for a single method, the part's defaults in a fusion."""
    from topomatch.stages.retrieval.fusion import FUSIONS
    from topomatch.stages.retrieval.methods import default_match_options

    return default_match_options(part) if method in FUSIONS else _options(args)


def _matrix(method: str, descriptors: dict, args) -> np.ndarray:
    """Full dissimilarity matrix of ``method`` (fused and re-ranked for a fusion)."""
    from topomatch.stages.retrieval.fusion import FUSIONS, fused_matrix
    from topomatch.stages.retrieval.ranking import dissimilarity_matrix

    parts = [dissimilarity_matrix(descriptors[p], p, _part_options(p, method, args)) for p in part_methods(method)]
    return fused_matrix(parts, FUSIONS[method]) if method in FUSIONS else parts[0]


def cmd_query(args) -> int:
    from topomatch.stages.retrieval.fusion import FUSIONS, fused_query
    from topomatch.stages.retrieval.ranking import dissimilarities, dissimilarity_matrix

    rows, descriptors = indexed_parts(args.db, args.method)
    parts = part_methods(args.method)
    t = time.perf_counter()
    query = {p: compute_descriptor(Path(args.mesh), p, _cache_for(Path(args.db)))[0] for p in parts}
    t_desc = time.perf_counter() - t
    t = time.perf_counter()
    rows_d = [dissimilarities(query[p], descriptors[p], p, _part_options(p, args.method, args)) for p in parts]
    if args.method in FUSIONS:
        mats = [dissimilarity_matrix(descriptors[p], p, _part_options(p, args.method, args)) for p in parts]
        d = fused_query(rows_d, mats, FUSIONS[args.method])
    else:
        d = rows_d[0]
    order = np.argsort(d, kind="stable")[: args.k]
    t_rank = time.perf_counter() - t
    endpoints = next((q.n_endpoints for q in query.values() if q.n_endpoints is not None), None)
    results = [{"rank": i + 1, "path": rows[j].path, "label": rows[j].label, "dissimilarity": float(d[j]),
                "endpoints": rows[j].n_endpoints} for i, j in enumerate(order) if np.isfinite(d[j])]
    if args.json:
        print(json.dumps({"query": args.mesh, "method": args.method, "endpoints": endpoints,
                          "seconds": {"descriptor": t_desc, "ranking": t_rank}, "results": results}))
    else:
        print(f"query {args.mesh} ({args.method}, {endpoints if endpoints is not None else '-'} "
              f"endpoints) against {len(rows)} shapes:")
        for r in results:
            print(f"  {r['rank']:>3}. {r['dissimilarity']:.5f}  {r['label'] or '':<12} {r['path']}")
    return 0


def cmd_evaluate(args) -> int:
    from topomatch.stages.retrieval.metrics import retrieval_metrics

    rows, descriptors = indexed_parts(args.db, args.method)
    keep = [i for i, r in enumerate(rows) if r.label]
    if len(keep) < 2:
        raise ConfigError(f"{args.db}: fewer than two labelled shapes for {args.method}; index with --labels")
    rows = [rows[i] for i in keep]
    t = time.perf_counter()
    D = _matrix(args.method, {p: [ds[i] for i in keep] for p, ds in descriptors.items()}, args)
    seconds = time.perf_counter() - t
    labels = np.array([r.label for r in rows])
    metrics = retrieval_metrics(D, labels)
    out = Path(args.out) if args.out else Path(args.db).with_suffix(f".{args.method}.npz")
    np.savez_compressed(out, D=D, paths=np.array([r.path for r in rows]), labels=labels)
    if args.json:
        print(json.dumps({"method": args.method, "n": len(rows), "matrix": str(out), "matrix_seconds": seconds,
                          **metrics.as_dict()}))
    else:
        print(metrics.table(args.method))
        print(f"{len(rows)} shapes; matrix ({seconds:.2f} s) written to {out}")
    return 0


if __name__ == "__main__":  # pragma: no cover
    from topomatch.pipeline.cli import main

    sys.exit(main())
