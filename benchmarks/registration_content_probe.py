"""The thirty-third round's probe: the ``content`` test's measure of recorded corpus rows, at their recorded
estimates, with the contents as the test took them before the round (Otsu foregrounds) and as it takes them now
(holes filled, 4-connected), and the verdicts each gives. The round changes no estimate and no other flag, so a
row's flags with the new measure are its recorded flags with ``content`` re-decided (``check.min_content``, 2D).

    TOPOMATCH_DATA_ROOT=../shared/data .venv/bin/python benchmarks/registration_content_probe.py \\
        benchmarks/results/registration_r31_ensemble_tune.json [--attack kinds|probability|sources] [--json OUT]

Rows of ours (2D, with a recorded ``content`` measure) are rebuilt from the corpus's specs at the default
``--cases-scale`` (``--attack``: the split registered by that attack's script first). Prints ok / FF / fw / silent
before and after, and every row that changes class."""

from __future__ import annotations

import argparse
import collections
import json
import math
import sys
import tempfile
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
import registration_corpus as corpus  # noqa: E402

from topomatch.stages.registration.image import foreground_mask  # noqa: E402
from topomatch.stages.registration.params import CheckSpec  # noqa: E402
from topomatch.stages.registration.search import SearchImages  # noqa: E402

MIN_CONTENT = CheckSpec().min_content


def contents(fixed, moving, theta: np.ndarray) -> tuple[float, float]:
    """(the measure with the Otsu foregrounds as they are, as before the round; the round's, their holes filled)."""
    images = SearchImages(fixed, moving, center=fixed.center, min_overlap=0.25)
    filled = images.content_overlap(theta)  # also pads the search copy's canvas for theta's cells
    cells = images._cells(np.asarray(theta, dtype=np.float64), np.zeros((1, images.dim), dtype=np.intp))[0]
    fixed_content = foreground_mask(images._fixed_small).ravel()[images._flat]
    moving_content = np.pad(foreground_mask(images.moving_small), images._pad).ravel()
    return np.count_nonzero(moving_content[cells] & fixed_content) / max(1, int(np.count_nonzero(fixed_content))), filled


def verdict(row: dict, flags: set[str]) -> str:
    return ("FF" if flags else "ok") if corpus.correct(row) else ("fw" if flags else "silent")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("files", nargs="+", type=Path)
    ap.add_argument("--attack", choices=("kinds", "probability", "sources"), default=None)
    ap.add_argument("--json", type=Path, default=None)
    args = ap.parse_args()
    if args.attack:
        __import__({"kinds": "registration_kind_attack", "probability": "registration_probability_attack",
                    "sources": "registration_source_attack"}[args.attack]).register_split()
    rows = [r for f in args.files for r in json.loads(f.read_text())["rows"] if str(r["method"]).startswith("ours")
            and r["dim"] == 2 and not r.get("error") and "content" in r["measures"]]
    specs = {s.id: s for split in {r["split"] for r in rows} for s in corpus.plan_split(split, 2)}
    out, counts, built = [], collections.Counter(), {}
    with tempfile.TemporaryDirectory() as tmp:
        for row in rows:
            if row["case"] not in built:
                built = {row["case"]: corpus.write_case(corpus.build_case(specs[row["case"]]), Path(tmp))[2:]}
            e = row["estimate"]
            old, new = contents(*built[row["case"]], np.array([math.radians(e["angle"]), e["tx"], e["ty"]]))
            flags = set(row["flags"]) - {"content"}
            before, after = (verdict(row, flags | ({"content"} if v < MIN_CONTENT else set())) for v in (old, new))
            counts[before, after] += 1
            out.append({"case": row["case"], "method": row["method"], "kind": row["kind"], "recorded": row["measures"]["content"],
                        "before_round": old, "round": new, "verdict_before": before, "verdict_after": after})
            if before != after:
                print(f"{row['case']} {row['method']} {row['kind']}: content {old:.3f} -> {new:.3f}, {before} -> {after}")
    for key in ("before", "after"):
        tally = collections.Counter(b if key == "before" else a for (b, a), n in counts.items() for _ in range(n))
        print(f"{key}: ok / FF / fw / silent = {' / '.join(str(tally[v]) for v in ('ok', 'FF', 'fw', 'silent'))}")
    if args.json:
        args.json.write_text(json.dumps({"command": " ".join(sys.argv), "rows": out}, indent=1))


if __name__ == "__main__":
    main()
