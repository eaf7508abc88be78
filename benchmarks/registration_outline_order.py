"""Why outline-only pairs are registered at order 1 (issue 30): the bundled ITK PD and T1 slices against their
own silhouettes, by JT at order 2 (the outline settings off), by the defaults (order 1, finest level smoothed)
and by MI without the smoothing.

Each slice's object (``structure.object_mask``: the content closed, holes filled) as a uniform 100 on 0 with 2 %
noise, moved by 6 random rigid transforms (+-20 deg, +-15 px, seeds ``[77, i]``); ``register(fixed, moving,
params)`` in process; TRE = mean over every pixel (px). A tune-side check: the ITK slices are a source of the
validation corpus's tune split.

    .venv/bin/python benchmarks/registration_outline_order.py [--json benchmarks/results/registration_outline_order.json]
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np

from topomatch.stages.registration.io import read_image
from topomatch.stages.registration.misalign import moved, random_transform
from topomatch.stages.registration.params import RegisterParams
from topomatch.stages.registration.register import register
from topomatch.stages.registration.structure import object_mask
from topomatch.stages.registration.transform import target_registration_error

ITK_DIR = Path(__file__).resolve().parent.parent / "data" / "images" / "itk"
VARIANTS = {"jt order 2, outline settings off": {"metric": {"outline_alpha": None}, "outline_smoothing": 0},
            "jt (defaults)": {},
            "mi (defaults)": {"metric": "mi"},
            "mi, no smoothing": {"metric": "mi", "outline_smoothing": 0}}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--seeds", type=int, default=6)
    ap.add_argument("--json", type=Path)
    args = ap.parse_args()
    rows = []
    for name in ("BrainProtonDensitySlice.png", "BrainT1Slice.png"):
        image = read_image(ITK_DIR / name)
        silhouette = image.with_data(np.where(object_mask(image), 100.0, 0.0))
        for i in range(args.seeds):
            rng = np.random.default_rng([77, i])
            truth = random_transform(rng, image.center, max_translation=15.0, max_angle=20.0)
            moving = moved(silhouette, truth, noise=0.02, rng=rng)
            for variant, params in VARIANTS.items():
                reg = register(image, moving, RegisterParams.model_validate(params))
                tre = float(target_registration_error(reg.transform, truth, image.points()).mean())
                rows.append({"image": name, "seed": i, "variant": variant, "tre": tre, "ok": reg.ok})
                print(f"{name} {i} {variant:34s} TRE {tre:6.2f} px {'ok' if reg.ok else 'flagged'}", flush=True)
    summary = {}
    for variant in VARIANTS:
        tre = [r["tre"] for r in rows if r["variant"] == variant]
        silent = sum(r["ok"] and r["tre"] > 1 for r in rows if r["variant"] == variant)
        summary[variant] = {"median": float(np.median(tre)), "min": min(tre), "max": max(tre), "silent_wrong": silent}
        print(f"{variant:34s} median {np.median(tre):.2f} px, range {min(tre):.2f}-{max(tre):.2f}, silent wrong {silent}")
    if args.json:
        args.json.write_text(json.dumps({"rows": rows, "summary": summary}, indent=1))


if __name__ == "__main__":
    main()
