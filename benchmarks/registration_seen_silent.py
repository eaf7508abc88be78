"""Every case that a seen report split of the corpus recorded as silently wrong, registered again with today's
defaults: does the class of error each one found still pass unflagged?

Usage::

    TOPOMATCH_DATA_ROOT=../shared/data .venv/bin/python benchmarks/registration_seen_silent.py \\
        [--splits final,final2,...] [--params JSON] [--json benchmarks/results/registration_seen_silent.json]

For each split's recorded JSON (``benchmarks/results/registration_corpus_<split>.json``), the cases where ``ours-jt``
or ``ours-mi`` passed its self-check with a wrong result (:func:`registration_corpus.correct` false) are rebuilt from
their seeds (:func:`registration_corpus.build_case`) and registered with JT and MI as a user runs it
(:func:`registration_corpus.run_ours`: ``topomatch.register`` on the written files). Prints then and now per case and
metric (TRE, ok / flags) and the count still silently wrong. These splits are *seen*: nothing here is a report number
and nothing is chosen on it; it finds which mechanisms are still open (docs/registration_history.md, tenth round).
"""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
import registration_corpus as corpus  # noqa: E402

RESULTS = Path(__file__).resolve().parent / "results"
SEEN = ("final", "final2", "final3", "final4", "final5", "final6")


def silent_cases(split: str) -> dict[str, dict]:
    """Case id -> {method: recorded row} for the cases a split recorded as silently wrong with JT or MI."""
    rows = json.loads((RESULTS / f"registration_corpus_{split}.json").read_text())["rows"]
    out: dict[str, dict] = {}
    for row in rows:
        if row["method"] in ("ours-jt", "ours-mi") and row["ok"] and not corpus.correct(row):
            out.setdefault(row["case"], {})[row["method"]] = row
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--splits", default=",".join(SEEN))
    ap.add_argument("--params", default="", help="JSON overrides of the register parameters (a candidate setting)")
    ap.add_argument("--json", type=Path, default=None)
    args = ap.parse_args()
    corpus.PARAMS.update(json.loads(args.params) if args.params else {})
    folder = Path(tempfile.mkdtemp(prefix="topomatch-seen-silent-"))
    out, still = [], {"ours-jt": 0, "ours-mi": 0}
    for split in args.splits.split(","):
        wanted = silent_cases(split)
        for dim in (2, 3):
            for spec in corpus.plan_split(split, dim):
                if spec.id not in wanted:
                    continue
                case = corpus.build_case(spec)
                fixed_path, moving_path, fixed, moving = corpus.write_case(case, folder)
                for metric in ("jt", "mi"):
                    method = f"ours-{metric}"
                    row = corpus.score(case, fixed, method, corpus.run_ours(metric, fixed_path, moving_path, fixed,
                                                                            moving))
                    then = wanted[spec.id].get(method)
                    row["then"] = {k: then[k] for k in ("tre", "ok", "flags")} if then else None
                    silent = row["ok"] and not corpus.correct(row)
                    still[method] += silent
                    out.append(row)
                    was = f"{then['tre']:.2f} ok" if then else "not silent"
                    print(f"{spec.id:32s} {metric} {spec.kind:12s} then {was:12s} now {row['tre']:.2f} "
                          f"{'ok' if row['ok'] else 'flagged ' + ','.join(row['flags'])}"
                          f"{'  SILENT' if silent else ''}", flush=True)
    print(f"still silently wrong: JT {still['ours-jt']}, MI {still['ours-mi']} (of {len(out) // 2} cases)")
    if args.json:
        args.json.write_text(json.dumps({"about": __doc__.split("\n\n")[0], "versions": corpus._versions(),
                                         "params": corpus.PARAMS, "rows": out,
                                         "still_silent": still}, indent=1))


if __name__ == "__main__":
    main()
