"""Could the self-check see a mirrored moving image? A probe for a next round (nothing here flags, nothing is chosen).

Each 2D case is registered (in memory, defaults); then the moving image is mirrored along x (its columns: with
rotations over the full circle, one mirror axis covers a flip along either axis in 2D), the mirrored pair's coarse
search's two best transforms are refined at the first level, the better one run through the schedule, and two ratios
are recorded: the mirrored pair's first-level value over the result's there (``coarse``) and its finest-level value
at the schedule's end over the result's (``fine``). A correctly oriented pair should have both well below 1, unless
its anatomy is symmetric about that axis (then near 1); a mirrored one above 1. The mirrored pair is measured with
the result's own measure (its order can differ otherwise: ``interior_spread`` is computed on a block-averaged copy
whose dropped row changes with a flip). ``--flip A`` mirrors the case's moving image along array axis A first (the
attack); ``-1`` keeps it. ``--dims 3`` (eleventh session, for a 3D test): the 3D search turns by at most
``check.angles``, so the moving image is mirrored along each array axis in turn, each with its ``coarse`` ratio
(``coarse_0`` ...; ``fine`` is not computed) and its time. Run::

    TOPOMATCH_DATA_ROOT=../shared/data .venv/bin/python benchmarks/registration_mirror_probe.py --split tune --flip -1 \\
        --json benchmarks/results/registration_mirror_probe_tune_normal.json
"""

from __future__ import annotations

import argparse
import math
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).parent))
import registration_corpus as rc  # noqa: E402

from topomatch.stages.registration import register as R  # noqa: E402
from topomatch.stages.registration.params import RegisterParams, for_dimension  # noqa: E402


def mirrored(image, axis: int):
    return image.with_data(np.ascontiguousarray(np.flip(image.data, axis=axis)))


def mirror_ratios(fixed, moving, registration, axis: int = -1, fine: bool = True) -> tuple[float, float]:
    """(coarse, fine): the pair mirrored along array ``axis`` (-1: x), its best values over the result's, at the first
    and the finest level (``fine`` False: NaN, not run)."""
    params = for_dimension(RegisterParams(), fixed.dim)
    mask = R.sample_mask(fixed, params)
    run = R._Run(fixed, moving, params, mask, None)
    theta = np.asarray(registration.transform.with_center(fixed.center).parameters)
    mirror = R._Run(fixed, mirrored(moving, axis % fixed.dim), params, mask, None)
    if mirror.metric != run.metric:  # the result's measure on both
        mirror.metric = run.metric
        mirror.levels = mirror._pyramid()
    grid = mirror.grid()
    order = [i for i in np.argsort(-grid.values, kind="stable") if math.isfinite(grid.values[i])][:2]
    if not order:
        return math.nan, math.nan
    start, value = max((mirror.refine(grid.thetas[i]) for i in order), key=lambda pv: pv[1])
    if not fine:
        return value / run.levels[0].objective(theta), math.nan
    end = mirror.schedule_from(start)[0]
    return value / run.levels[0].objective(theta), mirror.levels[-1].objective(end) / run.levels[-1].objective(theta)


HALF_TURNS = np.array([[0.0, 0.0, 0.0], [0.0, math.pi, 0.0], [0.0, 0.0, math.pi]])
"""With the moving image mirrored along x, no turn, a half turn about y and one about z: the flips along x, z and y."""


def grid_ratios(fixed, moving, registration) -> dict[str, float]:
    """3D, from the coarse searches alone (eleventh session): the moving image mirrored along x, searched with each of
    :data:`HALF_TURNS` composed with the search's own rotations (``full``) or alone (``bare``); each best search score
    over the unmirrored search's best (or its score at the result, if higher), and the mirrored searches' seconds."""
    params = for_dimension(RegisterParams(), fixed.dim)
    run = R._Run(fixed, moving, params, R.sample_mask(fixed, params), None)
    theta = np.asarray(registration.transform.with_center(fixed.center).parameters)
    grid = run.grid()
    here = max(float(np.max(grid.values)), grid.images.score(theta, min_overlap=0.0))
    c, out = params.check, {}
    own = np.vstack([np.zeros(3)] + [np.eye(3)[axis] * math.radians(a) for axis in range(3) for a in c.angles])
    flipped = mirrored(moving, 2)
    for name, rotations in (("bare", HALF_TURNS), ("full", np.vstack([h + own for h in HALF_TURNS]))):
        t0 = time.perf_counter()
        images = R.SearchImages(fixed, flipped, center=run.center, min_overlap=params.metric.min_overlap,
                                region=run.mask if c.search_region else None)
        best = R.grid_search(images, rotations, lambda a: R.initial_translation(fixed, flipped, "moments", a),
                             steps=c.grid, half_width=run.max_translation)
        out[f"grid_{name}"] = float(np.max(best.values)) / here
        out[f"seconds_{name}"] = time.perf_counter() - t0
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--split", default="tune")
    ap.add_argument("--sources", default="", help="only these sources (comma-separated)")
    ap.add_argument("--flip", type=int, default=-1, help="mirror the moving image along this array axis first (-1: no)")
    ap.add_argument("--dims", type=int, default=2, choices=(2, 3))
    ap.add_argument("--grid", action="store_true", help="3D: the coarse searches' ratios (grid_ratios) instead")
    ap.add_argument("--json", type=Path)
    args = ap.parse_args(argv)
    rows = []
    for spec in rc.plan_split(args.split, args.dims):
        if args.sources and spec.source not in args.sources.split(","):
            continue
        case = rc.build_case(spec)
        moving = case.moving if args.flip < 0 else mirrored(case.moving, args.flip)
        registration = R.register(case.fixed, moving)
        row = {"case": spec.id, "source": spec.source, "kind": spec.kind, "flip": args.flip,
               "ok": bool(registration.ok), "flags": [f.check for f in registration.flags],
               "seconds": registration.seconds}
        if args.dims == 2:
            row["coarse"], row["fine"] = mirror_ratios(case.fixed, moving, registration)
        if args.grid:
            row.update(grid_ratios(case.fixed, moving, registration))
        for axis in range(3) if args.dims == 3 and not args.grid else ():
            t0 = time.perf_counter()
            row[f"coarse_{axis}"] = mirror_ratios(case.fixed, moving, registration, axis, fine=False)[0]
            row[f"seconds_{axis}"] = time.perf_counter() - t0
        rows.append(row)
        print(f"{spec.id:34s} {spec.kind:20s} ok {registration.ok!s:5} " + " ".join(
            f"{k} {v:.3f}" for k, v in row.items() if k.startswith(("coarse", "fine", "seconds", "grid"))), flush=True)
    rc.save_study(args.json, __doc__, None, rows)
    return 0


if __name__ == "__main__":
    sys.exit(main())
