"""3D rigid registration: accuracy, speed and determinism of JT + SPSA against SimpleITK and elastix, side by side.

Usage::

    TOPOMATCH_DATA_ROOT=/work/shared/data python benchmarks/registration_3d.py [--set tune|report|all] \\
        [--cases 30] [--methods ours,simpleitk,elastix] [--json benchmarks/results/registration_3d.json]

Cases (:func:`topomatch.stages.registration.misalign.make_case`): the source volume is the fixed
volume (with noise); the moving volume is it moved by a random rigid T (each Euler angle uniform in
+-15 degrees, each translation in +-15 mm), cases 0-14 mono-modal (T1 -> T1), 15-29 multi-modal
(T1 -> a T2-like contrast: :func:`~topomatch.stages.registration.misalign.t2_like`), every third moving
volume cropped to a 70 % slab along a random axis, Gaussian noise of 3 % of the intensity range on
both. Sets:

- ``tune`` (the development set, on which the defaults were chosen): ITK's ``KmeansTest_T1UCharRaw``
  (128 x 128 x 62 voxels of 2 x 2 x 3 mm) and ``KmeansTest_T1RawSkullStrip`` (the same head, brain only),
  seed 1; ``tune-anatomical``: nibabel's ``anatomical.nii``
  (33 x 41 x 25 voxels of 2 mm), seeds 1, 2 and 3 (seeds 2 and 3 were report sets; their failures chose
  the finest level's reruns and the small-field-of-view coarse levels, so they became tuning sets);
- ``report`` (never used to choose anything): ``anatomical.nii`` with seed 4, ``KmeansTest_T1UCharRaw``
  with seed 3, and ITK's ``KmeansTest_T1RawSkullStrip`` (the same grid, brain only: a volume nothing
  was tuned on) with seed 3.

Success: mean target registration error over the fixed foreground (Otsu) voxels <= 1 mm, from the
true and estimated transforms. Methods: ours (the ``register`` defaults for volumes), SimpleITK (Euler3D,
Mattes MI, regular-step gradient descent, 3 levels, 20 % sampling:
:func:`~topomatch.stages.registration.simpleitk_reference.sitk_register` with ``SimpleITK3DParams``), and elastix's default
rigid parameter map through ``itk-elastix`` (the ``bench`` extra; skipped when not installed). All
in one process, one case after the other, with each library's default thread count.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import statistics
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from registration_corpus import elastix_available  # noqa: E402
from registration_corpus import run_elastix as corpus_elastix  # noqa: E402
from topomatch.stages.registration.evaluate import tre_points
from topomatch.stages.registration.image import Image
from topomatch.stages.registration.io import read_volume
from topomatch.stages.registration.misalign import Case, make_case
from topomatch.stages.registration.params import RegisterParams
from topomatch.stages.registration.register import Flag, Registration, register
from topomatch.stages.registration.simpleitk_reference import SimpleITK3DParams, sitk_register
from topomatch.stages.registration.transform import RigidTransform, target_registration_error

DATA = Path(os.environ.get("TOPOMATCH_DATA_ROOT", "/work/shared/data")) / "images"
SOURCES = {
    "kmeans": DATA / "itk_examples_data" / "KmeansTest_T1UCharRaw.nii.gz",
    "anatomical": DATA / "nibabel_testdata" / "anatomical.nii",
    "skullstrip": DATA / "itk_examples_data" / "KmeansTest_T1RawSkullStrip.nii.gz",
}
SETS = {"tune": [("kmeans", 1), ("skullstrip", 1)], "tune-anatomical": [("anatomical", 1), ("anatomical", 2), ("anatomical", 3)],
        "report": [("anatomical", 4), ("kmeans", 3), ("skullstrip", 3)]}


def cases(source: Image, n: int, seed: int) -> list[Case]:
    return [make_case(source, i, seed=seed, multimodal=i >= n // 2, crop=i % 3 == 2) for i in range(n)]


def mean_tre(truth: RigidTransform, estimate: RigidTransform, fixed: Image) -> float:
    return float(np.mean(target_registration_error(estimate, truth, tre_points(fixed))))


def run_ours(case: Case, params: RegisterParams) -> Registration:
    return register(case.fixed, case.moving, params)


def run_sitk(case: Case) -> Registration:
    return sitk_register(case.fixed, case.moving, SimpleITK3DParams())


def run_elastix(case: Case) -> Registration:
    """elastix's default rigid parameter map (EulerTransform, AdvancedMattesMI, ASGD, 4 resolutions), run as the
    validation corpus runs it (``registration_corpus.run_elastix``)."""
    result = corpus_elastix(None, None, case.fixed, case.moving)
    if result.transform is None:
        return Registration(RigidTransform.identity(tuple(case.fixed.center)), float("nan"),
                            (Flag("elastix", f"elastix failed: {result.error}"),), "elastix/rigid", result.seconds,
                            0, 0, "exception")
    return Registration(result.transform, float("nan"), (), "elastix/rigid(default map)", result.seconds, 0, 0, "")


def summarise(rows: list[dict]) -> dict:
    tre = [r["tre"] for r in rows]
    sec = [r["seconds"] for r in rows]
    ok = [r for r in rows if r["tre"] <= 1.0]
    wrong_unflagged = [r for r in rows if r["tre"] > 1.0 and r["ok"]]
    return {"cases": len(rows), "success": len(ok), "median_tre": statistics.median(tre), "mean_tre": float(np.mean(tre)),
            "max_tre": max(tre), "median_seconds": statistics.median(sec), "flagged": sum(not r["ok"] for r in rows),
            "failures_not_flagged": len(wrong_unflagged)}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--set", choices=["tune", "tune-anatomical", "report", "all"], default="all")
    ap.add_argument("--cases", type=int, default=30)
    ap.add_argument("--sources", default="kmeans,anatomical,skullstrip", help="only these source volumes of the sets")
    ap.add_argument("--methods", default="ours,simpleitk,elastix")
    ap.add_argument("--params", default="{}", help="JSON overrides of the register params (tuning only)")
    ap.add_argument("--json", type=Path, default=None)
    args = ap.parse_args()
    methods = args.methods.split(",")
    if "elastix" in methods and not elastix_available():
        print("itk-elastix is not installed (pip install 'topomatch[bench]'): elastix skipped")
        methods.remove("elastix")
    params = RegisterParams.model_validate(json.loads(args.params))
    # each library's one-time start-up in a process is paid once, outside the timings: elastix loads ITK's modules
    # (~20 s); ours imports scipy's pieces on first use
    warm = read_volume(SOURCES["anatomical"])
    warm_case = Case("warm-up", warm, warm, RigidTransform.identity(tuple(warm.center)), False, False)
    for m, run in (("elastix", run_elastix), ("ours", lambda c: run_ours(c, params))):
        if m in methods:
            t0 = time.perf_counter()
            run(warm_case)
            print(f"{m}: first call in the process (start-up included) {time.perf_counter() - t0:.2f} s", flush=True)
    out: dict = {"machine": {"python": platform.python_version(), "cpus": os.cpu_count(),
                             "load_average_at_start": list(os.getloadavg())},
                 "params": json.loads(args.params), "sets": {}}
    chosen = ["report", "tune"] if args.set == "all" else [args.set]
    for set_name in chosen:
        for source_name, seed in SETS[set_name]:
            if source_name not in args.sources.split(","):
                continue
            source = read_volume(SOURCES[source_name])
            key = f"{set_name}:{source_name}:seed{seed}"
            rows: dict[str, list[dict]] = {m: [] for m in methods}
            for case in cases(source, args.cases, seed):
                for m in methods:
                    reg = {"ours": lambda: run_ours(case, params), "simpleitk": lambda: run_sitk(case),
                           "elastix": lambda: run_elastix(case)}[m]()
                    tre = mean_tre(case.truth, reg.transform, case.fixed)
                    rows[m].append({"case": case.name, "tre": tre, "seconds": reg.seconds, "ok": reg.ok,
                                    "reason": reg.reason, "multimodal": case.multimodal, "cropped": case.cropped})
                print(f"{key} {case.name:30s} " + "  ".join(f"{m} {rows[m][-1]['tre']:6.3f} mm "
                                                            f"{rows[m][-1]['seconds']:5.2f} s"
                                                            f"{'' if rows[m][-1]['ok'] else ' FLAG'}" for m in methods),
                      flush=True)
            out["sets"][key] = {"summary": {m: summarise(r) for m, r in rows.items()}, "cases": rows}
            if args.json:  # after every set: a long run that is interrupted keeps what it measured
                args.json.parent.mkdir(parents=True, exist_ok=True)
                args.json.write_text(json.dumps(out, indent=1, default=float))
            for m in methods:
                s = out["sets"][key]["summary"][m]
                print(f"== {key} {m}: {s['success']}/{s['cases']} within 1 mm, median TRE {s['median_tre']:.3f} mm, "
                      f"median {s['median_seconds']:.2f} s, flagged {s['flagged']}, wrong and not flagged "
                      f"{s['failures_not_flagged']}", flush=True)
    if "ours" in methods:  # determinism: the same seed twice, bit-identical parameters
        source = read_volume(SOURCES["kmeans"])
        case = cases(source, 3, 2)[2]
        a, b = run_ours(case, params), run_ours(case, params)
        out["deterministic"] = a.transform.parameters == b.transform.parameters
        print(f"deterministic (same seed twice, identical parameters): {out['deterministic']}")
    out["machine"]["load_average_at_end"] = list(os.getloadavg())
    if args.json:
        args.json.parent.mkdir(parents=True, exist_ok=True)
        args.json.write_text(json.dumps(out, indent=1, default=float))


if __name__ == "__main__":
    main()
