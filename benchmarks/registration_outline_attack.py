"""An attack on the ``outline`` self-check from images it was not tuned on: outline-only moving images (silhouettes,
the issue's dilated uniform masks) and ordinary pairs, made from ITK example images that the validation corpus
(``registration_corpus.py``) never draws from, registered as a user does (``topomatch.register(fixed_path,
moving_path, metric=m)``, defaults, from files), elastix beside it when installed.

Sources: 2D ``BrainMidSagittalSlice.png``, ``FatMRISlice.png``, ``VisibleWomanHeadSlice.png``,
``VisibleWomanEyeSlice.png``, ``RatLungSlice1.mha``; 3D ``KmeansTest_T1RawSkullStrip.nii.gz`` (a 4-class label
map: the issue's public reproduction, fixed = the label map, moving = its foreground dilated by 2 voxels, made
uniform, 2 % noise, +-15 deg / +-15 mm). Moving kinds (each moved by a random rigid transform, +-15 deg and
+-15 pixels or mm about each axis, 2 % noise):

- ``same``: the source itself (the control: a flag there is a false alarm);
- ``labels``: the source quantised to its three Otsu classes (a label map with an inside);
- ``silhouette0`` / ``silhouette1`` / ``silhouette2``: the source's filled Otsu foreground, dilated by 0, 1, 2
  pixels, at one value (outline-only);
- discrete kinds, made after the move and without noise (the images ``metric.discrete_levels`` is for; not in the
  default run, ``--kinds threshold,posterized``): ``threshold``, the moved source above a percentile of its
  content drawn in [20, 80] (binary, with structure inside); ``posterized``, the moved source quantised to 6
  equal steps of its range (a kind the corpus never draws).

``--frame tight`` crops fixed and moving (after the move) to one window of 50-60 % of each axis at a random place
(the same window in both grids; physical coordinates kept), so that the object fills much of the grid: the frame in
which ``interior_structure`` and ``interior_spread`` cannot judge and ``check.min_residual`` does.

``--frame partner`` (2026-12-05, after a hand probe found it silently wrong) swaps the roles: the kind's image,
unmoved, with noise, is the *fixed* image, and the source moved by the truth and cut to a slab of 60-80 % of one axis
(``misalign.crop_slab``) the moving one, so that the moving image sees only part of the fixed outline.

Correct = mean TRE over the fixed content <= 1 pixel (2D) or 1 mm (3D), as in the corpus. Counts per kind:
ok (correct, passed) / FF (correct, flagged) / fw (wrong, flagged) / silent (wrong, passed).

    TOPOMATCH_DATA_ROOT=../shared/data .venv/bin/python benchmarks/registration_outline_attack.py \\
        --json benchmarks/results/registration_outline_attack.json
"""

from __future__ import annotations

import argparse
import collections
import json
import sys
import tempfile
from pathlib import Path

import numpy as np
from scipy import ndimage

sys.path.insert(0, str(Path(__file__).resolve().parent))
import registration_corpus as corpus  # noqa: E402  (files, methods and TRE as the corpus computes them)

from topomatch.pipeline.paths import data_root  # noqa: E402
from topomatch.stages.registration.image import Image, otsu_threshold  # noqa: E402
from topomatch.stages.registration.io import read_image  # noqa: E402
from topomatch.stages.registration.misalign import crop_slab, moved  # noqa: E402
from topomatch.stages.registration.transform import RigidTransform, n_angles  # noqa: E402

SOURCES_2D = ("BrainMidSagittalSlice.png", "FatMRISlice.png", "VisibleWomanHeadSlice.png", "VisibleWomanEyeSlice.png",
              "RatLungSlice1.mha")
SOURCES_3D = ("KmeansTest_T1RawSkullStrip.nii.gz",)
BUNDLED_2D = ("BrainT1Slice.png", "BrainProtonDensitySlice.png")
"""``--sources bundled``: the two ITK slices the project ships (``data/images/itk``), which the corpus draws from; the
hand probes of 2026-12-05 (a silhouette against a cropped partner) were made from them."""
VOLUMES_3D = ("example4d.nii.gz",)
"""``--sources volumes`` (fifteenth round): 3D only, from nibabel's own test data (installed with nibabel, never drawn by
the corpus): ``example4d.nii.gz``'s first frame, an EPI slab of 128 x 96 x 24 voxels of 2 x 2 x 2.2 mm (a functional
image: low contrast, 53 mm of the head in z)."""
KINDS = ("same", "labels", "silhouette0", "silhouette1", "silhouette2")
DISCRETE_KINDS = ("threshold", "posterized")
ALL_KINDS = KINDS + DISCRETE_KINDS
NOISE = 0.02


def moving_source(source: Image, kind: str) -> Image:
    """The unmoved moving image of ``kind`` made from ``source`` (module docstring)."""
    if kind == "same":
        return source
    if kind == "labels":
        low, high = corpus.multi_otsu(source.data[source.data > source.data.min()])
        return source.with_data(np.digitize(source.data, [low, high]).astype(np.float64), name=f"{source.name}_labels")
    mask = corpus._largest_filled(source.data > otsu_threshold(source.data))
    dilation = int(kind[-1])
    if dilation:
        mask = ndimage.binary_dilation(mask, iterations=dilation)
    return source.with_data(mask.astype(np.float64), name=f"{source.name}_{kind}")


def discrete_after_move(moved_source: Image, kind: str, rng: np.random.Generator) -> Image:
    """The moved source made discrete (module docstring): thresholded at a random percentile or posterized."""
    data = moved_source.data
    if kind == "threshold":
        level = np.percentile(data[data > otsu_threshold(data)], rng.uniform(20, 80))
        return moved_source.with_data((data > level).astype(np.float64))
    steps = np.floor(6 * (data - data.min()) / max(float(np.ptp(data)), 1e-12))
    return moved_source.with_data(np.minimum(steps, 5.0))


def tight_window(image: Image, rng: np.random.Generator) -> tuple[slice, ...]:
    """A window of 50-60 % of each axis at a random place (array order)."""
    keep = [max(8, int(round(rng.uniform(0.5, 0.6) * n))) for n in image.data.shape]
    start = [int(rng.integers(0, n - k + 1)) for n, k in zip(image.data.shape, keep)]
    return tuple(slice(a, a + k) for a, k in zip(start, keep))


def cropped(image: Image, window: tuple[slice, ...]) -> Image:
    """``image`` inside ``window`` (array order), its first pixel's physical position as the new origin."""
    first = np.array([w.start for w in window][::-1], dtype=np.float64)  # ITK order (x, y[, z])
    origin = tuple(float(v) for v in image.physical(first[None, :])[0])
    return Image(np.ascontiguousarray(image.data[window]), image.spacing, origin, image.direction, image.name,
                 image.source)


def random_truth(rng: np.random.Generator, image: Image) -> RigidTransform:
    """Angles within +-15 deg about each axis, translations within +-15 units, about the image's centre."""
    angles = np.radians(rng.uniform(-15, 15, n_angles(image.dim)))
    return RigidTransform((*angles, *rng.uniform(-15, 15, image.dim)), tuple(image.center))


def first_volume(path: Path) -> Image:
    """The first 3D frame of a NIfTI file (the file itself when it is 3D), read as the registration reads it."""
    import nibabel

    image = nibabel.load(str(path))
    if image.ndim == 3:
        return read_image(path)
    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp) / path.name
        nibabel.save(nibabel.Nifti1Image(np.asarray(image.dataobj[..., 0], dtype=np.float32), image.affine), str(out))
        return read_image(out)


def cases(seeds: int, kinds: tuple[str, ...] = KINDS, frame: str = "full", sources: str = "examples",
          dims: tuple[int, ...] = (2, 3)):
    """(id, fixed, moving, truth, kind) for every source, kind and seed (``frame``: module docstring)."""
    folder = data_root() / "images" / "itk_examples_data" if data_root() else None
    if sources == "bundled":
        folder = corpus.ITK_DIR
    elif sources == "volumes":
        import nibabel.testing

        folder = Path(nibabel.testing.data_path)
    elif folder is None or not folder.is_dir():
        raise SystemExit("set TOPOMATCH_DATA_ROOT to the shared data (images/itk_examples_data)")
    names = {"bundled": BUNDLED_2D, "volumes": VOLUMES_3D}.get(sources, SOURCES_2D + SOURCES_3D)
    names = [n for n in names if (3 if n in SOURCES_3D + VOLUMES_3D else 2) in dims]
    for name in names:
        source = first_volume(folder / name) if sources == "volumes" else read_image(folder / name)
        for kind in kinds:
            base = source if kind in DISCRETE_KINDS else moving_source(source, kind)
            for seed in range(seeds):
                rng = np.random.default_rng([seed, ALL_KINDS.index(kind), len(name)])
                truth = random_truth(rng, source)
                if kind in DISCRETE_KINDS:
                    moving = discrete_after_move(moved(base, truth, order=1), kind, rng)
                else:
                    moving = moved(base, truth, order=1, noise=NOISE, rng=rng)
                fixed = source
                if frame == "partner":  # module docstring; the discrete kinds are made after a move: not asked
                    noise = 0.0 if kind == "same" else NOISE * float(np.ptp(base.data))
                    fixed = base.with_data(base.data + noise * rng.normal(size=base.data.shape))
                    moving = crop_slab(moved(source, truth, order=1, noise=NOISE, rng=rng), int(rng.integers(source.dim)),
                                       float(rng.uniform(0.6, 0.8)), float(rng.uniform()))
                if frame == "tight":
                    window = tight_window(source, rng)
                    fixed, moving = cropped(source, window), cropped(moving, window)
                yield f"{Path(name).name.split('.')[0]}-{kind}-{seed}", fixed, moving, truth, kind


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--seeds", type=int, default=4, help="random transforms per source and kind")
    ap.add_argument("--metrics", default="jt,mi")
    ap.add_argument("--kinds", default=",".join(KINDS), help=f"any of {', '.join(ALL_KINDS)}")
    ap.add_argument("--frame", choices=("full", "tight", "partner"), default="full")
    ap.add_argument("--sources", choices=("examples", "bundled", "volumes"), default="examples",
                    help="the ITK example images of the data root (never drawn by the corpus), the two bundled slices, "
                         "or nibabel's EPI volume (3D only, never drawn by the corpus)")
    ap.add_argument("--dims", default="2,3", help="the sources of these dimensions only")
    ap.add_argument("--params", default="", help="JSON overrides of the register parameters (a counterfactual)")
    ap.add_argument("--json", type=Path)
    args = ap.parse_args(argv)
    kinds = tuple(k for k in args.kinds.split(",") if k)
    if set(kinds) - set(ALL_KINDS):
        ap.error(f"unknown kinds {sorted(set(kinds) - set(ALL_KINDS))}")
    if args.frame == "partner" and set(kinds) & set(DISCRETE_KINDS):
        ap.error(f"--frame partner takes the kinds {', '.join(KINDS)} (the discrete kinds are made after a move)")
    corpus.PARAMS.update(json.loads(args.params) if args.params else {})
    runners = {f"ours-{m}": (lambda m: lambda *a: corpus.run_ours(m, *a))(m) for m in args.metrics.split(",")}
    if corpus.elastix_available():
        runners["elastix"] = corpus.run_elastix
    rows, counts = [], collections.Counter()
    with tempfile.TemporaryDirectory() as tmp:
        for cid, fixed, moving, truth, kind in cases(args.seeds, kinds, args.frame, args.sources,
                                                      tuple(int(d) for d in args.dims.split(","))):
            fixed_path, moving_path = Path(tmp) / f"{cid}_fixed.nii.gz", Path(tmp) / f"{cid}_moving.nii.gz"
            corpus.write_image(fixed, fixed_path)
            corpus.write_image(moving, moving_path)
            fixed_read, moving_read = read_image(fixed_path), read_image(moving_path)
            line = [cid]
            for method, run in runners.items():
                result = run(fixed_path, moving_path, fixed_read, moving_read)
                est = result.transform
                tre = corpus.mean_tre(est.with_center(fixed_read.center), truth.with_center(fixed_read.center),
                                      fixed_read) if est is not None else float("inf")
                right = tre <= 1.0
                verdict = ("ok" if right else "silent") if result.ok else ("FF" if right else "fw")
                counts[(fixed.dim, kind, method, verdict)] += 1
                rows.append({"case": cid, "dim": fixed.dim, "kind": kind, "method": method, "tre": round(tre, 4),
                             "verdict": verdict, "flags": result.flags, "measures": result.measures})
                line.append(f"{method} {tre:.2f} {verdict}")
            print(" | ".join(line), flush=True)
    summary = {f"{dim}D {kind} {method}": "/".join(str(counts[(dim, kind, method, v)]) for v in ("ok", "FF", "fw",
                                                                                                  "silent"))
               for dim in sorted({row["dim"] for row in rows}) for kind in kinds for method in runners}
    print("ok / FF / fw / silent")
    for key, value in summary.items():
        print(f"  {key:28s} {value}")
    if args.json:
        args.json.write_text(json.dumps({"about": __doc__, "kinds": kinds, "frame": args.frame, "params": corpus.PARAMS, "summary": summary,
                                         "rows": rows}, indent=1))


if __name__ == "__main__":
    main()
