"""The selection protocol of docs/retrieval.md, run: fusion settings chosen on tune collections only.

Usage::

    .venv/bin/python benchmarks/retrieval_selection.py --watertight WT.db \
        --tune strong_tune.db --report strong_report.db strong_report_open.db \
        --json benchmarks/results/retrieval_selection.json

Every index must hold the five parts of the fusion (``topomatch index DIR --db X.db --labels L``
with the default method). From each index the labelled shapes' part matrices are read through the
public API (:meth:`topomatch.retrieval.Collection.part_matrices`). Collections:

* Watertight is split by class (sorted class names; even-indexed classes form half A, odd-indexed
  half B). Selection A chooses on half A plus the tune collections and is reported on half B;
  selection B the reverse. The full set is reported with each choice.
* Every collection also gets two degraded copies, built from the issue's description of the
  hidden articulated collection (where D2 and SH fall to 0.34 mAP and the AGD skeleton to 0.71):
  **scrambled**, D2's and the spherical harmonics' matrices permuted over all shapes (same values,
  no class information); **hidden-like**, half of the shapes permuted in D2 and SH and a quarter
  in AGD.

When the two selections differ, the default is the one of their two settings that the criterion prefers
pooled over both sides' tune collections. The grid: order weights (equal ... the two smallest), screening (none, 0.5, 0.6, 0.65, 0.7),
re-ranking k (none, 5, 10, auto = round(sqrt(n) / 2); "none" since 2026-12-02, third session), agreement power (0, 1, 2, 4: each kept part's scale
times its agreement relative to the best part's to that power), normalisation of the manifold-ranking
scores by the items' self-scores (0, 0.5, 1; 2026-12-02), the diffusion weight alpha (0.9, 0.95, 0.99;
2026-12-02, fixed at 0.9 before). The criterion, computed on the tune side only:
the worst margin over the tune collections of the fusion over its best part, in NN or in mAP, whichever
is smaller ("never worse than its best part"; mAP alone until 2026-12-01), then the mean mAP; since
2026-12-02 (third session) worst margins within :data:`MARGIN_TIE` of the best are tied, so the mean mAP
decides among them. The grid is evaluated on the choice side only; the report collections for the chosen
settings. The chosen settings and every method's
NN / mAP on every report collection are printed (markdown) and written as JSON.

``--grid rules`` (issue 29, 2026-12-03) replaces the grid by the agreement rules (Fusion.agreement_rule: mean,
consensus, iterative) x screens, the other settings at the default's; ``--guard G`` admits only settings that lose at
most G mAP against the default of the time on every undegraded choice-side collection (added after the rules grid's
tune-side numbers were read, before any report number); ``--choose-only`` stops after the choice.

``--grid parts`` (issue 29, 2026-12-05) evaluates the part sets of :data:`PART_SETS` (the new parts ``gps`` and ``lfd``
added or swapped in) x :data:`PART_SCREENS`, the other settings at the default's; every index must also hold the
``gps`` and ``lfd`` rows (``topomatch index ... --method gps``, ``--method lfd``), and "its best part" is the best of
all seven.
"""

from __future__ import annotations

import argparse
import itertools
import json
from dataclasses import replace
from pathlib import Path

import numpy as np

from topomatch.retrieval import open_index
from topomatch.stages.retrieval.catalogue import DEFAULT_METHOD, get_method
from topomatch.stages.retrieval.fusion import AGREEMENT_RULES, agreement, consensus_agreement, decide, fused_matrix
from topomatch.stages.retrieval.metrics import retrieval_metrics

ORDER_WEIGHTS = {"equal": None, "1,1,.5,.25,.1": (1, 1, 0.5, 0.25, 0.1), "1,1,.5,.25": (1, 1, 0.5, 0.25),
                 "1,1,1 (median)": (1, 1, 1), "1,1,.5": (1, 1, 0.5), "1,1 (two smallest)": (1, 1)}
#: "none" (no re-ranking; 2026-12-02, third session): whether to re-rank is chosen like the rest.
RERANK = {"none": None, "5": 5, "10": 10, "auto": "auto"}
SCREEN = {"none": None, "0.5": 0.5, "0.6": 0.6, "0.65": 0.65, "0.7": 0.7}
#: Agreement weighting (Fusion.agreement_power): 0 = off.
POWER = {"0": 0.0, "1": 1.0, "2": 2.0, "4": 4.0}
#: Manifold-ranking scores divided by the items' self-scores to this power (Fusion.rerank_normalisation; 2026-12-02).
NORMALISATION = {"0": 0.0, "0.5": 0.5, "1": 1.0}
#: Diffusion weight of manifold ranking (Fusion.rerank_alpha; fixed at 0.9 until 2026-12-02).
ALPHA = {"0.9": 0.9, "0.95": 0.95, "0.99": 0.99}
#: Settings whose worst margin is within this of the best are tied, and the mean mAP decides (2026-12-02,
#: third session, written before the run it was first used in): a margin is decided by one or two
#: queries, and without a tie the afternoon run of 2026-12-02 traded 0.06 mAP on a Watertight half
#: for a fraction of one query elsewhere. 0.005 is one query of a 200-shape collection.
MARGIN_TIE = 0.005
#: ``--grid rules`` (issue 29, 2026-12-03): what a part's agreement is measured against (Fusion.agreement_rule) and
#: the screen, every other setting at the current default's; fixed before any number of it was read.
RULE_SCREENS = {"none": None, "0.5": 0.5, "0.6": 0.6, "0.65": 0.65, "0.7": 0.7, "0.8": 0.8, "0.9": 0.9}
#: Degraded copies: part -> fraction of the shapes permuted. The light field (``lfd``, extrinsic, ~0.27 mAP on real
#: poses) is degraded as D2 and SH are; the GPS distributions (``gps``, intrinsic) as HKS and ShapeDNA, not at all
#: (issue 29, 2026-12-05, written before the parts grid was run). A part absent from a run is skipped.
DEGRADED = {"D2, SH scrambled": {"d2": 1.0, "sh": 1.0, "lfd": 1.0},
            "hidden-like": {"d2": 0.5, "sh": 0.5, "agd": 0.25, "lfd": 0.5}}
"""(``lfd`` last: the permutations are drawn from one stream in this order, so the other parts' copies are those of
the runs before it.)"""
#: ``--grid parts`` (issue 29, 2026-12-05, fixed before any fused number of it was read): the default's parts with
#: the new ones added or swapped in, each with the screens below, every other setting at the default's.
PART_SETS = {"default parts": ("agd", "hks", "shapedna", "d2", "sh"),
             "+gps": ("agd", "hks", "shapedna", "d2", "sh", "gps"),
             "+gps -agd": ("hks", "shapedna", "d2", "sh", "gps"),
             "+lfd": ("agd", "hks", "shapedna", "d2", "sh", "lfd"),
             "+gps +lfd": ("agd", "hks", "shapedna", "d2", "sh", "gps", "lfd")}
PART_SCREENS = {"none": None, "0.5": 0.5, "0.6": 0.6, "0.7": 0.7}


def load(db: str, extra: tuple[str, ...] = ()) -> tuple[dict[str, np.ndarray], np.ndarray]:
    """{part: (n, n) matrix} and (n,) class labels of the labelled shapes of an index: the default fusion's parts
    and the vector methods ``extra`` (``--grid parts``; every labelled shape must have a row of each)."""
    method = get_method(DEFAULT_METHOD)
    index = open_index(db)
    rows, descriptors = index.parts(DEFAULT_METHOD)
    keep = [i for i, r in enumerate(rows) if r.label]
    mats = dict(zip(method.parts, index.part_matrices(DEFAULT_METHOD, {p: [ds[i] for i in keep]
                                                                         for p, ds in descriptors.items()},
                                                      slot="labelled")))
    for part in extra:
        part_rows, part_descriptors = index.parts(part)
        where = {r.path: i for i, r in enumerate(part_rows)}
        missing = [rows[i].path for i in keep if rows[i].path not in where]
        if missing:
            raise SystemExit(f"{db}: {len(missing)} labelled shapes have no {part} row (e.g. {missing[0]}): "
                             f"topomatch index ... --method {part}")
        (mats[part],) = index.part_matrices(part, {part: [part_descriptors[part][where[rows[i].path]] for i in keep]},
                                            slot="labelled")
    return mats, np.array([rows[i].label for i in keep])


def restrict(coll, keep):
    mats, labels = coll
    return {p: M[np.ix_(keep, keep)] for p, M in mats.items()}, labels[keep]


def degraded(coll, fractions: dict[str, float], seed: int = 0):
    """The collection with, per part, that fraction of its shapes permuted among themselves."""
    mats, labels = coll
    rng = np.random.default_rng(seed)
    out = dict(mats)
    for p, fraction in fractions.items():
        if p not in mats:
            continue
        moved = rng.choice(len(labels), int(round(fraction * len(labels))), replace=False)
        perm = np.arange(len(labels))
        perm[moved] = rng.permutation(moved)
        out[p] = mats[p][np.ix_(perm, perm)]
    return out, labels


def grid_settings(base):
    """(name, Fusion) for every setting of the grid, from the default fusion ``base``."""
    for (w, ow), (k, rk), (s, sc), (a, pw), (b, beta), (al, alpha) in itertools.product(
            ORDER_WEIGHTS.items(), RERANK.items(), SCREEN.items(), POWER.items(), NORMALISATION.items(), ALPHA.items()):
        if rk is None and (beta, alpha) != (0.0, 0.9):
            continue  # without re-ranking the normalisation and alpha do nothing
        yield (f"weights {w}; k {k}; screen {s}; agreement power {a}; normalisation {b}; alpha {al}",
               replace(base, order_weights=ow, rerank_k=rk, screen=sc, agreement_power=pw, rerank_normalisation=beta,
                       rerank_alpha=alpha))


def rule_settings(base):
    """(name, Fusion) for ``--grid rules``: each agreement rule with each screen (no screen once), from ``base``."""
    yield "screen none", replace(base, screen=None)
    for rule, (s, screen) in itertools.product(AGREEMENT_RULES, RULE_SCREENS.items()):
        if screen is not None:
            yield f"agreement rule {rule}; screen {s}", replace(base, agreement_rule=rule, screen=screen)


def part_settings(base):
    """(name, Fusion) for ``--grid parts``: each part set of :data:`PART_SETS` with each screen."""
    for (name, parts), (s, screen) in itertools.product(PART_SETS.items(), PART_SCREENS.items()):
        yield f"{name}; screen {s}", replace(base, parts=parts, screen=screen)


def nn_map(D, labels) -> tuple[float, float]:
    m = retrieval_metrics(D, labels).micro
    return float(m["nn"]), float(m["map"])


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--watertight", required=True, help="index of SHREC'07 Watertight (default method, labelled)")
    ap.add_argument("--tune", nargs="*", default=[], help="indexes where settings may be chosen")
    ap.add_argument("--report", nargs="*", default=[], help="indexes only reported")
    ap.add_argument("--json", help="write the results here")
    ap.add_argument("--grid", choices=["full", "rules", "parts"], default="full",
                    help="full: the grid of the protocol (3,360 settings); rules: the agreement rules x screens, the "
                         "other settings at the default's (issue 29); parts: the part sets of PART_SETS x screens "
                         "(issue 29, 2026-12-05; every index must also hold gps and lfd)")
    ap.add_argument("--guard", type=float,
                    help="admit only settings that lose at most this much mAP against the current default on every "
                         "undegraded collection of the choice side (issue 29, 2026-12-03: the worst-margin criterion "
                         "otherwise buys a fraction of a query with 0.05-0.11 mAP on a Watertight half)")
    ap.add_argument("--choose-only", action="store_true",
                    help="stop after the choice: no report collection (Watertight's full set included) is evaluated")
    args = ap.parse_args()

    base = get_method(DEFAULT_METHOD).fusion
    extra = tuple(sorted({p for parts in PART_SETS.values() for p in parts} - set(base.parts))) \
        if args.grid == "parts" else ()
    all_parts = base.parts + extra
    wt = load(args.watertight, extra)
    classes = sorted(set(wt[1]))
    half_a = np.isin(wt[1], classes[0::2])
    colls = {"Watertight half A": restrict(wt, half_a), "Watertight half B": restrict(wt, ~half_a), "Watertight": wt}
    tune, report = [], ["Watertight"]
    for group, dbs in (("tune", args.tune), ("report", args.report)):
        for db in dbs:
            name = Path(db).stem
            colls[name] = load(db, extra)
            (tune if group == "tune" else report).append(name)
            for what, fractions in DEGRADED.items():
                colls[f"{name} ({what})"] = degraded(colls[name], fractions)
                (tune if group == "tune" else report).append(f"{name} ({what})")
    for half in ("Watertight half A", "Watertight half B"):
        colls[f"{half} (hidden-like)"] = degraded(colls[half], DEGRADED["hidden-like"])
    part_scores = {n: [nn_map(c[0][p], c[1]) for p in all_parts] for n, c in colls.items()}
    best_nn = {n: max(nn for nn, _ in scores) for n, scores in part_scores.items()}
    best_part = {n: max(ap for _, ap in scores) for n, scores in part_scores.items()}
    # each rule's first agreement is the same for every setting of one part set (consensus and iterative start from
    # the same one)
    agreements: dict = {}

    def first_agreement(n, fusion):
        key = ("mean" if fusion.agreement_rule == "mean" else "consensus", fusion.parts)
        if key not in agreements.setdefault(n, {}):
            mats = [colls[n][0][p] for p in fusion.parts]
            agreements[n][key] = agreement(mats) if key[0] == "mean" else consensus_agreement(mats)
        return agreements[n][key]

    def evaluate(fusion, names):
        out = {}
        for n in names:
            mats = [colls[n][0][p] for p in fusion.parts]
            out[n] = nn_map(fused_matrix(mats, fusion, decide(mats, fusion, agreements=first_agreement(n, fusion))),
                            colls[n][1])
        return out

    # every setting on the collections where a choice may be made (both Watertight halves, their
    # hidden-like copies and the tune collections); the report collections only for the settings chosen
    choice_side = [n for n in colls if n.startswith("Watertight half")] + tune
    settings = {"full": grid_settings, "rules": rule_settings, "parts": part_settings}[args.grid](base)
    grid = {name: (fusion, evaluate(fusion, choice_side)) for name, fusion in settings}

    def margin(results, names):
        # the worst margin over the best part, in NN or mAP, whichever is smaller
        return min(min(results[n][0] - best_nn[n], results[n][1] - best_part[n]) for n in names)

    current = evaluate(base, choice_side) if args.guard is not None else {}

    def admissible(g, names):
        # --guard: no real (undegraded) collection of the choice side loses more than the guard in mAP against the
        # catalogue's default when the script runs
        return args.guard is None or all(grid[g][1][n][1] >= current[n][1] - args.guard - 1e-9
                                          for n in names if n in current and "(" not in n)

    def choose(names, among=None):
        # the best worst margin, up to MARGIN_TIE; among those, the best mean mAP (then the better margin)
        among = sorted(grid) if among is None else sorted(among)
        among = [g for g in among if admissible(g, names)] or among
        top = max(margin(grid[g][1], names) for g in among)
        near = [g for g in among if margin(grid[g][1], names) >= top - MARGIN_TIE - 1e-9]  # one query is a tie
        return max(near, key=lambda g: (float(np.mean([grid[g][1][n][1] for n in names])), margin(grid[g][1], names)))

    def criterion(results, names):
        return margin(results, names), float(np.mean([results[n][1] for n in names]))

    out = {"selections": {}, "collections": {n: len(c[1]) for n, c in colls.items()}}
    if args.grid in ("rules", "parts"):  # small: every setting's results on the choice side, for the docs
        out["grid"] = {g: {n: [round(x, 4) for x in r] for n, r in res.items()} for g, (_, res) in grid.items()}
    for side, chosen_on, reported_on in (("A", "Watertight half A", "Watertight half B"),
                                         ("B", "Watertight half B", "Watertight half A")):
        names = [chosen_on, f"{chosen_on} (hidden-like)"] + tune
        best = choose(names)
        shown_here = [] if args.choose_only else [reported_on, f"{reported_on} (hidden-like)"] + report
        out["selections"][side] = {"chosen_on": names, "setting": best, "criterion": criterion(grid[best][1], names),
                                   "reported": {**{n: grid[best][1][n] for n in shown_here if n in grid[best][1]},
                                                **evaluate(grid[best][0], [n for n in shown_here
                                                                           if n not in grid[best][1]])}}
        print(f"selection {side} (chosen on {', '.join(names)}): {best}")
    # the default: the setting both selections chose; when they differ, the one `choose` prefers pooled
    # over both sides' tune collections (both Watertight halves and the tune collections)
    pooled = sorted(set(out["selections"]["A"]["chosen_on"]) | set(out["selections"]["B"]["chosen_on"]))
    candidates = {out["selections"][side]["setting"] for side in "AB"}
    out["default_rule"] = choose(pooled, among=candidates)
    print(f"default by the rule (agreement, else pooled over both tune sides): {out['default_rule']}")
    if args.choose_only:  # the choice, and nothing of the report side
        for side in "AB":
            del out["selections"][side]["reported"]  # empty
        if args.json:
            Path(args.json).write_text(json.dumps(out, indent=1))
        return
    shown = ["Watertight half A", "Watertight half B", "Watertight half A (hidden-like)",
             "Watertight half B (hidden-like)"] + report
    methods = {p: {n: nn_map(colls[n][0][p], colls[n][1]) for n in shown} for p in all_parts}
    equal = get_method("topomatch-equal").fusion
    methods["topomatch-equal"] = {n: nn_map(fused_matrix([colls[n][0][p] for p in equal.parts], equal), colls[n][1])
                                  for n in shown}
    if args.grid == "parts":  # the chosen settings themselves on every shown collection
        for side in "AB":
            name = out["selections"][side]["setting"]
            methods.setdefault(f"selection {side}: {name}", evaluate(grid[name][0], shown))
    methods[f"{DEFAULT_METHOD} (default)"] = {n: nn_map(fused_matrix([colls[n][0][p] for p in base.parts], base),
                                                        colls[n][1]) for n in shown}
    out["methods"] = methods
    out["default_at_run_time"] = repr(base)  # the "(default)" row's settings: the catalogue's when the script ran
    print("\n| method | " + " | ".join(shown) + " |\n|---|" + "---|" * len(shown))
    for m, res in methods.items():
        print(f"| {m} | " + " | ".join(f"{res[n][0]:.3f} / {res[n][1]:.3f}" for n in shown) + " |")
    if args.json:
        Path(args.json).write_text(json.dumps(out, indent=1))


if __name__ == "__main__":
    main()
