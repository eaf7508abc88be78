"""Where the 2D median TRE gap to elastix comes from: the optimiser stopping short, or the finest level's measure.
Tune side only (``registration_corpus.py``'s ``tune`` split, built in memory; nothing here is a report).

Usage::

    TOPOMATCH_DATA_ROOT=../shared/data .venv/bin/python benchmarks/registration_fine_level.py polish [--cases 30]
    TOPOMATCH_DATA_ROOT=../shared/data .venv/bin/python benchmarks/registration_fine_level.py variants \\
        [--names default,all,b48,it60,pv,avg4,all_b48,s40k,sm05,sm075,sm1]

- ``polish``: register with the defaults (JT), then maximise the finest level's own measure from the result with
  Powell (200 evaluations); prints the measure at the result, at the truth and after the polish, and the TRE of
  both. If the measure at the truth is below the measure at the result, the optimiser did its job and the error
  is the measure's.
- ``variants``: the 2D finest level changed one way at a time (:data:`VARIANTS`), JT and MI on every 2D tune case;
  correct count, median TRE over correct results (pixels), silent errors and false flags.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
import registration_corpus as corpus  # noqa: E402

from topomatch.stages.optimize.powell import PowellSettings, powell_maximize  # noqa: E402
from topomatch.stages.registration.params import DIMENSION_DEFAULTS, RegisterParams, for_dimension  # noqa: E402
from topomatch.stages.registration.register import _Run, register, sample_mask  # noqa: E402
from topomatch.stages.registration.transform import RigidTransform  # noqa: E402

VARIANTS = {
    "default": {}, "all": {"samples": None}, "s40k": {"samples": 40000}, "b48": {"bins": 48},
    "all_b48": {"samples": None, "bins": 48}, "pv": {"interpolation": "pv"}, "it60": {"iterations": 60},
    "avg4": {"average": 4}, "sm05": {"smoothing": 0.5}, "sm075": {"smoothing": 0.75}, "sm1": {"smoothing": 1.0},
}
"""Changes to the 2D finest level (:data:`DIMENSION_DEFAULTS`), one at a time."""


def tre_px(case: corpus.Case, parameters) -> float:
    """The corpus's mean TRE (:func:`registration_corpus.mean_tre`) in pixels, its 2D unit."""
    F = case.fixed
    return corpus.mean_tre(RigidTransform(tuple(parameters), tuple(F.center)), case.truth.with_center(F.center),
                           F) / max(F.spacing)


def polish(cases: list[corpus.Case]) -> None:
    rows = []
    for case in cases:
        F, M = case.fixed, case.moving
        params = for_dimension(RegisterParams(), 2)
        reg = register(F, M, params)
        run = _Run(F, M, params, sample_mask(F, params), None)
        fine = run.levels[-1].objective
        est = np.asarray(reg.transform.with_center(F.center).parameters)
        truth = np.asarray(case.truth.with_center(F.center).parameters)
        settings = PowellSettings(max_evaluations=200, xtol=0.002 * run.levels[-1].spacing, step=0.5)
        res = powell_maximize(fine, est, settings, scales=run.scales, lower=run.lower, upper=run.upper)
        rows.append((tre_px(case, est), tre_px(case, res.theta), fine(est), fine(truth), fine(res.theta)))
        print(f"{case.spec.id:28s} TRE {rows[-1][0]:.3f} -> polished {rows[-1][1]:.3f} px | measure at result "
              f"{rows[-1][2]:.4f}, truth {rows[-1][3]:.4f}, polished {rows[-1][4]:.4f}", flush=True)
    good = [r for r in rows if r[0] <= 1]
    print(f"{len(good)} correct: median TRE {np.median([r[0] for r in good]):.4f} -> polished "
          f"{np.median([r[1] for r in good]):.4f} px; measure at the truth below that at the result on "
          f"{sum(r[3] < r[2] for r in good)} of {len(good)}")


def variants(cases: list[corpus.Case], names: list[str]) -> None:
    for name in names:
        schedule = [dict(level) for level in DIMENSION_DEFAULTS[2]["schedule"]]
        schedule[-1].update(VARIANTS[name])
        for metric in ("jt", "mi"):
            params = RegisterParams.model_validate({"metric": {"name": metric}, "schedule": schedule})
            rows = []
            for case in cases:
                reg = register(case.fixed, case.moving, params)
                rows.append((tre_px(case, reg.transform.with_center(case.fixed.center).parameters), reg.ok))
            good = [t for t, _ in rows if t <= 1]
            silent, false_flags = sum(ok and t > 1 for t, ok in rows), sum(not ok and t <= 1 for t, ok in rows)
            print(f"{name:8s} {metric}: correct {len(good)} of {len(rows)}, median TRE {np.median(good):.4f} px, "
                  f"silent {silent}, false flags {false_flags}", flush=True)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("what", choices=("polish", "variants"))
    ap.add_argument("--cases", type=int, default=30, help="polish: the first N 2D tune cases")
    ap.add_argument("--names", default=",".join(VARIANTS), help="variants: which (comma-separated)")
    args = ap.parse_args()
    specs = corpus.plan_split("tune", 2)
    if args.what == "polish":
        polish([corpus.build_case(s) for s in specs[: args.cases]])
    else:
        variants([corpus.build_case(s) for s in specs], args.names.split(","))


if __name__ == "__main__":
    main()
