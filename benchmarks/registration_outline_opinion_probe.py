"""A probe for the kind attack's silent class (a parcellation whose inner boundaries do not correspond to the T1,
which fools every entropic measure): does **the outline's own answer** tell a fooled result from a right one?

For every recorded row of ours on a label kind (``atlas``, ``regions``) of the kind attack's splits, the label image
(the fixed image when swapped) is replaced by its object (label > 0, at 0 / 1) and the pair registered again with
the defaults (an outline-only pair: mutual information on the smoothed finest level); printed per row: the recorded
result's TRE, the outline answer's TRE and the distance between the two (mean displacement over the fixed grid, the
corpus's TRE between the two transforms), with the rows' verdicts. Nothing here changes the registration.

    TOPOMATCH_DATA_ROOT=../shared/data .venv/bin/python benchmarks/registration_outline_opinion_probe.py \\
        benchmarks/results/registration_kind_attack_2d.json ... [--json OUT]
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import sys
import tempfile
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
import registration_corpus as corpus  # noqa: E402
import registration_kind_attack as kinds  # noqa: E402

from topomatch.stages.registration.transform import RigidTransform  # noqa: E402

LABEL_KINDS = ("atlas", "regions")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("files", nargs="+", type=Path)
    ap.add_argument("--json", type=Path, default=None)
    args = ap.parse_args()
    kinds.register_split()
    rows = [r for f in args.files for r in json.loads(f.read_text())["rows"]
            if r["method"] == "ours-jt" and r["kind"] in LABEL_KINDS and not r.get("error")]
    specs = {s.id: s for split in {r["split"] for r in rows} for dim in (2, 3) for s in corpus.plan_split(split, dim)}
    out = []
    with tempfile.TemporaryDirectory() as tmp:
        for row in rows:
            case = corpus.build_case(specs[row["case"]])
            role = "fixed" if case.spec.swapped else "moving"
            image = getattr(case, role)
            case = dataclasses.replace(case, **{role: image.with_data((image.data > 0).astype(np.float64),
                                                                             name=image.name)})
            fixed_path, moving_path, fixed, moving = corpus.write_case(case, Path(tmp))
            outline = corpus.run_ours("jt", fixed_path, moving_path, fixed, moving)
            e = row["estimate"]  # named(): angles in degrees first, then the translation
            recorded = RigidTransform(tuple(np.radians(v) if n.startswith("angle") else v for n, v in e.items()),
                                      tuple(row["center"]))
            centre = tuple(fixed.center)
            apart = corpus.mean_tre(outline.transform.with_center(centre), recorded.with_center(centre), fixed)
            tre = corpus.mean_tre(outline.transform.with_center(centre), case.truth.with_center(centre), fixed)
            unit = row.get("unit", 1.0) if row["dim"] == 2 else 1.0
            verdict = ("FF" if row["flags"] else "ok") if corpus.correct(row) else ("fw" if row["flags"] else "silent")
            out.append({"case": row["case"], "dim": row["dim"], "kind": row["kind"], "verdict": verdict,
                        "tre": row["tre"], "outline_tre": tre, "apart": apart, "unit": unit,
                        "outline_ok": outline.ok})
            print(f"{row['case']:34s} {row['kind']:8s} {verdict:6s} tre {row['tre'] / unit:8.2f}  outline tre "
                  f"{tre / unit:8.2f} ({'ok' if outline.ok else 'flagged'})  apart {apart / unit:8.2f} units", flush=True)
    if args.json:
        args.json.write_text(json.dumps({"command": " ".join(sys.argv), "rows": out}, indent=1))


if __name__ == "__main__":
    main()
