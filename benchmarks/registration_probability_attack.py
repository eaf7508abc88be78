"""An attack on the self-check with a kind of moving image the corpus never drew and no threshold was tuned on:
**tissue probability maps** (what a segmentation tool such as SPM or FAST writes, and what users register to a T1),
and a **soft brain mask** (a mask smoothed by a Gaussian, as a template's brain-probability map is), registered as a
user does (``topomatch.register(fixed_path, moving_path, metric=m)``, defaults, from files), elastix beside it.

The cases are the validation corpus's (``registration_corpus.py``: its MNI152 2009a sources, its draws of rigid
transforms, sections, frames, crops and thick slices) in a split of their own, ``probability`` (seeds 27xxx, drawn by
no other script), whose moving kinds are made here and added to the corpus's kinds for this run only:

- ``gm_probability``, ``wm_probability``: the grey- or white-matter fraction map of the MNI template (values 0-1,
  smooth, no noise, no bias field: a probability map has neither);
- ``soft_mask``: the brain mask smoothed by a Gaussian of 2 voxels (outline-only, with a ramp instead of an edge);
- ``t1``: the control (the corpus's T1 with its noise and bias).

A third of the probability and soft-mask cases are swapped (the map is the fixed image, the moved T1 the moving one),
as the corpus swaps its label maps and silhouettes. ``--split probability-tight`` (2D, seeds 27x12): the same kinds,
every section cut to a window of 45-60 % of each axis at a random place (the corpus's tight frame: the object fills
the grid, where the outline tests judge least). ``probability-tight-2`` (seeds 28x12): the same design, declared once
the twenty-second round's rule had passed on the tune side (``probability-tight`` had been looked at), run once with
its code. ``probability-tight-3`` (seeds 31x12): the same design again, declared with the twenty-third round's rule
(soft masks, which ``probability-tight`` and ``probability-tight-2`` showed and which are seen now), run once with
the round's code, adopted or not.
``clean-tight`` (seeds 33x12): the same tight design with noise-free images that have exact plateaus and are not
soft masks: the template T1 as it is (exact zeros outside the head), the same clipped at the 95th percentile of the
head, the GM map, and the T1 control; a false-alarm attack on the twenty-third round's rule, run once after it.
``phantom-tight`` (seeds 36x12): the same tight design with BrainWeb-style phantoms (T1-, T2- and PD-like contrasts
from the tissue fractions, no noise, no bias field: a pure tissue is one exact value) and the T1; a second false-alarm
attack on the twenty-third round's rule, declared and run once after it.
``probability-box`` (3D, seeds 29x03; the corpus has no tight 3D frame): the same kinds, fixed and moving volume cut to
one box of 55-70 % of each axis at a random place (the same voxels of both grids: no thick slices, no slab crop here).
``probability-box-2`` (seeds 32x03): the same design, declared with the twenty-third round's rule, run once.
``probability-box-3`` (seeds 35x03): the same design, declared with the twenty-fourth round's rule (``probability-box-2``
is seen: its GM maps' misses were read for that round), run once.
``outline-box`` (3D, seeds 30x03): the same box with the corpus's own outline kinds (silhouette, label map, thresholded
and saturated volumes) and the T1: the issue's headline class in a frame the corpus never draws. Correct = mean TRE
<= 1 pixel (2D) / 1 mm (3D); counts per kind: ok / FF (correct, flagged) / fw (wrong, flagged) / silent (wrong, passed).

    TOPOMATCH_DATA_ROOT=../shared/data .venv/bin/python benchmarks/registration_probability_attack.py \\
        --json benchmarks/results/registration_probability_attack.json
"""

from __future__ import annotations

import dataclasses
import sys
from pathlib import Path

import numpy as np
from scipy import ndimage

sys.path.insert(0, str(Path(__file__).resolve().parent))
import registration_corpus as corpus  # noqa: E402  (the corpus's sources, draws, methods and scoring)

from topomatch.stages.registration.misalign import crop_slab  # noqa: E402

SPLIT = "probability"
TIGHT = {"probability-tight": 27012, "probability-tight-2": 28012, "probability-tight-3": 31012, "clean-tight": 33012,
         "phantom-tight": 36012}
"""The tight-frame splits and their seeds' base (+100 axial, +400 coronal, +500 sagittal sections)."""
KINDS = ("gm_probability", "wm_probability", "soft_mask", "t1")
CLEAN_KINDS = ("t1_clean", "t1_clipped", "gm_probability", "t1")
"""``clean-tight``'s kinds: noise-free images with exact plateaus that are not soft masks (a false-alarm attack on the
twenty-third round's rule)."""
PHANTOM_KINDS = ("t1_phantom", "t2_phantom", "pd_phantom", "t1")
"""``phantom-tight``'s kinds: BrainWeb-style contrasts from the tissue fractions without noise or bias field (a
phantom's pure tissue is one exact value: a plateau at the brightest tissue)."""
T1_VALUES = (0.25, 0.6, 1.0)
"""CSF, GM, WM of the T1 phantom (dark CSF, bright white matter); T2 and PD use the corpus's values."""
BOX = {"probability-box": (KINDS, 29003), "probability-box-2": (KINDS, 32003), "probability-box-3": (KINDS, 35003),
       "outline-box": (("silhouette", "labels", "threshold", "saturated", "t1"), 30003)}
"""The 3D box splits: their kinds and their seeds' base (+100 the 2 mm volumes, +700 the 1.5 mm ones)."""
SOFT_MASK_SIGMA = 2.0
"""Voxels: the Gaussian that makes the soft brain mask."""
SOURCES = {3: [("mni", 20), ("mni15", 10)], 2: [("mni-axial", 20), ("mni-coronal", 20), ("mni-sagittal", 20)]}
SEEDS = {("mni", 3): 27103, ("mni15", 3): 27703, ("mni-axial", 2): 27102, ("mni-coronal", 2): 27402,
         ("mni-sagittal", 2): 27502}


def kind_probability(tissue: str):
    def make(f: corpus.Fields, spec: corpus.CaseSpec, deg: corpus.Degrade) -> np.ndarray:
        return np.clip(f.maps[tissue], 0.0, 1.0)
    make.__doc__ = f"The {tissue.upper()} fraction map (0-1), as it is: no noise, no bias field."
    return make


def kind_soft_mask(f: corpus.Fields, spec: corpus.CaseSpec, deg: corpus.Degrade) -> np.ndarray:
    """The brain mask smoothed by a Gaussian of :data:`SOFT_MASK_SIGMA` voxels (no noise)."""
    return ndimage.gaussian_filter((f.maps["mask"] > 0.5).astype(np.float64), SOFT_MASK_SIGMA)


def kind_t1_clean(f: corpus.Fields, spec: corpus.CaseSpec, deg: corpus.Degrade) -> np.ndarray:
    """The template T1 as it is: no noise, no bias field (exactly 0 outside the head)."""
    return f.maps["t1"].copy()


def kind_t1_clipped(f: corpus.Fields, spec: corpus.CaseSpec, deg: corpus.Degrade) -> np.ndarray:
    """The template T1 clipped at the 95th percentile of its head, no noise (a saturated window, exact at both ends)."""
    t1 = f.maps["t1"]
    return np.minimum(t1, np.percentile(t1[t1 > 0], 95))


def kind_phantom(values):
    def make(f: corpus.Fields, spec: corpus.CaseSpec, deg: corpus.Degrade) -> np.ndarray:
        return corpus._contrast(f, values, spec.contrast_jitter)
    make.__doc__ = "A tissue-fraction contrast without noise or bias field (a phantom)."
    return make


def register_split() -> None:
    """Add the splits and their kinds to the corpus module (this process only; once: the wrappers below would
    otherwise crop a box twice)."""
    if SPLIT in corpus.SPLITS:
        return
    corpus.KIND_MAKERS.update({"gm_probability": kind_probability("gm"), "wm_probability": kind_probability("wm"),
                               "soft_mask": kind_soft_mask, "t1_clean": kind_t1_clean, "t1_clipped": kind_t1_clipped,
                               "t1_phantom": kind_phantom(T1_VALUES), "t2_phantom": kind_phantom(corpus.T2_VALUES),
                               "pd_phantom": kind_phantom(corpus.PD_VALUES)})
    corpus.SWAPPABLE = tuple(corpus.SWAPPABLE) + KINDS[:3]
    corpus.SPLITS.update({SPLIT: SOURCES, **{t: {2: SOURCES[2]} for t in TIGHT}, **{b: {3: SOURCES[3]} for b in BOX}})
    corpus.KINDS.update({split: KINDS for split in (SPLIT, *TIGHT)} | {box: kinds for box, (kinds, _) in BOX.items()}
                        | {"clean-tight": CLEAN_KINDS, "phantom-tight": PHANTOM_KINDS})
    corpus.SEEDS.update({(SPLIT, source, dim): seed for (source, dim), seed in SEEDS.items()})
    corpus.SEEDS.update({(box, source, 3): base + offset for box, (_, base) in BOX.items()
                         for source, offset in (("mni", 100), ("mni15", 700))})
    corpus.SEEDS.update({(tight, f"mni-{plane}", 2): base + offset for tight, base in TIGHT.items()
                         for plane, offset in (("axial", 100), ("coronal", 400), ("sagittal", 500))})
    last = max(corpus.SPLIT_ORDER.values())
    corpus.SPLIT_ORDER.update({split: last + 100 + i for i, split in enumerate((SPLIT, *TIGHT, *BOX))})
    plan = corpus.plan_case

    def plan_case(split: str, source: str, dim: int, index: int, place: int) -> corpus.CaseSpec:
        spec = plan(split, source, dim, index, place)
        if split in BOX:
            return dataclasses.replace(spec, thick=False, crop=None)
        if split not in TIGHT:
            return spec
        u = np.random.default_rng([spec.seed, index, 7]).uniform(size=4)  # the corpus's tight window: 45-60 %
        section = {"position": spec.section["position"], "spacing": spec.section["spacing"], "frame": "tight",
                   "crop_fractions": [float(v) for v in 0.45 + 0.15 * u[:2]], "crop_starts": [float(v) for v in u[2:]]}
        return dataclasses.replace(spec, section=section)

    corpus.plan_case = plan_case
    build = corpus.build_case

    def build_case(spec: corpus.CaseSpec) -> corpus.Case:
        case = build(spec)
        if spec.split not in BOX:
            return case
        u = np.random.default_rng([spec.seed, spec.index, 9]).uniform(size=6)
        fixed, moving = case.fixed, case.moving
        for axis in range(3):  # the same voxels of both grids (one source grid, no thick slices, no slab crop)
            fraction, start = 0.55 + 0.15 * u[axis], u[3 + axis]
            fixed, moving = (crop_slab(im, axis, fraction, start) for im in (fixed, moving))
        return dataclasses.replace(case, fixed=fixed.with_data(fixed.data, name=case.fixed.name),
                                   moving=moving.with_data(moving.data, name=case.moving.name))

    corpus.build_case = build_case
    needed = corpus.maps_needed

    def maps_needed(kind: str, f: corpus.Fields) -> set[str]:
        extra = {"gm_probability": {"gm"}, "wm_probability": {"wm"}, "soft_mask": {"mask"}, "t1_clean": set(),
                 "t1_clipped": set(), **{f"{c}_phantom": {"gm", "wm", "csf"} for c in ("t1", "t2", "pd")}}
        return extra[kind] | {"t1"} if kind in extra else needed(kind, f)

    corpus.maps_needed = maps_needed


if __name__ == "__main__":  # the corpus's command line (registration_corpus.py --help) on this split
    corpus.attack_main(SPLIT, sys.argv[1:], register_split)
