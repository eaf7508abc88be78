"""The residual test's measures on the tune side's images (the ninth round's threshold rule, docs/registration_history.md).

Usage::

    TOPOMATCH_DATA_ROOT=../shared/data .venv/bin/python benchmarks/registration_residual_measures.py \\
        [--splits tune,edge,tight,capture]

For every fixed and moving image of the splits (``registration_corpus.py``, built in memory) that the residual test
judges (``interior_structure`` and ``interior_spread`` both NaN: an object that fills the grid), four measures over
its two Otsu classes:

- ``total``: the within-class variance over the image's variance (the sixth round's measure, threshold 0.01);
- ``contrast``: the larger class variance over the squared difference of the class means
  (:func:`~topomatch.stages.registration.structure.two_class_residual`, the ninth round's, threshold 0.002);
- ``eroded``: ``contrast`` with each class eroded by one pixel first (the edge pixels left out; tried, not adopted);
- ``robust``: each class's squared robust scale (1.4826 x MAD) over the squared difference of the class medians (a
  blurred edge's ramp pixels are a minority of each class; tried, not adopted).

Prints each measure's range per split, dimension and moving kind, and the threshold rule: the geometric mean of the
largest ``contrast`` among outline-only kinds (silhouette, threshold) and the smallest among structured kinds (t1, t2,
pd, inverted, gamma).
"""

from __future__ import annotations

import argparse
import collections
import math
import sys
from pathlib import Path

import numpy as np
from scipy import ndimage

sys.path.insert(0, str(Path(__file__).resolve().parent))
import registration_corpus as corpus  # noqa: E402

from topomatch.stages.registration.image import Image, otsu_threshold  # noqa: E402
from topomatch.stages.registration.structure import two_class_residual  # noqa: E402

OUTLINE_ONLY = ("silhouette", "threshold", "silhouette_resampled")
MEASURES = ("total", "contrast", "eroded", "robust")
STRUCTURED = ("t1", "t2", "pd", "inverted", "gamma")


def measures(image: Image) -> dict[str, float] | None:
    """The four measures of an image the residual test judges, else None."""
    contrast = two_class_residual(image)
    if not math.isfinite(contrast):
        return None
    data = image.data
    upper = data > otsu_threshold(data)
    within = (upper.sum() * data[upper].var() + (~upper).sum() * data[~upper].var()) / data.size
    inner = [ndimage.binary_erosion(c, border_value=1) for c in (upper, ~upper)]
    eroded = (max(data[c].var() for c in inner) / (data[upper].mean() - data[~upper].mean()) ** 2
              if all(c.any() for c in inner) else math.nan)
    robust_scale = [1.4826 * np.median(np.abs(data[c] - np.median(data[c]))) for c in (upper, ~upper)]
    robust = max(robust_scale) ** 2 / (np.median(data[upper]) - np.median(data[~upper])) ** 2
    return {"total": float(within / data.var()), "contrast": contrast, "eroded": float(eroded),
            "robust": float(robust)}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--splits", default="tune,edge,tight,capture")
    args = ap.parse_args()
    groups: dict[tuple, list[dict]] = collections.defaultdict(list)
    for split in args.splits.split(","):
        for dim in (2, 3):
            for spec in corpus.plan_split(split, dim):
                case = corpus.build_case(spec)
                kinds = (spec.kind, "t1") if spec.swapped else ("t1", spec.kind)
                for image, kind in zip((case.fixed, case.moving), kinds):
                    values = measures(image)
                    if values is not None:
                        groups[(split, dim, kind)].append(values)
    print(f"{'split':8s} dim {'kind':11s}   n  " + "  ".join(f"{m:>17s}" for m in MEASURES))
    for (split, dim, kind), rows in sorted(groups.items()):
        ranges = "  ".join(f"{np.nanmin([r[m] for r in rows]):8.4f}-{np.nanmax([r[m] for r in rows]):8.4f}"
                           for m in MEASURES)
        print(f"{split:8s} {dim}D  {kind:11s} {len(rows):3d}  {ranges}")
    pooled = [(kind, r["contrast"]) for (_, _, kind), rows in groups.items() for r in rows]
    high = max(v for k, v in pooled if k in OUTLINE_ONLY)
    low = min(v for k, v in pooled if k in STRUCTURED)
    print(f"largest outline-only {high:.5f}, smallest structured {low:.5f}: geometric mean {math.sqrt(high * low):.5f}")


if __name__ == "__main__":
    main()
