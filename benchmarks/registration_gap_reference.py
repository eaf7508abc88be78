"""Exploration (issue 30, 2026-12-05; not adopted): the objects' own alignment as a second opinion on outline-only
pairs. For each outline-only row of a corpus run (those whose measures hold ``outline_gap``), Powell minimises
``structure.outline_gap`` from the result and prints how far its optimum lies from the result and from the truth.

Usage (a corpus run with ``--cache DIR`` first, so the case files are kept)::

    TOPOMATCH_DATA_ROOT=../shared/data .venv/bin/python benchmarks/registration_corpus.py --split tune \\
        --dims 2,3 --methods ours --metrics jt,mi --cache /tmp/corpus --json /tmp/tune.json
    .venv/bin/python benchmarks/registration_gap_reference.py /tmp/corpus /tmp/tune.json

Finding (docs/registration_history.md, sixth round): the gap's optimum moves correct results far (a silhouette's mask is
not the T1's Otsu object), so it is no reference; in 3D it costs about 80 s a case.
"""

from __future__ import annotations

import json
import math
import sys
import time

import numpy as np
from scipy.optimize import minimize

from topomatch.stages.registration.evaluate import target_registration_error, tre_points
from topomatch.stages.registration.image import rms_radius
from topomatch.stages.registration.io import read_image
from topomatch.stages.registration.params import RegisterParams, for_dimension
from topomatch.stages.registration.register import sample_mask
from topomatch.stages.registration.structure import outline_gap
from topomatch.stages.registration.transform import RigidTransform


def parameters(named: dict) -> np.ndarray:
    """A row's named parameters (angles in degrees) as the transform's parameters (radians)."""
    return np.array([math.radians(v) if n.startswith("angle") else v for n, v in named.items()])


def main(cache: str, results: list[str]) -> None:
    for path in results:
        for r in json.load(open(path))["rows"]:
            if not r["method"].startswith("ours") or "outline_gap" not in (r["measures"] or {}) or not r["estimate"]:
                continue
            fixed = read_image(f"{cache}/{r['case']}_fixed.nii.gz")
            moving = read_image(f"{cache}/{r['case']}_moving.nii.gz")
            k = 1 if fixed.dim == 2 else 3
            radius = rms_radius(fixed, sample_mask(fixed, for_dimension(RegisterParams(), fixed.dim)))
            scales = np.r_[[1 / radius] * k, [1.0] * fixed.dim]
            center = tuple(r["center"])
            theta, truth = parameters(r["estimate"]), parameters(r["truth"])

            def gap(z):
                value = outline_gap(fixed, moving, RigidTransform(tuple(z * scales), center))
                return value if math.isfinite(value) else 1e9

            t0 = time.perf_counter()
            start = gap(theta / scales)
            found = minimize(gap, theta / scales, method="Powell", options={"xtol": 0.05, "maxfev": 300})
            end = found.x * scales
            points = tre_points(fixed)

            def tre(a, b):
                return float(np.mean(target_registration_error(RigidTransform(tuple(a), center),
                                                               RigidTransform(tuple(b), center), points))) / r["unit"]

            print(f"{r['case']:34s} {r['method'][5:]:3s} {r['kind']:10s} {'swapped' if r['swapped'] else '':7s} "
                  f"tre {tre(theta, truth):6.2f}  gap optimum: {tre(end, truth):6.2f} from the truth, "
                  f"{tre(end, theta):6.2f} from the result; gap {start:.2f} -> {found.fun:.2f}; ok {r['ok']} "
                  f"{','.join(r['flags'])} ({time.perf_counter() - t0:.1f} s)", flush=True)


if __name__ == "__main__":
    main(sys.argv[1], sys.argv[2:])
