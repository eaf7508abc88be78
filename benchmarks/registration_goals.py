"""The issue's four accuracy goals, counted from the report splits' recorded rows (no registration is run).

Each report split (``final15``..``final52`` by default, the decision splits left out: every one declared before it ran,
run once, nothing chosen on it) is judged per dimension as the goals read (docs/registration.md, "Where the issue's goals stand"):

- *0 silent*: no result of ours that passed its self-check is wrong, with JT and with MI;
- *within 1 wherever elastix is*: no case elastix gets right (:func:`registration_corpus.correct`) that ours gets wrong,
  with JT and with MI;
- *false flags <= 1 %*: at most 1 % of the cases right and refused, with JT and with MI;
- *median TRE <= elastix's*: JT's median TRE (physical units) at most elastix's, an elastix run that gave no transform
  counting as an infinite error (``--finished``: over elastix's finished runs only).

Besides the per-split verdicts it pools the counts (``--from``/``--to``) and prints the JT silent rate over
``final2``–``--to`` beside elastix's wrong rate. Run::

    .venv/bin/python benchmarks/registration_goals.py [--to 52] [--json benchmarks/results/registration_goals.json]
"""

from __future__ import annotations

import argparse
import json
import math
import statistics
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).parent))
from registration_corpus import correct  # noqa: E402

RESULTS = Path(__file__).parent / "results"
METRICS = ("ours-jt", "ours-mi")
DECISION_SPLITS = {46, 48, 49}
"""Decision splits of the forty-fourth to forty-sixth rounds (their rows are the rounds' files): not report splits, left
out."""


def split_rows(n: int) -> list[dict]:
    return json.loads((RESULTS / f"registration_corpus_final{n}.json").read_text())["rows"]


def verdicts(rows: list[dict], dim: int, finished: bool = False) -> dict:
    """The four goals on one split and dimension: counts per method and whether each goal is met."""
    by = {m: {r["case"]: r for r in rows if r["dim"] == dim and r["method"] == m} for m in (*METRICS, "elastix")}
    cases = sorted(by["elastix"])
    out = {"cases": len(cases)}
    for m in METRICS:
        ours = by[m]
        out[m] = {"silent": sum(ours[c]["ok"] and not correct(ours[c]) for c in cases),
                  "false_flags": sum(not ours[c]["ok"] and correct(ours[c]) for c in cases),
                  "misses_where_elastix_right": sum(correct(by["elastix"][c]) and not correct(ours[c]) for c in cases)}
    elastix = [r["tre"] for c in cases if (r := by["elastix"][c])["tre"] is not None or not finished]
    out["median"] = {"ours-jt": statistics.median(by["ours-jt"][c]["tre"] for c in cases),
                     "elastix": statistics.median(math.inf if t is None else t for t in elastix)}
    out["met"] = {"silent": all(out[m]["silent"] == 0 for m in METRICS),
                  "within_1": all(out[m]["misses_where_elastix_right"] == 0 for m in METRICS),
                  "false_flags": all(out[m]["false_flags"] <= 0.01 * len(cases) for m in METRICS),
                  "median": out["median"]["ours-jt"] <= out["median"]["elastix"]}
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--from", dest="first", type=int, default=15)
    ap.add_argument("--to", dest="last", type=int, default=52)
    ap.add_argument("--finished", action="store_true", help="medians over elastix's finished runs only")
    ap.add_argument("--json", type=Path)
    args = ap.parse_args(argv)
    table = {n: {dim: verdicts(split_rows(n), dim, args.finished) for dim in (2, 3)}
             for n in range(args.first, args.last + 1) if n not in DECISION_SPLITS}
    goals = ("silent", "within_1", "false_flags", "median")
    print(f"{'split':8s} " + " ".join(f"{g + f' {d}D':>14s}" for g in goals for d in (2, 3)))
    for n, dims in table.items():
        print(f"final{n:<3d} " + " ".join(f"{'met' if dims[d]['met'][g] else '-':>14s}" for g in goals for d in (2, 3)))
    splits = len(table)
    summary = {f"{g}_{d}d": sum(dims[d]["met"][g] for dims in table.values()) for g in goals for d in (2, 3)}
    summary["splits"] = splits
    summary["silent_both"] = sum(dims[2]["met"]["silent"] and dims[3]["met"]["silent"] for dims in table.values())
    for d in (2, 3):
        cases = sum(dims[d]["cases"] for dims in table.values())
        summary[f"false_flags_jt_{d}d"] = f"{sum(dims[d]['ours-jt']['false_flags'] for dims in table.values())} of {cases}"
    pooled = {d: {"cases": 0, "jt_silent": 0, "elastix_wrong": 0} for d in (2, 3)}
    for n in range(2, args.last + 1):
        for r in split_rows(n) if n not in DECISION_SPLITS else ():
            p = pooled[r["dim"]]
            if r["method"] == "elastix":
                p["cases"] += 1
                p["elastix_wrong"] += not correct(r)
            elif r["method"] == "ours-jt":
                p["jt_silent"] += r["ok"] and not correct(r)
    summary["pooled_final2_to_last"] = pooled
    print(f"met, of {splits} splits: " + ", ".join(f"{k} {v}" for k, v in summary.items() if (k.endswith("d") and
                                                   not k.startswith("false_flags_jt")) or k == "silent_both"))
    for d in (2, 3):
        p = pooled[d]
        print(f"{d}D: JT false flags {summary[f'false_flags_jt_{d}d']} over final{args.first}-final{args.last}; "
              f"over final2-final{args.last} JT silent {p['jt_silent']} of {p['cases']} "
              f"({p['jt_silent'] / p['cases']:.2%}), elastix wrong {p['elastix_wrong']} ({p['elastix_wrong'] / p['cases']:.1%})")
    if args.json:
        args.json.write_text(json.dumps({"about": __doc__.splitlines()[0], "command": " ".join(sys.argv),
                                         "summary": summary, "splits": {f"final{n}": v for n, v in table.items()}},
                                        indent=1, default=str))
    return 0


if __name__ == "__main__":
    sys.exit(main())
