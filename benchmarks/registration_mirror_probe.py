"""Could the self-check see a mirrored moving image? A probe for a next round (nothing here flags, nothing is chosen).

Each 2D case is registered (in memory, defaults); then the moving image is mirrored along x (its columns: with
rotations over the full circle, one mirror axis covers a flip along either axis in 2D), the mirrored pair's coarse
search's two best transforms are refined at the first level, the better one run through the schedule, and two ratios
are recorded: the mirrored pair's first-level value over the result's there (``coarse``) and its finest-level value
at the schedule's end over the result's (``fine``). A correctly oriented pair should have both well below 1, unless
its anatomy is symmetric about that axis (then near 1); a mirrored one above 1. The mirrored pair is measured with
the result's own measure (its order can differ otherwise: ``interior_spread`` is computed on a block-averaged copy
whose dropped row changes with a flip). ``--flip A`` mirrors the case's moving image along array axis A first (the
attack); ``-1`` keeps it. Run::

    TOPOMATCH_DATA_ROOT=../shared/data .venv/bin/python benchmarks/registration_mirror_probe.py --split tune --flip -1 \\
        --json benchmarks/results/registration_mirror_probe_tune_normal.json
"""

from __future__ import annotations

import argparse
import math
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).parent))
import registration_corpus as rc  # noqa: E402

from topomatch.stages.registration import register as R  # noqa: E402
from topomatch.stages.registration.params import RegisterParams, for_dimension  # noqa: E402


def mirrored(image, axis: int):
    return image.with_data(np.ascontiguousarray(np.flip(image.data, axis=axis)))


def mirror_ratios(fixed, moving, registration) -> tuple[float, float]:
    """(coarse, fine): the x-mirrored pair's best values over the result's, at the first and the finest level."""
    params = for_dimension(RegisterParams(), fixed.dim)
    mask = R.sample_mask(fixed, params)
    run = R._Run(fixed, moving, params, mask, None)
    theta = np.asarray(registration.transform.with_center(fixed.center).parameters)
    mirror = R._Run(fixed, mirrored(moving, fixed.dim - 1), params, mask, None)
    if mirror.metric != run.metric:  # the result's measure on both
        mirror.metric = run.metric
        mirror.levels = mirror._pyramid()
    grid = mirror.grid()
    order = [i for i in np.argsort(-grid.values, kind="stable") if math.isfinite(grid.values[i])][:2]
    if not order:
        return math.nan, math.nan
    start, value = max((mirror.refine(grid.thetas[i]) for i in order), key=lambda pv: pv[1])
    end = mirror.schedule_from(start)[0]
    return value / run.levels[0].objective(theta), mirror.levels[-1].objective(end) / run.levels[-1].objective(theta)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--split", default="tune")
    ap.add_argument("--sources", default="", help="only these sources (comma-separated)")
    ap.add_argument("--flip", type=int, default=-1, help="mirror the moving image along this array axis first (-1: no)")
    ap.add_argument("--json", type=Path)
    args = ap.parse_args(argv)
    rows = []
    for spec in rc.plan_split(args.split, 2):
        if args.sources and spec.source not in args.sources.split(","):
            continue
        case = rc.build_case(spec)
        moving = case.moving if args.flip < 0 else mirrored(case.moving, args.flip)
        registration = R.register(case.fixed, moving)
        coarse, fine = mirror_ratios(case.fixed, moving, registration)
        rows.append({"case": spec.id, "source": spec.source, "kind": spec.kind, "flip": args.flip,
                     "ok": bool(registration.ok), "flags": [f.check for f in registration.flags],
                     "coarse": coarse, "fine": fine})
        print(f"{spec.id:34s} {spec.kind:20s} ok {registration.ok!s:5} coarse {coarse:.3f} fine {fine:.3f}", flush=True)
    rc.save_study(args.json, __doc__, None, rows)
    return 0


if __name__ == "__main__":
    sys.exit(main())
