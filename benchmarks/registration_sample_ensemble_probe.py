"""Where a 2D registration's error comes from, and what averaging over samples buys: the probe behind the thirty-first
round (docs/registration_history.md). No registration code is changed by it.

For the first ``--cases`` cases of a corpus split (``--kinds`` to restrict them), registered with the defaults but
``optimizer.ensemble: 0`` (the result before the round), the mean TRE in pixels of:

- ``result``: the registration's estimate;
- ``polished``: that estimate polished to the finest measure's own optimum (Nelder-Mead from it), on its own sample
  and (``polished-all``) on every fixed pixel of the finest level;
- ``same-k``: the mean of the estimate and ``k`` re-runs of the finest level from it on the *same* sample (the
  control: more iterations, no other sample);
- ``other-k``: the mean of the estimate and ``k`` re-runs on *other* samples (other subset, other jitter), k = 1 ..
  ``--reruns``: the round's rule without its one-unit cut.

Medians over the cases, per group: pairs read as images and outline-only pairs (``outline_measure``).

    TOPOMATCH_DATA_ROOT=../shared/data .venv/bin/python benchmarks/registration_sample_ensemble_probe.py \\
        --split edge --cases 40 --reruns 4
"""

from __future__ import annotations

import argparse
import statistics
import sys
from pathlib import Path

import numpy as np
from scipy.optimize import minimize

sys.path.insert(0, str(Path(__file__).resolve().parent))
import registration_corpus as corpus  # noqa: E402  (the corpus's cases)

from topomatch.stages.registration.params import RegisterParams, for_dimension  # noqa: E402
from topomatch.stages.registration.register import _Run, register, sample_mask  # noqa: E402
from topomatch.stages.registration.transform import RigidTransform  # noqa: E402


def probe(case: corpus.Case, reruns: int) -> tuple[bool, dict[str, float]]:
    """(outline-measured, {estimate name: mean TRE in pixels}) of one case."""
    params = for_dimension(RegisterParams(optimizer={"ensemble": 0}), 2)
    reg = register(case.fixed, case.moving, params)
    run = _Run(case.fixed, case.moving, params, sample_mask(case.fixed, params), None)
    li, fine = len(run.levels) - 1, run.levels[-1]
    theta = np.asarray(reg.transform.parameters)

    def tre(t) -> float:
        estimate = RigidTransform(tuple(t), tuple(case.fixed.center))
        return corpus.mean_tre(estimate, case.truth, case.fixed) / float(case.fixed.spacing[0])

    def polish(objective) -> np.ndarray:
        simplex = [theta] + [theta + d for d in np.diag([0.005, 0.3, 0.3])]
        return minimize(lambda t: -objective(t), theta, method="Nelder-Mead",
                        options={"xatol": 1e-4, "fatol": 1e-12, "maxiter": 2000, "initial_simplex": simplex}).x

    def rerun(objective) -> np.ndarray:
        return run.optimize(li, fine.spec, theta, lower=run.lower, upper=run.upper, objective=objective).theta

    every = fine.objective.on(run.histogram(fine.spec, fine.images, None, params.seed + 99))
    out = {"result": tre(theta), "polished": tre(polish(fine.objective)), "polished-all": tre(polish(every))}
    same = [rerun(fine.objective) for _ in range(reruns)]
    other = [rerun(run.on_sample(fine, params.seed + 7919 * (20 + k))) for k in range(reruns)]
    for k in range(1, reruns + 1):
        out[f"same-{k}"] = tre(np.mean([theta] + same[:k], axis=0))
        out[f"other-{k}"] = tre(np.mean([theta] + other[:k], axis=0))
    return run.outline_measure, out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--split", default="edge")
    ap.add_argument("--cases", type=int, default=40)
    ap.add_argument("--reruns", type=int, default=4)
    ap.add_argument("--kinds", default="", help="comma-separated corpus kinds (default: every kind)")
    args = ap.parse_args()
    kinds = set(filter(None, args.kinds.split(",")))
    specs = [s for s in corpus.plan_split(args.split, 2) if corpus.source_available(s.source)
             and (not kinds or s.kind in kinds)][: args.cases]
    rows = [probe(corpus.build_case(s), args.reruns) for s in specs]
    groups = {"all": [r for _, r in rows], "read as images": [r for o, r in rows if not o],
              "outline-only": [r for o, r in rows if o]}
    for group, chosen in groups.items():
        if not chosen:
            continue
        print(f"{args.split}, {group} ({len(chosen)} cases): median TRE (px)")
        for name in chosen[0]:
            better = sum(r[name] < r["result"] for r in chosen)
            print(f"  {name:13s} {statistics.median(r[name] for r in chosen):.4f}  (below the result on {better})")


if __name__ == "__main__":
    main()
