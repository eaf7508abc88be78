"""Cheaper settings of the fusion's costly parts, chosen on tune collections only (docs/retrieval.md).

Usage::

    TOPOMATCH_DATA_ROOT=../shared/data .venv/bin/python benchmarks/retrieval_part_costs.py \
        --watertight ../shared/data/meshes/shrec07_watertight --watertight-db w.db \
        --tune /tmp/stress/{strong_tune,similar_tune,hard_tune} \
        --report /tmp/stress/{strong_report,strong_report_open,similar_report} \
        --json benchmarks/results/retrieval_part_costs.json

A collection folder ``C`` holds its meshes and ``labels.csv``; its index is ``C.db`` (as
``benchmarks/retrieval_collections.py`` and the commands of docs/retrieval.md make them). Each part
variant below is registered as a method for this run and indexed into those indexes (in this
process; the stages it shares with the default method come from their caches). Tune side: the tune
collections and Watertight half A (even-indexed sorted classes); report side: the report
collections, Watertight half B and the full set.

The rule, fixed before the results were read: for each part (agd, d2, sh), the cheapest variant
whose own mAP on every tune collection is within 0.01 of the most expensive variant's, and whose
substitution into the default fusion keeps the fusion's mAP within 0.005 of the fusion with the
most expensive variants on every tune collection; then the combination must pass the fusion test
too (else the part with the largest fusion loss steps back to its next dearer variant, repeatedly).

Then the number of eigenpairs of the spectrum the intrinsic parts share (:data:`SPECTRUM_KS`; the part
ladders above are computed with the last, 60, the product's k when they were chosen) by the same rule,
with the parts chosen above: the smallest k for which agd, hks and shapedna each keep their mAP within
0.01 of k = 60's on every tune collection, and the fusion within 0.005. (It chose 40, now the product's.)
"""

from __future__ import annotations

import argparse
import itertools
import json
from dataclasses import replace
from pathlib import Path

import numpy as np

from retrieval_selection import nn_map
from topomatch.retrieval import index, open_index
from topomatch.stages.retrieval.catalogue import METHODS, SPECTRAL_CHAIN, CLEAN_CHAIN, get_method
from topomatch.stages.retrieval.fusion import fused_matrix

#: Eigenpairs of the shared spectrum, cheapest first; the last is the one the part ladders are computed with.
SPECTRUM_KS = (40, 60)
INTRINSIC = ("agd", "hks", "shapedna")
LADDER_CHAIN = SPECTRAL_CHAIN[:-1] + ({"spectrum": {"k": SPECTRUM_KS[-1]}},)

#: part -> [(variant name, the stage chain's last stages)], cheapest first; the last is the dearest.
ENDPOINT_TAIL = ("level_sets", "reeb_graph", "prune", "endpoint_hks_descriptor")
LADDERS = {
    "agd": [(name, LADDER_CHAIN + ({"morse": {"function": "agd", "sources": k, "sampling": how}},) + ENDPOINT_TAIL)
            for name, k, how in (("agd-farthest-32", 32, "farthest"), ("agd-farthest-64", 64, "farthest"),
                                 ("agd-sources-256", 256, "random"))],
    "d2": [(f"d2-pairs-2e{e}", CLEAN_CHAIN + ({"d2": {"n_pairs": 1 << e}},)) for e in (16, 17, 18)],
    "sh": [(f"sh-points-2e{e}", CLEAN_CHAIN + ({"spherical_harmonics": {"n_points": 1 << e}},))
           for e in (15, 16, 17)],
}


def k_variant(part: str, k: int) -> str:
    """Name of the product's ``part`` computed from ``k`` eigenpairs."""
    return f"{part}-k{k}"


def register_variants() -> None:
    """Add every variant to the catalogue of this process (not to the product)."""
    for part, ladder in LADDERS.items():
        for name, chain in ladder:
            METHODS[name] = replace(get_method(part), name=name, chain=chain)
    assert "spectrum" in SPECTRAL_CHAIN[-1]
    for k in SPECTRUM_KS:
        for part in INTRINSIC:
            method = get_method(part)
            chain = SPECTRAL_CHAIN[:-1] + ({"spectrum": {"k": k}},) + method.chain[len(SPECTRAL_CHAIN):]
            METHODS[k_variant(part, k)] = replace(method, name=k_variant(part, k), chain=chain)


def matrices(db: Path, methods: list[str]) -> tuple[dict[str, np.ndarray], np.ndarray]:
    """{method: (n, n) dissimilarities} and (n,) labels of the labelled shapes, rows in path order."""
    collection = open_index(db)
    out, labels, paths = {}, None, None
    for m in methods:
        rows, descriptors = collection.parts(m)
        keep = sorted((r.path, i) for i, r in enumerate(rows) if r.label)
        idx = [i for _, i in keep]
        if paths is None:
            paths, labels = [p for p, _ in keep], np.array([rows[i].label for i in idx])
        if [p for p, _ in keep] != paths:
            raise SystemExit(f"{db}: method {m} has other labelled shapes than {methods[0]}")
        out[m] = collection.part_matrices(m, {p: [ds[i] for i in idx] for p, ds in descriptors.items()},
                                         slot="labelled")[0]
    return out, labels


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--watertight", type=Path, required=True, help="Watertight folder (with labels.csv)")
    ap.add_argument("--watertight-db", type=Path, required=True)
    ap.add_argument("--tune", type=Path, nargs="*", default=[])
    ap.add_argument("--report", type=Path, nargs="*", default=[])
    ap.add_argument("--json")
    args = ap.parse_args()
    register_variants()
    variants = [name for ladder in LADDERS.values() for name, _ in ladder]
    methods = variants + [k_variant(p, k) for k in SPECTRUM_KS for p in INTRINSIC]
    sources = {c.name: (c, Path(f"{c}.db")) for c in args.tune + args.report}
    sources["Watertight"] = (args.watertight, args.watertight_db)
    colls = {}
    for name, (folder, db) in sources.items():
        for m in methods:
            index([folder], db, method=m, labels=folder / "labels.csv", workers=2)
        colls[name] = matrices(db, methods)
    wt_m, wt_l = colls.pop("Watertight")
    classes = sorted(set(wt_l))
    half_a = np.isin(wt_l, classes[0::2])
    for name, mask in (("Watertight half A", half_a), ("Watertight half B", ~half_a), ("Watertight", None)):
        idx = np.arange(len(wt_l)) if mask is None else np.flatnonzero(mask)
        colls[name] = ({m: M[np.ix_(idx, idx)] for m, M in wt_m.items()}, wt_l[idx])
    tune = [c.name for c in args.tune] + ["Watertight half A"]
    report = [c.name for c in args.report] + ["Watertight half B", "Watertight"]

    fusion = get_method("topomatch").fusion
    dearest = {part: ladder[-1][0] for part, ladder in LADDERS.items()}

    def fkey(sel: dict) -> str:
        return "fusion[" + ", ".join(sel[p] for p in LADDERS) + "]"

    res = {}
    for n, (mats, labels) in colls.items():
        res[n] = {m: nn_map(mats[m], labels) for m in methods}
        for combo in itertools.product(*([name for name, _ in ladder] for ladder in LADDERS.values())):
            sel = dict(zip(LADDERS, combo))
            base = SPECTRUM_KS[-1]
            parts = [mats[sel["agd"]], mats[k_variant("hks", base)], mats[k_variant("shapedna", base)],
                     mats[sel["d2"]], mats[sel["sh"]]]
            res[n][fkey(sel)] = nn_map(fused_matrix(parts, fusion), labels)

    def fusion_ok(sel: dict) -> bool:
        return all(res[n][fkey(sel)][1] >= res[n][fkey(dearest)][1] - 0.005 for n in tune)

    chosen = {}
    for part, ladder in LADDERS.items():
        for name, _ in ladder:
            own = all(res[n][name][1] >= res[n][dearest[part]][1] - 0.01 for n in tune)
            if own and fusion_ok({**dearest, part: name}):
                chosen[part] = name
                break
    while not fusion_ok(chosen):
        loss = {p: min(res[n][fkey({**dearest, p: chosen[p]})][1] - res[n][fkey(dearest)][1] for n in tune)
                for p in chosen if chosen[p] != dearest[p]}
        worst = min(loss, key=loss.get)
        ladder = [name for name, _ in LADDERS[worst]]
        chosen[worst] = ladder[ladder.index(chosen[worst]) + 1]

    def k_key(k: int) -> str:
        return f"fusion[spectrum k = {k}]"

    base = SPECTRUM_KS[-1]
    for n, (mats, labels) in colls.items():
        for k in SPECTRUM_KS:
            parts = [mats[k_variant("agd", k)], mats[k_variant("hks", k)], mats[k_variant("shapedna", k)],
                     mats[chosen["d2"]], mats[chosen["sh"]]]
            res[n][k_key(k)] = nn_map(fused_matrix(parts, fusion), labels)
    for k in SPECTRUM_KS:
        own = all(res[n][k_variant(p, k)][1] >= res[n][k_variant(p, base)][1] - 0.01
                  for n in tune for p in INTRINSIC)
        if own and all(res[n][k_key(k)][1] >= res[n][k_key(base)][1] - 0.005 for n in tune):
            chosen["spectrum k"] = k
            break

    shown = tune + report
    print("| setting | " + " | ".join(f"{n}{' (tune)' if n in tune else ''}" for n in shown) + " |")
    print("|---|" + "---|" * len(shown))
    for key in res[shown[0]]:
        print(f"| {key} | " + " | ".join(f"{res[n][key][0]:.3f} / {res[n][key][1]:.3f}" for n in shown) + " |")
    print(f"\nchosen: {chosen}")
    for n in shown:
        print(f"{n}: fusion with the dearest parts {res[n][fkey(dearest)][0]:.3f} / {res[n][fkey(dearest)][1]:.3f}, "
              f"with the chosen {res[n][fkey(chosen)][0]:.3f} / {res[n][fkey(chosen)][1]:.3f}")
    if args.json:
        Path(args.json).write_text(json.dumps({"tune": tune, "report": report, "chosen": chosen, "results": res},
                                              indent=1))


if __name__ == "__main__":
    main()
