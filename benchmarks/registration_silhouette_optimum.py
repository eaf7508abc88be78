"""Where the measure's optimum lies on the seen 2D silhouettes: at the truth, or at the wrong answer?

For each 2D silhouette row (``silhouette``, ``silhouette_resampled``) of the report splits ``final30``–``final44`` that
JT registered wrong (more than 1 pixel off: :func:`registration_corpus.correct`), and every ``--every``-th one it
registered right, the case is rebuilt from its
seeds, registered again as the user runs it (:func:`registration_corpus.run_ours`, defaults), and the finest level's
measure (the one the result climbed: on an outline-only pair JT and MI both measure at ``metric.outline_alpha``, order
1) is evaluated at the truth and at the answer on ``--samples`` fresh samples of that level (new seeds, not the run's).
``rel`` = (measure at the truth - measure at the answer) / |measure at the answer|, their mean: negative means the
measure prefers the wrong answer, so no optimiser, start or retry on this measure reaches the truth; positive means the
optimiser stopped short of a better value (a search or capture failure).

``--objects`` repeats both with each image replaced by its object (:func:`~.structure.object_mask`: Otsu's content,
closed, holes filled) and registers the objects too: does a silhouette-to-silhouette measure put the optimum at the
truth? (Images whose object fills the grid cannot be binned: skipped, counted.)

Nothing is chosen here: the rows read are seen (report rows already used to choose thresholds), and the study only
measures. Run::

    TOPOMATCH_DATA_ROOT=../shared/data .venv/bin/python benchmarks/registration_silhouette_optimum.py --objects \\
        --json benchmarks/results/registration_silhouette_optimum.json
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
from topomatch.stages.registration.structure import object_mask  # noqa: E402

RESULTS = Path(__file__).parent / "results"


def seen_rows(first: int, last: int, every: int) -> list[dict]:
    """The JT 2D silhouette rows of ``final<first>``..``final<last>``: every wrong one, every ``every``-th right one."""
    rows = []
    for n in range(first, last + 1):
        rows += [r for r in json.loads((RESULTS / f"registration_corpus_final{n}.json").read_text())["rows"]
                 if r["dim"] == 2 and r["method"] == "ours-jt" and r["kind"].startswith("silhouette")
                 and r["tre"] is not None]
    right = [r for r in rows if rc.correct(r)]
    return [r for r in rows if not rc.correct(r)] + right[::every]


def preference(fixed, moving, truth, answer, samples: int) -> float:
    """Mean over ``samples`` fresh samples of the finest level of (measure(truth) - measure(answer)) / |measure(answer)|."""
    params = for_dimension(RegisterParams(), fixed.dim)
    run = R._Run(fixed, moving, params, R.sample_mask(fixed, params), None)
    fine = run.levels[-1]
    rel = []
    for k in range(samples):
        objective = fine.objective.on(run.histogram(fine.spec, fine.images, fine.objective.histogram.n_samples, 1000 + k))
        at_truth, at_answer = objective(truth), objective(answer)
        rel.append((at_truth - at_answer) / abs(at_answer))
    return float(np.mean(rel))


def study(row: dict, folder: Path, samples: int, objects: bool) -> dict:
    case = rc.case_by_id(row["case"])
    fixed_path, moving_path, fixed, moving = rc.write_case(case, folder)
    result = rc.run_ours("jt", fixed_path, moving_path, fixed, moving)
    scored = rc.score(case, fixed, "ours-jt", result)
    truth = case.truth.with_center(fixed.center)
    answer = result.transform.with_center(fixed.center)
    out = {"case": row["case"], "kind": row["kind"], "degradations": row["degradations"], "unit": scored["unit"],
           "tre_px": scored["tre"] / scored["unit"], "recorded_tre_px": row["tre"] / row["unit"],
           "correct": rc.correct(scored), "ok": result.ok, "flags": result.flags,
           "rel": preference(fixed, moving, np.asarray(truth.parameters), np.asarray(answer.parameters), samples)}
    if objects:
        F, M = (im.with_data(object_mask(im).astype(np.float64)) for im in (fixed, moving))
        try:
            out["objects_rel"] = preference(F, M, np.asarray(truth.parameters), np.asarray(answer.parameters), samples)
            reg = R.register(F, M)
            out["objects_tre_px"] = rc.mean_tre(reg.transform.with_center(fixed.center), truth, fixed) / scored["unit"]
            out["objects_ok"] = bool(reg.ok)
        except ValueError as exc:  # an object that fills its grid: a constant image, nothing to bin
            out["objects_skipped"] = str(exc)
    return out


def summary(rows: list[dict]) -> dict:
    wrong, right = [r for r in rows if not r["correct"]], [r for r in rows if r["correct"]]
    silent = [r for r in wrong if r["ok"]]
    objects = [r for r in wrong if "objects_rel" in r]
    return {"wrong": len(wrong), "wrong_measure_prefers_answer": sum(r["rel"] < 0 for r in wrong),
            "silent": len(silent), "silent_measure_prefers_answer": sum(r["rel"] < 0 for r in silent),
            "right": len(right), "right_measure_prefers_answer": sum(r["rel"] < 0 for r in right),
            "wrong_with_objects": len(objects),
            "wrong_objects_measure_prefers_answer": sum(r["objects_rel"] < 0 for r in objects),
            "wrong_objects_registered_within_1px": sum(r["objects_tre_px"] <= 1.0 for r in objects),
            "right_objects_registered_within_1px": sum(r.get("objects_tre_px", np.inf) <= 1.0 for r in right),
            "objects_skipped": sum("objects_skipped" in r for r in rows)}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--first", type=int, default=30)
    ap.add_argument("--last", type=int, default=44)
    ap.add_argument("--every", type=int, default=7, help="every N-th correctly registered row (all wrong ones)")
    ap.add_argument("--samples", type=int, default=5)
    ap.add_argument("--objects", action="store_true", help="also the objects' measure and registration")
    ap.add_argument("--json", type=Path)
    args = ap.parse_args(argv)
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for row in seen_rows(args.first, args.last, args.every):
            rows.append(study(row, Path(tmp), args.samples, args.objects))
            r = rows[-1]
            print(f"{r['case']:32s} {r['tre_px']:6.2f} px ok {r['ok']!s:5} rel {r['rel']:+.4f}"
                  + (f" objects rel {r['objects_rel']:+.4f} {r['objects_tre_px']:6.2f} px" if "objects_rel" in r else ""),
                  flush=True)
    print(json.dumps(summary(rows), indent=1))
    rc.save_study(args.json, __doc__, summary(rows), rows)
    return 0


if __name__ == "__main__":
    sys.exit(main())
