"""A false-alarm check of the twenty-third round's soft-mask rule (``structure.PLATEAU``) on acquired volumes it was
not tuned on: the data root's three real MR volumes (``KmeansTest_T1RawSkullStrip``, skull-stripped, exact zeros
outside the brain; ``KmeansTest_T1UCharRaw``; nibabel's ``anatomical.nii``), each cut to 60 random boxes of 30-70 %
of each axis (``misalign.crop_slab``). Per volume: how many boxes the two-class residual judges (the other outline
tests cannot: the object fills the box), and on how many the rule fires (the residual 0 through the plateaus, not
through two exact levels). No registration: the rule decides before one. Prints one line per volume.

    TOPOMATCH_DATA_ROOT=../shared/data .venv/bin/python benchmarks/registration_plateau_false_alarm.py
"""

from __future__ import annotations

import math

import numpy as np

from topomatch.pipeline.paths import data_root
from topomatch.stages.registration.io import read_image
from topomatch.stages.registration.misalign import crop_slab
from topomatch.stages.registration.structure import interior_spread, interior_structure, two_class_residual

VOLUMES = ("itk_examples_data/KmeansTest_T1RawSkullStrip.nii.gz", "itk_examples_data/KmeansTest_T1UCharRaw.nii.gz",
           "nibabel_testdata/anatomical.nii")


def fires(box) -> bool:
    """Whether the plateau rule decided this box's residual: 0 on an image of more than two values (two exact levels
    score 0 without it)."""
    return two_class_residual(box) == 0.0 and np.unique(box.data).size > 2


def main() -> None:
    for name in VOLUMES:
        volume = read_image(data_root() / "images" / name)
        rng = np.random.default_rng(0)
        judged = fired = 0
        for _ in range(60):
            box = volume
            for axis in range(3):
                box = crop_slab(box, axis, rng.uniform(0.3, 0.7), rng.uniform())
            box = box.with_data(box.data.copy())
            if np.ptp(box.data) > 0 and math.isnan(interior_structure(box)) and math.isnan(interior_spread(box)):
                judged += 1
                fired += fires(box)
        print(f"{name}: {judged} of 60 boxes judged by the residual, the plateau rule fires on {fired}")


if __name__ == "__main__":
    main()
