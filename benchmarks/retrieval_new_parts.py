"""Issue 29's new parts (``gps``, ``lfd``): the GPS part's settings chosen on the tune side, the parts' cost per mesh,
and the query-adaptive weighting tried on the tune side (docs/retrieval.md, "Two new parts, alone").

Usage (after indexing the collections with the default method, as docs/retrieval.md shows)::

    TOPOMATCH_DATA_ROOT=../shared/data .venv/bin/python benchmarks/retrieval_new_parts.py gps-grid
    TOPOMATCH_DATA_ROOT=../shared/data .venv/bin/python benchmarks/retrieval_new_parts.py costs
    TOPOMATCH_DATA_ROOT=../shared/data .venv/bin/python benchmarks/retrieval_new_parts.py query-adaptive
    TOPOMATCH_DATA_ROOT=../shared/data .venv/bin/python benchmarks/retrieval_new_parts.py intrinsic-gate
    TOPOMATCH_DATA_ROOT=../shared/data .venv/bin/python benchmarks/retrieval_new_parts.py family-owa
    TOPOMATCH_DATA_ROOT=../shared/data .venv/bin/python benchmarks/retrieval_new_parts.py articulated-preset [--report]

``gps-grid``: k in 5 / 10 / 20 / 40, with Rustamov's shells or not; the rule, fixed before the run: the best mean mAP
over the tune side (Watertight half A, half B and the tune collections), ties within 0.005 to the smaller k. The
spectra are read from each index's stage cache (``<db>.cache``). ``--stress`` and ``--poses`` name the folders of
the built collections (default ``/tmp/stress``, ``$TOPOMATCH_POSES`` or ``/tmp/poses``).
"""

from __future__ import annotations

import argparse
import csv
import itertools
import json
import os
import sys
import time
import warnings
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import numpy as np
from scipy.spatial.distance import cdist

from topomatch.retrieval import cache_dir, compute_descriptor
from topomatch.stages.retrieval.gps import GPSParams, gps_histograms
from topomatch.stages.retrieval.metrics import retrieval_metrics

TUNE = ["twins_tune", "hires_twins_tune", "similar_tune", "hard_tune2", "strong_tune", "hires_tune"]
GPS_VARIANTS = [(k, shells) for k in (5, 10, 20, 40) for shells in (False, True)]


def watertight() -> Path:
    return Path(os.environ.get("TOPOMATCH_DATA_ROOT", "../shared/data")) / "meshes" / "shrec07_watertight"


def collections(stress: Path, poses: Path) -> dict[str, tuple[Path, Path]]:
    """name -> (folder with labels.csv, index)."""
    out = {"Watertight": (watertight(), stress / "wt.db"), "poses_tune": (poses / "poses_tune", poses / "poses_tune.db")}
    out.update({c: (stress / c, stress / f"{c}.db") for c in TUNE})
    return out


def _gps_variants(args) -> dict | None:
    path, cache = args
    try:
        _, result = compute_descriptor(path, "hks", cache=cache)
    except Exception:  # noqa: BLE001 (a mesh the default method could not index is left out, as the index does)
        return None
    spectrum = result.final("spectrum")
    full = {k: gps_histograms(spectrum, GPSParams(k=k)) for k in {k for k, _ in GPS_VARIANTS}}
    return {(k, shells): full[k] if shells else full[k][:GPSParams().bins] for k, shells in GPS_VARIANTS}


def gps_grid(args) -> None:
    results = {}
    for name, (root, db) in collections(args.stress, args.poses).items():
        rows = list(csv.DictReader(open(root / "labels.csv")))
        labels = np.array([r["class"] for r in rows])
        with ProcessPoolExecutor(2) as ex:
            descs = list(ex.map(_gps_variants, [(str(root / r["relative_path"]), cache_dir(db)) for r in rows],
                                chunksize=4))
        ok = [i for i, d in enumerate(descs) if d is not None]
        parts = {name: ok}
        if name == "Watertight":
            classes = np.unique(labels)
            parts = {"Watertight half A": [i for i in ok if labels[i] in classes[0::2]],
                     "Watertight half B": [i for i in ok if labels[i] in classes[1::2]]}
        for part, idx in parts.items():
            line = {}
            for v in GPS_VARIANTS:
                X = np.stack([descs[i][v] for i in idx])
                m = retrieval_metrics(cdist(X, X, "cityblock"), labels[idx]).micro
                line[f"k{v[0]}{'+shells' if v[1] else ''}"] = (round(float(m["nn"]), 3), round(float(m["map"]), 3))
            results[part] = line
            print(part, len(idx), line, flush=True)
    means = {v: float(np.mean([results[c][v][1] for c in results])) for v in next(iter(results.values()))}
    top = max(means.values())
    chosen = next(v for v in sorted(means, key=lambda v: (int(v[1:].split("+")[0]), "+" in v)) if means[v] >= top - 0.005)
    print("mean mAP", {k: round(x, 4) for k, x in means.items()}, "-> chosen:", chosen)
    if args.json:
        Path(args.json).write_text(json.dumps({"results": results, "mean_map": means, "chosen": chosen}, indent=1))


def costs(args) -> None:
    """Descriptor time alone per mesh: lfd on the cleaned mesh, gps on the cached shared spectrum; 2 meshes of each
    Watertight class (the first two by name); then lfd's comparison cost."""
    from topomatch.stages.retrieval.baselines import light_field

    root = watertight()
    by: dict[str, list[str]] = {}
    for r in csv.DictReader(open(root / "labels.csv")):
        by.setdefault(r["class"], []).append(r["relative_path"])
    paths = [root / p for c in sorted(by) for p in sorted(by[c])[:2]]
    cache = cache_dir(args.stress / "wt.db")
    lfd_t, gps_t, vertices = [], [], []
    for p in paths:
        spectrum = compute_descriptor(p, "hks", cache=cache)[1].final("spectrum")
        t = time.perf_counter()
        gps_histograms(spectrum, GPSParams())
        gps_t.append(time.perf_counter() - t)
        mesh = compute_descriptor(p, "d2", cache=cache)[1].final("mesh")
        if not lfd_t:
            light_field.descriptor(mesh)  # Open3D's first import and scene
        t = time.perf_counter()
        light_field.descriptor(mesh)
        lfd_t.append(time.perf_counter() - t)
        vertices.append(len(mesh.V))
    print(f"{len(paths)} meshes, median {int(np.median(vertices))} vertices (largest {max(vertices)})")
    print(f"lfd descriptor: median {np.median(lfd_t):.3f} s, 90th pct {np.percentile(lfd_t, 90):.3f}, max {max(lfd_t):.3f}")
    print(f"gps histograms: median {np.median(gps_t) * 1000:.1f} ms, max {max(gps_t) * 1000:.1f} ms")
    X = np.random.default_rng(0).random((400, light_field.LightFieldParams().light_fields * light_field.AXES
                                         * light_field.FEATURES)).astype(np.float32)
    t = time.perf_counter()
    light_field.distance_matrix(X)
    print(f"lfd 400 x 400 matrix: {time.perf_counter() - t:.1f} s")
    t = time.perf_counter()
    light_field.distance_matrix(X[:1], X)
    print(f"lfd one query against 400: {(time.perf_counter() - t) * 1000:.0f} ms")


def _effectiveness(D: np.ndarray, fraction: float) -> np.ndarray:
    """(n,) per-query quality of a part (Zheng et al., CVPR 2015): one over the area under its sorted distances'
    curve, min-max normalised over the nearest ``fraction`` of the collection (an L-shaped curve scores high)."""
    K = max(5, int(fraction * len(D)))
    M = D.astype(np.float64).copy()
    np.fill_diagonal(M, np.inf)
    S = np.sort(M, axis=1)[:, :K]
    s = (S[:, -1:] - S) / np.maximum(S[:, -1:] - S[:, :1], 1e-12)
    return 1.0 / np.maximum(s.mean(axis=1), 1e-6)


def _tune_side(args, extra: tuple[str, ...] = ()) -> dict:
    """{name: (part matrices, labels)}: the Watertight halves, the tune collections, ``poses_tune``, and the
    hidden-like copies of the halves and ``poses_tune`` (retrieval_selection.py's degradation)."""
    sys.path.insert(0, str(Path(__file__).parent))
    from retrieval_selection import DEGRADED, degraded, load, restrict

    colls = {}
    wt = load(str(args.stress / "wt.db"), extra)
    half_a = np.isin(wt[1], np.unique(wt[1])[0::2])
    colls["Watertight half A"], colls["Watertight half B"] = restrict(wt, half_a), restrict(wt, ~half_a)
    colls.update({c: load(str(args.stress / f"{c}.db"), extra) for c in TUNE})
    colls["poses_tune"] = load(str(args.poses / "poses_tune.db"), extra)
    for name in ("Watertight half A", "Watertight half B", "poses_tune"):
        colls[f"{name} (hidden-like)"] = degraded(colls[name], DEGRADED["hidden-like"])
    return colls


def query_adaptive(args) -> None:
    """The default fusion with each kept part's scale divided, per query, by its relative effectiveness to a power;
    tune side only (an exploration: nothing was built from it)."""
    from retrieval_selection import nn_map

    from topomatch.stages.retrieval.catalogue import METHODS
    from topomatch.stages.retrieval.fusion import decide, fuse, fused_matrix, manifold_ranking

    base = METHODS["topomatch"].fusion

    def fused(mats, fraction, power):
        decision = decide([mats[p] for p in base.parts], base)
        kept = [p for p in base.parts if p in decision.kept]
        E = np.stack([_effectiveness(mats[p], fraction) for p in kept])
        W = (E / E.max(axis=0)) ** power
        scaled = []
        for i, p in enumerate(kept):
            X = mats[p] / np.median(mats[p][~np.eye(len(mats[p]), dtype=bool)]) / W[i][:, None]
            scaled.append((X + X.T) / 2)
        D = fuse(scaled, [1.0] * len(scaled), base.order_weights)
        return manifold_ranking(D, decision.rerank_k, base.rerank_alpha, base.rerank_normalisation)

    colls = _tune_side(args)
    variants = [(f, p) for f in (0.1, 0.25) for p in (0.5, 1.0, 2.0)]
    print("collection | default | " + " | ".join(f"{f:g} / {p:g}" for f, p in variants))
    for name, (mats, labels) in colls.items():
        row = [nn_map(fused_matrix([mats[p] for p in base.parts], base), labels)]
        row += [nn_map(fused(mats, f, p), labels) for f, p in variants]
        print(name + " | " + " | ".join(f"{a:.3f} / {b:.3f}" for a, b in row), flush=True)


def intrinsic_gate(args) -> None:
    """The default fusion blended, pair by pair, with the fusion of the intrinsic spectral parts alone, by how well
    those parts agree on each item's 5 nearest neighbours (their mean pairwise overlap g_i; weight 1 above ``tau``,
    or rising linearly over ``soft`` above it; a pair's weight the min or mean of its items'), then re-ranked as the
    default is; tune side only (an exploration, 2026-12-05: nothing was built from it)."""
    from retrieval_selection import nn_map

    from topomatch.stages.retrieval.catalogue import METHODS
    from topomatch.stages.retrieval.fusion import (_neighbour_sets, decide, fuse, fused_matrix, kept_scales,
                                                   manifold_ranking, median_scale, rerank_neighbours)

    base = METHODS["topomatch"].fusion

    def blended(mats, intrinsic, tau, soft, pair):
        decision = decide([mats[p] for p in base.parts], base)
        kept = [p for p in base.parts if p in decision.kept]
        every = fuse([mats[p] for p in kept], kept_scales([mats[p] for p in base.parts], base, decision),
                     base.order_weights)
        alone = fuse([mats[p] for p in intrinsic], [median_scale(mats[p]) for p in intrinsic])
        sets = [_neighbour_sets(mats[p], 5) for p in intrinsic]
        g = np.mean([[len(np.intersect1d(a, b)) / 5 for a, b in zip(sets[i], sets[j])]
                     for i, j in itertools.combinations(range(len(sets)), 2)], axis=0)
        w = np.clip((g - tau) / soft, 0, 1) if soft else (g >= tau).astype(float)
        W = np.minimum.outer(w, w) if pair == "min" else np.add.outer(w, w) / 2
        D = W * alone / median_scale(alone) + (1 - W) * every / median_scale(every)
        return manifold_ranking(D, decision.rerank_k, base.rerank_alpha, base.rerank_normalisation)

    colls = _tune_side(args, ("gps",))
    variants = [(i, t, s, p) for i in (("hks", "shapedna"), ("hks", "shapedna", "gps"))
                for t in (0.4, 0.5, 0.6, 0.7, 0.8) for s in (0.0, 0.2) for p in ("min", "mean")]
    print("setting | " + " | ".join(colls))
    print("default | " + " | ".join("%.3f / %.3f" % nn_map(fused_matrix([m[p] for p in base.parts], base), labels)
                                    for m, labels in colls.values()), flush=True)
    def alone(m, intrinsic):
        D = fuse([m[p] for p in intrinsic], [median_scale(m[p]) for p in intrinsic])
        return manifold_ranking(D, rerank_neighbours(base, len(D)), base.rerank_alpha, base.rerank_normalisation)

    for intrinsic in dict.fromkeys(v[0] for v in variants):  # in the order of the variants
        print(f"{'+'.join(intrinsic)} alone | " + " | ".join(
            "%.3f / %.3f" % nn_map(alone(m, intrinsic), labels) for m, labels in colls.values()))
    for intrinsic, tau, soft, pair in variants:
        print(f"{'+'.join(intrinsic)}, tau {tau:g}, soft {soft:g}, {pair} | " + " | ".join(
            "%.3f / %.3f" % nn_map(blended(m, intrinsic, tau, soft, pair), labels) for m, labels in colls.values()),
            flush=True)


def family_owa(args) -> None:
    """The default fusion's "two smallest averaged" made to look across the two families of parts (intrinsic: agd,
    hks, shapedna, gps; extrinsic: d2, sh), so that two extrinsic parts agreeing on a wrong pair (one pose of two
    characters) cannot make it close alone: ``split``, the mean of each family's smallest scaled dissimilarity;
    ``intrinsic``, the two smallest when one of them is intrinsic, else the smallest and the smallest intrinsic one;
    every kept part of the default's screen, then its manifold ranking; tune side only (an exploration, 2026-12-05:
    nothing was built from it)."""
    from retrieval_selection import nn_map

    from topomatch.stages.retrieval.catalogue import METHODS
    from topomatch.stages.retrieval.fusion import decide, fused_matrix, manifold_ranking, median_scale

    base = METHODS["topomatch"].fusion

    def fused(mats, parts, rule):
        decision = decide([mats[p] for p in base.parts], base)
        kept = [p for p in parts if p in decision.kept or p not in base.parts]
        S = np.stack([mats[p] / median_scale(mats[p]) for p in kept])
        intrinsic = np.array([p not in ("d2", "sh") for p in kept])
        if rule == "split":
            D = np.mean([S[f].min(axis=0) for f in (intrinsic, ~intrinsic) if f.any()], axis=0)
        else:
            two, best = np.sort(S, axis=0)[:2], S[intrinsic].min(axis=0)
            D = np.where(best <= two[1], two.mean(axis=0), (two[0] + best) / 2)
        return manifold_ranking(D, decision.rerank_k, base.rerank_alpha, base.rerank_normalisation)

    colls = _tune_side(args, ("gps",))
    print("setting | " + " | ".join(colls))
    print("default | " + " | ".join("%.3f / %.3f" % nn_map(fused_matrix([m[p] for p in base.parts], base), labels)
                                    for m, labels in colls.values()), flush=True)
    for parts, rule in itertools.product((base.parts, base.parts + ("gps",)), ("split", "intrinsic")):
        print(f"{rule}{' +gps' if 'gps' in parts else ''} | " + " | ".join(
            "%.3f / %.3f" % nn_map(fused(m, parts, rule), labels) for m, labels in colls.values()), flush=True)


#: ``articulated-preset`` (2026-12-05, written before it was run): the part sets and combinations of a fused method for
#: collections the user knows to be articulated (the same characters in other poses), every other setting the
#: default's; chosen by the best mean mAP over the undegraded articulated tune collections, ties within 0.005 to fewer
#: parts, then to the plain sum. The report collections are read for the pick only, once.
PRESET_PARTS = [("hks", "shapedna"), ("hks", "gps"), ("shapedna", "gps"), ("hks", "shapedna", "gps"),
                ("agd", "hks", "shapedna", "gps")]
PRESET_TUNE = ["poses_tune"] + TUNE
PRESET_REPORT = ["poses_report", "sumner", "sumner_open", "hires_report", "hires_twins_report", "twins_report",
                 "strong_report", "strong_report_open", "similar_report", "fresh_report_open", "fresh2_report_open",
                 "fresh_similar_report", "fresh2_similar_report"]


def articulated_preset(args) -> None:
    """The articulated preset's part set and combination chosen on the tune side (:data:`PRESET_PARTS`, sum or the two
    smallest averaged); with ``--report``, the pick and the default on the report collections and Watertight."""
    from dataclasses import replace

    from retrieval_selection import load, nn_map

    from topomatch.stages.retrieval.catalogue import METHODS
    from topomatch.stages.retrieval.fusion import fused_matrix

    base = METHODS["topomatch"].fusion
    settings = {f"{'+'.join(parts)}, {'sum' if w is None else 'two smallest'}":
                replace(base, parts=parts, order_weights=w, screen=None)
                for parts in PRESET_PARTS for w in (None, (1, 1)) if w is None or len(parts) > 2}

    def db(name):
        return args.poses / f"{name}.db" if name.startswith("poses") else args.stress / f"{name}.db"

    tune = {c: load(str(db(c)), ("gps",)) for c in PRESET_TUNE}
    scores = {name: {c: nn_map(fused_matrix([m[p] for p in f.parts], f), labels) for c, (m, labels) in tune.items()}
              for name, f in settings.items()}
    print("setting | " + " | ".join(PRESET_TUNE) + " | mean mAP")
    for name, r in scores.items():
        print(f"{name} | " + " | ".join("%.3f / %.3f" % r[c] for c in PRESET_TUNE) +
              f" | {np.mean([r[c][1] for c in PRESET_TUNE]):.4f}")
    mean = {name: float(np.mean([r[c][1] for c in PRESET_TUNE])) for name, r in scores.items()}
    top = max(mean.values())
    pick = min((n for n in settings if mean[n] >= top - 0.005),
               key=lambda n: (len(settings[n].parts), settings[n].order_weights is not None, -mean[n]))
    print(f"pick: {pick} (mean mAP {mean[pick]:.4f}; best {top:.4f})")
    if not args.report:
        return
    print("report collection | default | " + pick)
    for c in ["Watertight"] + PRESET_REPORT:
        m, labels = load(str(args.stress / "wt.db" if c == "Watertight" else db(c)), ("gps",))
        print(f"{c} | " + " | ".join("%.3f / %.3f" % nn_map(fused_matrix([m[p] for p in f.parts], f), labels)
                                    for f in (base, settings[pick])), flush=True)


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("what", choices=["gps-grid", "costs", "query-adaptive", "intrinsic-gate", "family-owa",
                                           "articulated-preset"])
    ap.add_argument("--stress", type=Path, default=Path("/tmp/stress"))
    ap.add_argument("--poses", type=Path, default=Path(os.environ.get("TOPOMATCH_POSES", "/tmp/poses")))
    ap.add_argument("--json", help="gps-grid: write the results here")
    ap.add_argument("--report", action="store_true", help="articulated-preset: the pick on the report collections")
    args = ap.parse_args(argv)
    warnings.filterwarnings("ignore", module="topomatch")
    {"gps-grid": gps_grid, "costs": costs, "query-adaptive": query_adaptive, "intrinsic-gate": intrinsic_gate,
     "family-owa": family_owa, "articulated-preset": articulated_preset}[args.what](args)


if __name__ == "__main__":
    main()
