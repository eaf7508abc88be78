"""An attack with the pair the issue lists and the corpus never drew: **a skull-stripped image against a full head**
(what a brain-extraction tool writes: the T1 inside the brain, exact zeros outside), registered as a user does
(``topomatch.register(fixed_path, moving_path, metric=m)``, defaults, from files), elastix beside it.

The corpus's cases (``registration_corpus.py``: draws of rigid transforms, noise, bias fields, slab crops, thick slices,
swaps) in a split of their own, ``skull`` (seeds 55xxx, drawn by no other script, declared before any of its results
was seen), on the two sources with a head and a brain mask:

- 3D ``kmeans``: ITK's ``KmeansTest_T1UCharRaw`` (a whole head, 2 x 2 x 3 mm), its brain the non-zero labels of
  ``KmeansTest_T1RawSkullStrip`` in the data root (``images/itk_examples_data``; the same grid);
- 2D ``itk``: the bundled ``BrainT1Slice.png`` (head with skull), its brain the corpus's mask of it (the Otsu
  foreground's largest component, which the dark skull cuts off from the scalp).

Kinds: ``skull_stripped`` (the T1 with its bias field and noise inside the brain, exact 0 outside; a third of them
swapped into the fixed role, the full head then moving) and ``t1`` (the control). Correct = mean TRE <= 1 pixel (2D) /
1 mm (3D); counts: ok / FF (correct, flagged) / fw (wrong, flagged) / silent (wrong, passed).

    TOPOMATCH_DATA_ROOT=../shared/data .venv/bin/python benchmarks/registration_skull_attack.py \\
        --json benchmarks/results/registration_skull_attack.json
"""

from __future__ import annotations

import os
import sys
from functools import lru_cache
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
import registration_corpus as corpus  # noqa: E402  (the corpus's sources, draws, methods and scoring)

from topomatch.stages.registration.io import read_image  # noqa: E402

SPLIT = "skull"
KINDS = ("skull_stripped", "t1")
SOURCES = {3: [("kmeans", 24)], 2: [("itk", 40)]}
SEEDS = {("kmeans", 3): 55203, ("itk", 2): 55602}


@lru_cache(maxsize=None)
def kmeans_with_brain() -> corpus.Fields:
    """The corpus's ``kmeans`` source with a ``brain`` map: the skull-strip label map's non-zero voxels."""
    root = os.environ.get("TOPOMATCH_DATA_ROOT")
    path = Path(root or ".") / "images" / "itk_examples_data" / "KmeansTest_T1RawSkullStrip.nii.gz"
    if not root or not path.is_file():
        raise SystemExit(f"set TOPOMATCH_DATA_ROOT to the shared data (needs {path.name})")
    f = corpus.volume_source("kmeans")
    labels = read_image(path)
    if labels.shape != f.grid.shape:
        raise SystemExit(f"{path}: grid {labels.shape} is not the T1's {f.grid.shape}")
    return f.on(f.grid, {**f.maps, "brain": (labels.data > 0).astype(np.float64)})


def kind_skull_stripped(f: corpus.Fields, spec: corpus.CaseSpec, deg: corpus.Degrade) -> np.ndarray:
    """The T1 (bias field, noise) inside the brain, exact 0 outside."""
    brain = f.maps["brain"] > 0.5 if "brain" in f.maps else corpus._foreground(f)
    return np.where(brain, deg.noise(deg.bias(f.maps["t1"])), 0.0)


def register_split() -> None:
    """Add the split, its kind and the ``kmeans`` brain map to the corpus module (this process only)."""
    if SPLIT in corpus.SPLITS:
        return
    corpus.KIND_MAKERS["skull_stripped"] = kind_skull_stripped
    corpus.SWAPPABLE = tuple(corpus.SWAPPABLE) + ("skull_stripped",)
    corpus.SPLITS[SPLIT], corpus.KINDS[SPLIT] = SOURCES, KINDS
    corpus.SPLIT_ORDER[SPLIT] = max(corpus.SPLIT_ORDER.values()) + 100
    corpus.SEEDS.update({(SPLIT, source, dim): seed for (source, dim), seed in SEEDS.items()})
    fields, needed = corpus.source_fields, corpus.maps_needed

    def source_fields(spec: corpus.CaseSpec) -> corpus.Fields:
        return kmeans_with_brain() if spec.split == SPLIT and spec.source == "kmeans" else fields(spec)

    def maps_needed(kind: str, f: corpus.Fields) -> set[str]:
        return {"t1", "brain" if "brain" in f.maps else "mask"} if kind == "skull_stripped" else needed(kind, f)

    corpus.source_fields, corpus.maps_needed = source_fields, maps_needed


if __name__ == "__main__":  # the corpus's command line (registration_corpus.py --help) on this split
    corpus.attack_main(SPLIT, sys.argv[1:], register_split)
