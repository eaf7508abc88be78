"""For the next round's label-map detector (docs/registration.md, the kind attack): the share of an image's object
(``structure.object_mask``) whose pixels equal their next neighbour along every axis (exact plateaus), and its number
of distinct values, per kind, on the tune, blur and capture splits and the kind attack's ``kinds`` split (2D and 3D),
and for the two bundled ITK PNG slices (uint8). Measures the images only; registers nothing.

    TOPOMATCH_DATA_ROOT=../shared/data .venv/bin/python benchmarks/registration_label_plateau_probe.py
"""

from __future__ import annotations

import collections
import sys
import tempfile
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
import registration_corpus as corpus  # noqa: E402
import registration_kind_attack as kinds  # noqa: E402

from topomatch.stages.registration.image import Image  # noqa: E402
from topomatch.stages.registration.io import read_image  # noqa: E402
from topomatch.stages.registration.structure import object_mask  # noqa: E402

SPLITS = ("tune", "blur", "capture", "kinds")


def plateau_share(image: Image) -> float:
    """Share of the object's pixels equal to their next neighbour along every axis (NaN for an empty object)."""
    equal = np.ones(image.data.shape, dtype=bool)
    for axis in range(image.data.ndim):
        x = np.moveaxis(image.data, axis, 0)
        e = np.zeros(x.shape, dtype=bool)
        e[:-1] = x[:-1] == x[1:]
        equal &= np.moveaxis(e, 0, axis)
    obj = object_mask(image)
    return float(equal[obj].mean()) if obj.any() else float("nan")


def main() -> None:
    kinds.register_split()
    found = collections.defaultdict(list)
    with tempfile.TemporaryDirectory() as tmp:
        for split in SPLITS:
            for dim in (2, 3):
                for spec in corpus.plan_split(split, dim):
                    _, _, fixed, moving = corpus.write_case(corpus.build_case(spec), Path(tmp))
                    roles = (spec.kind, "t1") if spec.swapped else ("t1", spec.kind)
                    for kind, image in zip(roles, (fixed, moving)):
                        found[dim, kind].append((plateau_share(image), len(np.unique(image.data))))
    for (dim, kind), values in sorted(found.items()):
        shares, levels = np.array([s for s, _ in values]), [n for _, n in values]
        print(f"{dim}D {kind:22s} {len(values):4d} images  plateau share min / median / max {shares.min():.3f} / "
              f"{np.median(shares):.3f} / {shares.max():.3f}  distinct values {min(levels)}-{max(levels)}")
    for name in ("BrainT1Slice.png", "BrainProtonDensitySlice.png"):
        image = read_image(corpus.ITK_DIR / name)
        print(f"{name}: plateau share {plateau_share(image):.4f}, {len(np.unique(image.data))} distinct values")


if __name__ == "__main__":
    main()
