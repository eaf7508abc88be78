"""A probe that chose nothing (fifteenth round, 2026-12-05): could the outlines themselves say how far an outline-only
result is off, and so replace the ``outline`` flag's drop criterion (``check.outline_drop``), the source of most of its
false flags? Measured on the tune side's outline-only JT results, not adopted; docs/registration_history.md says why.

For each outline-only result (a row whose measures hold ``outline_gap``) of the given corpus JSON files: the moving
object (``structure.object_mask``) mapped onto the fixed grid at the estimate, its signed distance (``scipy.ndimage``'s
exact Euclidean transform, physical units) sampled on the fixed object's boundary pixels away from any border, and one
robust least-squares fit of ``d(p) = offset + n(p) . (delta + omega x (p - c))`` (n the fixed outline's normal): a
linearised ICP step. ``offset`` absorbs a uniformly grown or shrunk mask (a dilated silhouette), ``shift`` is the
fitted rigid displacement's mean length over those pixels: the outlines' own estimate of the residual misalignment.

    .venv/bin/python benchmarks/registration_corpus.py --split tune --dims 2,3 --methods ours --metrics jt \\
        --cache /tmp/cases --json /tmp/tune.json            # (and edge, tight, capture, blur, turn)
    .venv/bin/python benchmarks/registration_outline_fit_probe.py /tmp/cases /tmp/*.json \\
        --json benchmarks/results/registration_r15_outline_fit_probe.json
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np
from scipy import ndimage

from topomatch.stages.registration.image import border, grow
from topomatch.stages.registration.interpolation import resample
from topomatch.stages.registration.io import read_image
from topomatch.stages.registration.structure import object_mask
from topomatch.stages.registration.transform import RigidTransform


def outline_fit(fixed, moving, transform: RigidTransform) -> dict:
    """``n`` boundary pixels used, ``offset`` and ``shift`` (physical units), ``residual`` (robust deviation)."""
    fixed_object = object_mask(fixed)
    mapped = resample(moving.with_data(object_mask(moving).astype(np.float64)), transform, fixed, fill=np.nan)
    undefined = ~np.isfinite(mapped)
    moving_object = np.where(undefined, 0.0, mapped) > 0.5
    spacing = np.asarray(fixed.spacing, dtype=np.float64)[::-1]
    signed = (ndimage.distance_transform_edt(~moving_object, sampling=spacing)
              - ndimage.distance_transform_edt(moving_object, sampling=spacing))
    own = (ndimage.distance_transform_edt(~fixed_object, sampling=spacing)
           - ndimage.distance_transform_edt(fixed_object, sampling=spacing))
    used = fixed_object & grow(~fixed_object, 1.0) & ~grow(undefined | border(fixed_object.shape), 3.0)
    if used.sum() < 20:
        return {"n": int(used.sum())}
    normal = np.stack([g[used] for g in np.gradient(ndimage.gaussian_filter(own, 1.0), *spacing)], axis=1)
    normal /= np.maximum(np.linalg.norm(normal, axis=1, keepdims=True), 1e-9)
    q = np.argwhere(used) * spacing
    q -= q.mean(axis=0)
    if q.shape[1] == 2:
        arms = np.stack([-q[:, 1], q[:, 0]], axis=1)[:, None, :]  # d(p)/d(omega), one rotation
    else:
        arms = np.stack([np.cross(np.eye(3)[k], q) for k in range(3)], axis=1)
    design = np.column_stack([np.ones(len(q)), normal, (arms * normal[:, None, :]).sum(axis=2)])
    y, weights = signed[used], np.ones(len(q))
    for _ in range(5):  # iteratively reweighted (Huber, 1.5 robust deviations)
        solution = np.linalg.lstsq(design * weights[:, None], y * weights, rcond=None)[0]
        residual = y - design @ solution
        scale = 1.4826 * float(np.median(np.abs(residual))) + 1e-6
        weights = np.sqrt(np.minimum(1.0, 1.5 * scale / np.maximum(np.abs(residual), 1e-9)))
    dim = q.shape[1]
    displacement = solution[1: 1 + dim] + np.einsum("k,nkd->nd", solution[1 + dim:], arms)
    return {"n": int(len(q)), "offset": float(solution[0]), "residual": scale,
            "shift": float(np.mean(np.linalg.norm(displacement, axis=1)))}


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("cache", type=Path, help="the corpus's --cache folder of the runs")
    ap.add_argument("results", type=Path, nargs="+", help="the corpus's --json files")
    ap.add_argument("--json", type=Path)
    args = ap.parse_args(argv)
    rows = []
    for path in args.results:
        for r in json.loads(path.read_text())["rows"]:
            if not r["method"].startswith("ours") or "outline_gap" not in (r["measures"] or {}) or not r["estimate"]:
                continue
            fixed = read_image(args.cache / f"{r['case']}_fixed.nii.gz")
            moving = read_image(args.cache / f"{r['case']}_moving.nii.gz")
            estimate = RigidTransform.from_degrees(list(r["estimate"].values()), r["center"])
            row = {"case": r["case"], "dim": r["dim"], "kind": r["kind"], "method": r["method"], "tre": r["tre"],
                   "unit": r["unit"], "ok": r["ok"], "flags": r["flags"], "drop": r["measures"].get("consistency"),
                   **outline_fit(fixed, moving, estimate)}
            rows.append(row)
            print(json.dumps(row), flush=True)
    if args.json:
        args.json.write_text(json.dumps({"about": __doc__, "rows": rows}, indent=1))


if __name__ == "__main__":
    main()
