"""For the next round's label-map detector (docs/registration_history.md, the kind attack): the share of an image's object
(``structure.object_mask``) whose pixels equal their next neighbour along every axis (exact plateaus), and its number
of distinct values, per kind, on the tune, blur and capture splits and the kind attack's ``kinds`` split (2D and 3D),
and for the two bundled ITK PNG slices (uint8). Measures the images only; registers nothing.

    TOPOMATCH_DATA_ROOT=../shared/data .venv/bin/python benchmarks/registration_label_plateau_probe.py

``--compare SPLIT[:SCALE[:KINDS]] ...``: instead, for every image of those splits, whether the label test reads it as
a label map (share at least ``check.label_plateau``, three values or more) with the object above (the detector as the
thirty-fourth round's decision split ``kinds-5`` ran it) and with the object ``data > data.min()`` (the label test's
own object, ~40x cheaper on a 3D volume: no hole filling); prints every image on which the two readings differ.
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

from topomatch.pipeline.errors import InputError  # noqa: E402
from topomatch.stages.registration.image import Image  # noqa: E402
from topomatch.stages.registration.io import read_image  # noqa: E402
from topomatch.stages.registration.structure import object_mask  # noqa: E402

SPLITS = ("tune", "blur", "capture", "kinds")


def plateau_share(image: Image, obj: np.ndarray | None = None) -> float:
    """Share of the object's pixels (``obj``, default :func:`object_mask`) equal to their next neighbour along every
    axis (NaN for an empty object)."""
    equal = np.ones(image.data.shape, dtype=bool)
    for axis in range(image.data.ndim):
        x = np.moveaxis(image.data, axis, 0)
        e = np.zeros(x.shape, dtype=bool)
        e[:-1] = x[:-1] == x[1:]
        equal &= np.moveaxis(e, 0, axis)
    obj = object_mask(image) if obj is None else obj
    return float(equal[obj].mean()) if obj.any() else float("nan")


def compare(plans: list[str]) -> None:
    """The two readings of every image of ``plans`` (``split[:scale[:kind,kind]]``), and the images they differ on."""
    from topomatch.stages.registration.params import CheckSpec

    kinds.register_split()
    limit, counts, differ = CheckSpec().label_plateau, collections.Counter(), []
    with tempfile.TemporaryDirectory() as tmp:
        for plan in plans:
            split, scale, only = (plan.split(":") + ["1", ""])[:3]
            for dim in (2, 3):
                for spec in corpus.plan_split(split, dim, float(scale)):
                    if only and spec.kind not in only.split(","):
                        continue
                    try:
                        _, _, fixed, moving = corpus.write_case(corpus.build_case(spec), Path(tmp))
                    except InputError:  # a constant draw (a crop window that misses the object): not a case
                        continue
                    for role, image in (("fixed", fixed), ("moving", moving)):
                        several = len(np.unique(image.data)) > 2
                        full = several and plateau_share(image) >= limit
                        above = several and plateau_share(image, image.data > image.data.min()) >= limit
                        counts[split, dim, full, above] += 1
                        if full != above:
                            differ.append((spec.id, role, plateau_share(image), plateau_share(image, image.data > image.data.min())))
            print(split, "done", flush=True)
    for (split, dim, full, above), n in sorted(counts.items()):
        print(f"{split} {dim}D: read as a label map with the object {full}, with data > min {above}: {n} images")
    print(f"differ on {len(differ)} images", *differ, sep="\n  ")


def main() -> None:
    if "--compare" in sys.argv:
        return compare(sys.argv[sys.argv.index("--compare") + 1:])
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
