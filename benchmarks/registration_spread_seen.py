"""The seen report cases that the fortieth round changes, registered again with the code importable here: every
``ours-jt`` row of ``final15``–``final41`` (``benchmarks/results/registration_corpus_final<n>.json``) that was not
measured as an outline and whose smaller interior spread (``measures.spread_fixed`` / ``spread_moving``) is below
``--below``, rebuilt from its seeds and registered with JT as a user does (``topomatch.register(fixed_path,
moving_path)``, defaults). Run it from two trees (``PYTHONPATH=<a tree laid out by registration_speed.baseline_env>``
for the other) and compare the files: these splits are *seen*, so nothing here is a report number.

    TOPOMATCH_DATA_ROOT=../shared/data .venv/bin/python benchmarks/registration_spread_seen.py \\
        --out benchmarks/results/registration_r40_seen_round.json
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


def seen_cases(below: float, splits=range(15, 42)) -> list[tuple[str, float]]:
    """(case id, smaller interior spread) of each recorded JT row below ``below``, 3D first."""
    out = []
    for n in splits:
        for row in json.loads((RESULTS / f"registration_corpus_final{n}.json").read_text())["rows"]:
            m = row["measures"] or {}
            spread = min(m.get("spread_fixed", 9.0), m.get("spread_moving", 9.0))
            if row["method"] == "ours-jt" and row["tre"] is not None and "outline_alpha" not in m and spread < below:
                out.append((row["case"], spread))
    return sorted(out, key=lambda c: "-3d-" not in c[0])


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--below", type=float, default=0.15, help="the interior spread below which a row is taken")
    ap.add_argument("--out", type=Path, required=True)
    args = ap.parse_args()
    import topomatch

    folder, rows = Path(tempfile.mkdtemp(prefix="spread_seen_")), []
    for case_id, spread in seen_cases(args.below):
        case = corpus.case_by_id(case_id)
        fixed_path, moving_path, fixed, moving = corpus.write_case(case, folder)
        result = corpus.run_ours("jt", fixed_path, moving_path, fixed, moving)  # topomatch.register, defaults
        row = corpus.score(case, fixed, "ours-jt", result)
        rows.append({"case": case_id, "dim": case.spec.dim, "kind": case.spec.kind, "spread": spread,
                     "tre": row["tre"] / row["unit"], "ok": result.ok, "flags": sorted(result.flags),
                     "alpha": result.measures.get("outline_alpha")})
        print(json.dumps(rows[-1]), flush=True)
    args.out.write_text(json.dumps({"topomatch": topomatch.__file__, "command": " ".join(sys.argv), "rows": rows},
                                   indent=1) + "\n")


if __name__ == "__main__":
    main()
