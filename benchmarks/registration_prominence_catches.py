"""The seen wrong results that the ``prominence`` test alone refused, registered again with the code importable here: a
change that moves the coarse search's landscape (the thirty-ninth round) must not turn one of them silent.

The cases are every row of ``benchmarks/results`` (report splits and attacks, any release) whose result was wrong and
flagged by ``prominence`` only, up to 2026-12-06 (the list below, with the split scale each was drawn at); each is
rebuilt by its script's split registration, written as the corpus writes it and registered as a user does
(``topomatch.register(fixed_path, moving_path, metric=m)``, defaults), with the metrics that were caught. Run it from
two trees (``PYTHONPATH=<a tree laid out by registration_speed.baseline_env>`` for the other) and compare the lines.

    TOPOMATCH_DATA_ROOT=../shared/data .venv/bin/python benchmarks/registration_prominence_catches.py \\
        --out benchmarks/results/registration_prominence_catches.txt
"""

from __future__ import annotations

import argparse
import sys
import tempfile
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
import registration_corpus as corpus  # noqa: E402
import registration_kind_attack as kind_attack  # noqa: E402
import registration_pair_kind_attack as pair_kind_attack  # noqa: E402

CASES = [("final6-2d-mni-coronal-003", "jt,mi", 1), ("final31-2d-mni-coronal-008", "jt,mi", 1),
         ("kinds-3-2d-mni-sagittal-004", "jt,mi", 1), ("kinds-7-2d-mni-coronal-034", "jt", 5),
         ("final2-3d-anatomical-003", "mi", 1), ("final12-3d-anatomical-001", "mi", 1),
         ("final12-3d-anatomical-003", "jt", 1), ("kinds-3d-anatomical-003", "jt", 1),
         ("kinds-3-3d-anatomical-003", "jt", 1), ("kinds-7-3d-anatomical-002", "jt", 5),
         ("kinds-7-3d-anatomical-028", "jt,mi", 5), ("kinds-9-3d-anatomical-012", "jt", 10),
         ("kinds-9-3d-anatomical-048", "jt,mi", 10), ("kinds-9-3d-anatomical-057", "mi", 10),
         ("kinds-10-3d-anatomical-007", "mi", 5), ("pair-kinds-3d-anatomical-000", "mi", 2),
         ("pair-kinds-3d-anatomical-005", "jt", 2)]
"""(case id, the metrics prominence alone caught, the ``--cases-scale`` its split was run at)."""


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", type=Path, default=None, help="also write the lines here")
    args = ap.parse_args()
    import topomatch

    kind_attack.register_split()
    pair_kind_attack.register_split()
    folder, lines = Path(tempfile.mkdtemp(prefix="prominence_catches_")), []
    for case_id, metrics, scale in CASES:
        case = corpus.case_by_id(case_id, scale)
        fixed_path, moving_path, fixed, moving = corpus.write_case(case, folder)
        for metric in metrics.split(","):
            result = corpus.run_ours(metric, fixed_path, moving_path, fixed, moving)  # topomatch.register, defaults
            row = corpus.score(case, fixed, f"ours-{metric}", result)
            lines.append(f"{case_id:30s} {metric}  TRE {row['tre'] / row['unit']:6.2f} {'px' if case.spec.dim == 2 else 'mm'}  "
                         f"{'ok (silent)' if result.ok else 'flagged'}  {sorted(result.flags)}  prominence "
                         f"{result.measures.get('prominence', float('nan')):.2f}")
            print(lines[-1], flush=True)
    if args.out:
        args.out.write_text(f"topomatch {topomatch.__file__}\n" + "\n".join(lines) + "\n")


if __name__ == "__main__":
    main()
