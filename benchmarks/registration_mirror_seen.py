"""What the forty-fourth round's ``mirror`` test says on the seen 2D report rows, at their recorded answers.

The test only adds a flag, so its effect on a recorded row is read without registering again: each 2D JT row of
``final15``–``final45`` (2,972 cases, each registered once with the release of its day) is rebuilt from its seeds and
read back from its files as the user's run read it, a run is built as ``register`` builds one, and
:func:`~topomatch.stages.registration.register.check_mirror` is asked at the row's recorded estimate. Counted: the
correct results it would refuse that passed (new false flags), the wrong ones it would refuse that passed (silent
errors caught), and the ratio's distribution. The recorded estimates come from older releases for older splits; the
test reads only the images and the estimate. Run::

    TOPOMATCH_DATA_ROOT=../shared/data .venv/bin/python benchmarks/registration_mirror_seen.py --first 15 --last 45 \\
        --json benchmarks/results/registration_mirror_seen.json
"""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).parent))
import registration_corpus as rc  # noqa: E402

from topomatch.stages.registration import register as R  # noqa: E402
from topomatch.stages.registration.params import RegisterParams, for_dimension  # noqa: E402
from topomatch.stages.registration.transform import RigidTransform  # noqa: E402

RESULTS = Path(__file__).parent / "results"


def mirror_at(row: dict, folder: Path) -> dict:
    """The row's case, its mirror ratio and flag at the recorded estimate."""
    case = rc.case_by_id(row["case"])
    _, _, fixed, moving = rc.write_case(case, folder)
    params = for_dimension(RegisterParams(), 2)
    run = R._Run(fixed, moving, params, R.sample_mask(fixed, params), None)
    run.measures, run.better = {}, None
    e = row["estimate"]
    theta = np.asarray(RigidTransform.euler2d(e["tx"], e["ty"], e["angle"], row["center"]).with_center(fixed.center).parameters)
    flags = R.check_mirror(run, theta, run.levels[-1].objective(theta), "")
    return {"case": row["case"], "kind": row["kind"], "source": row["source"], "correct": rc.correct(row),
            "ok": row["ok"], "mirror": run.measures.get("mirror"), "flagged": bool(flags)}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--first", type=int, default=15)
    ap.add_argument("--last", type=int, default=45)
    ap.add_argument("--part", default="0/1", help="k/n: every n-th row from the k-th (to split the work)")
    ap.add_argument("--json", type=Path)
    args = ap.parse_args(argv)
    k, n = (int(x) for x in args.part.split("/"))
    rows = [r for i in range(args.first, args.last + 1)
            for r in json.loads((RESULTS / f"registration_corpus_final{i}.json").read_text())["rows"]
            if r["dim"] == 2 and r["method"] == "ours-jt" and r["estimate"] is not None][k::n]
    out = []
    with tempfile.TemporaryDirectory() as tmp:
        for row in rows:
            out.append(mirror_at(row, Path(tmp)))
            o = out[-1]
            print(f"{o['case']:34s} {o['kind']:20s} correct {o['correct']!s:5} ok {o['ok']!s:5} mirror {o['mirror']}"
                  f"{' FLAG' if o['flagged'] else ''}", flush=True)
    summary = {"rows": len(out),
               "new_false_flags": sum(o["flagged"] and o["correct"] and o["ok"] for o in out),
               "flags_on_correct": sum(o["flagged"] and o["correct"] for o in out),
               "silent_caught": sum(o["flagged"] and not o["correct"] and o["ok"] for o in out),
               "flags_on_wrong": sum(o["flagged"] and not o["correct"] for o in out),
               "wrong": sum(not o["correct"] for o in out), "silent": sum(not o["correct"] and o["ok"] for o in out)}
    print(json.dumps(summary))
    rc.save_study(args.json, __doc__, summary, out)
    return 0


if __name__ == "__main__":
    sys.exit(main())
